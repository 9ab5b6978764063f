"""The paper's validation flown on the nonlinear 6-DOF quadrotors, with identified models.

The paper validates twice: in simulation with exact models and in flight, where the
models are identified and therefore wrong. This module gives the second kind of evidence
without hardware: the nonlinear vehicles of :mod:`ilcdob.vehicles.quadrotor` are the
"real vehicles" and the pipeline is the paper's (Sec. IV):

1. fly step and chirp experiments with every vehicle and identify its plant
   ``P_hat(s) = b0 / (s^2 (s + a0))`` (:func:`ilcdob.identification.fleet_id.identify_vehicle`);
2. build every loop (PID ``C``, ``Q``, ``M = Q/P_hat``) and the closed-form learning filters
   of the Theorem (paper Sec. III, :func:`ilcdob.design.closed_form_filters`) from the
   identified models;
3. fly the four scenarios with no DOB, only DOB and learning iterations 1..n, passed around
   the fleet cyclically as in :mod:`ilcdob.validation.reproduce`.

The outer loop of one vehicle (x axis, the loop of paper Sec. II), at the flight computer's rate
``Ts`` (the fleet's sample time), is the same discrete blocks as the linear loop
(:class:`ilcdob.loop.LoopSystem` ``C``, ``Q``, ``M``) stepped sample by sample with the
nonlinear vehicle in between::

    x_m[k]   = x(t_k) + n[k]                       (position sensor, white noise n)
    u1[k]    = C{r - x_m}[k] + a_ref[k]            (a_ref if the PID feeds it forward)
    d_hat[k] = M{x_m}[k] - Q{u2}[k]                (DOB)
    u2[k]    = u1[k] - d_hat[k] - d_f[k]           held over [t_k, t_k + Ts)

``u2`` is the vehicle's commanded x acceleration and nothing else: the wind ``d(t)`` and the
vehicle's own noise (:class:`ilcdob.specs.NoiseSpec`) act on the airframe as an external
force ``m d(t)``, evaluated at the vehicle's inner (integration) rate. y and z are held at 0
by their own PIDs, as in :func:`~ilcdob.vehicles.quadrotor.fly`. Every trial starts
from hover at rest at the origin with every controller state at zero, which is consistent:
each scenario starts with ``r = 0``, ``dr/dt = 0`` and ``d = 0``.

Tracking error and RMSE are those of the *true* position (``e = r - x``); the controller,
the DOB and the learning only see the measured position ``x_m``, as on a real vehicle.

What the real vehicles change, and how the learning law handles it
------------------------------------------------------------------
Flown as is on these vehicles, the Theorem's law diverges within three iterations. Four
causes, each fixed at its root (numbers from the development runs, 0.5 mm sensor noise):

* **Sensor noise through the plant inverse.** ``L1 = -(1 - Q_j) Gd_{j-1}^{-1}`` contains
  ``1/P_hat ~ s^2 (tau s + 1)``, gain ~1e5 at the Nyquist frequency: 0.5 mm of white
  position noise became tens of m/s^2 of learning signal and the tilt limit saturated. The
  learning passes a zero-phase low-pass *robustness filter* F before and after the plant
  inverse (:func:`robustness_filter`, 10 rad/s: above the winds' content, below where
  the identified models' error reaches the Theorem's bound ``|1 + P C|/2``).
* **Trial boundaries.** Whatever the extension of the trial, the inverse turns a jump in a
  derivative into a spike, and iterating made spikes at the start and end of the trial
  grow (trial-domain instability that the frequency check cannot show). The filters run
  over a horizon extended as the flight is flown (:func:`learning_horizon`): at rest
  before ``t = 0``, a line fitted to the last 0.25 s after the end.
* **Where the wind acts.** The wind pushes the airframe, the command first passes the
  attitude loop ``A = s^2 P``: each vehicle's command-side equivalent of the same wind is
  ``A_j^{-1}{d}``. The Theorem with these wind maps gains the factor
  ``W = A_hat_{j-1}/A_hat_j`` (:func:`airframe_path_filter`); without it UAV3, learning
  from UAV1 (tau 0.139 vs 0.100 s), kept ~5 mm of error at the fixed point (noise-free,
  scenario 1), and the full run leaves 1-6 % of the DOB-only RMSE instead of 0.5-3 %.
* **One-pass convergence.** With exact models the law reaches its fixed point in one
  flight (as the paper reports) and from then on copies the previous vehicle's sensor
  noise and residual every flight. A learning gain ``gamma < 1`` (``learning_gain``,
  default 1: the Theorem's law) averages them over the chain: the error falls by
  ``1 - gamma`` per flight to the same floor.

So the law flown is (:class:`VehicleLearning`)::

    d_f,j = F{ W{ L1_j{ F{gamma e_{j-1} + Gf_{j-1}{d_f,{j-1}}} } } }

which with ``F = W = gamma = 1`` is the Theorem's ``L1_j{e_{j-1}} + L2_j{d_f,{j-1}}``.

Disturbance estimate against the truth: ``d_hat + d_f`` is a command-side signal (what
the vehicle must be commanded to cancel the wind), the true disturbance is the airframe's
acceleration ``d``. They are compared as airframe accelerations, the estimate passed
through the model's attitude chain: ``rmse(A_hat{d_hat + d_f} - d)``
(:attr:`NonlinearFlight.rmse_dhat`).
"""

from __future__ import annotations

import math
import sys
import time
import tomllib
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import signal as sps

