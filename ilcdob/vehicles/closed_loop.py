"""A vehicle flown on its own controller: it tracks a full-state setpoint, and learning enters through one
of the setpoint's channels.

Labs fly their own position controller (PX4's cascade, ArduPilot's, a Crazyflie's PID or Mellinger
controller, rotorpy's SE3) and will not replace it. Every such flight stack accepts a setpoint of
position, velocity and acceleration feed-forward (PX4 ``trajectory_setpoint``, ArduPilot guided-mode
targets, the Crazyflie full-state setpoint). The learning signal is added to one of them, its
*channel*:

* ``"position"``: an offset of the position setpoint, m (every flight stack accepts one);
* ``"velocity"``: a velocity feed-forward, m/s;
* ``"acceleration"``: an acceleration feed-forward, m/s^2 (PX4 adds it after its velocity loop, to the
  acceleration its controller commands).

A :class:`ClosedLoopVehicle` offers ``ts``, ``reset()``, ``position()`` (measured, m, relative to the
start) and ``track(position, velocity, acceleration)`` (one sample time towards that setpoint, world
frame, gravity excluded). :func:`fly_closed_loop` flies one trial of it: the reference's setpoint with
the learning signal added on its channel. rotorpy's multirotors on their own SE3 controller are such a
vehicle (:meth:`~ilcdob.vehicles.rotorpy_vehicle.RotorpyVehicle.track`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ilcdob.channel_loop import CHANNELS, check_channel
from ilcdob.errors import SpecError

from .interface import per_axis, trial_samples

__all__ = ["ClosedLoopVehicle", "ClosedLoopTrial", "fly_closed_loop", "setpoint_rows"]



def setpoint_rows(position: object, velocity: object, acceleration: object) -> list[np.ndarray]:
    """The three rows of one setpoint (:meth:`ClosedLoopVehicle.track`), checked, as new float arrays.

    Parameters
    ----------
    position, velocity, acceleration : array_like
        ``(3,)`` each, m, m/s, m/s^2.

    Returns
    -------
    list of numpy.ndarray
        ``[position, velocity, acceleration]``, each ``(3,)`` (copies: a caller may add to them).

    Raises
    ------
    SpecError
        A row that is not three finite numbers.
    """
    rows = []
    for what, value in (("position", position), ("velocity", velocity), ("acceleration", acceleration)):
        v = np.array(value, float).reshape(-1)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise SpecError(f"`{what}`: got {value!r}, expected 3 finite values")
        rows.append(v)
    return rows


@runtime_checkable
class ClosedLoopVehicle(Protocol):
    """A vehicle on its own controller (module docstring): a structural type, not instantiated.

    Parameters
    ----------
    *args, **kwargs
        None: a protocol is not instantiated.

    Attributes
    ----------
    ts : float
        Setpoint period, s.
    """

    ts: float

    def reset(self) -> None:
        """Hover at rest at the start, every state of the vehicle and its controller at rest."""

    def position(self) -> np.ndarray:
        """Measured position relative to the start, ``(3,)``, m."""

    def track(self, position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray) -> None:
        """Fly one ``ts`` towards the setpoint (world frame).

        Parameters
        ----------
        position : numpy.ndarray
            ``(3,)``, m, relative to the start.
        velocity : numpy.ndarray
            ``(3,)``, m/s, feed-forward.
        acceleration : numpy.ndarray
            ``(3,)``, m/s^2, feed-forward, gravity excluded.
        """


@dataclass(frozen=True)
class ClosedLoopTrial:
    """One trial of a vehicle on its own controller.

    Attributes
    ----------
    t : numpy.ndarray
        Sample times, s.
    reference : numpy.ndarray
        Reference position, ``N x 3``, m.
    y_meas : numpy.ndarray
        Measured position, ``N x 3``, m (before the setpoint of the same sample).
    learning : numpy.ndarray
        Learning signal on the channel, ``N x 3`` (:data:`~ilcdob.channel_loop.CHANNEL_UNITS`).
    channel : str
        Where it entered.
    command : numpy.ndarray or None
        The acceleration the vehicle's controller commanded over each sample, ``N x 3``, m/s^2, gravity
        excluded (what a flight stack logs, e.g. PX4's acceleration setpoint), where the vehicle reports
        it as ``commanded_acceleration`` after each :meth:`~ClosedLoopVehicle.track`; else None.
    """

    t: np.ndarray
    reference: np.ndarray
    y_meas: np.ndarray
    learning: np.ndarray
    channel: str
    command: np.ndarray | None = None

    @property
    def error(self) -> np.ndarray:
        """Measured tracking error ``reference - y_meas``, ``N x 3``, m."""
        return self.reference - self.y_meas


def fly_closed_loop(vehicle: ClosedLoopVehicle, reference: object, *, velocity: object = None,
                    acceleration: object = None, learning: object = None, channel: str = "acceleration",
                    n: int | None = None) -> ClosedLoopTrial:
    """Fly one trial of ``vehicle`` on its own controller from :meth:`ClosedLoopVehicle.reset`.

    At sample ``k`` the vehicle's position is measured, then it tracks the setpoint ``(r[k], v[k], a[k])``
    with ``learning[k]`` added to the ``channel`` row for ``ts``.

    Parameters
    ----------
    vehicle : ClosedLoopVehicle
    reference : array_like or mapping
        Reference position, m: ``N x 3`` or per axis (missing axes: 0, hold the start).
    velocity, acceleration : array_like or mapping, optional
        The reference's feed-forward, m/s and m/s^2 (default 0: a position setpoint alone).
    learning : array_like or mapping, optional
        Learning signal on ``channel`` (:data:`~ilcdob.channel_loop.CHANNEL_UNITS`), per axis or ``N x 3``; default none.
    channel : {"position", "velocity", "acceleration"}
        Where ``learning`` enters the setpoint.
    n : int, optional
        Samples (default: the reference's length; needed when ``reference`` is a mapping of fewer axes
        than the signals say).

    Returns
    -------
    ClosedLoopTrial

    Raises
    ------
    SpecError
        Not a closed-loop vehicle, an unknown channel, signals of other lengths or not finite.
    """
    if not isinstance(vehicle, ClosedLoopVehicle):
        raise SpecError(f"`vehicle`: got {type(vehicle).__name__}, expected a vehicle with ts, reset(), position() "
                        "and track(position, velocity, acceleration)")
    row = CHANNELS.index(check_channel(channel))
    n = trial_samples(reference, n)
    if n < 2:
        raise SpecError(f"`reference`: {n} sample(s), expected a trial of at least 2")
    r = per_axis(reference, n, "reference")
    setpoint = [r, per_axis(velocity, n, "velocity"), per_axis(acceleration, n, "acceleration")]
    d_f = per_axis(learning, n, "learning")
    setpoint[row] = setpoint[row] + d_f
    vehicle.reset()
    y = np.zeros((n, 3))
    logs = hasattr(vehicle, "commanded_acceleration")
    command = np.zeros((n, 3)) if logs else None
    for k in range(n):
        y[k] = vehicle.position()
        vehicle.track(setpoint[0][k], setpoint[1][k], setpoint[2][k])
        if logs:
            command[k] = vehicle.commanded_acceleration
    return ClosedLoopTrial(np.arange(n) * vehicle.ts, r, y, d_f, CHANNELS[row], command)
