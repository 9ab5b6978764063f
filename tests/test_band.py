"""The learning band: the robustness filter F around the learning filter and its corner (ilcdob.design.filters.band)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal as sps

from ilcdob.design.filters.band import (AMPLIFICATION_TOL, END_FIT_S, NOISE_SHARE, OFF_FRACTION, LearningBand,
                                        check_bandwidth,
                                        choose_band, estimate_noise, learning_horizon)
from ilcdob.design.law import LawContext, LearningLaw
from ilcdob.design.law.designed import Designed
from ilcdob.design.pair import design_pair, pair_band
from ilcdob.errors import SpecError

TS = 0.02


def test_learning_horizon_rest_before_and_line_after():
    x = np.array([1.0, 2.0, 3.0, 4.0])
    ext = learning_horizon(x, TS, 10)
    np.testing.assert_array_equal(ext[:10], 0.0)
    np.testing.assert_array_equal(ext[10:14], x)
    np.testing.assert_allclose(ext[14:], 5.0 + np.arange(10), atol=1e-12)  # the line through the samples
    np.testing.assert_array_equal(learning_horizon(x, TS, 0), x)
    with pytest.raises(SpecError, match="`pad`"):
        learning_horizon(x, TS, -1)


def test_learning_horizon_fits_only_the_last_end_fit_seconds():
    n_fit = int(round(END_FIT_S / TS))
    x = np.concatenate([np.full(50, 7.0), 2.0 * np.arange(n_fit)])  # a kink before the last END_FIT_S
    np.testing.assert_allclose(learning_horizon(x, TS, 3)[-3:], 2.0 * np.arange(n_fit, n_fit + 3), atol=1e-9)


def _through(band, learn, x):
    """``x`` (no learning signal) through a law of ``band`` around ``learn`` (:mod:`ilcdob.design.law`)."""
    law = LearningLaw.from_dict({}, LawContext(core=Designed("test", learn), band=band))
    return law.apply(x, np.zeros_like(x))


@pytest.mark.parametrize("cutoff", [2.0, 10.0, 40.0])
def test_filter_gain_is_the_stated_response_with_zero_phase(cutoff):
    """A sinusoid through the band's stages with an identity learning filter comes out scaled by ``response(w)`` =
    |Butterworth|^4 (two forward-backward passes), built here from scipy.signal.butter, with zero phase
    (interior samples, 1e-6 of the amplitude: the ends are outside the comparison)."""
    band = LearningBand(TS, cutoff)
    t = np.arange(6000) * TS
    b, a = sps.butter(band.order, cutoff / (math.pi / TS))
    for w in (0.5 * cutoff, cutoff, 1.5 * cutoff):
        if w >= math.pi / TS:
            continue
        x = np.sin(w * t + 0.3)
        y = _through(band, lambda e, df: e + df, x)
        gain = abs(sps.freqz(b, a, worN=[w * TS])[1][0]) ** 4
        assert band.response([w])[0] == pytest.approx(gain, rel=1e-9)
        interior = slice(2000, 4000)
        np.testing.assert_allclose(y[interior], gain * x[interior], atol=1e-6)


def test_no_band_is_the_learning_filter_itself():
    band = LearningBand(TS, None, source="off")
    x = np.random.default_rng(0).normal(size=300)
    np.testing.assert_array_equal(_through(band, lambda e, df: 3.0 * e, x), 3.0 * x)
    assert band.pad == 0 and band.sos is None
    np.testing.assert_array_equal(band.response([1.0, 100.0]), 1.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noise_level_and_signal_edge_are_measured(seed):
    """White noise of 0.5 mm plus two sinusoids (0.94 rad/s, 10 cm; 6 rad/s, 2 mm): the estimate is within 5 %
    of 0.5 mm (its scatter over seeds is ~1 %), and the signal edge lies within two Welch bins of 6 rad/s."""
    rng = np.random.default_rng(seed)
    t = np.arange(3000) * TS
    e = 0.1 * np.sin(0.94 * t) + 0.002 * np.sin(6.0 * t) + rng.normal(0.0, 5e-4, t.size)
    est = estimate_noise(e, TS)
    assert est.std == pytest.approx(5e-4, rel=0.05)
    bin_w = 2 * math.pi * est.f[1]
    assert abs(est.edge - 6.0) <= 2 * bin_w


def test_noise_free_data_leave_the_law_unfiltered():
    t = np.arange(3000) * TS
    e = 0.1 * np.sin(0.94 * t) + 1e-3 * np.sin(4.0 * t)
    assert estimate_noise(e, TS).std == 0.0 and estimate_noise(e, TS).edge is None
    band = choose_band(TS, "auto", error=e)
    assert band.cutoff is None and band.source == "off"
    assert "no resolved noise floor" in band.reason


def test_noise_budget_edge_keeps_the_noise_driven_learning_signal_at_its_share(fleet):
    """The corner of the noise budget (a stated sensor noise of 2 mm, UAV2's tilt limit, UAV1 -> UAV2), flown
    through the pair's own learning on pure white noise of that level: the learning signal's RMS is NOISE_SHARE of
    the limit, to 10 % (an 18,000-sample realisation; the budget is an integral over the filters' responses,
    this is a simulation)."""
    from ilcdob.design import closed_form_filters

    a_max = fleet.systems[1].limits.max_acceleration
    lf = closed_form_filters(fleet.loop("UAV1"), fleet.loop("UAV2"))
    band = choose_band(TS, "auto", noise_std=2e-3, a_max=a_max, l1_gain=lambda w: np.abs(lf.l1_response(w)))
    assert band.reason == "set by the noise budget edge" and band.source == "fleet"
    noise = np.random.default_rng(3).normal(0.0, 2e-3, 18000)
    stated = design_pair(fleet, "UAV1", "UAV2", band=band.cutoff)
    rms = np.sqrt(np.mean(stated.learn(noise, np.zeros_like(noise))[1000:-1000] ** 2))
    assert rms == pytest.approx(NOISE_SHARE * a_max, rel=0.1)
    # pure noise carries no signal: from the trial alone the band closes to the lowest Welch bin
    assert pair_band(fleet, "UAV1", "UAV2", error=noise).reason == "set by the signal edge"


def test_model_edge_is_the_largest_safe_corner():
    """|Delta| / (|1 + P C|/2) = 2 above 5 rad/s: the chosen corner keeps F (ratio - 1) within the tolerance,
    and a corner 5 % higher does not."""
    w = np.geomspace(0.01, 150.0, 400)
    ratio = np.where(w > 5.0, 2.0, 0.3)
    band = choose_band(TS, "auto", trust=(w, ratio))
    assert band.reason == "set by the model edge" and band.source == "fleet"
    assert np.max(band.response(w) * (ratio - 1).clip(0)) <= AMPLIFICATION_TOL
    higher = LearningBand(TS, 1.05 * band.cutoff)
    assert np.max(higher.response(w) * (ratio - 1).clip(0)) > AMPLIFICATION_TOL
    assert choose_band(TS, "auto", trust=(w, np.full(w.size, 0.5))).cutoff is None  # trusted everywhere


def test_stated_off_and_high_corners():
    t = np.arange(3000) * TS
    e = np.sin(t) + np.random.default_rng(0).normal(0, 1e-3, t.size)
    assert choose_band(TS, 7.0, error=e).cutoff == 7.0 and choose_band(TS, 7.0, error=e).source == "stated"
    assert choose_band(TS, "off", error=e).cutoff is None
    w = np.geomspace(0.01, 150.0, 400)
    high = choose_band(TS, "auto", trust=(w, np.where(w > 140.0, 1.5, 0.1)))  # only the very top is untrusted
    assert high.cutoff is None and f"{OFF_FRACTION:g} x Nyquist" in high.reason


@pytest.mark.parametrize("value", [0.0, -1.0, 200.0, "fast", float("nan"), True])
def test_bad_bandwidths_are_refused(value):
    with pytest.raises(SpecError, match="--bandwidth.*'auto', 'off' or a corner frequency in \\(0, 157.1\\)"):
        check_bandwidth(value, TS)
    assert check_bandwidth("AUTO", TS) == "auto" and check_bandwidth("12.5", TS) == 12.5


def test_short_trials_are_refused_for_the_noise_estimate():
    with pytest.raises(SpecError, match="at least 64"):
        estimate_noise(np.zeros(10), TS)
