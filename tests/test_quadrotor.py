"""The nonlinear quadrotor that stands in for the real vehicles in identification experiments."""

from __future__ import annotations

import time
from dataclasses import replace

import control as ct
import numpy as np
import pytest

from ilcdob.discretize import discretize_plant
from ilcdob.errors import SignalError, SpecError
from ilcdob.signals import FlightData
from ilcdob.vehicles.quadrotor import (
                                       QuadrotorParams,
                                       equivalent_tau,
                                       fit_first_order,
                                       fly,
                                       linear_equivalent_tau,
                                       table_i_vehicles,
                                       )
from ilcdob.identification.results import fit_percent
from ilcdob.specs import PIDSpec, PlantSpec

NAMES = ["UAV1", "UAV2", "UAV3"]

#: Tolerances stated by the tests below.
TAU_REL_TOL = 0.02          # equivalent tau of the nonlinear vehicle vs the fleet's tau
CHIRP_FIT_MIN = 95.0        # % (MATLAB fit) of 1/(s^2 (tau s + 1)) to the flown x
CHIRP_TAU_REL_TOL = 0.05    # tau that best explains the flown x vs the fleet's tau
STEP_FIT_MIN = 92.0         # % fit of a 0.1 m step flown vs the fleet's linear closed loop


@pytest.fixture(scope="module")
def vehicles() -> dict[str, QuadrotorParams]:
    return table_i_vehicles()


def _spec(fleet, name):
    return next(s for s in fleet.systems if s.name == name)


def _linear_x(tau: float, u: np.ndarray, ts: float, drag: float = 0.0) -> np.ndarray:
    """ZOH response of 1/(s (s + drag) (tau s + 1)) to the recorded command, from rest."""
    sys = discretize_plant(PlantSpec(num=[1.0], den=np.polymul([tau, 1.0], [1.0, drag, 0.0])), ts)
    return np.asarray(ct.forced_response(sys, U=u).outputs)


def test_table_i_matches_fleet(fleet, vehicles):
    assert sorted(vehicles) == sorted(fleet.names) == NAMES
    table = {"UAV1": ("F450", 0.921, 0.228), "UAV2": ("S500", 1.001, 0.240), "UAV3": ("Tarot 650", 1.234, 0.318)}
    derived_tau = {"UAV1": 0.100, "UAV2": 0.1053, "UAV3": 0.1395}  # default_fleet.md, tau = 0.10 s * arm/0.228 m
    for name, p in vehicles.items():
        assert (p.frame, p.mass, p.arm) == table[name]
        assert p.tau == pytest.approx(derived_tau[name], rel=1e-12)
        # the fleet's identified plant b0/(s^2 (s + a0)) finds that lag within 5 %
        assert 1.0 / _spec(fleet, name).plant.den[1] == pytest.approx(derived_tau[name], rel=0.05)
        # documented assumptions: J = diag(0.15, 0.15, 0.28) m l^2, thrust-to-weight 2
        assert p.inertia[0] == pytest.approx(0.15 * p.mass * p.arm**2)
        assert p.inertia[2] == pytest.approx(0.28 * p.mass * p.arm**2)
        assert 4 * p.max_thrust_per_rotor == pytest.approx(2.0 * p.mass * 9.81)


def test_hover_without_inputs_stays_put(fleet, vehicles):
    for name in NAMES:
        fd = fly(vehicles[name], _spec(fleet, name), 10.0, noise_std=0.0)
        for sig in ("x_true", "y_true", "z_true", "x", "acc_cmd"):
            assert np.max(np.abs(fd[sig])) < 1e-3, (name, sig)
        assert np.max(np.abs(fd["pitch"])) < 1e-6


def test_hover_with_noise_stays_close(fleet, vehicles):
    fd = fly(vehicles["UAV3"], _spec(fleet, "UAV3"), 10.0, noise_std=0.005, seed=4)
    assert np.std(fd["x"] - fd["x_true"]) == pytest.approx(0.005, rel=0.15)
    assert np.max(np.abs(fd["x_true"])) < 0.02
    assert np.max(np.abs(fd["z_true"])) < 0.02