from ilcdob.design import LearningFilters, closed_form_filters
from ilcdob.design.closed_form import simulate_map
from ilcdob.signals import as_signal
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet, default_fleet, fleet_from_dict
from ilcdob.identification.fleet_id import VehicleIdentification, fleet_toml, identify_vehicle
from ilcdob.vehicles.quadrotor import (DiscretePID, QuadrotorParams, limit_tilt, make_advance,
                                             table_i_vehicles)
from ilcdob.loop import LoopSystem
from ilcdob.specs import PlantSpec

from .reproduce import ReproductionResult, ScenarioResult, SystemResult, learning_chain
from .scenarios import Scenario, scenario
from .simulate import Flight, rmse

#: Length of the trial end fitted by the line that extends it (:func:`learning_horizon`), s.
END_FIT_S = 0.25

__all__ = ["NonlinearSettings", "NonlinearFlight", "NonlinearReproduction", "VehicleLearning", "fly_loop",
           "model_attitude", "airframe_path_filter", "learning_horizon", "robustness_filter",
           "identify_vehicles", "run_nonlinear_scenario", "reproduce_nonlinear"]


@dataclass(frozen=True)
class NonlinearSettings:
    """Settings of the nonlinear reproduction.

    Attributes
    ----------
    sensor_noise_std : float
        Standard deviation of the white noise on the measured position (x, y, z), m (>= 0,
        < 0.1). Default 0.5 mm: motion-capture grade, as in indoor multi-vehicle
        experiments. The same sensor flies the identification experiments.
    seed : int
        Seed (>= 0) of every random stream: identification flights and sensor noise of each
        trial (``numpy.random.default_rng`` of a ``SeedSequence`` keyed by scenario, system
        and trial).
    identify : bool
        Identify the vehicles from step and chirp flights (the paper's pipeline, default).
        ``False`` keeps the fleet file's plants as the models.
    learning_cutoff : float or None
        Corner frequency ``w_c`` of the zero-phase robustness filter F on the learning
        signal, rad/s (> 0; ``None`` disables it). Default 10 rad/s: above every
        disturbance of the scenarios (0.94 and 1.41 rad/s, half-wave harmonics up to
        ~8.5 rad/s) and below the band where ``1/P_hat`` amplifies sensor noise.
    learning_filter_order : int
        Order ``n`` of the Butterworth prototype (1..8); applied forwards and backwards.
    airframe_disturbance : bool
        Learn with the wind's true path (it acts on the airframe): the correction
        ``W = P_hat_{j-1}/P_hat_j`` of :func:`airframe_path_filter` (default). ``False``
        flies the paper's law as is, which assumes the wind at the command input.
    learning_gain : float
        ``gamma`` in (0, 1]: the share of the newly reconstructed error learned per flight
        (:class:`VehicleLearning`). 1 (default) is the Theorem's law, which reaches its
        fixed point in one pass (the paper, Section IV: learning converges in the first
        iteration) and then copies the previous vehicle's sensor noise and own residual every
        flight, so iterations 1-3 stay on that floor, a few percent apart in either direction.
        A smaller gain averages them over the chain: the error falls geometrically (factor
        ``1 - gamma`` per flight) to the same floor instead of jumping there; the path
        changes, the final accuracy does not. Measured on the full run (seed 0), learning
        1 / 2 / 3 over the DOB-only RMSE: gain 1, 0.44-3.33 % / 0.38-3.33 % / 0.36-3.35 %;
        gain 0.5, 12-50 % / 1.5-7.2 % / 0.46-2.97 %.
    inner_rate_hz : float
        Integration and inner-loop rate of the vehicles, Hz (a multiple of ``1/Ts``).
    """

    sensor_noise_std: float = 0.0005
    seed: int = 0
    identify: bool = True
    learning_cutoff: float | None = 10.0
    learning_filter_order: int = 4
    airframe_disturbance: bool = True
    learning_gain: float = 1.0
    inner_rate_hz: float = 500.0

    def __post_init__(self) -> None:
        v = self.sensor_noise_std
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0.0 <= v < 0.1):
            raise SpecError(f"`sensor_noise_std`: got {v!r}, expected a standard deviation in [0, 0.1) m")
        object.__setattr__(self, "sensor_noise_std", float(v))
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise SpecError(f"`seed`: got {self.seed!r}, expected an integer >= 0")
        if not isinstance(self.airframe_disturbance, bool):
            raise SpecError(f"`airframe_disturbance`: got {self.airframe_disturbance!r}, expected True or False")
        if not isinstance(self.identify, bool):
            raise SpecError(f"`identify`: got {self.identify!r}, expected True or False")
        wc = self.learning_cutoff
        if wc is not None:
            if isinstance(wc, bool) or not isinstance(wc, (int, float)) or not (math.isfinite(wc) and wc > 0):
                raise SpecError(f"`learning_cutoff`: got {wc!r}, expected a frequency > 0 rad/s or None")
            object.__setattr__(self, "learning_cutoff", float(wc))
        n = self.learning_filter_order
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= 8:
            raise SpecError(f"`learning_filter_order`: got {n!r}, expected an integer in 1..8")
        g = self.learning_gain
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not (0.0 < g <= 1.0):
            raise SpecError(f"`learning_gain`: got {g!r}, expected a number in (0, 1]")
        object.__setattr__(self, "learning_gain", float(g))
        r = self.inner_rate_hz
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not (math.isfinite(r) and r >= 50):
            raise SpecError(f"`inner_rate_hz`: got {r!r}, expected a rate >= 50 Hz")

    def to_dict(self) -> dict[str, object]:
        return {"sensor_noise_std_m": self.sensor_noise_std, "seed": int(self.seed),
                "identify": self.identify, "learning_cutoff_rad_s": self.learning_cutoff,
                "learning_filter_order": int(self.learning_filter_order),
                "airframe_disturbance": self.airframe_disturbance, "learning_gain": self.learning_gain,
                "inner_rate_hz": self.inner_rate_hz}


