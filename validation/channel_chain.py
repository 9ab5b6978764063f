"""The paper's learning chain among vehicles on their own controllers (docs/closed_loop.md).

What a lab whose vehicles keep their flight stack's position controller does, on any
:class:`~ilcdob.vehicles.closed_loop.ClosedLoopVehicle`:

1. :func:`identify_channel_loops`: per vehicle and axis the channel it learns through is identified from
   two chirp flights on its own controller (:func:`~.channel_id.identify_channel`) and becomes its
   :class:`~ilcdob.channel_loop.ChannelLoop` (``Gd = G_ch / K``, ``K`` the vehicle's channel gain).
2. :func:`fly_channel_chain`: every vehicle flies the trial without learning, then the cyclic chain of
   :func:`~.reproduce.learning_chain` passes learning around the order, each learning signal computed
   from the previous flight's measured error by the closed-form design between the two vehicles'
   identified loops (:func:`ilcdob.design.pair.design_channel_pair`, its band chosen per trial).

No ilcdob controller flies: the vehicles hold their paths with their own loops, and the learning signal is
added to the setpoint row of each vehicle's channel. With ``dob=`` the vehicles fly the paper's DOB on top
(:class:`~ilcdob.vehicles.dob_loop.AddOnDOB`, built on each airframe identified in step 1, after which the
channel is identified again with the DOB flying), and :func:`fly_channel_chain` flies them so. A vehicle
whose loops are :class:`~ilcdob.loop.LoopSystem` objects is ilcdob's PID + DOB (its ``make`` returns a
:class:`~ilcdob.vehicles.dob_loop.PaperLoopVehicle`): a mixed fleet. Units: s, m, m/s, m/s^2.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Mapping, Sequence

import numpy as np

from ilcdob.channel_loop import ChannelLoop, channel_loop, check_channel
from ilcdob.design.maps.channel_filters import learning_channel
from ilcdob.design.pair import PairDesign, design_channel_pair
from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.specs import DOBSpec
from ilcdob.vehicles.dob_loop import AddOnDOB
from ilcdob.vehicles.closed_loop import ClosedLoopTrial, ClosedLoopVehicle, fly_closed_loop
from ilcdob.vehicles.interface import AXES

from .channel_id import ChannelFit, identify_channel
from .reproduce import check_iterations, learning_chain

__all__ = ["MakeDisturbed", "ChannelChain", "identify_channel_loops", "with_dob", "fly_channel_chain"]

#: ``make(name, seed, command_disturbance, wind) -> ClosedLoopVehicle``: a fresh vehicle at rest, ``seed`` its
#: sensor noise's, the disturbances callables of time (s) -> ``(3,)`` (m/s^2 added to the command; m/s of wind)
#: or None.
MakeDisturbed = Callable[[str, int, Callable | None, Callable | None], ClosedLoopVehicle]


def with_dob(make: MakeDisturbed, loops: Mapping[str, Mapping[str, ChannelLoop | LoopSystem]]) -> MakeDisturbed:
    """``make`` with every vehicle whose loops carry an add-on DOB (:attr:`ChannelLoop.dob`) wrapped in it.

    Parameters
    ----------
    make : callable
        :data:`MakeDisturbed`.
    loops : mapping
        ``loops[name][axis]``; the DOB of a vehicle runs on its loops' axes, on their airframes.

    Returns
    -------
    callable
        :data:`MakeDisturbed`.
    """
    def flown(name, seed, cmd, wind):
        vehicle = make(name, seed, cmd, wind)
        mine = [lp for lp in loops.get(name, {}).values() if isinstance(lp, ChannelLoop) and lp.dob is not None]
        if not mine:
            return vehicle
        return AddOnDOB(vehicle, {ax: lp.airframe for ax, lp in loops[name].items()}, mine[0].dob, mine[0].channel)

    return flown


def identify_channel_loops(make: MakeDisturbed, channels: Mapping[str, str], ts: float,
                           axes: Sequence[str] = ("x",), duration: float = 30.0, *, dob: DOBSpec | None = None,
                           zero_at_origin: bool = False
                           ) -> tuple[dict[str, dict[str, ChannelLoop]], dict[str, dict[str, ChannelFit]]]:
    """Every vehicle's loop per axis from its channel's identification flights (module docstring, step 1).

    Parameters
    ----------
    make : callable
        :data:`MakeDisturbed` (flown without disturbance here); the vehicle's ``channel_gain(channel)``
        gives ``K`` per axis.
    channels : mapping of str to str
        Vehicle name -> the channel it learns through.
    ts : float
        Setpoint period, s.
    axes : sequence of str
        The axes learned.
    duration : float
        Length of each identification flight, s.
    dob : DOBSpec, optional
        Fly every vehicle with the add-on DOB of this ``Q`` on its identified airframes and identify its
        channel again so (module docstring); the loops carry it.
    zero_at_origin : bool
        The vehicles' loops integrate: their channel maps' zero at s = 0 fixed
        (:func:`~ilcdob.validation.channel_id.identify_channel`).

    Returns
    -------
    loops : dict
        ``loops[name][axis]``: :class:`ChannelLoop`.
    fits : dict
        ``fits[name][axis]``: the channel fit it came from (with ``dob``: the one with the DOB flying; the
        loop keeps the airframe fitted without it, the model its DOB runs on).
    """
    loops: dict[str, dict[str, ChannelLoop]] = {}
    fits: dict[str, dict[str, ChannelFit]] = {}
    for name, channel in channels.items():
        check_channel(channel)
        gain = np.asarray(make(name, 0, None, None).channel_gain(channel), float)

        def identified(flown: MakeDisturbed, airframes: Mapping[str, object] | None, q: DOBSpec | None) -> None:
            fits[name] = {ax: identify_channel(lambda nm, seed: flown(nm, seed, None, None), name, ts, channel, ax,
                                               duration, zero_at_origin=zero_at_origin) for ax in axes}
            loops[name] = {ax: channel_loop(name, ts, channel, f.plant, float(gain[AXES.index(ax)]),
                                            f.airframe if airframes is None else airframes[ax], q, f.identification)
                           for ax, f in fits[name].items()}

        identified(make, None, None)
        if dob is not None:
            if any(f.airframe is None for f in fits[name].values()):
                raise SpecError(f"`dob`: vehicle {name!r} logs no commanded acceleration, so no airframe was "
                                "identified for its DOB to invert")
            airframes = {ax: lp.airframe for ax, lp in loops[name].items()}
            identified(with_dob(make, {name: {ax: replace(lp, dob=dob) for ax, lp in loops[name].items()}}),
                       airframes, dob)
    return loops, fits


@dataclass(frozen=True)
class ChannelChain:
    """The flights of one chain (:func:`fly_channel_chain`).

    Attributes
    ----------
    order : list of str
        The learning order.
    axes : tuple of str
        The axes learned.
    baseline : dict of str to ClosedLoopTrial
        Each vehicle's flight without learning.
    learning : dict of str to list of ClosedLoopTrial
        Each vehicle's learning flights, in order.
    chain : list of (str, str)
        (source, target) of every step.
    """

    order: list[str]
    axes: tuple[str, ...]
    baseline: dict[str, ClosedLoopTrial]
    learning: dict[str, list[ClosedLoopTrial]]
    chain: list[tuple[str, str]]

    def rmse(self, trial: ClosedLoopTrial) -> float:
        """RMS tracking error over the learned axes of one trial.

        Parameters
        ----------
        trial : ClosedLoopTrial
            A flight of this chain (its ``error`` in m, one column per axis).

        Returns
        -------
        float
            The RMS of the error over the chain's ``axes`` and the whole trial, m.
        """
        idx = [AXES.index(ax) for ax in self.axes]
        return float(np.sqrt(np.mean(trial.error[:, idx] ** 2)))

    def ratios(self) -> dict[str, list[float]]:
        """Per vehicle, each learning flight's RMSE over its flight without learning."""
        return {name: [self.rmse(f) / self.rmse(self.baseline[name]) for f in flights]
                for name, flights in self.learning.items()}


