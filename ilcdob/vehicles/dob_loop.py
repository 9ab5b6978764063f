"""Vehicles whose loop carries the paper's DOB, flown as vehicles on their own controller (docs/closed_loop.md).

Two ways a DOB joins a vehicle that learns through a setpoint channel
(:mod:`ilcdob.vehicles.closed_loop`):

* :class:`AddOnDOB`: the lab keeps its flight stack's controller and adds the paper's DOB on top. Per axis,
  from the measured position ``y`` and the acceleration the controller commanded ``a_c`` (what PX4 logs
  as its acceleration setpoint), ``d_hat = M{y} - Q{a_c}`` with ``M = Q/P_hat`` on the vehicle's
  identified airframe ``P_hat`` (commanded acceleration -> position); ``-d_hat/K`` is added to the
  channel, ``K`` the controller's acceleration per unit of channel signal, so the controller commands
  ``-d_hat`` more. The learning signal is added to the channel as well, after the DOB: the DOB sees it in
  ``a_c`` and leaves it alone, as the paper's DOB leaves ``d_f`` (paper Sec. II).
* :class:`PaperLoopVehicle`: ilcdob's PID + DOB (:class:`~ilcdob.controller.OuterLoopController`) flying a
  :class:`~ilcdob.vehicles.interface.Vehicle`, offered with the setpoint interface so that it learns
  alongside vehicles on their own controllers. Its channel is the acceleration feed-forward: a learning
  signal ``u`` there is ``-d_f`` of the paper's loop.

For both, with ``D = 1 - Q + P (M + C)`` of the vehicle's loop ``C``, the learning signal reaches the
position through ``Gf = K P/D`` and a disturbance added to the command through ``Gd = (1 - Q) P/D``
(:mod:`ilcdob.channel_loop`). Units: s, m, m/s^2, the channel's unit.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from ilcdob.controller import DisturbanceObserver
from ilcdob.discretize import m_block, q_block
from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.specs import DOBSpec, PIDSpec, PlantSpec

from .closed_loop import ClosedLoopVehicle, setpoint_rows
from ilcdob.channel_loop import CHANNELS, check_channel
from .interface import AXES, Vehicle, axis_controllers

__all__ = ["AddOnDOB", "PaperLoopVehicle"]


class _Wrapped:
    """A vehicle wrapped by a per-sample law acting on the sample's measurement (:meth:`position`, then ``track``)."""

    vehicle: ClosedLoopVehicle | Vehicle
    _y: np.ndarray | None = None

    def position(self) -> np.ndarray:
        """The wrapped vehicle's measured position, ``(3,)``, m; the law acts on it at the next ``track``."""
        self._y = np.asarray(self.vehicle.position(), float)
        return self._y.copy()

    def _measured(self) -> np.ndarray:
        """This sample's measurement, taken now if :meth:`position` was not asked for it."""
        y = self._y if self._y is not None else np.asarray(self.vehicle.position(), float)
        self._y = None
        return y