@dataclass(frozen=True)
class NonlinearFlight(Flight):
    """One trial of a nonlinear vehicle: a :class:`~ilcdob.validation.simulate.Flight` whose
    ``y``/``e`` are the *true* position and error and ``d`` the disturbance as it acts on the
    airframe (force / mass, wind + the vehicle's noise), plus what the flight computer saw.

    Attributes
    ----------
    y_meas : array, m
        Measured position ``x_m`` (true position + sensor noise).
    e_meas : array, m
        Measured tracking error ``r - x_m`` (what the learning uses).
    d_est : array, m/s^2
        The total estimate ``d_hat + d_f`` (command side) expressed as the acceleration it
        stands for on the airframe: ``A_hat{d_hat + d_f}`` with the model's attitude chain
        ``A_hat = s^2 P_hat`` under zero-order hold (:func:`model_attitude`).
    saturated : int
        Samples at which the tilt limit cut the commanded acceleration (``u2`` is the
        command actually sent).
    """

    y_meas: np.ndarray = field(default_factory=lambda: np.zeros(0))
    e_meas: np.ndarray = field(default_factory=lambda: np.zeros(0))
    d_est: np.ndarray = field(default_factory=lambda: np.zeros(0))
    saturated: int = 0

    @property
    def rmse_dhat(self) -> float:
        """RMSE of the disturbance estimate against the true disturbance, m/s^2:
        ``rmse(A_hat{d_hat + d_f} - d)`` (both as accelerations of the airframe)."""
        return rmse(self.d_est - self.d)