def fly_channel_chain(loops: Mapping[str, Mapping[str, ChannelLoop | LoopSystem]], make: MakeDisturbed,
                      reference: np.ndarray, order: Sequence[str], iterations: int = 3, *,
                      velocity: np.ndarray | None = None,
                      acceleration: np.ndarray | None = None, command_disturbance: Callable | None = None,
                      wind: Callable | None = None, band: object = "auto", disturbance: str = "command"
                      ) -> ChannelChain:
    """Fly the chain (module docstring, step 2).

    Parameters
    ----------
    loops : mapping
        ``loops[name][axis]`` (:func:`identify_channel_loops`), or the :class:`~ilcdob.loop.LoopSystem` of a
        vehicle on ilcdob's PID + DOB (module docstring); every vehicle the same axes.
    make : callable
        :data:`MakeDisturbed`; flight ``k`` of the ``i``-th vehicle of ``order`` has seed ``10 k + i``; a
        vehicle whose loops carry an add-on DOB flies it (:func:`with_dob`).
    reference : numpy.ndarray
        ``N x 3`` position, m, from where the vehicles start.
    order : sequence of str
        Learning order.
    iterations : int
        Learning flights per vehicle.
    velocity, acceleration : numpy.ndarray, optional
        The reference's feed-forward, ``N x 3`` (m/s, m/s^2).
    command_disturbance, wind : callable, optional
        The disturbance of every flight (:data:`MakeDisturbed`).
    band : "auto", float or None
        The learning band (:func:`~ilcdob.design.pair.design_channel_pair`).
    disturbance : {"command", "airframe", "wind"}
        Where the law assumes the disturbance acts (:func:`~ilcdob.design.pair.design_channel_pair`): ``"wind"``
        is the wind law, learning the wind velocity through each airframe's identified drag.

    Returns
    -------
    ChannelChain

    Raises
    ------
    SpecError
        An order naming vehicles without loops, vehicles with other axes, a bad iteration count.
    """
    check_iterations(iterations)
    order = list(order)
    missing = [nm for nm in order if nm not in loops]
    if missing or not order:
        raise SpecError(f"`order`: got {order!r}; {missing or 'none'} have no loops (loops for {sorted(loops)})")
    axes = tuple(ax for ax in AXES if ax in loops[order[0]])
    if any(tuple(ax for ax in AXES if ax in loops[nm]) != axes for nm in order):
        raise SpecError(f"`loops`: every vehicle needs loops for the same axes ({list(axes)})")
    designs: dict[tuple[str, str, str], PairDesign] = {}
    count = {nm: 0 for nm in order}
    flown = with_dob(make, loops)

    def fly(name: str, learning: dict[str, np.ndarray] | None) -> ClosedLoopTrial:
        vehicle = flown(name, 10 * count[name] + order.index(name), command_disturbance, wind)
        count[name] += 1
        return fly_closed_loop(vehicle, reference, velocity=velocity, acceleration=acceleration, learning=learning,
                               channel=learning_channel(loops[name][axes[0]]))

    def step(src: str, tgt: str, prev: ClosedLoopTrial) -> ClosedLoopTrial:
        u = {}
        for ax in axes:
            if (src, tgt, ax) not in designs:
                designs[src, tgt, ax] = design_channel_pair(loops[src][ax], loops[tgt][ax], band=band,
                                                              disturbance=disturbance)
            i = AXES.index(ax)
            u[ax] = designs[src, tgt, ax].learning(prev.error[:, i], prev.learning[:, i]).d_f
        return fly(tgt, u)

    baseline = {nm: fly(nm, None) for nm in order}
    learning, chain = learning_chain(order, iterations, baseline[order[0]], step)
    return ChannelChain(order, axes, baseline, learning, chain)
