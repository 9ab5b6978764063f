"""A rotorpy multirotor as a :class:`~ilcdob.vehicles.interface.Vehicle`: a simulator nobody here wrote.

rotorpy (PyPI ``rotorpy``, MIT licence; the ``[rotorpy]`` extra) integrates a quadrotor's rigid
body with first-order motors, rotor drag, parasitic drag and translational lift on the airspeed
``v - wind`` (its ``Multirotor``), one ``scipy.integrate.solve_ivp`` call per step. ilcdob's
outer loop commands an acceleration per axis; rotorpy's own geometric controller (``SE3Control``)
is the inner loop that turns it into thrust and attitude: given the vehicle's current position
and velocity as its reference and the command as the reference acceleration, its position and
velocity terms vanish and it asks the rotors for ``m (a + g e3)`` (pure feed-forward through
its attitude loop, which lags 0.1-0.2 s). Nothing of ilcdob's vehicle models is used.

Two disturbances, as in the paper and beyond it:

* ``command_disturbance(t)``: the paper's virtual disturbance, an acceleration (m/s^2, ``(3,)``)
  added to the command before the inner loop;
* ``wind(t)``: a wind velocity (m/s, world frame, ``(3,)``) acting through the airframe's drag
  (``state["wind"]``, held over each step), so one wind gives vehicles of different mass and
  drag different accelerations.

A lab's own airframe flies as itself: ``RotorpyVehicle("ours", airframe={...})`` with a complete
rotorpy parameter set (the keys of rotorpy's shipped sets: mass, inertia, arm geometry, rotor and
motor constants, drag coefficients, motor limits and the SE3 controller's gains), or
``airframe="hummingbird"`` with ``params`` changing some of its values. ``name`` is what the
vehicle is called in results.

Flown on its own controller: :meth:`RotorpyVehicle.track` gives rotorpy's SE3 controller a full-state
setpoint (position, velocity and acceleration feed-forward), which it tracks with its own position
gains (``position_gains``; rotorpy's defaults ``kp = (6.5, 6.5, 15)``, ``kd = (4, 4, 9)``): the
vehicle of :class:`~ilcdob.vehicles.closed_loop.ClosedLoopVehicle`, learning through one of those
setpoint channels with no ilcdob controller in the loop.

The vehicle starts each trial hovering at rest at ``altitude``; :meth:`RotorpyVehicle.position`
is measured from there. rotorpy draws its motor noise from NumPy's global generator on every
step (also when the noise is zero), so trials are repeatable but not independent of it.
"""

from __future__ import annotations

import copy
import importlib
from typing import Callable, Mapping

import numpy as np

from ilcdob.errors import SpecError

from .closed_loop import setpoint_rows
from ilcdob.channel_loop import check_channel

__all__ = ["RotorpyVehicle", "ROTORPY_VEHICLES", "shipped_airframe", "airframe_parameters", "airframe_summary"]

#: ilcdob's names of the parameter sets rotorpy ships (module ``rotorpy.vehicles.<value>``): mass 0.03, 0.044, 0.5
#: and 1.0 kg, arm 4.3, 4.3, 17 and 24 cm; their drag differs in kind (rotor drag only; rotor drag and translational
#: lift; both and lift; parasitic only).
ROTORPY_VEHICLES = {"crazyflie": "crazyflie_params", "crazyfliebrushless": "crazyfliebrushless_params",
                    "hummingbird": "hummingbird_params", "px4": "px4_sihsim_quadx_params"}
_G = 9.81


#: Keys rotorpy's SE3 controller reads beside a shipped set's (its attitude gains).
_SE3_GAINS = {"kp_att", "kd_att"}


def shipped_airframe(name: str) -> dict:
    """A copy of rotorpy's parameter set ``name``: the start of a lab's own airframe (module docstring).

    Parameters
    ----------
    name : str
        A key of :data:`ROTORPY_VEHICLES`.

    Returns
    -------
    dict
        rotorpy's ``quad_params`` of that vehicle (SI units, as rotorpy documents them).
    """
    return copy.deepcopy(importlib.import_module(f"rotorpy.vehicles.{ROTORPY_VEHICLES[name]}").quad_params)