def _rigid_body_split(plant: PlantSpec, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` of the attitude chain ``A_hat = s^2 P_hat`` of a model ``A_hat/s^2``."""
    num = np.trim_zeros(np.asarray(plant.num, float), "f")
    den = np.trim_zeros(np.asarray(plant.den, float), "f")
    k = 0
    while den.size > 1 and den[-1] == 0.0:
        den, k = den[:-1], k + 1
    if k != 2 or num[-1] == 0.0:
        raise SpecError(f"model of {name!r}: got P_hat = {list(plant.num)}/{list(plant.den)} with {k} "
                        "integrator(s); the nonlinear vehicles need models A(s)/s^2 (attitude chain times "
                        "the rigid body's two integrators), e.g. b0/(s^2 (s + a0))")
    return num, den


def model_attitude(loop: LoopSystem) -> tuple[np.ndarray, np.ndarray, int]:
    """The model's attitude chain ``A_hat = s^2 P_hat`` under zero-order hold.

    Returns
    -------
    (b, a, delay) : (numpy.ndarray, numpy.ndarray, int)
        ``z^-1`` coefficients for :func:`scipy.signal.lfilter` and the model's input delay
        in whole samples (rounded).
    """
    num, den = _rigid_body_split(loop.spec.nominal_plant, loop.name)
    b, a, _ = sps.cont2discrete((num, den), loop.ts, method="zoh")
    return np.atleast_1d(np.squeeze(b)), np.atleast_1d(a), int(round(loop.spec.nominal_plant.delay / loop.ts))


def _mats(sys_) -> tuple[list[list[float]], list[float], list[float], float]:
    """Block matrices as nested lists: pure-Python products beat NumPy for 2-3 states."""
    a = np.asarray(sys_.A, float)
    return (a.tolist(), np.asarray(sys_.B, float)[:, 0].tolist(), np.asarray(sys_.C, float)[0].tolist(),
            float(np.asarray(sys_.D).ravel()[0]))


class _Block:
    """A discrete SISO state-space block stepped by hand: ``y = C x + D u``, ``x+ = A x + B u``."""

    def __init__(self, sys_) -> None:
        self.a, self.b, self.c, self.d = _mats(sys_)
        self.x = [0.0] * len(self.b)

    def output(self, u: float = 0.0) -> float:
        return sum(ci * xi for ci, xi in zip(self.c, self.x)) + self.d * u

    def update(self, u: float) -> None:
        x = self.x
        self.x = [sum(aij * xj for aij, xj in zip(row, x)) + bi * u for row, bi in zip(self.a, self.b)]


def fly_loop(vehicle: QuadrotorParams, loop: LoopSystem, r: object, disturbance: object,
             d_f: object | None = None, mode: str = "dob", a_ref: object | None = None,
             noise_std: float = 0.0, rng: np.random.Generator | None = None) -> NonlinearFlight:
    """Fly one trial of the nonlinear ``vehicle`` under ``loop``'s outer loop (see module
    docstring; the loop of paper Sec. II with the vehicle in place of ``P``).

    Parameters
    ----------
    vehicle : QuadrotorParams
        The "real vehicle"; its inner rate must be a multiple of ``1/loop.ts``.
    loop : LoopSystem
        Supplies the discrete PID ``C``, ``Q`` and ``M = Q/P_hat`` (built from the model).
    r : array, m
        x reference over the trial, ``N`` samples at ``loop.ts``.
    disturbance : callable
        External x acceleration (force / mass) on the airframe, m/s^2 (wind + the system's
        noise): a vectorised callable of time (s), evaluated at the inner rate.
    d_f : array, m/s^2, optional
        Learning signal (mode ``"dob"`` only).
    mode : {"dob", "no_dob"}
    a_ref : array, m/s^2, optional
        Reference acceleration, fed forward if the PID's ``acceleration_feedforward`` is on.
    noise_std : float
        Standard deviation of the white position-sensor noise, m (>= 0).
    rng : numpy.random.Generator, optional
        Source of the sensor noise (required when ``noise_std > 0``).

    Returns
    -------
    NonlinearFlight
        ``y``, ``e``: true position and error; ``y_meas``, ``e_meas``: measured;
        ``d``: the disturbance acting on the airframe at ``t_k``; ``d_hat``, ``d_f``, ``u2``
        as flown; ``d_est``: ``d_hat + d_f`` as an airframe acceleration.
    """
    if not isinstance(vehicle, QuadrotorParams):
        raise SpecError(f"`vehicle`: got {type(vehicle).__name__}, expected a QuadrotorParams")
    if not isinstance(loop, LoopSystem):
        raise SpecError(f"`loop`: got {type(loop).__name__}, expected a LoopSystem")
    if mode not in ("dob", "no_dob"):
        raise SpecError(f"`mode`: got {mode!r}, expected 'dob' or 'no_dob'")
    if isinstance(noise_std, bool) or not isinstance(noise_std, (int, float)) or not (0.0 <= noise_std < 0.1):
        raise SpecError(f"`noise_std`: got {noise_std!r}, expected a standard deviation in [0, 0.1) m")
    if noise_std > 0 and not isinstance(rng, np.random.Generator):
        raise SpecError(f"`rng`: got {rng!r}, expected a numpy.random.Generator when noise_std > 0")
    ts = loop.ts
    ratio = ts * vehicle.inner_rate_hz
    nin = int(round(ratio))
    if nin < 1 or abs(ratio - nin) > 1e-9 * max(1.0, ratio):
        raise SpecError(f"`vehicle.inner_rate_hz`: got {vehicle.inner_rate_hz:g} Hz, expected a multiple "
                        f"of the outer rate 1/Ts = {1 / ts:g} Hz")
    r = as_signal(r, "r")
    n = r.size
    if n < 2:
        raise SpecError(f"`r`: got {n} sample(s), expected a trial of at least 2 samples")
    t = np.arange(n) * ts
    t_inner = np.arange(n * nin) * vehicle.inner_dt
    if not callable(disturbance):
        raise SpecError(f"`disturbance`: got {type(disturbance).__name__}, expected a vectorised callable "
                        "of time (s) returning m/s^2")
    d_out = as_signal(np.broadcast_to(np.asarray(disturbance(t), float), t.shape), "disturbance")
    d_inner = as_signal(np.broadcast_to(np.asarray(disturbance(t_inner), float), t_inner.shape), "disturbance")
    ab, aa, adelay = model_attitude(loop)
    df = np.zeros(n) if d_f is None else as_signal(d_f, "d_f", n)
    if mode == "no_dob" and np.any(df):
        raise SpecError("`d_f`: a learning signal needs the DOB loop (mode='dob')")
    aff = np.zeros(n)
    if a_ref is not None and loop.spec.controller.acceleration_feedforward:
        aff = as_signal(a_ref, "a_ref", n)
    noise = rng.normal(0.0, noise_std, size=(n, 3)) if noise_std > 0 else np.zeros((n, 3))
    if float(np.asarray(loop.Q.D).ravel()[0]) != 0.0:
        raise SpecError("Q must be strictly proper in discrete time (algebraic loop through the DOB)")

    advance = make_advance(vehicle)
    c_blk, q_blk, m_blk = _Block(loop.C), _Block(loop.Q), _Block(loop.M)
    pid_y = DiscretePID(loop.spec.controller, ts)
    pid_z = DiscretePID(vehicle.z_controller, ts)
    s = [0.0] * 6 + [1.0, 0.0, 0.0, 0.0] + [0.0] * 3 + [vehicle.hover_rotor_speed] * 4
    wprev = (0.0, 0.0)
    d_list = d_inner.tolist()
    tan_max = math.tan(vehicle.max_tilt)
    use_dob = mode == "dob"
    r_l, aff_l, df_l, nz = r.tolist(), aff.tolist(), df.tolist(), noise.tolist()
    y, ym_arr, dh, u2 = (np.zeros(n) for _ in range(4))
    saturated = 0
    for k in range(n):
        x_true = s[0]
        xm, ym, zm = x_true + nz[k][0], s[1] + nz[k][1], s[2] + nz[k][2]
        em = r_l[k] - xm
        u1 = c_blk.output(em) + aff_l[k]
        c_blk.update(em)
        if use_dob:
            dhk = m_blk.output(xm) - q_blk.output()
            u2k = u1 - dhk - df_l[k]
        else:
            dhk, u2k = 0.0, u1
        u2k, ay, az, limited = limit_tilt(u2k, pid_y(-ym), pid_z(-zm), tan_max)
        saturated += limited
        if use_dob:
            q_blk.update(u2k)
            m_blk.update(xm)
        y[k], ym_arr[k], dh[k], u2[k] = x_true, xm, dhk, u2k
        if k < n - 1:
            s, wprev = advance(s, u2k, ay, az, d_list, k * nin, nin, wprev, None)
    est = sps.lfilter(ab, aa, dh + df)
    if adelay:
        est = np.concatenate([np.zeros(adelay), est[:-adelay]])
    return NonlinearFlight(system=loop.name, mode=mode, t=t, r=r, y=y, e=r - y, d=d_out, d_hat=dh,
                           d_f=df, u2=u2, y_meas=ym_arr, e_meas=r - ym_arr, d_est=est,
                           saturated=saturated)


def _linear_tail(x: np.ndarray, n_fit: int, n_pad: int) -> np.ndarray:
    """``n_pad`` samples continuing ``x`` along the least-squares line through its last
    ``n_fit`` samples (robust to noise, keeps the slope)."""
    m = min(n_fit, x.size)
    k = np.arange(m, dtype=float)
    coef = np.polyfit(k, x[-m:], 1) if m > 1 else np.array([0.0, x[-1]])
    return np.polyval(coef, np.arange(m, m + n_pad, dtype=float))


def learning_horizon(x: object, ts: float, pad: int) -> np.ndarray:
    """Extend one trial by ``pad`` samples at each end, as it is flown: before ``t = 0`` the
    vehicle hovers at rest (zeros), after the end the signal continues along the
    least-squares line through its last ``END_FIT_S`` seconds (0.25 s: long enough to
    average the sensor noise, short enough to follow the trend at the end; with 1 s the
    end of scenario 4, where the half-wave wind has a kink at 59.99 s, was learned badly).

    A mirror image at the end would bend the signal flat there, a point reflection about the
    last (noisy) sample adds a step; an end-to-end zero-phase filter whose start is cut at
    ``t = 0`` hands the plant inverse a jump in the derivatives. Each of these, fed through
    ``1/P_hat``, grew from one learning iteration to the next on the nonlinear vehicles.
    """
    x = as_signal(x, "x")
    if isinstance(pad, bool) or not isinstance(pad, (int, np.integer)) or pad < 0:
        raise SpecError(f"`pad`: got {pad!r}, expected an integer number of samples >= 0")
    if pad == 0:
        return x
    return np.concatenate([np.zeros(pad), x, _linear_tail(x, max(2, int(round(END_FIT_S / ts))), pad)])


def robustness_filter(x: object, ts: float, cutoff: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass ``F`` (forward-backward, ``|F| = 1/(1 + (w/w_c)^(2n))``).

    Parameters
    ----------
    x : array
        Signal, already extended (:func:`learning_horizon`); run without further padding.
    ts : float
        Sample time, s.
    cutoff : float
        Corner ``w_c`` of the prototype, rad/s, below the Nyquist frequency ``pi/ts``.
    order : int
        Prototype order ``n`` (1..8).
    """
    x = as_signal(x, "x")
    nyq = math.pi / ts
    if isinstance(cutoff, bool) or not isinstance(cutoff, (int, float)) or not 0.0 < cutoff < nyq:
        raise SpecError(f"`cutoff`: got {cutoff!r} rad/s, expected a frequency in (0, {nyq:.4g}) rad/s "
                        f"(the Nyquist frequency at Ts = {ts:g} s)")
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or not 1 <= order <= 8:
        raise SpecError(f"`order`: got {order!r}, expected an integer in 1..8")
    sos = sps.butter(order, cutoff / nyq, output="sos")
    return sps.sosfiltfilt(sos, x, padtype=None)


def airframe_path_filter(source: LoopSystem, target: LoopSystem) -> tuple[np.ndarray, np.ndarray]:
    """Discrete ``W = A_hat_{j-1} / A_hat_j = P_hat_{j-1} / P_hat_j`` (Tustin): the
    airframe-wind correction of the learning filter.

    The wind acts on the rigid body (``x'' = A{u2} + d``), not at the command input that
    the paper's loop ``y = P{u2 + d}`` (Sec. II) assumes. Its command-side equivalent
    differs per vehicle, ``A_j^{-1}{d}``, so vehicle j-1's data reconstruct *its* equivalent
    and vehicle j needs its own. With the wind maps ``Gd_j = P_j (1 - Q_j)/D_j * A_j^{-1}``
    in the Theorem's ``L1_j = (Gf_j Gd_{j-1})^{-1} Gd_j`` (paper Sec. III) the paper's L1
    gains exactly the factor ``A_{j-1}/A_j``, built here from the models
    (``A_hat = s^2 P_hat``). Around a cycle of the fleet the factors multiply to 1.

    Returns
    -------
    (b, a) : numpy.ndarray
        ``z^-1`` coefficients of W for :func:`scipy.signal.lfilter`.

    Raises
    ------
    SpecError
        A model is not ``A(s)/s^2``, the model delays differ, or ``A_hat_j`` has a zero in
        the closed right half plane (W would be unstable).
    """
    ns, ds = _rigid_body_split(source.spec.nominal_plant, source.name)
    nt, dt_ = _rigid_body_split(target.spec.nominal_plant, target.name)
    ps, pt = source.spec.nominal_plant, target.spec.nominal_plant
    if abs(ps.delay - pt.delay) > 1e-9:
        raise SpecError(f"models of {source.name!r} and {target.name!r}: delays {ps.delay:g} s and "
                        f"{pt.delay:g} s differ; the airframe correction needs equal model delays")
    zt = np.roots(nt) if nt.size > 1 else np.zeros(0)
    if np.any(zt.real >= 0):
        raise SpecError(f"model of {target.name!r}: zeros {zt} in the closed right half plane; "
                        "A_hat_j-1/A_hat_j would be unstable")
    b, a = sps.bilinear(np.polymul(ns, dt_), np.polymul(ds, nt), fs=1.0 / source.ts)
    return np.atleast_1d(b), np.atleast_1d(a)


@dataclass(frozen=True)
class VehicleLearning:
    """The learning law flown on the vehicles (module docstring)::

        d_f,j = F{ W{ L1_j{ F{gamma e_{j-1} + Gf_{j-1}{d_f,{j-1}}} } } }

    which with ``F = W = gamma = 1`` is the Theorem's ``L1_j{e_{j-1}} + L2_j{d_f,{j-1}}``
    (the Theorem, paper Sec. III), evaluated as in
    :meth:`ilcdob.design.LearningFilters.apply`
    (``L2 = L1 Gf_{j-1}``).

    Attributes
    ----------
    filters : LearningFilters
        The closed-form filters of the Theorem from the identified models.
    path : tuple of numpy.ndarray or None
        ``(b, a)`` of the airframe correction W (:func:`airframe_path_filter`), or ``None``
        for the paper's law as is (wind assumed at the command input).
    cutoff : float or None
        Corner of the robustness filter F, rad/s (:func:`robustness_filter`); ``None``:
        ``F = 1`` and no horizon extension.
    order : int
        Butterworth order of F.
    gain : float
        Learning gain ``gamma`` in (0, 1] on the new error: ``gamma L1{e_{j-1}} +
        L2{d_f,{j-1}}`` (1: the Theorem's law).
    """

    filters: LearningFilters
    path: tuple[np.ndarray, np.ndarray] | None
    cutoff: float | None
    order: int = 4
    gain: float = 1.0

    @property
    def pad(self) -> int:
        """Samples added at each end of the trial (:func:`learning_horizon`): six periods of
        the corner frequency, where F's impulse response has decayed."""
        if self.cutoff is None:
            return 0
        return int(6 * math.ceil(2 * math.pi / self.cutoff / self.filters.source.ts))

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """Learning signal of vehicle j from vehicle j-1's trial.

        Parameters
        ----------
        e_prev : array, m
            Vehicle j-1's *measured* tracking error.
        df_prev : array, m/s^2
            The learning signal vehicle j-1 flew with (zeros if none).

        Returns
        -------
        numpy.ndarray
            ``d_f,j``, m/s^2, same length.
        """
        lf = self.filters
        ts = lf.source.ts
        e = as_signal(e_prev, "e_prev")
        df_prev = as_signal(df_prev, "df_prev", e.size)
        e_virtual = self.gain * e
        if np.any(df_prev):
            e_virtual = e_virtual + simulate_map(lf.source.G_f, df_prev)
        pad = self.pad
        x = learning_horizon(e_virtual, ts, pad)
        if self.cutoff is not None:
            x = robustness_filter(x, ts, self.cutoff, self.order)
        df = lf.L1.apply(x, "e_prev")
        if self.path is not None:
            df = sps.lfilter(self.path[0], self.path[1], df)
        if self.cutoff is not None:
            df = robustness_filter(df, ts, self.cutoff, self.order)
        return df[pad:pad + e.size]


def identify_vehicles(fleet: Fleet, vehicles: dict[str, QuadrotorParams],
                      settings: NonlinearSettings,
                      progress: Callable[[str], None] | None = None
                      ) -> tuple[Fleet, dict[str, VehicleIdentification], str]:
    """Identify every vehicle from step and chirp flights and build the fleet of the models.

    Each system of the returned fleet has the identified ``P_hat`` as its plant (so its
    loop's ``M = Q/P_hat`` and its learning filters use the model); controllers, DOBs and
    noises are ``fleet``'s. Source: ``"identified_fleet.toml"``.

    Returns
    -------
    (Fleet, dict, str)
        The fleet of the models, the identification of every vehicle, and the fleet file
        of the models (TOML text).
    """
    say = progress or (lambda msg: None)
    results = {}
    for i, name in enumerate(fleet.names):
        results[name] = identify_vehicle(name, fleet, seed=int(settings.seed) + 10 * i,
                                         noise_std=settings.sensor_noise_std, progress=None,
                                         vehicle=vehicles[name])
        est = results[name].estimate
        say(f"identified {name}: fit {est.fit_estimation:.2f} % (estimation), "
            f"{est.fit_validation:.2f} % (held out)")
    header = (f"# Identified from synthetic step + chirp flights of the nonlinear vehicles "
              f"(ilcdob.validation.nonlinear, seed {settings.seed}, sensor noise "
              f"{settings.sensor_noise_std:g} m); controllers, DOBs and noises from {fleet.source}")
    text = fleet_toml(fleet, results, header)
    return fleet_from_dict(tomllib.loads(text), "identified_fleet.toml"), results, text


def _check_vehicles(fleet: Fleet, vehicles: dict[str, QuadrotorParams] | None,
                    inner_rate_hz: float) -> dict[str, QuadrotorParams]:
    if vehicles is None:
        vehicles = table_i_vehicles(inner_rate_hz)
    if not isinstance(vehicles, dict):
        raise SpecError(f"`vehicles`: got {type(vehicles).__name__}, expected a dict name -> QuadrotorParams")
    missing = [name for name in fleet.names if name not in vehicles]
    if missing:
        raise SpecError(f"`fleet`: system(s) {missing} have no nonlinear vehicle; vehicles exist for "
                        f"{sorted(vehicles)} (the paper's Table I). Rename the fleet's systems or pass "
                        "`vehicles`")
    for name in fleet.names:
        if not isinstance(vehicles[name], QuadrotorParams):
            raise SpecError(f"`vehicles[{name!r}]`: got {type(vehicles[name]).__name__}, expected a "
                            "QuadrotorParams")
    return {name: vehicles[name] for name in fleet.names}


def _learning_for(fleet: Fleet, cache: dict, src: str, tgt: str, settings: NonlinearSettings) -> VehicleLearning:
    """The learning law of the pair; ``cache`` holds the closed-form filters (for figures)."""
    if (src, tgt) not in cache:
        cache[(src, tgt)] = closed_form_filters(fleet.loop(src), fleet.loop(tgt))
    path = airframe_path_filter(fleet.loop(src), fleet.loop(tgt)) if settings.airframe_disturbance else None
    return VehicleLearning(cache[(src, tgt)], path, settings.learning_cutoff, settings.learning_filter_order,
                           settings.learning_gain)


def _rng(settings: NonlinearSettings, sid: int, index: int, trial: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(settings.seed), 1000 + sid, index, trial]))


def run_nonlinear_scenario(fleet: Fleet, vehicles: dict[str, QuadrotorParams], sc: Scenario,
                           iterations: int = 3, filters: dict | None = None,
                           settings: NonlinearSettings | None = None) -> ScenarioResult:
    """Fly one scenario with every nonlinear vehicle: no DOB, only DOB, ``iterations``
    learning trials passed around the fleet in ``sc``'s order (the chain of
    :mod:`ilcdob.validation.reproduce`), each learning signal from the previous flight's
    *measured* error by :class:`VehicleLearning`.

    Parameters
    ----------
    fleet : Fleet
        Loops built from the models (identified plants).
    vehicles : dict
        Fleet name -> nonlinear vehicle.
    sc : Scenario
    iterations : int
        Learning trials per system (>= 1).
    filters : dict, optional
        Cache of closed-form filters keyed by (source, target), filled as needed.
    settings : NonlinearSettings, optional
    """
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise SpecError(f"`iterations`: got {iterations!r}, expected an integer >= 1")
    if not isinstance(sc, Scenario):
        raise SpecError(f"`sc`: got {type(sc).__name__}, expected a Scenario")
    settings = settings if settings is not None else NonlinearSettings()
    vehicles = _check_vehicles(fleet, vehicles, settings.inner_rate_hz)
    filters = {} if filters is None else filters
    ts = fleet.sample_time
    t = sc.time(ts)
    r = sc.reference(t)
    a_ref = sc.acceleration(t)
    order = sc.order(fleet.names)
    specs = {s.name: s for s in fleet.systems}
    index = {name: i for i, name in enumerate(fleet.names)}

    def dist(name: str) -> Callable[[np.ndarray], np.ndarray]:
        noise = specs[name].noise
        return lambda tt: sc.disturbance(tt) + noise(tt)

    def flight(name: str, trial: int, mode: str, d_f: np.ndarray | None = None) -> NonlinearFlight:
        return fly_loop(vehicles[name], fleet.loop(name), r, dist(name), d_f=d_f, mode=mode, a_ref=a_ref,
                        noise_std=settings.sensor_noise_std, rng=_rng(settings, sc.id, index[name], trial))

    base = {name: (flight(name, 0, "no_dob"), flight(name, 1, "dob")) for name in order}
    flown = {name: 0 for name in order}  # learning flights so far: trial index of the noise seed

    def step(src: str, tgt: str, prev: NonlinearFlight) -> NonlinearFlight:
        df = _learning_for(fleet, filters, src, tgt, settings).apply(prev.e_meas, prev.d_f)
        flown[tgt] += 1
        return flight(tgt, 1 + flown[tgt], "dob", df)

    learning, chain = learning_chain(order, iterations, base[order[0]][1], step)
    systems = {name: SystemResult(base[name][0], base[name][1], tuple(learning[name])) for name in order}
    return ScenarioResult(scenario=sc, order=order, systems=systems, chain=chain)


@dataclass(frozen=True)
class NonlinearReproduction(ReproductionResult):
    """A :class:`~ilcdob.validation.reproduce.ReproductionResult` flown on the nonlinear
    vehicles; ``fleet`` holds the identified models.

    Attributes
    ----------
    settings : NonlinearSettings
    vehicles : dict
        Fleet name -> the nonlinear vehicle flown.
    identification : dict
        Fleet name -> :class:`~ilcdob.identification.fleet_id.VehicleIdentification`
        (empty when ``settings.identify`` is False).
    identified_toml : str
        The fleet file of the models (written as ``identified_fleet.toml``).
    """

    settings: NonlinearSettings = field(default_factory=NonlinearSettings)
    vehicles: dict = field(default_factory=dict)
    identification: dict = field(default_factory=dict)
    identified_toml: str = ""

    def to_dict(self) -> dict[str, object]:
        """The schema of :meth:`ReproductionResult.to_dict` with ``"plant": "nonlinear"``."""
        data = super().to_dict()
        data["plant"] = "nonlinear"
        return data

    def acceptance(self) -> list[dict[str, object]]:
        """The reproduction's acceptance per scenario and system (needs 3 or more iterations).

        ``rmse_learning[2] <= 0.10 rmse_dob`` and ``rmse_dhat_learning[2] <= 0.3
        rmse_dhat_dob``. ``spread`` (``max / min - 1`` of the learning RMSE over iterations
        1..3) is reported, not judged: with the Theorem's gain 1 learning reaches its floor
        in the first iteration and the later iterations scatter on it (``learning_gain``).
        """
        if self.iterations < 3:
            raise SpecError(f"`iterations`: the acceptance needs 3 learning iterations, the run has "
                            f"{self.iterations}")
        rows = []
        for sr in self.scenarios:
            for name in sr.order:
                m = sr.systems[name].metrics()
                learn, dhat = m["rmse_learning"], m["rmse_dhat_learning"]
                rows.append({
                    "scenario": sr.scenario.id, "system": name,
                    "error_ratio": learn[2] / m["rmse_dob"],
                    "spread": max(learn[:3]) / min(learn[:3]) - 1.0,
                    "dhat_ratio": dhat[2] / m["rmse_dhat_dob"],
                })
        for row in rows:
            row["passed"] = bool(row["error_ratio"] <= 0.10 and row["dhat_ratio"] <= 0.3)
        return rows

    def markdown_plant(self) -> list[str]:
        """The description of this run for the report's README.md (:mod:`ilcdob.app.output`)."""
        s = self.settings
        lines = [
            f"**Plant: nonlinear.** The nonlinear 6-DOF quadrotors (`ilcdob.vehicles.quadrotor`, "
            f"Table I vehicles, inner loops at {s.inner_rate_hz:g} Hz) fly every trial; the outer loop (PID + DOB "
            f"+ learning signal, x axis) runs at the fleet's sample time {self.fleet.sample_time} s with "
            f"{1e3 * s.sensor_noise_std:g} mm of white position-sensor noise; wind and per-vehicle noise act on "
            "the airframe as external forces. "
            + ("Models identified from step and chirp flights of the same vehicles "
               "(`identified_fleet.toml`, fits below); " if s.identify else "Models from the fleet file; ")
            + f"filters designed from the models; {self.iterations} learning iterations. Learning law: the "
            "Theorem's closed-form filters with the airframe-wind correction, a zero-phase robustness filter "
            f"at {s.learning_cutoff} rad/s and learning gain {s.learning_gain:g} "
            "(`ilcdob.validation.nonlinear` explains each). Tracking RMSE: true position; disturbance "
            "estimate: A_hat{d_hat + d_f} against the wind + noise acceleration on the airframe. Regenerate "
            "with `ilcdob reproduce --plant nonlinear --out <dir>`; numbers are in `results.json`.",
        ]
        if self.iterations >= 3:
            lines += ["", "Acceptance: learning 3 / only DOB <= 0.10 and d est. learning 3 / only DOB <= 0.3 "
                          "(spread: max / min - 1 of the learning RMSE over iterations 1-3, for information):", "",
                      "| scenario | system | learning 3 / DOB | spread 1-3 | d est. learning 3 / DOB | passed |",
                      "|---|---|---|---|---|---|"]
            for row in self.acceptance():
                lines.append(f"| {row['scenario']} | {row['system']} | {row['error_ratio']:.4f} | "
                             f"{100 * row['spread']:.1f} % | {row['dhat_ratio']:.3f} | "
                             f"{'yes' if row['passed'] else 'NO'} |")
        return lines


def reproduce_nonlinear(fleet: Fleet | None = None, scenario_ids: list[int] = (1, 2, 3, 4),
                        iterations: int = 3, settings: NonlinearSettings | None = None,
                        vehicles: dict[str, QuadrotorParams] | None = None,
                        progress: Callable[[str], None] | None = None,
                        scenarios: list[Scenario] | None = None) -> NonlinearReproduction:
    """Identify the vehicles, design the filters and fly the scenarios (module docstring).

    Parameters
    ----------
    fleet : Fleet, optional
        Controllers, DOBs and noises of the systems (default: the built-in fleet); with
        ``settings.identify`` False its plants are the models.
    scenario_ids : list of int
        Scenarios to fly (1-4).
    iterations : int
        Learning iterations (>= 1).
    settings : NonlinearSettings, optional
    vehicles : dict, optional
        Fleet name -> :class:`QuadrotorParams` (default: :func:`table_i_vehicles`).
    progress : callable, optional
        Receives one line per step (default: printed to stderr).
    scenarios : list of Scenario, optional
        Fly these instead of ``scenario_ids`` (e.g. shortened copies, for tests).
    """
    say = progress if progress is not None else (lambda msg: print(msg, file=sys.stderr, flush=True))
    settings = settings if settings is not None else NonlinearSettings()
    if not isinstance(settings, NonlinearSettings):
        raise SpecError(f"`settings`: got {type(settings).__name__}, expected a NonlinearSettings")
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise SpecError(f"`iterations`: got {iterations!r}, expected an integer >= 1")
    base = fleet if fleet is not None else default_fleet()
    if not isinstance(base, Fleet):
        raise SpecError(f"`fleet`: got {type(base).__name__}, expected a Fleet or None")
    vehicles = _check_vehicles(base, vehicles, settings.inner_rate_hz)
    scs = list(scenarios) if scenarios is not None else [scenario(sid) for sid in scenario_ids]
    start = time.perf_counter()
    if settings.identify:
        models, ident, toml_text = identify_vehicles(base, vehicles, settings, say)
    else:
        models, ident, toml_text = base, {}, fleet_toml(base, {})
    say(f"identification: {time.perf_counter() - start:.1f} s")
    filters: dict = {}
    results = []
    for i, sc in enumerate(scs, 1):
        t0 = time.perf_counter()
        results.append(run_nonlinear_scenario(models, vehicles, sc, iterations, filters, settings))
        say(f"[{i}/{len(scs)}] scenario {sc.id} ({sc.title}, nonlinear): {time.perf_counter() - t0:.1f} s")
    return NonlinearReproduction(fleet=models, scenarios=results, iterations=iterations, filters=filters,
                                 elapsed_s=time.perf_counter() - start, settings=settings, vehicles=vehicles,
                                 identification=ident, identified_toml=toml_text)
