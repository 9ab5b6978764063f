"""A vehicle ilcdob can fly, and one trial of ilcdob's control law on it (docs/theory.md section 1).

The protocol is what a flight computer sees of its airframe at the outer loop's rate: an
acceleration command per axis goes in, a measured position comes out. Anything that offers
it (a third-party simulator, a hardware-in-the-loop bench, a companion computer's link to
the autopilot) is flown by :func:`fly_vehicle` with one
:class:`~ilcdob.controller.OuterLoopController` per axis: the same control law as ilcdob's own
linear simulations. ilcdob's own nonlinear quadrotor is such a vehicle
(:class:`~ilcdob.vehicles.quadrotor_vehicle.QuadrotorVehicle`), as are rotorpy's multirotors
(:class:`~ilcdob.vehicles.rotorpy_vehicle.RotorpyVehicle`). An axis that is only held (not learned)
may fly its PID alone: give it a :class:`~ilcdob.specs.PIDSpec` instead of a loop.

Frames and units: world frame, z up; positions in m, accelerations in m/s^2 with gravity
excluded (a hovering vehicle is commanded 0). Axis ``i`` of a command or a position is x, y, z
for ``i`` = 0, 1, 2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Protocol, runtime_checkable

import numpy as np

from ilcdob.controller import OuterLoopController
from ilcdob.errors import SpecError
from ilcdob.fleet import AXES  # the fleet file's axes, in the order of the command and position vectors
from ilcdob.loop import LoopSystem
from ilcdob.specs import PIDSpec

__all__ = ["Vehicle", "VehicleTrial", "fly_vehicle", "axis_controllers", "AXES"]


@runtime_checkable
class Vehicle(Protocol):
    """What ilcdob needs of a vehicle to fly it (module docstring).

    A structural type: any object with these members is a ``Vehicle`` (``isinstance`` checks
    them); nothing derives from it or constructs it.

    Parameters
    ----------
    *args, **kwargs
        None: a protocol is not instantiated.

    Attributes
    ----------
    ts : float
        The outer loop's sample time, s: :meth:`step` advances the vehicle by it.
    """

    ts: float

    def reset(self) -> None:
        """Back to hover, at rest, at the position that :meth:`position` reports as 0."""

    def position(self) -> np.ndarray:
        """The measured position now, ``(3,)``, m (relative to where :meth:`reset` left the vehicle)."""

    def step(self, command: np.ndarray) -> np.ndarray:
        """Hold an acceleration command for one sample time.

        Parameters
        ----------
        command : numpy.ndarray
            ``(3,)``, m/s^2, world frame, gravity excluded.

        Returns
        -------
        numpy.ndarray
            The command the vehicle applied (after its own limits; the command itself when it
            has none): the DOB must see what was flown.
        """


@dataclass(frozen=True)
class VehicleTrial:
    """One trial flown by :func:`fly_vehicle`; arrays are ``N x 3`` (columns x, y, z) unless stated.

    Attributes
    ----------
    t : numpy.ndarray
        Sample times, s (``N``).
    r, y_meas : numpy.ndarray
        Reference and measured position, m.
    command, applied : numpy.ndarray
        Acceleration command of the control law and as the vehicle applied it, m/s^2.
    d_hat, d_f : numpy.ndarray
        The DOB's estimate and the learning signal flown, m/s^2.
    """

    t: np.ndarray
    r: np.ndarray
    y_meas: np.ndarray
    command: np.ndarray
    applied: np.ndarray
    d_hat: np.ndarray
    d_f: np.ndarray

    @property
    def e_meas(self) -> np.ndarray:
        """The measured tracking error ``r - y_meas``, m."""
        return self.r - self.y_meas

    def rmse(self, axis: int = 0) -> float:
        """RMSE of the measured tracking error of one axis, m.

        Parameters
        ----------
        axis : int
            0, 1 or 2 (x, y, z).

        Returns
        -------
        float
        """
        return float(np.sqrt(np.mean(self.e_meas[:, axis] ** 2)))


def trial_samples(reference: object, n: int | None) -> int:
    """Samples of a trial: ``n`` when given, else the reference's length.

    Parameters
    ----------
    reference : array_like or mapping
        ``N x 3``, or per axis (every axis the same length).
    n : int or None

    Returns
    -------
    int
        0 for a scalar reference (which :func:`per_axis` then refuses).

    Raises
    ------
    SpecError
        Axes of a mapping with different lengths and no ``n``.
    """
    if n is not None:
        return n
    if isinstance(reference, Mapping):
        sizes = {np.asarray(v).size for v in reference.values()}
        if len(sizes) != 1:
            raise SpecError("`reference`: give every axis the same number of samples, or `n`")
        return sizes.pop()
    return np.asarray(reference).shape[0] if np.ndim(reference) else 0


def per_axis(value: object, n: int, name: str) -> np.ndarray:
    """``value`` as an ``n x 3`` array, one column per axis (x, y, z).

    Parameters
    ----------
    value : None, array_like or mapping
        None (zeros), ``(n, 3)``, or a mapping axis name -> ``(n,)`` (missing axes: zeros).
    n : int
        Samples.
    name : str
        The input's name, for messages.

    Returns
    -------
    numpy.ndarray
        ``n x 3``, finite.

    Raises
    ------
    SpecError
        Unknown axes, other lengths or shapes, NaN or inf.
    """
    if value is None:
        return np.zeros((n, 3))
    if isinstance(value, Mapping):
        bad = [k for k in value if k not in AXES]
        if bad:
            raise SpecError(f"`{name}`: unknown axes {bad}, expected keys from {list(AXES)}")
        out = np.zeros((n, 3))
        for i, ax in enumerate(AXES):
            if ax in value:
                col = np.asarray(value[ax], float).reshape(-1)
                if col.size != n:
                    raise SpecError(f"`{name}[{ax!r}]`: got {col.size} samples, expected {n}")
                out[:, i] = col
    else:
        out = np.asarray(value, float)
        if out.shape != (n, 3):
            raise SpecError(f"`{name}`: got shape {out.shape}, expected ({n}, 3) or a mapping axis -> samples")
    if not np.all(np.isfinite(out)):
        raise SpecError(f"`{name}`: contains NaN or inf")
    return out


class _PIDAlone:
    """An axis held by its PID alone, with the interface of :class:`~ilcdob.controller.OuterLoopController`
    (no DOB: ``d_hat`` 0, no learning signal); stepped as :class:`~ilcdob.vehicles.quadrotor.DiscretePID`."""

    d_hat = 0.0

    def __init__(self, spec: PIDSpec, ts: float, axis: str) -> None:
        from .quadrotor import DiscretePID

        self._pid, self._axis = DiscretePID(spec, ts), axis

    def command(self, reference: float, measurement: float, *, feedforward: float = 0.0,
                learning: float = 0.0) -> float:
        if learning:
            raise SpecError(f"`learning`: axis {self._axis!r} flies its PID alone (a PIDSpec in `loops`), which takes "
                            "no learning signal")
        return self._pid(reference - measurement) + feedforward

    def update(self, applied: float | None = None) -> None:
        """Nothing to advance: the PID advanced in :meth:`command`."""


def axis_controllers(vehicle: Vehicle, loops: Mapping[str, LoopSystem | PIDSpec], dob: bool = True
                     ) -> list[OuterLoopController | _PIDAlone]:
    """The per-axis control law :func:`fly_vehicle` flies ``vehicle`` with, x, y, z, at rest.

    Parameters
    ----------
    vehicle : Vehicle
    loops : mapping of str to LoopSystem or PIDSpec
        As :func:`fly_vehicle`.
    dob : bool
        Run the DOB on the axes with a loop.

    Returns
    -------
    list
        One :class:`~ilcdob.controller.OuterLoopController` (or PID alone) per axis.

    Raises
    ------
    SpecError
        ``vehicle`` lacks the protocol, an axis has no loop, or sample times differ.
    """
    if not isinstance(vehicle, Vehicle):
        raise SpecError(f"`vehicle`: got {type(vehicle).__name__}, expected an object with ts, reset(), "
                        "position() and step(command) (ilcdob.vehicles.interface.Vehicle)")
    missing = [ax for ax in AXES if ax not in loops]
    if missing:
        raise SpecError(f"`loops`: no loop for axes {missing}; every axis needs one (the same loop may serve several)")
    for ax in AXES:
        if isinstance(loops[ax], PIDSpec):
            continue
        if not isinstance(loops[ax], LoopSystem):
            raise SpecError(f"`loops[{ax!r}]`: got {type(loops[ax]).__name__}, expected a LoopSystem or a PIDSpec")
        if abs(loops[ax].ts - vehicle.ts) > 1e-12 * vehicle.ts:
            raise SpecError(f"`loops[{ax!r}]`: sample time {loops[ax].ts} s, but the vehicle steps {vehicle.ts} s")
    return [_PIDAlone(loops[ax], vehicle.ts, ax) if isinstance(loops[ax], PIDSpec) else
            OuterLoopController(loops[ax], dob=dob) for ax in AXES]


def fly_vehicle(vehicle: Vehicle, loops: Mapping[str, LoopSystem | PIDSpec], reference: object, *,
                learning: object = None, feedforward: object = None, dob: bool = True,
                n: int | None = None) -> VehicleTrial:
    """Fly one trial of ``vehicle`` with ilcdob's control law on every axis, from :meth:`Vehicle.reset`.

    Parameters
    ----------
    vehicle : Vehicle
        Anything with the protocol (module docstring).
    loops : mapping of str to LoopSystem or PIDSpec
        The loop (PID, Q, M from the model) of each axis ``"x"``, ``"y"``, ``"z"``; all three are
        needed. Their sample time must be ``vehicle.ts``. An axis given a ``PIDSpec`` is held by
        that PID alone (discretised at ``vehicle.ts``; no DOB, whatever ``dob`` says, and no
        learning signal).
    reference : array_like or mapping
        Reference position, m: ``N x 3``, or per axis (missing axes: 0, i.e. hold the start).
    learning, feedforward : array_like or mapping, optional
        Learning signal ``d_f`` and reference acceleration ``a_ff`` per axis, m/s^2 (default 0).
    dob : bool
        Run the DOB on every axis (False: the PID alone; then no learning signal).
    n : int, optional
        Samples of the trial (default: the reference's; needed when it is a mapping without axes).

    Returns
    -------
    VehicleTrial

    Raises
    ------
    SpecError
        ``vehicle`` lacks the protocol, an axis has no loop, sample times differ, or a signal has the
        wrong shape.
    """
    ctl = axis_controllers(vehicle, loops, dob)
    n = trial_samples(reference, n)
    r = per_axis(reference, n, "reference")
    d_f = per_axis(learning, n, "learning")
    a_ff = per_axis(feedforward, n, "feedforward")
    if not dob and np.any(d_f):
        raise SpecError("`learning`: a learning signal needs the DOB (dob=True)")
    vehicle.reset()
    y, cmd, applied, d_hat = (np.zeros((n, 3)) for _ in range(4))
    r_l, d_f_l, a_ff_l = r.tolist(), d_f.tolist(), a_ff.tolist()  # Python floats: the loop runs per sample
    for k in range(n):
        y[k] = vehicle.position()
        y_k, r_k, d_f_k, a_ff_k = y[k].tolist(), r_l[k], d_f_l[k], a_ff_l[k]
        cmd[k] = [c.command(r_k[i], y_k[i], feedforward=a_ff_k[i], learning=d_f_k[i]) for i, c in enumerate(ctl)]
        d_hat[k] = [c.d_hat for c in ctl]
        applied[k] = vehicle.step(cmd[k].copy())
        for c, a in zip(ctl, applied[k].tolist()):
            c.update(a)
    return VehicleTrial(np.arange(n) * vehicle.ts, r, y, cmd, applied, d_hat, d_f)
