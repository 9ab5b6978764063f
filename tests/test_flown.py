"""The learning law as flown on a real vehicle with wrong models (ilcdob.design.flown)."""

from __future__ import annotations

import numpy as np
import pytest

from ilcdob.design import closed_form_filters
from ilcdob.design.flown import (END_FIT_S, VehicleLearning, airframe_path_filter, learning_horizon, model_attitude,
                                 robustness_filter, vehicle_learning)
from ilcdob.errors import SpecError


def _response(b: np.ndarray, a: np.ndarray, w: np.ndarray, ts: float) -> np.ndarray:
    z = np.exp(-1j * w * ts)
    return np.polyval(b[::-1], z) / np.polyval(a[::-1], z)


def test_model_attitude_has_the_model_dc_gain(fleet):
    lp = fleet.loop("UAV2")
    b, a, delay = model_attitude(lp)
    num, den = lp.spec.nominal_plant.num, lp.spec.nominal_plant.den
    assert np.sum(b) / np.sum(a) == pytest.approx(num[-1] / den[-3])
    assert delay == 0


def test_airframe_correction_is_one_around_a_cycle_and_for_equal_models(fleet):
    w = np.array([0.3, 1.0, 5.0, 20.0])
    ts = fleet.sample_time

    def resp(src: str, tgt: str) -> np.ndarray:
        return _response(*airframe_path_filter(fleet.loop(src), fleet.loop(tgt)), w, ts)

    cycle = resp("UAV1", "UAV2") * resp("UAV2", "UAV3") * resp("UAV3", "UAV1")
    np.testing.assert_allclose(cycle, 1.0, atol=1e-9)
    np.testing.assert_allclose(resp("UAV1", "UAV1"), 1.0, atol=1e-12)
    assert abs(resp("UAV1", "UAV3")[0]) == pytest.approx(1.0, abs=0.02)  # DC: both ~unit gain


def test_models_without_two_integrators_are_refused(fleet_file):
    import ilcdob

    text = fleet_file().read_text().replace("den = [0.12, 1.0, 0.0, 0.0]", "den = [0.12, 1.0, 1.0]")
    flt = ilcdob.load_fleet(fleet_file(text, "one.toml"))
    with pytest.raises(SpecError, match=r"model of 'B'.*0 integrator"):
        model_attitude(flt.loop("B"))
    with pytest.raises(SpecError, match="A\\(s\\)/s\\^2"):
        airframe_path_filter(flt.loop("A"), flt.loop("B"))


def test_robustness_filter_is_zero_phase_in_band_and_cuts_noise():
    ts = 0.02
    t = np.arange(3000) * ts
    slow = np.sin(0.9425 * t)
    fast = np.sin(60.0 * t)
    pad = 200
    y = robustness_filter(learning_horizon(slow + fast, ts, pad), ts, 10.0)[pad:-pad]
    core = slice(300, -300)
    np.testing.assert_allclose(y[core], slow[core], atol=1e-3)


def test_robustness_filter_rejects_bad_arguments():
    with pytest.raises(SpecError, match="`cutoff`"):
        robustness_filter(np.zeros(10), 0.02, 200.0)
    with pytest.raises(SpecError, match="`order`"):
        robustness_filter(np.zeros(10), 0.02, 10.0, order=9)


def test_learning_horizon_rest_before_and_line_after():
    x = 1.0 + 0.5 * np.arange(100)
    ext = learning_horizon(x, 0.02, 10)
    np.testing.assert_array_equal(ext[:10], 0.0)
    np.testing.assert_allclose(ext[-10:], 1.0 + 0.5 * np.arange(100, 110))
    np.testing.assert_array_equal(learning_horizon(x, 0.02, 0), x)
    with pytest.raises(SpecError, match="`pad`"):
        learning_horizon(x, 0.02, -1)


def test_learning_horizon_fits_only_the_last_end_fit_seconds():
    ts = 0.02
    n_fit = int(round(END_FIT_S / ts))
    x = np.concatenate([np.full(200, 5.0), 2.0 * np.arange(n_fit)])  # a kink before the fitted end
    np.testing.assert_allclose(learning_horizon(x, ts, 3)[-3:], 2.0 * np.arange(n_fit, n_fit + 3), atol=1e-9)


def test_vehicle_learning_without_extras_is_the_theorem(fleet):
    lf = closed_form_filters(fleet.loop("UAV1"), fleet.loop("UAV2"))
    t = np.arange(600) * fleet.sample_time
    e = 0.01 * np.sin(0.9425 * t) * (1 - np.exp(-t))
    df = 0.2 * np.sin(0.9425 * t + 0.3) * (1 - np.exp(-t))
    plain = VehicleLearning(lf, None, None, gain=1.0)
    assert plain.pad == 0
    np.testing.assert_allclose(plain.apply(e, df), lf.apply(e, df), atol=1e-12)
    built = vehicle_learning(fleet.loop("UAV1"), fleet.loop("UAV2"), cutoff=None, airframe_disturbance=False)
    np.testing.assert_allclose(built.apply(e, df), lf.apply(e, df), atol=1e-12)


def test_vehicle_learning_builds_the_flown_law(fleet):
    src, tgt = fleet.loop("UAV1"), fleet.loop("UAV3")
    law = vehicle_learning(src, tgt, gain=0.5)
    assert law.cutoff == 10.0 and law.order == 4 and law.gain == 0.5
    for got, want in zip(law.path, airframe_path_filter(src, tgt)):
        np.testing.assert_array_equal(got, want)
    assert law.pad == 6 * int(np.ceil(2 * np.pi / 10.0 / fleet.sample_time))
    lf = closed_form_filters(src, tgt)
    assert vehicle_learning(src, tgt, filters=lf).filters is lf
    # the gain scales the new error only: with no previous learning signal the output scales with it
    t = np.arange(800) * fleet.sample_time
    e = 0.01 * np.sin(0.9425 * t) * (1 - np.exp(-t))
    np.testing.assert_allclose(law.apply(e, np.zeros_like(e)),
                               0.5 * vehicle_learning(src, tgt, filters=lf).apply(e, np.zeros_like(e)), atol=1e-12)