@pytest.mark.parametrize("name", NAMES)
def test_equivalent_tau_matches_fleet(vehicles, name):
    p = vehicles[name]
    res = equivalent_tau(p)
    assert abs(res.relative_error) < TAU_REL_TOL, (name, res.tau, p.tau)
    # the response is close to, not exactly, first order (motor lag + rate loop)
    assert res.fit_percent > 80.0
    assert res.response[-1] == pytest.approx(1.0, abs=0.01)   # mass compensation: DC gain 1
    # the linearised design predicts the nonlinear vehicle
    lin = linear_equivalent_tau(p.att_gain, p.rate_gain, p.rate_d_gain, p.motor_time_constant,
                                p.inner_dt, 10 * p.tau)
    assert lin == pytest.approx(res.tau, rel=1e-3)


def test_equivalent_tau_detects_a_slow_attitude_loop(vehicles):
    p = vehicles["UAV1"]
    slow = replace(p, att_gain=0.5 * p.att_gain)
    assert equivalent_tau(slow).tau > 1.6 * p.tau


@pytest.mark.parametrize("name", NAMES)
def test_small_signal_x_matches_fleet_plant_over_a_chirp(fleet, vehicles, name):
    p, spec = vehicles[name], _spec(fleet, name)
    T, amp, f0, f1 = 10.0, 0.5, 0.1, 3.0     # s, m/s^2, Hz, Hz

    def chirp(t):
        return amp * np.sin(2 * np.pi * (f0 * t + (f1 - f0) / (2 * T) * t**2))

    fd = fly(p, spec, T, injection=chirp, noise_std=0.0)
    u, y = fd["acc_cmd"], fd["x_true"]
    assert np.std(y) > 0.02                                   # the chirp does move the vehicle
    fit = fit_percent(y, _linear_x(p.tau, u, fd.ts))
    assert fit > CHIRP_FIT_MIN, (name, fit)
    # the fit discriminates tau: half or twice the time constant is clearly worse
    assert fit_percent(y, _linear_x(0.5 * p.tau, u, fd.ts)) < fit - 3.0
    assert fit_percent(y, _linear_x(2.0 * p.tau, u, fd.ts)) < fit - 3.0
    # with the vehicle's small linear drag in the model, the best tau is the fleet's tau
    drag = p.drag_xy / p.mass
    taus = p.tau * np.linspace(0.8, 1.2, 41)
    best = taus[np.argmax([fit_percent(y, _linear_x(tk, u, fd.ts, drag)) for tk in taus])]
    assert abs(best / p.tau - 1) < CHIRP_TAU_REL_TOL, (name, best)


def _linear_closed_loop_step(spec, ts: float, t: np.ndarray, t_step: float) -> np.ndarray:
    """x of the fleet's linear loop (ZOH plant, Tustin PID) for the same reference step."""
    from ilcdob.discretize import discretize_pid

    pd_, cd = discretize_plant(spec.plant, ts), discretize_pid(spec.controller, ts)
    a, b, c = (np.asarray(m, float) for m in (pd_.A, pd_.B, pd_.C))
    ac, bc, cc, dc = (np.asarray(m, float) for m in (cd.A, cd.B, cd.C, cd.D))
    xp, xc, out = np.zeros((a.shape[0], 1)), np.zeros((ac.shape[0], 1)), np.empty(t.size)
    for k, tk in enumerate(t):
        out[k] = (c @ xp).item()
        e = (1.0 if tk >= t_step else 0.0) - out[k]
        u = (cc @ xc).item() + dc.item() * e
        xc = ac @ xc + bc * e
        xp = a @ xp + b * u
    return out


@pytest.mark.parametrize("name", NAMES)
def test_small_step_reference_is_tracked_like_the_linear_loop(fleet, vehicles, name):
    # 0.1 m: the PID's derivative kick (about 40 (m/s^2)/m at the first sample) stays below
    # the tilt limit, so the step is small-signal
    p, spec = vehicles[name], _spec(fleet, name)
    fd = fly(p, spec, 20.0, reference=lambda t: np.where(t >= 1.0, 0.1, 0.0), noise_std=0.0)
    x = fd["x_true"]
    assert np.all(np.abs(x[fd.t < 1.0]) < 1e-6)
    assert np.max(np.abs(x[fd.t > 15.0] - 0.1)) < 0.003          # settles on the reference
    assert np.max(x) < 0.15                                      # bounded overshoot
    assert np.all(fd["x_ref"][fd.t >= 1.0] == 0.1)
    # ... and flies like the fleet's linear loop (the same PID around 1/(s^2 (tau s + 1))).
    # The derivative kick is a broadband input, where the vehicle (motor lag + rate loop) lags
    # more than a first-order model: UAV1, with the largest kick, reaches about 94.7 %.
    lin = 0.1 * _linear_closed_loop_step(spec, fd.ts, fd.t, 1.0)
    assert fit_percent(x, lin) > STEP_FIT_MIN, fit_percent(x, lin)
    slow = 0.1 * _linear_closed_loop_step(replace(spec, plant=PlantSpec([1.0], [2 * p.tau, 1.0, 0.0, 0.0])),
                                          fd.ts, fd.t, 1.0)
    assert fit_percent(x, slow) < fit_percent(x, lin) - 5.0      # the comparison can tell tau


