"""Round trips: data simulated from known transfer functions are identified back.

Acceptance criteria of the identification: noise-free, every parameter within 0.1 %; at 20 dB
output SNR, held-out fit above 95 % and the true parameters inside the reported 3-sigma
intervals in at least 9 of 10 seeded runs. Held-out fit is measured against the noiseless
validation response (model quality); against a validation output that itself carries 20 dB
noise the attainable ceiling would be 90 %.
"""

from __future__ import annotations

import numpy as np
import pytest

from ilcdob.errors import SignalError, SpecError
from ilcdob.signals import FlightData
from ilcdob.identification.oe import simulate_zoh
from ilcdob.uncertainty import ModelStructure
from ilcdob.identification.results import fit_percent
from ilcdob.identification.synthetic import closed_loop_flight
from ilcdob.identification.tfest import FitOptions, tfest
from ilcdob.specs import PIDSpec, PlantSpec

TS = 0.02
#: C(s) = 3 + 0.3/s + 0.12 s/(0.05 s + 1)
PID = PIDSpec(kp=3.0, ki=0.3, kd=0.12, derivative_filter=0.05)
QUIET = {"progress": None}   # silent (the default)


def _excitation(n: int, seed: int, integrators: int = 0) -> np.ndarray:
    """Chirp plus random steps; for plants with integrators a cosine chirp from 0.2 Hz plus
    random doublets (zero net velocity), so that the open-loop position stays bounded."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * TS
    f0, f1, dur = (0.05, 4.0, t[-1]) if integrators == 0 else (0.2, 4.0, t[-1])
    phase = 2 * np.pi * (f0 * t + (f1 - f0) * t**2 / (2 * dur))
    if integrators == 0:
        steps = np.repeat(rng.choice([-1.0, 1.0], size=n // 150 + 1), 150)[:n]
        u = 0.7 * np.sin(phase) + 0.5 * steps
        return u - u.mean()
    doublet = np.concatenate([np.ones(25), -np.ones(25), np.zeros(100)])
    signs = rng.choice([-1.0, 1.0], size=n // doublet.size + 1)
    doublets = np.concatenate([s * doublet for s in signs])[:n]
    return 0.7 * np.cos(phase) + 2.0 * doublets


def _closed_loop(structure, theta, r, noise, delay=0.0):
    """PID (Tustin) around the ZOH plant; measured output y + noise is fed back."""
    den, num = structure.split(theta)
    return closed_loop_flight(PlantSpec(num, den, delay), PID, r, TS, noise)


CASES = {
    # name: (structure, num, den, delay, closed_loop)
    "stable": (ModelStructure(2, 1, 0), [2.0, 3.0], [1.0, 1.4, 4.0], 0.0, False),
    "integrators": (ModelStructure(3, 0, 2), [10.0], [1.0, 10.0, 0.0, 0.0], 0.0, False),
    "delay": (ModelStructure(2, 1, 0), [2.0, 3.0], [1.0, 1.4, 4.0], 0.05, False),
    "closed_loop": (ModelStructure(3, 0, 2), [7.0], [1.0, 7.0, 0.0, 0.0], 0.0, True),
}


def _experiment(case: str, seed: int, snr_db: float | None, n: int = 3000):
    structure, num, den, delay, closed = CASES[case]
    theta = structure.join(num, den)
    rng = np.random.default_rng(1000 + seed)
    if closed:
        t = np.arange(n) * TS
        r = np.repeat(np.random.default_rng(seed).choice([-0.5, 0.5], size=n // 200 + 1), 200)[:n]
        r = r + 0.2 * np.sin(2 * np.pi * (0.05 * t + 1.5 * t**2 / (2 * t[-1])))
        _, y_clean = _closed_loop(structure, theta, r, np.zeros(n), delay)
        scale = 0.0 if snr_db is None else np.std(y_clean) / 10 ** (snr_db / 20)
        noise = scale * rng.standard_normal(n)
        u, y = _closed_loop(structure, theta, r, noise, delay)
        return FlightData(t, {"u": u, "y": y + noise, "y_clean": y, "r": r}, source=f"{case}-{seed}"), theta
    u = _excitation(n, seed, structure.n_integrators)
    y_clean = simulate_zoh(structure, theta, u, TS, delay)
    scale = 0.0 if snr_db is None else np.std(y_clean) / 10 ** (snr_db / 20)
    y = y_clean + scale * rng.standard_normal(n)
    return FlightData(np.arange(n) * TS, {"u": u, "y": y, "y_clean": y_clean}, source=f"{case}-{seed}"), theta


def _options(case: str) -> FitOptions:
    delay = CASES[case][3]
    return FitOptions(delay="auto" if delay else 0.0)


@pytest.mark.parametrize("case", list(CASES))
def test_noise_free_round_trip_recovers_every_parameter(case):
    data, theta = _experiment(case, 0, None)
    est = tfest(data, "u", "y", CASES[case][0], FitOptions(delay=_options(case).delay), **QUIET)
    np.testing.assert_allclose(est.theta, theta, rtol=1e-3)
    assert abs(est.delay - CASES[case][3]) < 1e-3 * TS
    assert est.fit_estimation > 99.9


@pytest.mark.parametrize("case", list(CASES))
def test_20db_snr_fit_and_three_sigma_coverage(case):
    structure = CASES[case][0]
    covered, fits = 0, []
    for seed in range(10):
        data, theta = _experiment(case, seed, 20.0)
        held_out, _ = _experiment(case, 100 + seed, None)
        est = tfest(data, "u", "y", structure, _options(case), **QUIET)
        truth = np.concatenate([theta, [CASES[case][3]]]) if est.delay_estimated else theta
        got = np.concatenate([est.theta, [est.delay]]) if est.delay_estimated else est.theta
        covered += bool(np.all(np.abs(got - truth) <= 3 * est.std))
        u_val = held_out["u"]
        fits.append(fit_percent(held_out["y_clean"], est.predict(u_val, held_out["y_clean"])))
    assert min(fits) > 95.0, fits
    assert covered >= 9, covered


def test_joint_fit_of_several_experiments():
    a, theta = _experiment("stable", 1, 20.0)
    b, _ = _experiment("stable", 2, 20.0)
    single = tfest(a, "u", "y", CASES["stable"][0], **QUIET)
    joint = tfest([a, b], "u", "y", CASES["stable"][0], **QUIET)
    assert np.all(joint.std < single.std)  # twice the data: smaller intervals
    assert np.all(np.abs(joint.theta - theta) <= 3 * joint.std)


def test_initial_state_is_estimated():
    structure, num, den, _, _ = CASES["stable"]
    theta = structure.join(num, den)
    u = _excitation(2000, 3)
    from ilcdob.identification.results import free_response_basis

    y = simulate_zoh(structure, theta, u, TS) + free_response_basis(structure, theta, TS, 2000) @ np.array([1.5, -2.0])
    data = FlightData(np.arange(2000) * TS, {"u": u, "y": y})
    est = tfest(data, "u", "y", structure, **QUIET)
    np.testing.assert_allclose(est.theta, theta, rtol=1e-3)
    at_rest = tfest(data, "u", "y", structure, FitOptions(estimate_x0=False), **QUIET)
    assert np.max(np.abs(at_rest.theta / theta - 1)) > 1e-2  # ignoring x0 biases the fit


def test_uncertainty_bound_and_samples():
    data, theta = _experiment("stable", 4, 20.0)
    est = tfest(data, "u", "y", CASES["stable"][0], **QUIET)
    w = np.logspace(-1, 2, 30)
    bound = est.uncertainty(w)
    assert np.all(bound > 0) and np.all(np.isfinite(bound))
    samples = est.sample(200, np.random.default_rng(0))
    rel = np.array([np.abs(np.polyval(n, 1j * w) / np.polyval(d, 1j * w) / est.frequency_response(w) - 1)
                    for n, d, _ in samples])
    # the 3-sigma linearised bound covers at least 97 % of sampled models at every frequency
    assert np.all(np.mean(rel <= bound, axis=0) >= 0.97)


def test_bad_input_is_reported():
    t = np.arange(100) * TS
    with pytest.raises(SignalError, match="too few"):
        tfest(FlightData(t, {"u": np.sin(t), "y": np.cos(t)}), "u", "y", ModelStructure(4, 2, 0), **QUIET)
    t = np.arange(1000) * TS
    with pytest.raises(SignalError, match="does not excite"):
        tfest(FlightData(t, {"u": np.ones(1000), "y": np.cos(t)}), "u", "y", ModelStructure(2), **QUIET)
    with pytest.raises(SpecError, match="n_zeros"):
        ModelStructure(2, 2, 0)


def test_progress_is_a_callback_and_silent_by_default(capsys):
    """``progress(done, total, what)`` per delay-sweep point and per LM start; None prints nothing."""
    data, _ = _experiment("delay", 5, 20.0, n=1500)
    calls = []
    tfest(data, "u", "y", CASES["delay"][0], FitOptions(delay="auto", max_delay=0.1),
          progress=lambda done, total, what: calls.append((done, total, what)))
    assert all(isinstance(d, int) and isinstance(t, int) and isinstance(w, str) for d, t, w in calls)
    sweep = [(d, t) for d, t, w in calls if w.startswith("delay sweep")]
    assert sweep and [d for d, _ in sweep] == list(range(1, sweep[0][1] + 1))
    runs = [(d, t) for d, t, w in calls if w.startswith("LM:")]
    assert runs and runs[-1][0] == runs[-1][1]
    assert any(w.startswith("initial estimate") and d == 0 for d, _, w in calls)
    capsys.readouterr()
    tfest(data, "u", "y", CASES["delay"][0], FitOptions(delay="auto", max_delay=0.1))
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
