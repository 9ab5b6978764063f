"""Dryden turbulence (ilcdob.vehicles.dryden) against the MIL-F-8785C spectra written out here."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal as sps

from ilcdob.errors import SpecError
from ilcdob.vehicles.dryden import DrydenWind


def test_series_has_the_dryden_spectra_and_intensities():
    """4000 s at 100 Hz, V = 10 m/s, L = 20 / 20 / 10 m: per component the standard deviation is its
    sigma (measured 0.98 / 1.03 / 1.01 of it) and the Welch spectrum follows the standard's one-sided
    spectrum from 0.05 to 10 rad/s (median ratio measured 1.01 / 1.00 / 1.00). Tolerances: 10 % on
    sigma (about 30 correlation times per percent of a 4000 s record) and on the median ratio."""
    ts, v = 0.01, 10.0
    sigma, length = np.array([1.0, 0.8, 0.5]), np.array([20.0, 20.0, 10.0])
    wind = DrydenWind(4000.0, ts, sigma=sigma, length=length, airspeed=v, seed=1)
    x = wind.series
    np.testing.assert_allclose(x.std(axis=0), sigma, rtol=0.1)
    f, p = sps.welch(x, fs=1 / ts, nperseg=2**14, axis=0)
    w = 2 * np.pi * f
    band = (w > 0.05) & (w < 10.0)
    for i in range(3):
        tau = length[i] / v
        if i == 0:
            phi = sigma[i] ** 2 * (2 * length[i] / (np.pi * v)) / (1 + (tau * w) ** 2)
        else:
            phi = sigma[i] ** 2 * (length[i] / (np.pi * v)) * (1 + 3 * (tau * w) ** 2) / (1 + (tau * w) ** 2) ** 2
        assert np.median(p[band, i] / (2 * np.pi) / phi[band]) == pytest.approx(1.0, abs=0.1), i


def test_low_altitude_parameters_and_sampling():
    """MIL-F-8785C below 1000 ft at 10 m (32.8 ft) and W20 = 5 m/s: L_w = h, L_u = h/(0.177 + 0.000823 h)^1.2,
    sigma_w = 0.1 W20, sigma_u = sigma_w/(0.177 + 0.000823 h)^0.4 (computed here in ft); the mean wind is
    W20 along ``direction``; the callable holds each sample."""
    h_ft = 10.0 / 0.3048
    f = 0.177 + 0.000823 * h_ft
    wind = DrydenWind.low_altitude(60.0, 0.02, 10.0, 5.0, direction=np.pi / 2, seed=3)
    np.testing.assert_allclose(wind.length, [h_ft / f**1.2 * 0.3048] * 2 + [10.0], rtol=1e-12)
    np.testing.assert_allclose(wind.sigma, [0.5 / f**0.4] * 2 + [0.5], rtol=1e-12)
    assert abs(wind.series[:, 1].mean() - 5.0) < 1.0 and abs(wind.series[:, 0].mean()) < 1.0
    np.testing.assert_array_equal(wind(0.03), wind.series[1])
    np.testing.assert_array_equal(wind(1e6), wind.series[-1])
    with pytest.raises(SpecError, match="`altitude`"):
        DrydenWind.low_altitude(10.0, 0.01, 1000.0, 5.0)
    with pytest.raises(SpecError, match="`sigma`"):
        DrydenWind(10.0, 0.01, sigma=(1.0, -1.0, 0.0))
    with pytest.raises(SpecError, match="`ts`"):
        DrydenWind(10.0, 20.0)


def test_a_series_too_long_is_refused_before_it_is_allocated():
    with pytest.raises(SpecError, match=r"DrydenWind: a duration of 1e\+12 s at a sample time of 0\.001 s is "
                                        r"1e\+15 samples; expected at most 5,000,000"):
        DrydenWind(1e12, 0.001)  # 24 PB of white noise
