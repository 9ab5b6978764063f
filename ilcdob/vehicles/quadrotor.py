"""A small nonlinear 6-DOF quadrotor: the "real vehicle" of the identification experiments.

Identification needs flight data from something other than the linear model it fits. This
module flies a rigid-body quadrotor with rotor dynamics, a flight-stack-like inner loop
(acceleration -> thrust + attitude -> body rates -> rotor speeds) and the fleet's outer
x-position PID, and records what a flight log would hold.

Frames and units
----------------
World frame: x forward, y left, z up (ENU-like, gravity ``-G e_z`` with ``G = 9.81 m/s^2``).
Body frame: x forward, y left, z up along the collective thrust. Attitude: unit quaternion
``q = (w, x, y, z)`` (Hamilton, body-to-world). Positions in m, velocities in m/s,
accelerations in m/s^2, angles in rad, body rates in rad/s, rotor speeds in rad/s, forces
in N, torques in N m, time in s.

Rigid-body model (state of 17 numbers: p, v, q, omega, four rotor speeds)::

    p' = v
    m v' = R e_z T - m G e_z - D v + m d(t) e_x          (D = diag(c_xy, c_xy, c_z), N s/m)
    q' = 0.5 q (x) (0, omega)
    J omega' = M - omega x J omega                        (J = diag(Jxx, Jyy, Jzz))
    Omega_i' = (Omega_cmd_i - Omega_i) / tau_m            (first-order motor lag)
    f_i = k_f Omega_i^2,  yaw reaction torque = -/+ k_m Omega_i^2

Rotors in the PX4 quad-X layout at ``(+-a, +-a)``, ``a = arm / sqrt(2)``: rotor 0 front
right and 1 rear left spin counter-clockwise, 2 front left and 3 rear right clockwise.
Rotor gyroscopic effects, blade flapping, induced drag and ground effect are not modelled.
Integration: classical fixed-step RK4 at ``inner_rate_hz`` (default 500 Hz), quaternion
renormalised after every step; the inner controller runs at the same rate and its rotor
commands are held over the step.

Inner loops (at ``inner_rate_hz``), as a flight stack does:

1. thrust mapping: desired force ``F = m (a_cmd + G e_z)`` (mass compensation); thrust axis
   ``b3_d = F/|F|``, zero yaw; collective thrust ``T = F . b3`` (projection on the current
   body z axis, as PX4 does). Tilt limited to ``max_tilt``;
2. attitude: geometric error ``e_R = 0.5 vee(R_d^T R - R^T R_d)``, rate setpoint
   ``omega_c = -k_att e_R`` (roll/pitch) and ``-k_att_yaw e_R,z`` (yaw);
3. body rates: ``omega_c' = k_rate (omega_c - omega) - k_rate_d (omega - omega_prev)/dt``
   (PD, derivative on the measurement by a backward difference), torque
   ``M = J omega_c' + omega x J omega``; yaw rate P only;
4. mixer: exact inverse of the quad-X allocation, per-rotor thrust clipped to
   ``[0, k_f Omega_max^2]``, ``Omega_cmd = sqrt(f / k_f)``.

Near hover the commanded-to-achieved x acceleration of this chain is approximately
``1/(tau s + 1)``: linearised, the pitch loop is ``k_att k_r / (tau_m s^3 + (1 + k_rd) s^2 +
k_r s + k_att k_r)``, whose first moment is ``1/k_att``; :meth:`QuadrotorParams.from_table`
chooses ``k_att`` on the exact sampled linearisation so that the least-squares first-order
fit of the step response equals the fleet's ``tau``. :func:`equivalent_tau` measures the same
quantity on the nonlinear simulation. So from commanded x acceleration to x position the
vehicle behaves like ``P(s) = 1/(s^2 (tau s + 1))`` (plus the small linear drag).

Outer loop (at ``ts``, zero-order hold): x from the fleet's PID (Tustin, via
:func:`ilcdob.discretize.discretize_pid`), ``a_cmd,x = C{r - x_meas} + w``; y with the same
PID towards 0; z with ``QuadrotorParams.z_controller`` towards 0. The PID's
``acceleration_feedforward`` is not used (the reference here is a step; chirps enter through
``w``). No anti-windup (the limits are not reached in small-signal experiments).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy.linalg import expm
from scipy.optimize import brentq, minimize_scalar
from scipy.signal import lfilter, ss2tf

from ilcdob.discretize import discretize_pid
from ilcdob.errors import SignalError, SpecError
from ilcdob.signals import FlightData, check_grid
from ilcdob.specs import PIDSpec, SystemSpec

__all__ = [
    "GRAVITY", "QuadrotorParams", "TauFit", "TABLE_I", "table_i_vehicles", "fly", "equivalent_tau",
    "linear_equivalent_tau", "fit_first_order", "limit_tilt", "make_advance", "DiscretePID",
]

#: Gravity, m/s^2.
GRAVITY = 9.81
G = GRAVITY

#: Paper Table I (Modi et al. 2024) with the fleet's derived tau (default_fleet.toml):
#: fleet name -> (frame, mass kg, arm m, tau s).
TABLE_I: dict[str, tuple[str, float, float, float]] = {
    "UAV1": ("F450", 0.921, 0.228, 0.100),
    "UAV2": ("S500", 1.001, 0.240, 0.1053),
    "UAV3": ("Tarot 650", 1.234, 0.318, 0.1395),
}

# Reference values of the F450 (arm 0.228 m) that the other frames scale from.
_REF_ARM = 0.228          # m
_REF_MOTOR_TAU = 0.020    # s, motor + ESC speed time constant of a 450-class frame
_REF_OMEGA_MAX = 1000.0   # rad/s (about 9500 rpm, 10" propeller)
_REF_KM_OVER_KF = 0.016   # m, rotor drag torque / thrust ratio of a 10" propeller
_INERTIA_XY = 0.15        # Jxx = Jyy = 0.15 m l^2
_INERTIA_Z = 0.28         # Jzz = 0.28 m l^2
_THRUST_TO_WEIGHT = 2.0
_DRAG_PER_MASS = 0.01     # 1/s: c_xy = c_z = 0.01 m (N s/m)
_RATE_LOOP_KR_TM = 2.0    # k_rate * tau_m
_RATE_LOOP_ZETA = 0.7     # damping of the linearised rate loop


def _finite(name: str, value: object, *, lo: float | None = None, hi: float | None = None,
            lo_open: bool = True, valid: str | None = None) -> float:
    """``float(value)`` checked finite and in range, else SpecError naming name/value/range."""
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        v = float("nan")
    ok = math.isfinite(v)
    if ok and lo is not None:
        ok = v > lo if lo_open else v >= lo
    if ok and hi is not None:
        ok = v < hi
    if not ok:
        if valid is None:
            parts = []
            if lo is not None:
                parts.append(f"{'>' if lo_open else '>='} {lo:g}")
            if hi is not None:
                parts.append(f"< {hi:g}")
            valid = "a finite number" + (" " + " and ".join(parts) if parts else "")
        raise SpecError(f"`{name}`: got {value!r}, expected {valid}")
    return v


@dataclass(frozen=True)
class QuadrotorParams:
    """Physical parameters and inner-loop gains of one quadrotor.

    Build the paper's vehicles with :meth:`from_table` or :func:`table_i_vehicles`; every
    number :meth:`from_table` assumes is listed there.

    Attributes
    ----------
    name : str
        Vehicle name (the fleet's ``UAV1``...).
    mass : float
        kg (> 0).
    arm : float
        Centre-to-rotor distance, m (> 0).
    inertia : tuple of 3 float
        ``(Jxx, Jyy, Jzz)``, kg m^2 (> 0), principal axes = body axes.
    motor_time_constant : float
        ``tau_m``, s (> 0): first-order lag of each rotor speed.
    thrust_coefficient : float
        ``k_f``, N/(rad/s)^2 (> 0): rotor thrust ``f = k_f Omega^2``.
    torque_coefficient : float
        ``k_m``, N m/(rad/s)^2 (> 0): rotor drag (yaw reaction) torque ``k_m Omega^2``.
    max_rotor_speed : float
        ``Omega_max``, rad/s (> 0); hover must need less than 90 % of the maximum thrust.
    drag_xy, drag_z : float
        Linear aerodynamic drag ``c``, N s/m (>= 0), force ``-c v`` in the world frame.
    att_gain : float
        Roll/pitch attitude P gain ``k_att``, 1/s (> 0).
    rate_gain : float
        Roll/pitch rate P gain ``k_rate``, 1/s (> 0).
    rate_d_gain : float
        Roll/pitch rate D gain ``k_rate_d`` (dimensionless, >= 0).
    yaw_att_gain, yaw_rate_gain : float
        Yaw attitude and rate P gains, 1/s (> 0).
    z_controller : PIDSpec
        Altitude PID (m -> m/s^2), Tustin at the outer rate.
    tau : float or None
        The equivalent attitude time constant the gains were tuned for, s (documentation
        and metadata only; ``None`` when the gains were given by hand).
    frame : str
        Airframe name (``"F450"``...), for records.
    inner_rate_hz : float
        Rate of the integrator and inner loops, Hz (>= 50).
    max_tilt : float
        Tilt limit of the thrust mapping, rad, in (0, pi/2).
    """

    name: str
    mass: float
    arm: float
    inertia: tuple[float, float, float]
    motor_time_constant: float
    thrust_coefficient: float
    torque_coefficient: float
    max_rotor_speed: float
    drag_xy: float
    drag_z: float
    att_gain: float
    rate_gain: float
    rate_d_gain: float
    yaw_att_gain: float = 4.0
    yaw_rate_gain: float = 20.0
    z_controller: PIDSpec = field(default_factory=lambda: PIDSpec(kp=4.0, ki=0.4, kd=3.2,
                                                                  derivative_filter=0.05))
    tau: float | None = None
    frame: str = ""
    inner_rate_hz: float = 500.0
    max_tilt: float = 0.6

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise SpecError(f"`name`: got {self.name!r}, expected a non-empty string")
        for fname in ("mass", "arm", "motor_time_constant", "thrust_coefficient", "torque_coefficient",
                      "max_rotor_speed", "att_gain", "rate_gain", "yaw_att_gain", "yaw_rate_gain"):
            object.__setattr__(self, fname, _finite(fname, getattr(self, fname), lo=0.0))
        for fname in ("drag_xy", "drag_z", "rate_d_gain"):
            object.__setattr__(self, fname, _finite(fname, getattr(self, fname), lo=0.0, lo_open=False))
        object.__setattr__(self, "inner_rate_hz", _finite("inner_rate_hz", self.inner_rate_hz, lo=50.0,
                                                          lo_open=False))
        object.__setattr__(self, "max_tilt", _finite("max_tilt", self.max_tilt, lo=0.0, hi=math.pi / 2,
                                                     valid="an angle in (0, pi/2) rad"))
        try:
            inertia = tuple(float(v) for v in self.inertia)  # type: ignore[union-attr]
        except (TypeError, ValueError):
            inertia = ()
        if len(inertia) != 3 or not all(math.isfinite(v) and v > 0 for v in inertia):
            raise SpecError(f"`inertia`: got {self.inertia!r}, expected three finite numbers > 0 "
                            "(Jxx, Jyy, Jzz in kg m^2)")
        object.__setattr__(self, "inertia", inertia)
        if self.tau is not None:
            object.__setattr__(self, "tau", _finite("tau", self.tau, lo=0.0))
        if not isinstance(self.z_controller, PIDSpec):
            raise SpecError(f"`z_controller`: got {type(self.z_controller).__name__}, expected a PIDSpec")
        if not isinstance(self.frame, str):
            raise SpecError(f"`frame`: got {self.frame!r}, expected a string")
        hover_fraction = self.mass * G / (4.0 * self.max_thrust_per_rotor)
        if hover_fraction >= 0.9:
            raise SpecError(
                f"`max_rotor_speed`: got {self.max_rotor_speed:g} rad/s, hover needs "
                f"{100 * hover_fraction:.0f} % of the maximum thrust; expected a value with hover "
                f"below 90 %, i.e. max_rotor_speed > "
                f"{math.sqrt(self.mass * G / (4 * 0.9 * self.thrust_coefficient)):.4g} rad/s")

    # ------------------------------------------------------------------ derived values
    @property
    def max_thrust_per_rotor(self) -> float:
        """``k_f Omega_max^2``, N."""
        return self.thrust_coefficient * self.max_rotor_speed ** 2

    @property
    def hover_rotor_speed(self) -> float:
        """Rotor speed at hover, rad/s."""
        return math.sqrt(self.mass * G / (4.0 * self.thrust_coefficient))

    @property
    def inner_dt(self) -> float:
        """Inner-loop (integration) step, s."""
        return 1.0 / self.inner_rate_hz

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_table(cls, name: str, mass: float, arm: float, tau: float, *, frame: str = "",
                   inner_rate_hz: float = 500.0, **overrides: Any) -> "QuadrotorParams":
        """A vehicle from the paper's Table I entries plus the fleet's ``tau``.

        Assumed numbers (F450 values at ``arm = 0.228 m``; ``s = arm / 0.228 m``; frames are
        taken as geometrically similar, consistent with default_fleet.md's ``tau ~ arm``):

        * inertia: ``Jxx = Jyy = 0.15 m l^2``, ``Jzz = 0.28 m l^2`` (four motors of about a
          quarter of the mass at the arm tips plus a compact hub; F450: 0.0072 and
          0.0134 kg m^2, close to published F450 values of about 0.0075 and 0.013);
        * motor time constant ``tau_m = 0.020 s * s`` (larger propellers spin up slower);
        * maximum rotor speed ``Omega_max = 1000 rad/s / s``; thrust coefficient from a
          thrust-to-weight ratio of 2: ``k_f = 2 m G / (4 Omega_max^2)``;
        * drag-torque coefficient ``k_m = 0.016 m * s * k_f``;
        * linear drag ``c_xy = c_z = 0.01 m`` N s/m (velocity decay rate 0.01 1/s). Kept
          small on purpose: the x plant is then ``1/(s (s + 0.01) (tau s + 1))``, within the
          accuracy of the fleet's double integrator over a flight of a few tens of seconds
          (at 0.05 1/s a 10 s chirp is matched by ``1/(s^2 (tau s + 1))`` only to about
          85-90 %). Override ``drag_xy`` to study drag as a model mismatch;
        * rate loop: ``k_rate = 2 / tau_m``, ``k_rate_d = 2 * 0.7 * sqrt(k_rate tau_m) - 1``
          (linearised rate loop ``k_r/(tau_m s^2 + (1 + k_rd) s + k_r)`` with damping 0.7 and
          about 3.5 times the attitude bandwidth);
        * attitude gain ``k_att``: solved so that :func:`linear_equivalent_tau` equals
          ``tau`` (about ``1/tau``);
        * yaw: ``k_att_yaw = 4 1/s``, ``k_rate_yaw = 20 1/s``; altitude PID
          ``kp = 4, ki = 0.4, kd = 3.2, Tf = 0.05 s``; tilt limit 0.6 rad.

        Parameters
        ----------
        name : str
            Fleet name of the vehicle.
        mass : float
            kg.
        arm : float
            m.
        tau : float
            Target equivalent time constant of commanded -> achieved acceleration, s.
        frame : str
            Airframe name for records.
        inner_rate_hz : float
            Inner-loop and integration rate, Hz.
        **overrides
            Any other field, replacing the assumed value (the attitude gain is then tuned
            with the overridden rate loop / motor lag unless ``att_gain`` is given).
        """
        mass = _finite("mass", mass, lo=0.0)
        arm = _finite("arm", arm, lo=0.0)
        tau = _finite("tau", tau, lo=0.0)
        inner_rate_hz = _finite("inner_rate_hz", inner_rate_hz, lo=50.0, lo_open=False)
        scale = arm / _REF_ARM
        ml2 = mass * arm ** 2
        tau_m = overrides.pop("motor_time_constant", _REF_MOTOR_TAU * scale)
        tau_m = _finite("motor_time_constant", tau_m, lo=0.0)
        omega_max = overrides.pop("max_rotor_speed", _REF_OMEGA_MAX / scale)
        omega_max = _finite("max_rotor_speed", omega_max, lo=0.0)
        kf = overrides.pop("thrust_coefficient", _THRUST_TO_WEIGHT * mass * G / (4.0 * omega_max ** 2))
        k_rate = overrides.pop("rate_gain", _RATE_LOOP_KR_TM / tau_m)
        k_rate = _finite("rate_gain", k_rate, lo=0.0)
        k_rate_d = overrides.pop("rate_d_gain",
                                 max(0.0, 2.0 * _RATE_LOOP_ZETA * math.sqrt(k_rate * tau_m) - 1.0))
        k_rate_d = _finite("rate_d_gain", k_rate_d, lo=0.0, lo_open=False)
        att_gain = overrides.pop("att_gain", None)
        if att_gain is None:
            att_gain = _tune_att_gain(tau, k_rate, k_rate_d, tau_m, 1.0 / inner_rate_hz)
        fields = dict(
            name=name, mass=mass, arm=arm,
            inertia=(_INERTIA_XY * ml2, _INERTIA_XY * ml2, _INERTIA_Z * ml2),
            motor_time_constant=tau_m, thrust_coefficient=kf,
            torque_coefficient=_REF_KM_OVER_KF * scale * kf, max_rotor_speed=omega_max,
            drag_xy=_DRAG_PER_MASS * mass, drag_z=_DRAG_PER_MASS * mass,
            att_gain=att_gain, rate_gain=k_rate, rate_d_gain=k_rate_d, tau=tau, frame=frame,
            inner_rate_hz=inner_rate_hz,
        )
        unknown = set(overrides) - set(cls.__dataclass_fields__)
        if unknown:
            raise SpecError(f"`overrides`: unknown field(s) {sorted(unknown)}; valid: "
                            f"{sorted(cls.__dataclass_fields__)}")
        fields.update(overrides)
        return cls(**fields)


def table_i_vehicles(inner_rate_hz: float = 500.0) -> dict[str, QuadrotorParams]:
    """The paper's three vehicles (Table I) keyed by fleet name ``UAV1``, ``UAV2``, ``UAV3``.

    F450 0.921 kg / 0.228 m / tau 0.100 s; S500 1.001 kg / 0.240 m / 0.1053 s; Tarot 650
    1.234 kg / 0.318 m / 0.1395 s (tau from default_fleet.toml). See
    :meth:`QuadrotorParams.from_table` for the assumed numbers.

    Parameters
    ----------
    inner_rate_hz : float
        Rate of the simulated attitude and rate loops, Hz.

    Returns
    -------
    dict of str to QuadrotorParams
        ``UAV1`` (F450), ``UAV2`` (S500), ``UAV3`` (Tarot 650).
    """
    return {name: QuadrotorParams.from_table(name, m, l, tau, frame=frame, inner_rate_hz=inner_rate_hz)
            for name, (frame, m, l, tau) in TABLE_I.items()}


# ---------------------------------------------------------------------- tau fitting
@dataclass(frozen=True)
class TauFit:
    """First-order fit ``1 - exp(-t/tau)`` of a normalised acceleration step response.

    Attributes
    ----------
    tau : float
        Fitted time constant, s.
    target : float or None
        The vehicle's design ``tau``, s.
    fit_percent : float
        MATLAB fit of the first-order response to the measured one, %.
    t : numpy.ndarray
        Time of the samples, s (from the step).
    response : numpy.ndarray
        Achieved / commanded acceleration (dimensionless).
    """

    tau: float
    target: float | None
    fit_percent: float
    t: np.ndarray
    response: np.ndarray

    @property
    def relative_error(self) -> float:
        """``tau / target - 1`` (nan without a target)."""
        return self.tau / self.target - 1.0 if self.target else float("nan")


def fit_first_order(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares time constant of a normalised step response, ``y(t) ~ 1 - exp(-t/tau)``.

    Parameters
    ----------
    t : array_like
        Time from the step, s.
    y : array_like
        Normalised response (1 in steady state).

    Returns
    -------
    tau : float
        Fitted time constant, s (searched between 1e-3 and 1 times the span of ``t``).
    fit : float
        MATLAB fit percent of the first-order response to ``y``.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    span = float(t[-1] - t[0])

    def cost(log_tau: float) -> float:
        return float(np.sum((y - (1.0 - np.exp(-t / math.exp(log_tau)))) ** 2))

    res = minimize_scalar(cost, bounds=(math.log(span * 1e-3), math.log(span)), method="bounded",
                          options={"xatol": 1e-7})
    tau = math.exp(res.x)
    yhat = 1.0 - np.exp(-t / tau)
    fit = 100.0 * (1.0 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean()))
    return tau, float(fit)


def _linear_pitch_step(att_gain: float, rate_gain: float, rate_d_gain: float, tau_m: float, dt: float,
                       n: int) -> np.ndarray:
    """Normalised step response ``theta/theta_d`` of the sampled linearised pitch loop."""
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0 / tau_m]])
    b = np.array([[0.0], [0.0], [1.0 / tau_m]])
    big = np.zeros((4, 4))
    big[:3, :3] = a * dt
    big[:3, 3:] = b * dt
    e = expm(big)
    phi, gam = e[:3, :3], e[:3, 3]
    # closed loop on z = [theta, omega, alpha, omega_prev], input theta_d:
    # u = k_r (k_a (theta_d - theta) - omega) - k_rd (omega - omega_prev)/dt
    k = np.array([-rate_gain * att_gain, -rate_gain - rate_d_gain / dt, 0.0, rate_d_gain / dt])
    acl = np.zeros((4, 4))
    acl[:3, :] = np.hstack([phi, np.zeros((3, 1))]) + np.outer(gam, k)
    acl[3, 1] = 1.0
    bcl = np.zeros((4, 1))
    bcl[:3, 0] = gam * rate_gain * att_gain
    # y[j] = theta[j] for a unit step from rest; strictly proper, run at C speed by lfilter
    num, den = ss2tf(acl, bcl, np.eye(1, 4), np.zeros((1, 1)))
    return lfilter(num[0], den, np.ones(n))


def linear_equivalent_tau(att_gain: float, rate_gain: float, rate_d_gain: float,
                          motor_time_constant: float, inner_dt: float, horizon: float) -> float:
    """Equivalent ``tau`` (s) of the sampled, linearised attitude chain at hover.

    The step response of ``theta/theta_d`` (equal to achieved/commanded x acceleration at
    hover) at the inner-loop samples over ``horizon`` s, fitted by :func:`fit_first_order`.

    Parameters
    ----------
    att_gain : float
        Attitude P gain, 1/s.
    rate_gain : float
        Rate P gain, 1/s.
    rate_d_gain : float
        Rate D gain (dimensionless).
    motor_time_constant : float
        First-order motor lag, s.
    inner_dt : float
        Inner-loop step, s.
    horizon : float
        Length of the step response fitted, s.

    Returns
    -------
    float
        The equivalent first-order time constant, s.
    """
    check_grid(horizon, inner_dt, "linear_equivalent_tau: the step response")
    n = int(round(horizon / inner_dt)) + 1
    y = _linear_pitch_step(att_gain, rate_gain, rate_d_gain, motor_time_constant, inner_dt, n)
    return fit_first_order(np.arange(n) * inner_dt, y)[0]


def _tune_att_gain(tau: float, rate_gain: float, rate_d_gain: float, tau_m: float, dt: float) -> float:
    horizon = 10.0 * tau

    def err(k_att: float) -> float:
        return linear_equivalent_tau(k_att, rate_gain, rate_d_gain, tau_m, dt, horizon) - tau

    lo, hi = 0.3 / tau, 3.0 / tau
    try:
        return float(brentq(err, lo, hi, xtol=1e-6))
    except ValueError:
        raise SpecError(
            f"`tau`: got {tau!r} s, which the inner loops (motor lag {tau_m:g} s, rate gain "
            f"{rate_gain:g} 1/s, rate D {rate_d_gain:g}, inner step {dt:g} s) cannot reach with an "
            f"attitude gain in [{lo:.3g}, {hi:.3g}] 1/s; expected tau of at least a few motor time "
            "constants") from None


# ---------------------------------------------------------------------- the simulator
def make_advance(p: QuadrotorParams) -> Callable[..., Any]:
    """Build the hot loop: ``advance(s, ax, ay, az, d_list, j0, nstep, wprev, rec)``.

    The returned function runs ``nstep`` inner steps from state list ``s`` with the
    acceleration command held, the external disturbance acceleration ``d_list[j0 + i]`` held
    over step ``i``; it returns ``(s, wprev)``. With ``rec`` a list, it appends the x specific
    thrust (m/s^2) before each step. Pure-Python scalar code: faster than NumPy for a
    17-state system.

    Parameters
    ----------
    p : QuadrotorParams
        The vehicle (its constants are bound into the closure).

    Returns
    -------
    callable
        ``advance``, as above.
    """
    m = p.mass
    inv_m = 1.0 / m
    jx, jy, jz = p.inertia
    ijx, ijy, ijz = 1.0 / jx, 1.0 / jy, 1.0 / jz
    kf = p.thrust_coefficient
    a = p.arm / math.sqrt(2.0)
    c = p.torque_coefficient / p.thrust_coefficient
    km = p.torque_coefficient
    itm = 1.0 / p.motor_time_constant
    cxy = p.drag_xy * inv_m
    cz = p.drag_z * inv_m
    ka, kr, krd = p.att_gain, p.rate_gain, p.rate_d_gain
    kay, kry = p.yaw_att_gain, p.yaw_rate_gain
    h = p.inner_dt
    inv_h = 1.0 / h
    h2, h6 = 0.5 * h, h / 6.0
    fmax = p.max_thrust_per_rotor
    tmax = 4.0 * fmax
    i4a, i4c = 0.25 / a, 0.25 / c
    sqrt = math.sqrt

    def deriv(s: list[float], c0: float, c1: float, c2: float, c3: float, d: float) -> list[float]:
        _, _, _, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz, o0, o1, o2, o3 = s
        s0, s1, s2, s3 = o0 * o0, o1 * o1, o2 * o2, o3 * o3
        tm = kf * (s0 + s1 + s2 + s3) * inv_m
        mx = kf * a * (-s0 + s1 + s2 - s3)
        my = kf * a * (-s0 + s1 - s2 + s3)
        mz = km * (-s0 - s1 + s2 + s3)
        return [
            vx, vy, vz,
            2.0 * (qx * qz + qw * qy) * tm - cxy * vx + d,
            2.0 * (qy * qz - qw * qx) * tm - cxy * vy,
            (qw * qw - qx * qx - qy * qy + qz * qz) * tm - G - cz * vz,
            -0.5 * (qx * wx + qy * wy + qz * wz),
            0.5 * (qw * wx + qy * wz - qz * wy),
            0.5 * (qw * wy + qz * wx - qx * wz),
            0.5 * (qw * wz + qx * wy - qy * wx),
            (mx - (jz - jy) * wy * wz) * ijx,
            (my - (jx - jz) * wz * wx) * ijy,
            (mz - (jy - jx) * wx * wy) * ijz,
            (c0 - o0) * itm, (c1 - o1) * itm, (c2 - o2) * itm, (c3 - o3) * itm,
        ]

    def advance(s: list[float], ax: float, ay: float, az: float, d_list: list[float], j0: int, nstep: int,
                wprev: tuple[float, float], rec: list[float] | None) -> tuple[list[float], tuple[float, float]]:
        fx, fy, fz = m * ax, m * ay, m * (az + G)
        fn = sqrt(fx * fx + fy * fy + fz * fz)
        b3x, b3y, b3z = fx / fn, fy / fn, fz / fn
        n2 = sqrt(b3y * b3y + b3z * b3z)
        b2y, b2z = b3z / n2, -b3y / n2                      # b2d = b3d x e_x / |.|, b2x = 0
        b1x, b1y, b1z = b2y * b3z - b2z * b3y, b2z * b3x, -b2y * b3x
        wpx, wpy = wprev
        for i in range(nstep):
            _, _, _, _, _, _, qw, qx, qy, qz, wx, wy, wz, o0, o1, o2, o3 = s
            # rotation matrix (body -> world)
            r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
            r01 = 2.0 * (qx * qy - qw * qz)
            r02 = 2.0 * (qx * qz + qw * qy)
            r10 = 2.0 * (qx * qy + qw * qz)
            r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
            r12 = 2.0 * (qy * qz - qw * qx)
            r20 = 2.0 * (qx * qz - qw * qy)
            r21 = 2.0 * (qy * qz + qw * qx)
            r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
            if rec is not None:
                rec.append(kf * (o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3) * inv_m * r02)
            # e_R = 0.5 vee(Rd^T R - R^T Rd); (Rd^T R)_ij = col_i(Rd) . col_j(R)
            m01 = b1x * r01 + b1y * r11 + b1z * r21
            m02 = b1x * r02 + b1y * r12 + b1z * r22
            m10 = b2y * r10 + b2z * r20
            m12 = b2y * r12 + b2z * r22
            m20 = b3x * r00 + b3y * r10 + b3z * r20
            m21 = b3x * r01 + b3y * r11 + b3z * r21
            ex, ey, ez = 0.5 * (m21 - m12), 0.5 * (m02 - m20), 0.5 * (m10 - m01)
            # collective thrust: projection of the desired force on the body z axis
            t = fx * r02 + fy * r12 + fz * r22
            t = 0.0 if t < 0.0 else (tmax if t > tmax else t)
            # rate loop -> angular acceleration command -> torque
            ux = kr * (-ka * ex - wx) - krd * (wx - wpx) * inv_h
            uy = kr * (-ka * ey - wy) - krd * (wy - wpy) * inv_h
            uz = kry * (-kay * ez - wz)
            mx = jx * ux + (jz - jy) * wy * wz
            my = jy * uy + (jx - jz) * wz * wx
            mz = jz * uz + (jy - jx) * wx * wy
            # mixer (exact inverse of the quad-X allocation), per-rotor clip
            tq, ax_, ay_, az_ = 0.25 * t, mx * i4a, my * i4a, mz * i4c
            f0 = tq - ax_ - ay_ - az_
            f1 = tq + ax_ + ay_ - az_
            f2 = tq + ax_ - ay_ + az_
            f3 = tq - ax_ + ay_ + az_
            c0 = sqrt((0.0 if f0 < 0.0 else (fmax if f0 > fmax else f0)) / kf)
            c1 = sqrt((0.0 if f1 < 0.0 else (fmax if f1 > fmax else f1)) / kf)
            c2 = sqrt((0.0 if f2 < 0.0 else (fmax if f2 > fmax else f2)) / kf)
            c3 = sqrt((0.0 if f3 < 0.0 else (fmax if f3 > fmax else f3)) / kf)
            wpx, wpy = wx, wy
            d = d_list[j0 + i]
            # RK4
            k1 = deriv(s, c0, c1, c2, c3, d)
            k2 = deriv([x + h2 * k for x, k in zip(s, k1)], c0, c1, c2, c3, d)
            k3 = deriv([x + h2 * k for x, k in zip(s, k2)], c0, c1, c2, c3, d)
            k4 = deriv([x + h * k for x, k in zip(s, k3)], c0, c1, c2, c3, d)
            s = [x + h6 * (q1 + 2.0 * (q2 + q3) + q4) for x, q1, q2, q3, q4 in zip(s, k1, k2, k3, k4)]
            qn = 1.0 / sqrt(s[6] * s[6] + s[7] * s[7] + s[8] * s[8] + s[9] * s[9])
            s[6] *= qn
            s[7] *= qn
            s[8] *= qn
            s[9] *= qn
        return s, (wpx, wpy)

    return advance


def limit_tilt(ax: float, ay: float, az: float, tan_max: float) -> tuple[float, float, float, bool]:
    """Commanded accelerations (m/s^2) within the vehicle's limits, as a flight controller does.

    ``az`` is clipped to ``[-G/2, G]``; the horizontal command is scaled down (direction kept)
    to ``(G + az) tan(max_tilt)``, the most a tilt of ``max_tilt`` gives.

    Parameters
    ----------
    ax, ay, az : float
        Commanded accelerations, m/s^2 (``az`` on top of gravity compensation).
    tan_max : float
        ``tan(max_tilt)``.

    Returns
    -------
    ax, ay, az : float
        The limited command, m/s^2.
    scaled : bool
        Whether the horizontal command was scaled down.
    """
    az = min(max(az, -0.5 * G), G)
    amax = (G + az) * tan_max
    ah = math.hypot(ax, ay)
    if ah > amax:
        return ax * amax / ah, ay * amax / ah, az, True
    return ax, ay, az, False


class DiscretePID:
    """Tustin PID stepped by hand: ``u[k] = C x[k] + D e[k]``, ``x[k+1] = A x[k] + B e[k]``.

    Calling it with the error ``e[k]`` returns ``u[k]`` and advances the state.

    Parameters
    ----------
    spec : PIDSpec
        The controller, discretised with :func:`ilcdob.discretize.discretize_pid`.
    ts : float
        Sample time, s.
    """

    def __init__(self, spec: PIDSpec, ts: float) -> None:
        ss = discretize_pid(spec, ts)
        self.a = np.asarray(ss.A, float)
        self.b = np.asarray(ss.B, float)[:, 0]
        self.c = np.asarray(ss.C, float)[0]
        self.d = float(np.asarray(ss.D, float)[0, 0])
        self.x = np.zeros(self.a.shape[0])

    def __call__(self, e: float) -> float:
        u = float(self.c @ self.x) + self.d * e
        self.x = self.a @ self.x + self.b * e
        return u


def _sample_input(fn: Callable[[Any], Any] | None, t: np.ndarray, name: str) -> np.ndarray:
    """Evaluate a callable of time on ``t`` (vectorised if it can, else sample by sample)."""
    if fn is None:
        return np.zeros_like(t)
    if not callable(fn):
        raise SpecError(f"`{name}`: got {fn!r}, expected a callable of time (s) or None")
    vals: np.ndarray | None = None
    try:
        v = np.asarray(fn(t), dtype=float)
        if v.shape == t.shape:
            vals = v
        elif v.ndim == 0:
            vals = np.full_like(t, float(v))
    except Exception:  # noqa: BLE001 - not vectorisable: fall back to scalar calls
        vals = None
    if vals is None:
        try:
            vals = np.array([float(fn(float(tk))) for tk in t])
        except (TypeError, ValueError) as exc:
            raise SpecError(f"`{name}`: calling it with a time in s must return a number; got {exc}") from exc
    bad = np.flatnonzero(~np.isfinite(vals))
    if bad.size:
        raise SignalError(f"`{name}`: non-finite value {vals[bad[0]]!r} at t = {t[bad[0]]:.6g} s")
    return vals


def _simulate(p: QuadrotorParams, x_pid: PIDSpec, ts: float, n_out: int, r: np.ndarray, w: np.ndarray,
              d_inner: np.ndarray, noise: np.ndarray, delay_steps: int, open_loop_x: bool,
              record_inner: bool) -> dict[str, Any]:
    """Core loop; see :func:`fly`. ``noise`` is (n_out, 3); ``d_inner`` on the inner grid."""
    nin = int(round(ts * p.inner_rate_hz))
    advance = make_advance(p)
    pid_x, pid_y, pid_z = DiscretePID(x_pid, ts), DiscretePID(x_pid, ts), DiscretePID(p.z_controller, ts)
    om = p.hover_rotor_speed
    s = [0.0] * 6 + [1.0, 0.0, 0.0, 0.0] + [0.0] * 3 + [om] * 4
    wprev = (0.0, 0.0)
    d_list = d_inner.tolist()
    tan_max = math.tan(p.max_tilt)
    rec: list[float] | None = [] if record_inner else None
    hist: list[tuple[float, float, float]] = []
    out = {k: np.empty(n_out) for k in ("acc_cmd", "x", "x_true", "y_true", "z_true", "pitch")}
    r_l, w_l = r.tolist(), w.tolist()
    for k in range(n_out):
        px, py, pz = s[0], s[1], s[2]
        if delay_steps:
            hist.append((px, py, pz))        # hist[k*nin + i]: position at inner step i of interval k
            j = k * nin - delay_steps
            mx_, my_, mz_ = hist[j] if j >= 0 else hist[0]
        else:
            mx_, my_, mz_ = px, py, pz
        xm, ym, zm = mx_ + noise[k, 0], my_ + noise[k, 1], mz_ + noise[k, 2]
        ux = pid_x(r_l[k] - xm)
        ax = w_l[k] if open_loop_x else ux + w_l[k]
        ax, ay, az, _ = limit_tilt(ax, pid_y(-ym), pid_z(-zm), tan_max)
        qw, qx, qy, qz = s[6], s[7], s[8], s[9]
        out["acc_cmd"][k] = ax
        out["x"][k] = xm
        out["x_true"][k] = px
        out["y_true"][k] = py
        out["z_true"][k] = pz
        out["pitch"][k] = math.asin(max(-1.0, min(1.0, 2.0 * (qw * qy - qz * qx))))
        if k == n_out - 1:
            break
        if delay_steps:
            # positions at the inner steps of this interval, for delayed measurements
            s_run, j0 = s, k * nin
            for i in range(nin):
                if i:
                    hist.append((s_run[0], s_run[1], s_run[2]))
                s_run, wprev = advance(s_run, ax, ay, az, d_list, j0 + i, 1, wprev, rec)
            s = s_run
        else:
            s, wprev = advance(s, ax, ay, az, d_list, k * nin, nin, wprev, rec)
    out["inner"] = np.asarray(rec) if rec is not None else None
    return out


def _check_ts(p: QuadrotorParams, ts: float) -> int:
    ts = _finite("ts", ts, lo=0.0)
    ratio = ts * p.inner_rate_hz
    nin = int(round(ratio))
    if nin < 1 or abs(ratio - nin) > 1e-9 * max(1.0, ratio):
        raise SpecError(f"`ts`: got {ts!r} s, expected a positive multiple of the inner step "
                        f"{p.inner_dt:g} s (inner_rate_hz = {p.inner_rate_hz:g})")
    return nin


def fly(params: QuadrotorParams, controller_spec: PIDSpec | SystemSpec, t_end: float, ts: float = 0.02,
        reference: Callable[[Any], Any] | None = None, injection: Callable[[Any], Any] | None = None,
        disturbance: Callable[[Any], Any] | None = None, noise_std: float = 0.003,
        seed: int | np.random.Generator = 0, *, measurement_delay: float = 0.0,
        experiment: str | None = None) -> FlightData:
    """Fly the nonlinear quadrotor from hover at the origin and record the x-axis signals.

    Parameters
    ----------
    params : QuadrotorParams
        The vehicle.
    controller_spec : PIDSpec or SystemSpec
        The outer-loop PID of x (and y); a ``SystemSpec`` contributes its ``controller``.
    t_end : float
        Duration, s (>= ts); samples at ``t = k ts``, ``k = 0..floor(t_end/ts)``.
    ts : float
        Outer-loop (flight computer) sample time, s; a multiple of ``params.inner_dt``.
    reference : callable or None
        x position reference ``r(t)``, m (default 0).
    injection : callable or None
        Additive acceleration ``w(t)`` on the x command, m/s^2: ``a_cmd,x = C{r - x} + w``.
    disturbance : callable or None
        External x acceleration ``d(t)``, m/s^2, applied as the force ``m d`` on the body
        (held over each inner step).
    noise_std : float
        Standard deviation of the white position-measurement noise on x, y, z, m (>= 0).
    seed : int or numpy.random.Generator
        Seed of ``numpy.random.default_rng`` for the measurement noise (or a generator).
    measurement_delay : float
        Delay of the position measurement, s (>= 0), rounded to inner steps.
    experiment : str, optional
        Label for ``source`` (default: built from the inputs given).

    Returns
    -------
    FlightData
        On the outer grid: ``acc_cmd`` (m/s^2, the x command sent after the tilt limit: the
        plant input for identification), ``x`` (measured, m), ``x_true``, ``x_ref``, ``w``
        (m/s^2), ``d`` (m/s^2), ``y_true``, ``z_true`` (m) and ``pitch`` (rad). Signals at
        sample k are the state at ``t_k`` and the command applied over ``[t_k, t_k + ts)``.

    Notes
    -----
    The fleet PID differentiates the error, so a reference step of size ``h`` gives a kick of
    about ``h kd 2/(2 Tf + ts)`` at its first sample (about 40 h m/s^2 for UAV1): steps above
    about 0.15 m hit the tilt limit (``G tan(max_tilt)``, 6.7 m/s^2 by default) and are no
    longer small-signal; the recorded ``acc_cmd`` is the limited command. The integrators
    have no anti-windup, so after a saturated step x settles slowly (integral mode, ~10 s).
    """
    if not isinstance(params, QuadrotorParams):
        raise SpecError(f"`params`: got {type(params).__name__}, expected a QuadrotorParams")
    if isinstance(controller_spec, SystemSpec):
        pid = controller_spec.controller
    elif isinstance(controller_spec, PIDSpec):
        pid = controller_spec
    else:
        raise SpecError(f"`controller_spec`: got {type(controller_spec).__name__}, expected a PIDSpec "
                        "or a SystemSpec")
    nin = _check_ts(params, ts)
    t_end = _finite("t_end", t_end, lo=ts, lo_open=False, valid=f"a finite duration >= ts = {ts:g} s")
    noise_std = _finite("noise_std", noise_std, lo=0.0, lo_open=False)
    measurement_delay = _finite("measurement_delay", measurement_delay, lo=0.0, lo_open=False)
    if isinstance(seed, np.random.Generator):
        rng, seed_meta = seed, None
    elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0:
        rng, seed_meta = np.random.default_rng(int(seed)), int(seed)
    else:
        raise SpecError(f"`seed`: got {seed!r}, expected an integer >= 0 or a numpy Generator")
    check_grid(t_end, params.inner_dt, f"fly: the inner loop's grid (inner_rate_hz = {params.inner_rate_hz:g})")
    n_out = int(math.floor(t_end / ts + 1e-9)) + 1
    t = np.arange(n_out) * ts
    r = _sample_input(reference, t, "reference")
    w = _sample_input(injection, t, "injection")
    d_out = _sample_input(disturbance, t, "disturbance")
    t_inner = np.arange(n_out * nin) * params.inner_dt
    d_inner = _sample_input(disturbance, t_inner, "disturbance")
    noise = rng.normal(0.0, noise_std, size=(n_out, 3)) if noise_std > 0 else np.zeros((n_out, 3))
    delay_steps = int(round(measurement_delay * params.inner_rate_hz))
    res = _simulate(params, pid, ts, n_out, r, w, d_inner, noise, delay_steps, False, False)
    if experiment is None:
        parts = [name for name, fn in (("reference", reference), ("injection", injection),
                                       ("disturbance", disturbance)) if fn is not None]
        experiment = " + ".join(parts) if parts else "hover"
    signals = {"acc_cmd": res["acc_cmd"], "x": res["x"], "x_true": res["x_true"], "x_ref": r, "w": w,
               "d": d_out, "y_true": res["y_true"], "z_true": res["z_true"], "pitch": res["pitch"]}
    units = {"acc_cmd": "m/s^2", "x": "m", "x_true": "m", "x_ref": "m", "w": "m/s^2", "d": "m/s^2",
             "y_true": "m", "z_true": "m", "pitch": "rad"}
    meta = {
        "vehicle": params.name, "frame": params.frame, "experiment": experiment, "seed": seed_meta,
        "noise_std_m": noise_std, "measurement_delay_s": delay_steps * params.inner_dt, "ts": ts,
        "inner_rate_hz": params.inner_rate_hz, "tau_design_s": params.tau, "mass_kg": params.mass,
        "arm_m": params.arm, "controller": {"kp": pid.kp, "ki": pid.ki, "kd": pid.kd,
                                             "derivative_filter": pid.derivative_filter},
        "plant_input": "acc_cmd", "plant_output": "x", "simulator": "ilcdob.vehicles.quadrotor",
    }
    src = f"quadrotor simulation {params.name}" + (f" ({params.frame})" if params.frame else "") + \
        f", {experiment}, seed {seed_meta}"
    return FlightData(t=t, signals=signals, units=units, metadata=meta, source=src)


def equivalent_tau(params: QuadrotorParams, step: float = 0.1, horizon: float | None = None,
                   x_controller: PIDSpec | None = None) -> TauFit:
    """Measure the equivalent ``tau`` of commanded -> achieved x acceleration at hover.

    The nonlinear vehicle hovers with its y and z loops closed (no noise), the x outer loop
    open, and gets a step of ``step`` m/s^2 in the commanded x acceleration at ``t = 0``.
    The achieved acceleration is the x component of the specific rotor thrust
    ``R e_z sum(f_i) / m`` (drag, an airframe effect outside the inner loop, is excluded),
    sampled at the inner rate over ``horizon`` s (default ``10 tau``, or 1 s without a
    design tau) and fitted by ``1 - exp(-t/tau)`` (:func:`fit_first_order`).

    Parameters
    ----------
    params : QuadrotorParams
    step : float
        Step size, m/s^2 (small: the measure is a small-signal one), nonzero, |step| < 2.
    horizon : float, optional
        Fit window, s.
    x_controller : PIDSpec, optional
        PID of the y loop during the test (x is open; default: kp 1, ki 0, kd 1.4,
        Tf 0.05 s).

    Returns
    -------
    TauFit
        The fitted ``tau`` with the design target and the response.
    """
    step = _finite("step", step, valid="a finite nonzero acceleration in m/s^2 with |step| < 2")
    if step == 0.0 or abs(step) >= 2.0:
        raise SpecError(f"`step`: got {step!r}, expected a nonzero acceleration with |step| < 2 m/s^2")
    if horizon is None:
        horizon = 10.0 * params.tau if params.tau else 1.0
    horizon = _finite("horizon", horizon, lo=0.0)
    ts = params.inner_dt * max(1, int(round(0.02 * params.inner_rate_hz)))
    check_grid(horizon, params.inner_dt, "equivalent_tau: the step response")
    n_out = int(math.ceil(horizon / ts)) + 1
    nin = int(round(ts * params.inner_rate_hz))
    pid = x_controller or PIDSpec(kp=1.0, ki=0.0, kd=1.4, derivative_filter=0.05)
    res = _simulate(params, pid, ts, n_out, np.zeros(n_out), np.full(n_out, step),
                    np.zeros(n_out * nin), np.zeros((n_out, 3)), 0, True, True)
    y = res["inner"] / step
    tt = np.arange(y.size) * params.inner_dt
    keep = tt <= horizon + 1e-12
    tau, fit = fit_first_order(tt[keep], y[keep])
    return TauFit(tau=tau, target=params.tau, fit_percent=fit, t=tt[keep], response=y[keep])