def airframe_parameters(airframe: object) -> dict:
    """The parameter set of a shipped name or of a lab's own complete mapping, checked against the shipped keys.

    Parameters
    ----------
    airframe : str or mapping
        A key of :data:`ROTORPY_VEHICLES`, or a complete rotorpy parameter set (SI units).

    Returns
    -------
    dict
        A copy of the set.

    Raises
    ------
    SpecError
        An unknown name, a set missing a key every shipped set has, or a key no shipped set has.
    """
    if isinstance(airframe, str):
        if airframe not in ROTORPY_VEHICLES:
            raise SpecError(f"`airframe`: got {airframe!r}, expected one of {sorted(ROTORPY_VEHICLES)} or a "
                            "complete rotorpy parameter set")
        return shipped_airframe(airframe)
    if not isinstance(airframe, Mapping):
        raise SpecError(f"`airframe`: got {type(airframe).__name__}, expected a shipped set's name or a mapping "
                        "of rotorpy parameters")
    shipped = [set(importlib.import_module(f"rotorpy.vehicles.{m}").quad_params) for m in ROTORPY_VEHICLES.values()]
    required = set.intersection(*shipped)
    missing = sorted(required - set(airframe))
    if missing:
        raise SpecError(f"`airframe`: the parameter set lacks {missing} (a complete rotorpy set has "
                        f"{sorted(required)}; start from a shipped one, e.g. airframe='hummingbird' with `params`)")
    known = set.union(*shipped) | _SE3_GAINS
    unknown = sorted(set(airframe) - known)
    if unknown:
        raise SpecError(f"`airframe`: {unknown} are not rotorpy parameters (known: {sorted(known)})")
    return copy.deepcopy(dict(airframe))


def airframe_summary(airframe: object) -> dict:
    """Mass (kg), inertias (kg m^2) and mean arm (m, rotor distance from the centre) of an airframe.

    Parameters
    ----------
    airframe : str or mapping
        As :func:`airframe_parameters`.

    Returns
    -------
    dict
        ``mass_kg``, ``inertia_kg_m2`` (Ixx, Iyy, Izz), ``arm_m``.
    """
    a = airframe_parameters(airframe)
    arm = float(np.mean([np.linalg.norm(np.asarray(r, float)[:2]) for r in a["rotor_pos"].values()]))
    return {"mass_kg": float(a["mass"]), "inertia_kg_m2": [float(a[k]) for k in ("Ixx", "Iyy", "Izz")], "arm_m": arm}


def _rotorpy():
    try:
        multirotor = importlib.import_module("rotorpy.vehicles.multirotor")
        control = importlib.import_module("rotorpy.controllers.quadrotor_control")
    except ImportError as exc:
        raise SpecError("the rotorpy vehicles need the optional package rotorpy: pip install 'ilcdob[rotorpy]' "
                        f"({exc})") from None
    return multirotor.Multirotor, control.SE3Control