def test_large_step_saturates_at_the_tilt_limit_and_still_settles(fleet, vehicles):
    p = vehicles["UAV1"]
    fd = fly(p, _spec(fleet, "UAV1"), 20.0, reference=lambda t: np.where(t >= 1.0, 1.0, 0.0),
             noise_std=0.003, seed=2)
    limit = 9.81 * np.tan(p.max_tilt)
    assert np.max(np.abs(fd["acc_cmd"])) == pytest.approx(limit, rel=0.05)   # the command sent
    assert np.max(np.abs(fd["pitch"])) < p.max_tilt + 0.05
    assert np.max(np.abs(fd["x_true"][fd.t > 15.0] - 1.0)) < 0.03


def test_disturbance_pushes_in_its_direction(fleet, vehicles):
    spec = _spec(fleet, "UAV1")
    for sign in (+1.0, -1.0):
        fd = fly(vehicles["UAV1"], spec, 8.0, disturbance=lambda t: sign * 0.5 * (t >= 1.0), noise_std=0.0)
        x = fd["x_true"]
        assert sign * x[np.argmax(np.abs(x))] > 0.05           # displaced along d
        assert np.min(sign * x) > -0.005                      # not against it
        assert np.all(fd["d"][fd.t >= 1.0] == sign * 0.5)
        # the controller pushes back: a mean commanded acceleration against d
        assert sign * np.mean(fd["acc_cmd"][fd.t > 4.0]) < -0.3


def test_injection_enters_the_command(fleet, vehicles):
    spec = _spec(fleet, "UAV1")
    fd = fly(vehicles["UAV1"], spec, 2.0, injection=lambda t: 0.2 * np.ones_like(t), noise_std=0.0)
    assert fd["acc_cmd"][0] == pytest.approx(0.2)            # at rest: C{0} + w
    assert np.all(fd["w"] == 0.2)
    assert fd["x_true"][-1] > 0.0


def test_seeded_noise_is_reproducible(fleet, vehicles):
    p, spec = vehicles["UAV1"], _spec(fleet, "UAV1")
    a = fly(p, spec, 3.0, noise_std=0.003, seed=11)
    b = fly(p, spec, 3.0, noise_std=0.003, seed=11)
    c = fly(p, spec, 3.0, noise_std=0.003, seed=12)
    g = fly(p, spec, 3.0, noise_std=0.003, seed=np.random.default_rng(11))
    for sig in a.signals:
        np.testing.assert_array_equal(a[sig], b[sig])
        np.testing.assert_array_equal(a[sig], g[sig])
    assert not np.array_equal(a["x"], c["x"])
    assert a.metadata["seed"] == 11 and a.metadata["noise_std_m"] == 0.003
    assert a.metadata["vehicle"] == "UAV1" and "F450" in a.source


def test_flight_data_layout(fleet, vehicles, tmp_path):
    fd = fly(vehicles["UAV1"], _spec(fleet, "UAV1"), 1.0, ts=0.02)
    assert isinstance(fd, FlightData)
    assert fd.ts == pytest.approx(0.02) and len(fd) == 51 and fd.t[0] == 0.0
    for sig in ("acc_cmd", "x", "x_true", "x_ref", "w", "d"):
        assert sig in fd.signals
    assert fd.units["acc_cmd"] == "m/s^2" and fd.units["x"] == "m"
    fd.to_csv(str(tmp_path / "flight.csv"))
    assert (tmp_path / "flight.csv").read_text().startswith("# units: time=s, acc_cmd=m/s^2")


