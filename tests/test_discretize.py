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


# --- conditioning at fast sampling and high q_order (ilcdob/discretize.py, "Conditioning") -----------------

from ilcdob import PIDSpec  # noqa: E402
from ilcdob.discretize import m_block, pid_block, plant_block, q_block  # noqa: E402
from test_conditioning import tustin_s, zoh_reference  # noqa: E402


def _zpk(block, w):
    z = np.exp(1j * w * block.ts)
    return block.gain * np.prod(z[:, None] - block.zeros, axis=1) / np.prod(z[:, None] - block.poles, axis=1)


def test_q_is_a_cascade_of_lags_sampled_exactly():
    ts, tau, n, delay = 0.001, 0.15, 8, 0.0437
    blk = q_block(DOBSpec(n, tau), PlantSpec((1.0,), (1.0, 0.0, 0.0), delay), ts)
    w = np.geomspace(0.1, 0.8 * np.pi / ts, 30)
    want = zoh_reference(lambda s: (tau * s + 1.0) ** (-n), ts, w, delay)
    np.testing.assert_allclose(blk.response(w), want, rtol=1e-10)  # measured 3e-13
    np.testing.assert_allclose(freqresp(blk.sys, w), want, rtol=1e-8)  # the plain realisation, z I - A
    # analytic poles: the lags' e^{-Ts/tau} and one 0 per delay state (43 samples + a fraction)
    assert blk.delay_states == 44
    np.testing.assert_array_equal(blk.poles, np.concatenate([np.full(n, np.exp(-ts / tau)), np.zeros(44)]))
    # delta form: A - I without cancellation (the diagonal is expm1(-Ts/tau), not 1 - e^{-Ts/tau} rounded)
    assert np.all(np.diag(blk.a_minus_i)[:n] == np.expm1(-ts / tau))
    np.testing.assert_allclose(blk.a_minus_i + np.eye(blk.sys.nstates), blk.sys.A, rtol=0, atol=1e-15)


@pytest.mark.parametrize("plant", [
    PlantSpec((10.37568301,), (1.0, 10.32326473, 0.0, 0.0)),
    PlantSpec((4.0,), (1.0, 0.4, 4.0, 0.0, 0.0)),       # lightly damped poles: complex zeros of M
    PlantSpec((1.0, 0.2, 9.0), (1.0, 3.0, 0.0, 0.0, 0.0)),  # complex zeros: complex poles of M
    PlantSpec((-1.0, 10.0), (1.0, 8.0, 0.0, 0.0)),      # non-minimum phase: M inverts P_mp (zero mirrored)
])
@pytest.mark.parametrize("ts", [0.001, 0.02])
def test_m_is_mapped_pole_by_pole_with_tustin(plant, ts):
    w = np.geomspace(0.05, 0.9 * np.pi / ts, 60)
    s = tustin_s(ts, w)
    for n in sorted({plant.relative_degree, plant.relative_degree + 2, 8}):
        blk = m_block(DOBSpec(n, 0.15), plant, ts)
        # M = Q/P_mp: a right-half-plane zero of the model is mirrored, P_mp = P_hat (z + s)/(z - s)
        num_mp = np.polyval(plant.num, s)
        for z in np.roots(plant.num):
            if z.real > 0:
                num_mp = num_mp * (z + s) / (z - s)
        want = np.polyval(plant.den, s) / num_mp / (0.15 * s + 1.0) ** n
        # measured <= 4e-10 (delta-form response; the reference's polynomials in s limit it) and 3e-13 (zpk)
        np.testing.assert_allclose(blk.response(w), want, rtol=1e-8)
        np.testing.assert_allclose(_zpk(blk, w), want, rtol=1e-11)
        # the model's integrators are zeros at z = 1 exactly, the relative-degree deficit at z = -1
        integrators = len(plant.den) - len(np.trim_zeros(np.asarray(plant.den), "b"))
        assert np.sum(blk.zeros == 1.0) == integrators
        assert np.sum(blk.zeros == -1.0) == n - plant.relative_degree
        # the realisation's eigenvalues are the analytic poles (cascade of sections)
        eig = 1 + np.linalg.eigvals(blk.a_minus_i)
        np.testing.assert_allclose(np.sort_complex(eig), np.sort_complex(blk.poles), rtol=0, atol=1e-14)
        q_pole = (1 - ts / 0.3) / (1 + ts / 0.3)
        assert np.sum(np.abs(blk.poles - q_pole) < 1e-15) == n  # Q's n-fold pole, exactly repeated