class RotorpyVehicle:
    """One rotorpy quadrotor flown through ilcdob's vehicle protocol (module docstring).

    Parameters
    ----------
    name : str
        What the vehicle is called; without ``airframe``, a key of :data:`ROTORPY_VEHICLES`.
    ts : float
        Outer-loop sample time, s (> 0): each :meth:`step` integrates this long.
    altitude : float
        Hover altitude at the start of a trial, m.
    command_disturbance : callable, optional
        ``t -> (3,)`` acceleration added to the command, m/s^2 (the paper's disturbance).
    wind : callable, optional
        ``t -> (3,)`` wind velocity, m/s, world frame.
    noise_std : float
        Standard deviation of white position-sensor noise per axis, m (>= 0).
    seed : int
        Seed of the sensor noise.
    params : dict, optional
        Changes to the airframe's parameter set (e.g. ``{"mass": 0.6}``).
    airframe : str or mapping, optional
        The parameter set: a key of :data:`ROTORPY_VEHICLES`, or a lab's own complete set (every key of
        rotorpy's shipped sets; module docstring). Default: ``name``'s shipped set.
    position_gains : (array_like, array_like), optional
        ``(kp, kd)`` of rotorpy's SE3 position loop per axis (1/s^2, 1/s; > 0), used by :meth:`track`
        (default: rotorpy's).

    Raises
    ------
    SpecError
        An unknown name or airframe, a parameter set missing keys (named) or with keys rotorpy does not
        read, a bad sample time, noise or disturbance.
    """

    def __init__(self, name: str, ts: float = 0.01, *, altitude: float = 1.0,
                 command_disturbance: Callable[[float], np.ndarray] | None = None,
                 wind: Callable[[float], np.ndarray] | None = None, noise_std: float = 0.0, seed: int = 0,
                 params: dict | None = None, airframe: str | Mapping[str, object] | None = None,
                 position_gains: tuple[object, object] | None = None):
        if not isinstance(name, str) or not name:
            raise SpecError(f"`name`: got {name!r}, expected the vehicle's name")
        if airframe is None and name not in ROTORPY_VEHICLES:
            raise SpecError(f"`name`: got {name!r}, expected one of {sorted(ROTORPY_VEHICLES)} (or give the "
                            "airframe's parameter set as `airframe`)")
        if not (np.isfinite(ts) and ts > 0):
            raise SpecError(f"`ts`: got {ts!r}, expected a sample time > 0 s")
        if not (np.isfinite(noise_std) and noise_std >= 0):
            raise SpecError(f"`noise_std`: got {noise_std!r}, expected a standard deviation >= 0 m")
        for what, fn in (("command_disturbance", command_disturbance), ("wind", wind)):
            if fn is not None and not callable(fn):
                raise SpecError(f"`{what}`: got {type(fn).__name__}, expected a callable of time (s) returning (3,)")
        multirotor, se3 = _rotorpy()
        base = airframe_parameters(name if airframe is None else airframe)
        unknown = sorted(set(params or {}) - set(base) - _SE3_GAINS)
        if unknown:
            raise SpecError(f"`params`: {unknown} are not parameters of the {name!r} airframe (it has "
                            f"{sorted(base)})")
        self.params = {**base, **(params or {})}
        self.name, self.ts, self.altitude = name, float(ts), float(altitude)
        self.command_disturbance, self.wind = command_disturbance, wind
        self.noise_std, self.seed = float(noise_std), int(seed)
        self._model = multirotor(self.params, initial_state=self._hover(), control_abstraction="cmd_motor_speeds",
                                 aero=True)
        self._inner = se3(self.params)
        if position_gains is not None:
            kp, kd = (np.broadcast_to(np.asarray(g, float), (3,)).copy() for g in position_gains)
            if not (np.all(np.isfinite(kp)) and np.all(np.isfinite(kd)) and np.all(kp > 0) and np.all(kd > 0)):
                raise SpecError(f"`position_gains`: got {position_gains!r}, expected (kp, kd) > 0 per axis")
            self._inner.kp_pos, self._inner.kd_pos = kp, kd  # SE3Control's public gains
        self.reset()

    def channel_gain(self, channel: str) -> np.ndarray:
        """The acceleration its SE3 position loop commands per unit of ``channel`` signal, per axis.

        1 on the acceleration channel, ``kp`` (1/s^2) on the position channel, ``kd`` (1/s) on the
        velocity channel (``a = a_ff + kp (r - x) + kd (v_ref - v)``: rotorpy's ``SE3Control``).

        Parameters
        ----------
        channel : {"position", "velocity", "acceleration"}

        Returns
        -------
        numpy.ndarray
            ``(3,)``.
        """
        gains = {"position": self._inner.kp_pos, "velocity": self._inner.kd_pos, "acceleration": np.ones(3)}
        return np.asarray(gains[check_channel(channel)], float).copy()

    @property
    def mass(self) -> float:
        """Mass, kg."""
        return float(self.params["mass"])

    def _hover(self) -> dict:
        p = self.params
        w_hover = np.sqrt(p["mass"] * _G / (p["num_rotors"] * p["k_eta"]))
        return {"x": np.array([0.0, 0.0, self.altitude]), "v": np.zeros(3), "q": np.array([0.0, 0.0, 0.0, 1.0]),
                "w": np.zeros(3), "wind": np.zeros(3), "rotor_speeds": np.full(p["num_rotors"], w_hover)}

    def reset(self) -> None:
        """Hover at rest at ``altitude``, time 0, the sensor noise restarted from ``seed``."""
        self.state = self._hover()
        self.t = 0.0
        self.commanded_acceleration = np.zeros(3)  # what its SE3 loop last commanded, m/s^2, gravity excluded
        self._rng = np.random.default_rng(self.seed)

    def position(self) -> np.ndarray:
        """Measured position relative to the start, ``(3,)``, m."""
        y = self.state["x"] - np.array([0.0, 0.0, self.altitude])
        return y + self._rng.normal(0.0, self.noise_std, 3) if self.noise_std else y

    def _vector(self, fn: Callable[[float], np.ndarray] | None, what: str) -> np.ndarray:
        if fn is None:
            return np.zeros(3)
        v = np.asarray(fn(self.t), float).reshape(-1)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise SpecError(f"`{what}`: at t = {self.t:g} s it returned {v!r}, expected 3 finite values")
        return v

    def _advance(self, x: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
        """One ``ts`` of the SE3 controller tracking the flat output ``(x, v, a)`` (world frame, absolute)."""
        s = self.state
        s["wind"] = self._vector(self.wind, "wind")
        d = self._vector(self.command_disturbance, "command_disturbance")
        flat = {"x": x, "x_dot": v, "x_ddot": a + d,
                "x_dddot": np.zeros(3), "x_ddddot": np.zeros(3), "yaw": 0.0, "yaw_dot": 0.0, "yaw_ddot": 0.0}
        control = self._inner.update(self.t, s, flat)
        # what the controller commanded, as a flight stack logs it: the disturbance is the world's, not its
        self.commanded_acceleration = np.asarray(control["cmd_acc"], float) - np.array([0.0, 0.0, _G]) - d
        self.state = self._model.step(s, control, self.ts)
        self.t += self.ts

    def track(self, position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray) -> None:
        """Fly ``ts`` on rotorpy's own SE3 controller towards a full-state setpoint (module docstring).

        Parameters
        ----------
        position : array_like
            ``(3,)``, m, relative to the start (as :meth:`position` measures).
        velocity : array_like
            ``(3,)``, m/s, its velocity feed-forward.
        acceleration : array_like
            ``(3,)``, m/s^2, its acceleration feed-forward (gravity excluded); the command disturbance
            is added to it, which is adding it to the controller's command.

        Raises
        ------
        SpecError
            A setpoint that is not three finite numbers per row.
        """
        rows = setpoint_rows(position, velocity, acceleration)
        self._advance(rows[0] + np.array([0.0, 0.0, self.altitude]), rows[1], rows[2])

    def step(self, command: np.ndarray) -> np.ndarray:
        """Hold the acceleration ``command`` (``(3,)``, m/s^2) plus the command disturbance for ``ts``.

        Parameters
        ----------
        command : array_like
            World-frame acceleration, gravity excluded.

        Returns
        -------
        numpy.ndarray
            The command (rotorpy limits the rotor speeds inside its model; what the airframe
            then does is the simulator's own).
        """
        a = np.asarray(command, float).reshape(-1)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise SpecError(f"`command`: got {command!r}, expected 3 finite accelerations (m/s^2)")
        self._advance(self.state["x"], self.state["v"], a)  # its own position: the SE3 loop feeds a forward
        return a
