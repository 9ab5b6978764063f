"""The identify figures: a Bode phase that starts at its low-frequency asymptote, the signal's own name on the
compare axis, and a legend that says how wide the uncertainty band is.

The truth of the phase is written here from the factors: ``10.43 / (s^2 (s + 10.03))`` has
``arg G(jw) = -180 deg - atan(w / 10.03)`` (from -180 to -270 deg); with a right-half-plane zero,
``(1 - s/4.5) / (s^2 (0.1 s + 1))`` (written ``10 (1 - 0.2222 s) / (s^2 (s + 10))``) has
``-180 - atan(w / 4.5) - atan(0.1 w)`` (to -360 deg); a delay adds ``-w tau``.
"""

from __future__ import annotations

import numpy as np
import pytest

from ilcdob.identification.oe import simulate_zoh
from ilcdob.identification.plots import fit_figures, phase_deg
from ilcdob.identification.results import TFEstimate
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure


def _estimate(num, den, delay=0.0, ts=0.01, n=2000):
    """A TFEstimate of ``num / den`` (integrators: the trailing zeros of ``den``), its log simulated."""
    st = ModelStructure(len(den) - 1, len(num) - 1, len(den) - len(np.trim_zeros(den, "b")))
    theta = st.join(list(num), list(den))
    t = np.arange(n) * ts
    u = np.sign(np.sin(2 * np.pi * 0.2 * t))
    y = simulate_zoh(st, theta, u, ts, delay) + 1e-3 * np.random.default_rng(0).standard_normal(n)
    cov = 1e-6 * np.eye(st.n_params + (1 if delay else 0))
    est = TFEstimate.from_fit(structure=st, theta=theta, delay=delay, covariance=cov, delay_estimated=bool(delay),
                              sigma2=1e-6, experiments=[(u, y)], ts=ts, validation=None, input="u", output="y",
                              trend=0, fitted=None, solver={})
    return est, FlightData(t, {"u": u, "y": y}, units={"u": "m/s^2", "y": "m"})


@pytest.mark.parametrize("num, den, delay, truth", [
    ([10.43], [1.0, 10.03, 0.0, 0.0], 0.0, lambda w: -180 - np.degrees(np.arctan(w / 10.03))),
    ([-0.2222 * 10, 10.0], [1.0, 10.0, 0.0, 0.0], 0.0,
     lambda w: -180 - np.degrees(np.arctan(w / (10 / 2.222))) - np.degrees(np.arctan(0.1 * w))),
    ([30.0], [1.0, 6.0, 30.0], 0.05, lambda w: -np.degrees(np.arctan2(6.0 * w, 30.0 - w ** 2)) - np.degrees(0.05 * w)),
], ids=["two integrators", "rhp zero", "delay"])
def test_the_bode_phase_is_the_factors_phase(num, den, delay, truth):
    est, fd = _estimate(num, den, delay)
    w = np.logspace(-2, np.log10(0.999 * np.pi / est.ts), 300)
    np.testing.assert_allclose(phase_deg(est, w), truth(w), atol=1e-6)
    drawn = fit_figures(est, [fd], [], w=w)["bode.png"].axes[1].lines[0].get_ydata()
    np.testing.assert_allclose(drawn, truth(w), atol=1e-6)


def test_the_compare_axis_names_the_signal_and_the_legend_the_band():
    est, fd = _estimate([10.43], [1.0, 10.03, 0.0, 0.0])
    figs = fit_figures(est, [fd], [], signals=("vehicle_local_position_setpoint.ax", "vehicle_local_position.x"))
    assert figs["compare.png"].axes[0].get_ylabel() == "vehicle_local_position.x (m)"
    label = figs["bode.png"].axes[0].get_legend().get_texts()[1].get_text()
    assert label.startswith("3-sigma |Delta| band (at most ") and "too narrow to see" in label, label


def test_a_log_on_an_epoch_clock_is_drawn_from_its_first_sample():
    """A log stamped in epoch seconds (PX4's sample logs): the compare axis counts from the first sample and the
    title states that sample's time to the microsecond, instead of ticks offset by "+1.7107733e9"."""
    est, fd = _estimate([10.43], [1.0, 10.03, 0.0, 0.0], ts=0.125, n=400)  # steps exact in binary at 1.7e9 s
    t0 = 1710773350.5
    late = FlightData(fd.t + t0, dict(fd.signals), dict(fd.units))
    ax = fit_figures(est, [late], [])["compare.png"].axes[0]
    np.testing.assert_allclose(ax.lines[0].get_xdata(), fd.t, atol=1e-6)
    assert "time from t = 1710773350.5 s" in ax.get_title()