@pytest.mark.parametrize("pid", [PIDSpec(3.0, 0.3, 2.42, 0.05), PIDSpec(3.0, 0.0, 2.4, 0.05),
                                 PIDSpec(1.2, 0.12, 0.0, 0.05)])
def test_pid_is_parallel_tustin(pid):
    ts = 0.001
    blk = pid_block(pid, ts)
    w = np.geomspace(0.05, 0.9 * np.pi / ts, 40)
    s = tustin_s(ts, w)
    want = pid.kp + pid.ki / s + pid.kd * s / (pid.derivative_filter * s + 1)
    np.testing.assert_allclose(blk.response(w), want, rtol=1e-12)
    np.testing.assert_allclose(_zpk(blk, w), want, rtol=1e-12)
    lag = (pid.derivative_filter - ts / 2) / (pid.derivative_filter + ts / 2)
    assert np.allclose(blk.poles, [1.0, lag] if pid.ki > 0 else [lag], rtol=0, atol=1e-16)


@pytest.mark.parametrize("delay", [0.0, 0.0437])
def test_sampled_plant_zeros_are_accurate(delay):
    # relative degree 3 with a fractional delay at 1 ms: its input entries are ~Ts^3; realised in s Ts the
    # zeros keep their digits (measured zero-pole form vs the Poisson ZOH 3e-13; with the tf2ss realisation
    # the zeros were off by 2.5e-8 relative)
    ts = 0.001
    plant = PlantSpec((10.37568301,), (1.0, 10.32326473, 0.0, 0.0), delay)
    blk = plant_block(plant, ts)
    w = np.geomspace(0.1, 0.8 * np.pi / ts, 30)
    want = zoh_reference(lambda s: 10.37568301 / np.polyval(plant.den, s), ts, w, delay)
    z = np.exp(1j * w * ts)
    unit = np.prod(z[:, None] - blk.zeros, axis=1) / np.prod(z[:, None] - blk.poles, axis=1)
    ratio = want / unit
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-10)
    np.testing.assert_allclose(blk.response(w), want, rtol=1e-10)


def test_non_minimum_phase_model_puts_its_all_pass_on_the_q_branch():
    """P_hat = 10 (1 - s/10)/(s^2 (s + 8)) has a zero at s = +10: M = Q/P_mp (zero mirrored to
    -10) and the Q branch is Q A, A = (10 - s)/(10 + s); checked against scipy's ZOH of Q A and
    the Tustin substitution of Q/P_mp, and the DOB loop is stable (it was not with M = Q/P_hat)."""
    from scipy import signal as sps

    from ilcdob.discretize import m_block, q_block, rhp_zeros
    from ilcdob.loop import build_loop, freqresp
    from ilcdob.specs import DOBSpec, PIDSpec, PlantSpec, SystemSpec

    ts, tau = 0.02, 0.2
    model = PlantSpec((-1.0, 10.0), (1.0, 8.0, 0.0, 0.0))
    dob = DOBSpec(q_order=3, q_time_constant=tau)
    assert np.allclose(rhp_zeros(model), [10.0])
    w = np.array([0.3, 1.0, 3.0, 10.0, 40.0])
    z = np.exp(1j * w * ts)
    q_den = np.polymul(np.polymul([tau, 1.0], [tau, 1.0]), [tau, 1.0])
    qa_num, qa_den = [-1.0, 10.0], np.polymul(q_den, [1.0, 10.0])
    bd, ad, _ = sps.cont2discrete((qa_num, qa_den), ts, method="zoh")
    want_q = np.polyval(np.ravel(bd), z) / np.polyval(ad, z)
    assert np.max(np.abs(freqresp(q_block(dob, model, ts).sys, w) / want_q - 1)) < 1e-9
    s = 2 / ts * (z - 1) / (z + 1)
    want_m = np.polyval([1.0, 8.0, 0.0, 0.0], s) / (np.polyval(q_den, s) * np.polyval([1.0, 10.0], s))
    assert np.max(np.abs(freqresp(m_block(dob, model, ts).sys, w) / want_m - 1)) < 1e-9
    spec = SystemSpec("NMP", model, PIDSpec(1.0, 0.1, 1.2, 0.05), dob)
    loop = build_loop(spec, ts)
    assert np.max(np.abs(loop.poles())) < 1