class AddOnDOB(_Wrapped):
    """A vehicle on its own controller with the paper's DOB added through its learning channel (module docstring).

    A :class:`~ilcdob.vehicles.closed_loop.ClosedLoopVehicle` itself: identify its channel and fly it as any
    other (:func:`~ilcdob.vehicles.closed_loop.fly_closed_loop`).

    Parameters
    ----------
    vehicle : ClosedLoopVehicle
        It must report ``commanded_acceleration`` (``(3,)``, m/s^2, gravity excluded, what its controller
        commanded over the last :meth:`track`, without the disturbance) and ``channel_gain(channel)``.
    airframes : mapping of str to PlantSpec
        Per axis with a DOB (``"x"``, ``"y"``, ``"z"``), the identified airframe ``P_hat`` (commanded
        acceleration -> position, :attr:`ilcdob.validation.channel_id.ChannelFit.airframe`).
    dob : DOBSpec
        The DOB's ``Q``; ``q_order`` at least each airframe's relative degree.
    channel : {"position", "velocity", "acceleration"}
        Where the DOB's estimate (and the learning signal) enters.

    Raises
    ------
    SpecError
        A vehicle without the protocol, the commanded acceleration or the channel gain; unknown axes, models
        that are not plants, a ``Q`` of too low an order for a model, a channel gain that is not > 0.
    """

    def __init__(self, vehicle: ClosedLoopVehicle, airframes: Mapping[str, PlantSpec], dob: DOBSpec,
                 channel: str = "acceleration"):
        if not (isinstance(vehicle, ClosedLoopVehicle) and hasattr(vehicle, "commanded_acceleration")
                and callable(getattr(vehicle, "channel_gain", None))):
            raise SpecError(f"`vehicle`: got {type(vehicle).__name__}, expected a vehicle on its own controller "
                            "(ts, reset(), position(), track()) that reports commanded_acceleration and "
                            "channel_gain(channel)")
        if not isinstance(dob, DOBSpec):
            raise SpecError(f"`dob`: got {type(dob).__name__}, expected a DOBSpec (the DOB's Q)")
        if not airframes or set(airframes) - set(AXES):
            raise SpecError(f"`airframes`: got axes {sorted(airframes or {})}, expected some of {list(AXES)}")
        self.vehicle, self.dob, self.channel = vehicle, dob, check_channel(channel)
        self.ts = float(vehicle.ts)
        gain = np.asarray(vehicle.channel_gain(self.channel), float).reshape(-1)
        self._observers: dict[int, tuple[DisturbanceObserver, float]] = {}
        for ax, model in airframes.items():
            if not isinstance(model, PlantSpec):
                raise SpecError(f"`airframes[{ax!r}]`: got {type(model).__name__}, expected a PlantSpec (commanded "
                                "acceleration -> position)")
            if dob.q_order < model.relative_degree:
                raise SpecError(f"`dob.q_order`: got {dob.q_order}, below the relative degree "
                                f"{model.relative_degree} of the {ax} airframe (M = Q/P_hat would be improper)")
            i = AXES.index(ax)
            if not (np.isfinite(gain[i]) and gain[i] > 0):
                raise SpecError(f"the vehicle's {self.channel} channel gain on {ax} is {gain[i]!r}; expected > 0")
            obs = DisturbanceObserver(q_block(dob, model, self.ts).sys, m_block(dob, model, self.ts).sys)
            self._observers[i] = (obs, float(gain[i]))
        self.reset()

    def channel_gain(self, channel: str) -> np.ndarray:
        """The wrapped vehicle's ``K`` (the DOB leaves it as it is).

        Parameters
        ----------
        channel : {"position", "velocity", "acceleration"}

        Returns
        -------
        numpy.ndarray
            ``(3,)``, as the vehicle's ``channel_gain``.
        """
        return self.vehicle.channel_gain(channel)

    @property
    def commanded_acceleration(self) -> np.ndarray:
        """What the vehicle's controller commanded over the last :meth:`track`, DOB included, m/s^2."""
        return self.vehicle.commanded_acceleration

    def reset(self) -> None:
        """The vehicle at rest, the DOB at rest."""
        self.vehicle.reset()
        for obs, _ in self._observers.values():
            obs.reset()
        self.d_hat = np.zeros(3)  # the last estimate, m/s^2
        self._y = None

    def track(self, position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray) -> None:
        """One ``ts`` towards the setpoint with ``-d_hat/K`` added to the channel (module docstring).

        Parameters
        ----------
        position, velocity, acceleration : array_like
            ``(3,)`` each, m, m/s, m/s^2 (:meth:`ClosedLoopVehicle.track`).

        Raises
        ------
        SpecError
            A row that is not three finite numbers.
        """
        rows = setpoint_rows(position, velocity, acceleration)
        y = self._measured()
        row = CHANNELS.index(self.channel)
        for i, (obs, k) in self._observers.items():
            self.d_hat[i] = obs.estimate(float(y[i]))
            rows[row][i] -= self.d_hat[i] / k
        self.vehicle.track(*rows)
        a_c = np.asarray(self.vehicle.commanded_acceleration, float)
        for i, (obs, _) in self._observers.items():
            obs.update(float(a_c[i]), float(y[i]))


class PaperLoopVehicle(_Wrapped):
    """A :class:`~ilcdob.vehicles.interface.Vehicle` flown by ilcdob's PID + DOB, with a setpoint interface
    (module docstring).

    The PID acts on the position error (its derivative on the error's, so the velocity row of a setpoint
    is implied by its position row and not used); the acceleration row is the feed-forward ``a_ff`` of
    :class:`~ilcdob.controller.OuterLoopController`, the learning signal's channel.

    Parameters
    ----------
    vehicle : Vehicle
        Takes an acceleration command per sample (:meth:`~ilcdob.vehicles.interface.Vehicle.step`).
    loops : mapping of str to LoopSystem or PIDSpec
        Every axis's loop (:func:`~ilcdob.vehicles.interface.fly_vehicle`).

    Raises
    ------
    SpecError
        As :func:`~ilcdob.vehicles.interface.axis_controllers`.
    """

    def __init__(self, vehicle: Vehicle, loops: Mapping[str, LoopSystem | PIDSpec]):
        axis_controllers(vehicle, loops)
        self.vehicle, self.loops, self.ts = vehicle, dict(loops), float(vehicle.ts)
        self.reset()

    def channel_gain(self, channel: str) -> np.ndarray:
        """1 on the acceleration channel, the only one this loop offers.

        Parameters
        ----------
        channel : str
            Must be ``"acceleration"``.

        Returns
        -------
        numpy.ndarray
            ``(3,)`` ones.

        Raises
        ------
        SpecError
            Another channel.
        """
        if check_channel(channel) != "acceleration":
            raise SpecError(f"`channel`: got {channel!r}; ilcdob's PID + DOB takes a learning signal on the "
                            "acceleration channel only (its feed-forward)")
        return np.ones(3)

    def reset(self) -> None:
        """The vehicle and every axis's controller at rest."""
        self.vehicle.reset()
        self._ctl = axis_controllers(self.vehicle, self.loops)
        self.commanded_acceleration = np.zeros(3)
        self.d_hat = np.zeros(3)
        self._y = None

    def track(self, position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray) -> None:
        """One sample of the PID + DOB towards the setpoint, its acceleration row fed forward.

        Parameters
        ----------
        position, velocity, acceleration : array_like
            ``(3,)`` each, m, m/s (not used: class docstring), m/s^2.

        Raises
        ------
        SpecError
            A row that is not three finite numbers.
        """
        r, _, a_ff = setpoint_rows(position, velocity, acceleration)
        y = self._measured()
        cmd = np.array([c.command(float(r[i]), float(y[i]), feedforward=float(a_ff[i]))
                        for i, c in enumerate(self._ctl)])
        self.d_hat = np.array([c.d_hat for c in self._ctl])
        applied = np.asarray(self.vehicle.step(cmd.copy()), float)
        for c, a in zip(self._ctl, applied.tolist()):
            c.update(a)
        self.commanded_acceleration = applied