def test_measurement_delay_shifts_the_measurement(fleet, vehicles):
    spec = _spec(fleet, "UAV1")
    fd = fly(vehicles["UAV1"], spec, 4.0, reference=lambda t: 0.5 * (t >= 0.5), noise_std=0.0,
             measurement_delay=0.04)
    np.testing.assert_allclose(fd["x"][2:], fd["x_true"][:-2], atol=1e-12)
    assert fd.metadata["measurement_delay_s"] == pytest.approx(0.04)


def test_sixty_second_flight_is_fast(fleet, vehicles):
    t0 = time.perf_counter()
    fly(vehicles["UAV3"], _spec(fleet, "UAV3"), 60.0, reference=lambda t: 1.0 * (t > 1.0))
    assert time.perf_counter() - t0 < 5.0


def test_fit_first_order_recovers_tau():
    t = np.linspace(0, 1.5, 301)
    tau, fit = fit_first_order(t, 1 - np.exp(-t / 0.137))
    assert tau == pytest.approx(0.137, rel=1e-4) and fit > 99.9


@pytest.mark.parametrize("kwargs, field", [
    (dict(mass=-1.0), "`mass`"),
    (dict(arm=0.0), "`arm`"),
    (dict(tau=float("nan")), "`tau`"),
    (dict(tau=0.005), "`tau`"),                  # faster than the motors allow
    (dict(max_rotor_speed=300.0, thrust_coefficient=2e-5), "`max_rotor_speed`"),   # cannot hover
    (dict(motor_time_constant=0.0), "`motor_time_constant`"),
    (dict(drag_xy=-0.1), "`drag_xy`"),
    (dict(inner_rate_hz=10.0), "`inner_rate_hz`"),
    (dict(bogus=1.0), "`overrides`"),
])
def test_invalid_parameters_raise(kwargs, field):
    base = dict(name="X", mass=1.0, arm=0.25, tau=0.1)
    base.update(kwargs)
    with pytest.raises(SpecError, match=field):
        QuadrotorParams.from_table(**base)


def test_invalid_parameters_direct(vehicles):
    p = vehicles["UAV1"]
    with pytest.raises(SpecError, match=r"`inertia`.*three finite numbers > 0"):
        replace(p, inertia=(0.01, -0.01, 0.02))
    with pytest.raises(SpecError, match=r"`max_tilt`: got 2.0.*\(0, pi/2\)"):
        replace(p, max_tilt=2.0)
    with pytest.raises(SpecError, match=r"`mass`: got -1"):
        replace(p, mass=-1)
    with pytest.raises(SpecError, match="`name`"):
        replace(p, name="")


def test_invalid_flight_arguments(fleet, vehicles):
    p, spec = vehicles["UAV1"], _spec(fleet, "UAV1")
    with pytest.raises(SpecError, match=r"`ts`: got 0.003.*multiple of the inner step 0.002"):
        fly(p, spec, 1.0, ts=0.003)
    with pytest.raises(SpecError, match="`t_end`"):
        fly(p, spec, 0.0)
    with pytest.raises(SpecError, match="`noise_std`: got -0.1"):
        fly(p, spec, 1.0, noise_std=-0.1)
    with pytest.raises(SpecError, match="`seed`"):
        fly(p, spec, 1.0, seed=-3)
    with pytest.raises(SpecError, match="`controller_spec`"):
        fly(p, {"kp": 1.0}, 1.0)
    with pytest.raises(SpecError, match="`injection`"):
        fly(p, spec, 1.0, injection=0.5)
    with pytest.raises(SignalError, match="`disturbance`: non-finite"):
        fly(p, spec, 1.0, disturbance=lambda t: np.where(t > 0.5, np.nan, 0.0))
    with pytest.raises(SpecError, match="`step`"):
        equivalent_tau(p, step=0.0)
    # a plain PIDSpec works as well as the SystemSpec
    fd = fly(p, PIDSpec(kp=3.0, ki=0.3, kd=2.42, derivative_filter=0.05), 0.5)
    assert len(fd) == 26


def test_a_flight_too_long_is_refused_before_it_is_allocated(fleet, vehicles):
    with pytest.raises(SpecError, match=r"fly: the inner loop's grid \(inner_rate_hz = 500\): a duration of 1e\+12 s "
                                        r"at a sample time of 0\.002 s is 5e\+14 samples; expected at most 5,000,000"):
        fly(vehicles["UAV1"], _spec(fleet, "UAV1"), 1e12)  # 4 PB of inner-loop disturbance samples
