"""The grids, weights and option checks the FIR designs share (ilcdob.design.filters.frequency_grid).

FIROptions and RobustSetOptions build their grids and weights through the shared functions; the
grids are pinned here against the formulas the options used before they shared them, to the bit,
and the option messages word for word (they are what a user reads).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ilcdob.design.filters.coefficients import direct_form_grid
from ilcdob.design.methods.fir import POINTS_PER_RIPPLE, FIROptions
from ilcdob.design.filters.frequency_grid import FitWeighting, check_advance, check_count, check_w_min, log_linear_grid
from ilcdob.design.methods.robust_set import RobustSetOptions
from ilcdob.errors import SpecError


@pytest.mark.parametrize("ts", [0.02, 0.01, 0.005, 0.0123, 0.001])
def test_log_linear_grid_with_exact_ends_is_the_exports_check_grid(ts):
    wn = math.pi / ts
    got = log_linear_grid(wn * 1e-4, wn, 2048, np.linspace(wn / 2048, wn, 2048), exact_ends=True)
    np.testing.assert_array_equal(got, direct_form_grid(ts))


@pytest.mark.parametrize("ts", [0.02, 0.01, 0.005])
def test_the_options_grids_are_the_formulas_they_had(ts):
    o = RobustSetOptions(n_taps=61, n_grid=40, w_min=0.1, n_verify=500)
    nyq = np.pi / ts
    want = np.unique(np.concatenate([np.logspace(np.log10(0.1), np.log10(nyq), 40),
                                     np.linspace(nyq / 61, nyq, 61)]))
    np.testing.assert_array_equal(o.grid(ts), want)
    want = np.unique(np.concatenate([np.logspace(-4, np.log10(0.1), 200), np.linspace(0.1, nyq, 500)]))
    np.testing.assert_array_equal(o.verify_grid(ts), want)
    f = FIROptions(n_taps=40, advance=3, w_min=0.05, n_grid=50)
    w_max = 0.999 * np.pi / ts
    step = 2 * np.pi / (40 * ts) / POINTS_PER_RIPPLE
    grid = np.unique(np.concatenate([np.logspace(np.log10(0.05), np.log10(w_max), 50),
                                     np.arange(0.05 + step, w_max, step)]))
    keep = np.concatenate([[True], np.diff(np.log(grid)) > 1e-3 * np.log(w_max / 0.05) / 50])
    np.testing.assert_array_equal(f.grid(ts), grid[keep])


def test_weights_are_the_band_weight_inside_the_band_ends_included():
    w = np.array([0.1, 0.3, 1.0, 5.0, 5.1])
    for o in (FIROptions(weight_band=(0.3, 5.0), band_weight=10.0), RobustSetOptions(weight_band=(0.3, 5.0),
                                                                                     band_weight=10.0)):
        assert isinstance(o, FitWeighting)
        np.testing.assert_array_equal(o.weights(w), [1.0, 10.0, 10.0, 10.0, 1.0])
        assert o.weights(w.reshape(5, 1)).shape == (5, 1)


@pytest.mark.parametrize("cls, kwargs, message", [
    (FIROptions, {"n_taps": 1}, "`n_taps`: got 1, expected an integer >= 2"),
    (RobustSetOptions, {"n_taps": 2}, "`n_taps`: got 2, expected an integer >= 3"),
    (FIROptions, {"advance": 80}, "`advance`: got 80, expected an integer in [0, n_taps - 1 = 79]"),
    (RobustSetOptions, {"advance": -1}, "`advance`: got -1, expected None or an integer in [0, n_taps - 1 = 300]"),
    (FIROptions, {"w_min": 0.0}, "`w_min`: got 0.0, expected a frequency > 0 rad/s (a FIR cannot match the "
                                 "integrator of L1 at DC)"),
    (RobustSetOptions, {"w_min": -1.0}, "`w_min`: got -1.0, expected a frequency > 0 rad/s"),
    (FIROptions, {"n_grid": 9}, "`n_grid`: got 9, expected an integer >= 10"),
    (RobustSetOptions, {"n_verify": 10}, "`n_verify`: got 10, expected an integer >= n_grid = 150"),
    (FIROptions, {"weight_band": (2, 1)}, "`weight_band`: got (2, 1), expected (lo, hi) with 0 <= lo < hi"),
    (RobustSetOptions, {"weight_band": (2, 1)}, "`weight_band`: got (2, 1), expected (lo, hi) with 0 <= lo < hi "
                                                "rad/s"),
    (FIROptions, {"band_weight": 0.0}, "`band_weight`: got 0.0, expected > 0"),
    (RobustSetOptions, {"ridge": -1.0}, "`ridge`: got -1.0, expected >= 0"),
    (FIROptions, {"max_iter": 0}, "`max_iter`: got 0, expected an integer >= 1"),
    (RobustSetOptions, {"max_exchange": -1}, "`max_exchange`: got -1, expected an integer >= 0"),
    # the first bad field in the order the options always checked them is the one named
    (FIROptions, {"band_weight": -1.0, "ridge": -1.0}, "`band_weight`: got -1.0, expected > 0"),
    (RobustSetOptions, {"n_grid": 3, "w_min": -1.0}, "`n_grid`: got 3, expected an integer >= 20"),
    (FIROptions, {"n_grid": 3, "w_min": -1.0}, "`w_min`: got -1.0"),
])
def test_option_messages(cls, kwargs, message):
    with pytest.raises(SpecError) as err:
        cls(**kwargs)
    assert str(err.value).startswith(message)


def test_checks_accept_what_is_valid():
    check_count("n", np.int64(3), 3)
    check_advance(None, 5, optional=True)
    check_advance(4, 5)
    check_w_min(1e-9)
    with pytest.raises(SpecError, match="expected an integer >= 3"):
        check_count("n", 3.0, 3)
    with pytest.raises(SpecError, match=r"got None, expected an integer in \[0, n_taps - 1 = 4\]"):
        check_advance(None, 5)
    with pytest.raises(SpecError, match="expected a frequency > 0 rad/s$"):
        check_w_min(float("nan"))
