"""An output-error fit does not depend on the unit of time.

The same records with their time stamps multiplied by 1000 and by 1/1000 (seconds read as milliseconds or as
kiloseconds) must give the same model in the new unit: the same held-out fit (within 0.05 points, the
acceptance) and the poles and delay scaled by the factor (relative 1e-4: the search runs in the data's
units, so only rounding and the stopping point differ; measured: fits within 3e-7 points, poles within
1e-7). The cases: slow processes, whose poles lie below any grid stated in rad/s (Ts 10 s and 2 s,
delays of several samples, one lightly damped), an integrating process with drift (Ts 0.5 s, a trend of degree
1) and a hard case at 10 ms (coloured noise, a fractional delay).
Each model is also held to the true plant's own held-out fit (MATLAB ``compare``, same initial-condition
and trend handling) within 0.5 points.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

from ilcdob.identification.oe import simulate_zoh
from ilcdob.identification.results import compare, fit_percent
from ilcdob.identification.tfest import FitOptions, tfest
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure

SCALES = (1e3, 1e-3)


def _slow_ts10():
    """2 (200 s + 1) / ((500 s + 1)(100 s + 1)), 30 s delay, Ts 10 s, steps held 300 s (the tuples: structure,
    theta, Ts, delay, samples, input hold (-1: doublets), noise AR pole, trend degree)."""
    s = ModelStructure(2, 1, 0)
    return s, s.join(np.array([400.0, 2.0]) / 5e4, np.array([1.0, 600 / 5e4, 1 / 5e4])), 10.0, 30.0, 1500, 30, 0.0, 0


def _slow_ts2():
    """1 / ((60 s + 1)(15 s + 1)), 12 s delay, Ts 2 s, steps held 120 s."""
    s = ModelStructure(2, 0, 0)
    return s, s.join(np.array([1 / 900.0]), np.array([1.0, 75 / 900.0, 1 / 900.0])), 2.0, 12.0, 3600, 60, 0.0, 0


def _resonant_ts10():
    """A lightly damped mode, 0.02 (s + 0.05) / (s^2 + 0.006 s + 0.0004) (0.02 rad/s, damping 0.15), Ts 10 s,
    coloured noise."""
    s = ModelStructure(2, 1, 0)
    return s, s.join(np.array([0.02, 0.001]), np.array([1.0, 0.006, 0.0004])), 10.0, 20.0, 2000, 12, 0.9, 0


def _stable_ts001():
    """(2 s + 3) / (s^2 + 1.4 s + 4), 50 ms delay, Ts 10 ms, coloured noise."""
    s = ModelStructure(2, 1, 0)
    return s, s.join(np.array([2.0, 3.0]), np.array([1.0, 1.4, 4.0])), 0.01, 0.05, 4000, 150, 0.95, 0


def _integrating_ts05():
    """An integrating process 0.5 / (s (2 s + 1)), 1.5 s delay, Ts 0.5 s, zero-mean doublets, an output drift of
    a fifth of the output's spread over the record (fitted as a trend of degree 1)."""
    s = ModelStructure(2, 0, 1)
    return s, s.join(np.array([0.25]), np.array([1.0, 0.5, 0.0])), 0.5, 1.5, 3000, -1, 0.0, 1


CASES = {"Ts 10 s": _slow_ts10, "Ts 2 s": _slow_ts2, "resonant Ts 10 s": _resonant_ts10, "Ts 10 ms": _stable_ts001,
         "integrating with drift, Ts 0.5 s": _integrating_ts05}


def _records(case):
    structure, theta, ts, delay, n, hold, pole, trend = case()
    out = []
    for seed in (0, 1):
        rng = np.random.default_rng(seed)
        if hold > 0:
            u = np.repeat(rng.choice([-1.0, 1.0], n // hold + 1), hold)[:n]
        else:  # doublets: zero net input, so the integrating output stays bounded
            unit = np.concatenate([np.ones(20), -np.ones(20), np.zeros(60)])
            u = np.concatenate([v * unit for v in rng.choice([-1.0, 1.0], n // unit.size + 1)])[:n]
        y = simulate_zoh(structure, theta, u, ts, delay)
        noise = lfilter([1.0], [1.0, -pole], rng.standard_normal(n))
        drift = 0.2 * np.std(y) * np.linspace(-1, 1, n) if trend else 0.0
        out.append((u, y + drift + 0.05 * np.std(y) * noise / np.std(noise)))
    return structure, theta, ts, delay, out, trend


def _fit(structure, ts, records, scale, trend=0):
    flights = [FlightData(np.arange(u.size) * ts * scale, {"u": u, "y": y}) for u, y in records]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = tfest(flights[0], "u", "y", structure, FitOptions(delay="auto", trend=trend), progress=None)
    held = fit_percent(flights[1]["y"], est.predict(flights[1]["u"], flights[1]["y"]))
    return est, held


@pytest.mark.parametrize("name", list(CASES))
def test_scaling_time_scales_the_model_and_keeps_the_fit(name):
    structure, theta, ts, delay, records, trend = _records(CASES[name])
    est, held = _fit(structure, ts, records, 1.0, trend)
    u, y = records[1]
    truth = fit_percent(y, compare(structure, theta, delay, ts, u, y, est.trend))
    assert held >= truth - 0.5, (held, truth)
    poles = np.sort_complex(np.roots(est.den))
    for scale in SCALES:
        other, held_other = _fit(structure, ts, records, scale, trend)
        assert held_other == pytest.approx(held, abs=0.05), (scale, held, held_other)
        np.testing.assert_allclose(np.sort_complex(np.roots(other.den)) * scale, poles, rtol=1e-4,
                                   err_msg=f"poles at time scale {scale:g}")
        assert other.delay / scale == pytest.approx(est.delay, rel=1e-4, abs=1e-9 * ts), scale
