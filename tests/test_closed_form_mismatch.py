"""Case II of the Theorem: learning from a system whose model is wrong.

With P_{j-1} = (1 + Delta) P_hat_{j-1} and the frequency-wise bound
|Delta(e^{jw})| < |1 + P_{j-1} C_{j-1}| / 2 (docs/theory.md section 2), learning must still
lower the error: ||e_j|| < ||e'_j||, e'_j being system j's error without learning.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import ilcdob
from ilcdob import PlantSpec, build_loop, freqresp
from ilcdob.design import closed_form_filters
from ilcdob.validation.simulate import rmse, simulate_flight

FLEET = ilcdob.default_fleet()
TS = FLEET.sample_time
GRID = np.linspace(1e-3, 0.999 * np.pi / TS, 4000)  # rad/s, up to Nyquist
N = 2000


def _mismatched_source(num_mult, den_mult):
    spec = FLEET.systems[0]
    true = PlantSpec(tuple(np.polymul(spec.plant.num, num_mult)), tuple(np.polymul(spec.plant.den, den_mult)))
    return build_loop(replace(spec, plant=true, model=spec.plant), TS)


def _bound_margin(src) -> float:
    """max over the grid of |Delta| / (|1 + P C| / 2); < 1 means the bound holds."""
    p, p_hat, c = freqresp(src.P, GRID), freqresp(src.nominal.P, GRID), freqresp(src.C, GRID)
    return float(np.max(np.abs(p / p_hat - 1) / (np.abs(1 + p * c) / 2)))


def _improvement(src, dist_w) -> float:
    tgt = FLEET.loops[1]
    t = np.arange(N) * TS
    d = sum(np.sin(w * t + i) for i, w in enumerate(dist_w))
    r = np.zeros(N)
    flown = simulate_flight(src, r, d)
    without = simulate_flight(tgt, r, d)
    df = closed_form_filters(src, tgt).apply(flown.e, flown.d_f)
    with_learning = simulate_flight(tgt, r, d, d_f=df)
    return rmse(with_learning.e) / rmse(without.e)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(gain=st.floats(-0.25, 0.25), lag=st.floats(0.001, 0.03), lead_ratio=st.floats(0.7, 1.3),
       w_high=st.floats(2.0, 40.0))
def test_inside_the_bound_learning_still_improves(gain, lag, lead_ratio, w_high):
    # Delta: a gain error and a lead/lag, P = (1 + gain) (lead s + 1)/(lag s + 1) P_hat
    src = _mismatched_source([(1 + gain) * lead_ratio * lag, 1 + gain], [lag, 1.0])
    assume(_bound_margin(src) < 1.0)
    assert _improvement(src, [0.5, 0.9425, w_high]) < 1.0


def test_outside_the_bound_learning_can_make_it_worse():
    # Delta = 1.5 s/(s + 5): |Delta| -> 1.5 above 5 rad/s, where |1 + P C| -> 1
    src = _mismatched_source([2.5, 5.0], [1.0, 5.0])
    assert _bound_margin(src) > 2.0
    assert _improvement(src, [10.0]) > 1.5
    # the same model error with a disturbance where the bound holds (low frequency) is fine
    assert _improvement(src, [0.3]) < 0.5
