"""Discretisation of the blocks: ZOH with delay, Tustin PID, and the DOB identity M P = Q."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from ilcdob import DOBSpec, PlantSpec, freqresp
from ilcdob.discretize import discretize_m, discretize_plant, discretize_q

TS = 0.02
PLANT = PlantSpec((1.0,), (0.1, 1.0, 0.0, 0.0))


def test_zoh_matches_python_control_without_delay():
    mine = discretize_plant(PLANT, TS)
    ref = ct.sample_system(ct.tf([1.0], [0.1, 1.0, 0.0, 0.0]), TS, method="zoh")
    w = np.logspace(-2, 2, 50)
    np.testing.assert_allclose(freqresp(mine, w), freqresp(ct.ss(ref), w), rtol=1e-6)


def test_zoh_sampling_zero_makes_the_plant_non_minimum_phase():
    # docs/theory.md section 1: relative degree 3 + ZOH -> a sampling zero near z = -3.6
    zeros = discretize_plant(PLANT, TS).zeros()
    outside = zeros[np.abs(zeros) > 1]
    assert outside.size == 1
    assert -3.8 < outside[0].real < -3.4


def _step_samples_exact(delay: float, n: int) -> np.ndarray:
    """Samples of the analytic step response of 1/(s^2 (tau s + 1)) delayed by ``delay``:
    y(t') = t'^2/2 - tau t' + tau^2 (1 - exp(-t'/tau)), t' = t - delay >= 0."""
    tau = 0.1
    tp = np.maximum(np.arange(n) * TS - delay, 0.0)
    return tp**2 / 2 - tau * tp + tau**2 * (1 - np.exp(-tp / tau))


@pytest.mark.parametrize("delay", [0.04, 0.03, 0.013])
def test_zoh_with_delay_matches_continuous_step_response(delay):
    n = 100
    sysd = discretize_plant(PlantSpec(PLANT.num, PLANT.den, delay), TS)
    y = np.asarray(ct.forced_response(sysd, U=np.ones(n)).outputs).ravel()
    exact = _step_samples_exact(delay, n)
    # ZOH with delay is exact for a held input: agreement to rounding
    np.testing.assert_allclose(y, exact, atol=1e-10)


def test_dob_identity_m_times_p_equals_q_at_low_frequency():
    dob = DOBSpec(3, 0.15)
    p, q, m = discretize_plant(PLANT, TS), discretize_q(dob, PLANT, TS), discretize_m(dob, PLANT, TS)
    w = np.logspace(-2, 1, 40)
    err = np.abs(freqresp(p, w) * freqresp(m, w) - freqresp(q, w))
    assert np.max(err) < 1e-3  # Tustin M; the ZOH M of an earlier draft gave 0.6 at 0.5 rad/s
