"""A vehicle on its own controller as the learning sees it: its identified maps (docs/closed_loop.md).

The paper's learning needs two maps per vehicle (paper Sec. III): ``Gd`` from an acceleration
disturbance to the position, and ``Gf`` from the learning signal to the position.
For a vehicle flying its own controller, with the learning signal ``u`` added to one row of the
setpoint its flight stack accepts (:mod:`ilcdob.vehicles.closed_loop`)::

    y = T r + Gd d + Gf u,      e = r - y,      Gf = K Gd

``K`` is the controller's map from the channel to the acceleration it commands
(:mod:`ilcdob.channel_gain`): 1 on the acceleration feed-forward channel (added to the command, where
the paper's disturbance acts), ``kp`` for a position offset and ``kd`` for a velocity offset on a single
position/velocity loop such as rotorpy's SE3 or a Crazyflie's Mellinger controller without its integral
(the setpoint reaches the airframe only through ``K``, whatever else the loop feeds back), and a transfer
function with the velocity integral on a cascade's position or velocity channel (PX4, ArduPilot).
``Gd`` is identified: on the acceleration channel it is the channel's own map; from a setpoint
channel's map ``G_ch`` it is ``G_ch / K``. Where ``K`` depends on frequency both are kept
(:attr:`ChannelLoop.channel_map`) and sampled apart: ``Gf`` is the zero-order hold of ``G_ch`` as the
setpoint is flown, ``Gd`` that of ``G_ch / K``, so their sampled ratio is not the continuous ``K``.
``d`` is an acceleration added to the controller's command, as the paper's disturbance and the learning
signal are; a force on the rigid body (wind through drag) bypasses the
attitude loop, and the learning reaches it through the airframe correction of
:mod:`ilcdob.design.maps.flown`, built from each vehicle's identified airframe (commanded
acceleration -> position, :attr:`ChannelLoop.airframe`).

With the add-on DOB (:class:`~ilcdob.vehicles.dob_loop.AddOnDOB`: the paper's DOB on the identified
airframe, its estimate taken off through the same channel, the learning signal added after it) the
vehicle's maps are ``Gf = K P/D`` and ``Gd = (1 - Q) P/D`` with ``D = 1 - Q + P (M + C)`` of the
vehicle's own loop ``C``: so ``Gd = (1 - Q) Gf / K`` exactly, whatever the airframe model's error (it
enters ``D`` only). ``G_ch`` is then identified with the DOB flying, and :attr:`ChannelLoop.dob` holds
its ``Q``.

``T`` is the reference map: the reference ``r`` (m) the vehicle is sent -> its position, as the flight stack
flies it (whatever it feeds forward of ``r``'s derivatives). Only the ``exact-reference`` law uses it
(:mod:`ilcdob.design.maps.reference`); it is identified from flights of the reference alone
(:attr:`ChannelLoop.reference_map`), and on the position channel it defaults to the channel's own map
(an offset added to the position setpoint is flown as the setpoint is).

Units: s, m, the channel's unit for ``u`` (:data:`CHANNEL_UNITS`), m/s^2 for ``d``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import control as ct
import numpy as np

from .channel_gain import ChannelGain, as_channel_gain
from .discretize import DiscreteBlock, plant_block, q_block
from .errors import SpecError, UnstableLoopError
from .loop import STABILITY_MARGIN
from .names import check_name
from .specs import DOBSpec, IdentificationSpec, LimitSpec, PlantSpec, SensorSpec

__all__ = ["CHANNELS", "CHANNEL_UNITS", "SLOWEST_ROOT", "check_channel", "ChannelLoop", "channel_loop",
           "ChannelSystemSpec"]

#: The setpoint channels a learning signal can enter through (module docstring), in the setpoint's row order.
CHANNELS = ("position", "velocity", "acceleration")
#: Unit of a learning signal on each channel.
CHANNEL_UNITS = {"position": "m", "velocity": "m/s", "acceleration": "m/s^2"}
#: rad/s: the slowest root a channel map keeps beside the origin. A pole this close to a zero fixed at s = 0
#: cancels it (a loop without an integral fitted with a spurious pole-zero pair there: 1.2e-4 rad/s for the PD
#: loop of ``tests/test_cascade.py``; a cascade's slowest pole is its velocity integral's, near ``kiv / kpv``:
#: 0.23 and 0.44 rad/s for the tests' two), and a right-half-plane zero this slow is the zero at s = 0 of a loop
#: that integrates placed a little off by a free fit (:mod:`ilcdob.identification.origin_zero`).
SLOWEST_ROOT = 0.01


def check_channel(channel: object, what: str = "channel") -> str:
    """Return ``channel`` if it is one of :data:`CHANNELS`.

    Parameters
    ----------
    channel : object
    what : str
        Name of the input, for the message.

    Raises
    ------
    SpecError
        Any other value.
    """
    if channel not in CHANNELS:
        raise SpecError(f"`{what}`: got {channel!r}, expected one of {list(CHANNELS)} (position: a setpoint offset in "
                        "m; velocity, acceleration: feed-forward in m/s, m/s^2)")
    return str(channel)



def _stable_block(plant: PlantSpec, ts: float, name: str, what: str) -> DiscreteBlock:
    """``plant`` sampled (:func:`plant_block`), refused unless all its poles are inside the unit circle."""
    block = plant_block(plant, ts)
    bad = block.poles[np.abs(block.poles) >= STABILITY_MARGIN]
    if bad.size:
        raise UnstableLoopError(f"vehicle {name!r}: its {what} has poles {np.round(bad, 6)} on or outside the unit "
                                "circle; a vehicle on its own controller must hold its position (identify the "
                                "closed loop, not the airframe)")
    return block


@dataclass(frozen=True)
class ChannelLoop:
    """One vehicle axis on its own controller (module docstring).

    Attributes
    ----------
    name : str
        The vehicle.
    ts : float
        Setpoint period, s.
    channel : {"position", "velocity", "acceleration"}
        Where the learning signal enters.
    disturbance_map : PlantSpec
        ``G_ch / K`` in continuous time: acceleration added to the command (m/s^2) -> position (m); stable.
        Without the add-on DOB this is ``Gd`` itself; with it ``Gd = (1 - Q)`` times it (module docstring).
    channel_gain : float or ChannelGain
        ``K``: acceleration (m/s^2) the controller commands per unit of channel signal (1 on the
        acceleration channel; :mod:`ilcdob.channel_gain`).
    airframe : PlantSpec or None
        The airframe's identified model, commanded acceleration (m/s^2) -> position (m), with one
        integrator and a drag pole, where the flights logged the commanded acceleration; needed for a
        disturbance on the airframe or in wind (module docstring).
    dob : DOBSpec or None
        The add-on DOB's ``Q`` when the vehicle flies one (:class:`~ilcdob.vehicles.dob_loop.AddOnDOB`, built on
        ``airframe``); None: the vehicle's loop alone.
    identification : IdentificationSpec or None
        The channel fit's parameters and covariance (:attr:`ilcdob.validation.channel_id.ChannelFit.identification`):
        its Delta set (:meth:`delta`).
    reference_map : PlantSpec or None
        ``T`` (module docstring): reference (m) -> position (m), continuous, identified; None: on the position
        channel the channel map ``K Gd`` (:attr:`G_r`), elsewhere not known.
    channel_map : PlantSpec or None
        ``G_ch``, the channel's identified map (channel unit -> m, continuous), where ``K`` depends on frequency
        (required there, and equal to ``K`` times ``disturbance_map``); None for a constant ``K``
        (``G_ch = K disturbance_map``). Build both with :func:`channel_loop`.
    """

    name: str
    ts: float
    channel: str
    disturbance_map: PlantSpec
    channel_gain: float | ChannelGain = 1.0
    airframe: PlantSpec | None = None
    dob: DOBSpec | None = None
    identification: IdentificationSpec | None = None
    reference_map: PlantSpec | None = None
    channel_map: PlantSpec | None = None
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_channel(self.channel)
        if not isinstance(self.disturbance_map, PlantSpec):
            raise SpecError(f"`disturbance_map`: got {type(self.disturbance_map).__name__}, expected a PlantSpec "
                            "(the identified map from an acceleration on the airframe to the position)")
        self._cache["gain"] = as_channel_gain(self.channel_gain)
        k = self.gain.constant
        if self.airframe is not None and not isinstance(self.airframe, PlantSpec):
            raise SpecError(f"`airframe`: got {type(self.airframe).__name__}, expected a PlantSpec (commanded "
                            "acceleration -> position) or None")
        if self.identification is not None and not isinstance(self.identification, IdentificationSpec):
            raise SpecError(f"`identification`: got {type(self.identification).__name__}, expected an "
                            "IdentificationSpec (the channel fit's parameters and covariance) or None")
        if self.reference_map is not None and not isinstance(self.reference_map, PlantSpec):
            raise SpecError(f"`reference_map`: got {type(self.reference_map).__name__}, expected a PlantSpec "
                            "(reference -> position, identified) or None")
        if self.dob is not None and not isinstance(self.dob, DOBSpec):
            raise SpecError(f"`dob`: got {type(self.dob).__name__}, expected a DOBSpec (the add-on DOB's Q) or None")
        if self.dob is not None and self.airframe is None:
            raise SpecError(f"vehicle {self.name!r}: an add-on DOB needs the identified airframe it inverts "
                            "(`airframe`, commanded acceleration -> position)")
        if self.channel == "acceleration" and k != 1.0:
            raise SpecError(f"`channel_gain`: got {self.gain.describe() if k is None else k} on the acceleration "
                            "channel, where the learning signal is added where a disturbance acts: it must be 1")
        self._cache["block"] = _stable_block(self.disturbance_map, self.ts, self.name, "disturbance map")
        if k is None:
            self._check_channel_map()
        elif self.channel_map is not None:
            raise SpecError(f"vehicle {self.name!r}: `channel_map` is kept only where K depends on frequency; with "
                            f"{self.gain.describe()} it is K times `disturbance_map` (give None)")
        if self.reference_map is not None:
            self.G_r  # noqa: B018 - built now: an unstable reference map is refused with the vehicle

    def _check_channel_map(self) -> None:
        """A frequency-dependent ``K``: ``channel_map`` given, equal to ``K`` times ``disturbance_map``, no DOB."""
        what = f"vehicle {self.name!r} ({self.gain.describe()})"
        if not isinstance(self.channel_map, PlantSpec):
            raise SpecError(f"{what}: a K that depends on frequency needs the identified channel map as "
                            "`channel_map` (a PlantSpec); build the loop with ilcdob.channel_loop.channel_loop")
        if self.dob is not None:
            raise SpecError(f"{what}: the add-on DOB is built for a constant K; give the vehicle no DOB or learn on "
                            "its acceleration channel")
        if abs(self.channel_map.delay - self.disturbance_map.delay) > 1e-12:
            raise SpecError(f"{what}: `channel_map` delay {self.channel_map.delay:g} s differs from "
                            f"`disturbance_map`'s {self.disturbance_map.delay:g} s")
        s = 1j * np.geomspace(1e-2, 0.9 * np.pi / self.ts, 50)
        g_ch = np.polyval(self.channel_map.num, s) / np.polyval(self.channel_map.den, s)
        g_d = np.polyval(self.disturbance_map.num, s) / np.polyval(self.disturbance_map.den, s)
        err = float(np.max(np.abs(g_ch - self.gain.response(s) * g_d) / np.abs(g_ch)))
        if not err <= 1e-6:
            raise SpecError(f"{what}: `channel_map` is not K times `disturbance_map` (relative difference {err:.3g} "
                            "up to 0.9 Nyquist); build the loop with ilcdob.channel_loop.channel_loop")
        self._cache["channel_block"] = _stable_block(self.channel_map, self.ts, self.name, "channel map")

    @property
    def gain(self) -> ChannelGain:
        """``K`` (:attr:`channel_gain`) as a :class:`~ilcdob.channel_gain.ChannelGain`."""
        return self._cache["gain"]

    @property
    def channel_block(self) -> DiscreteBlock | None:
        """``G_ch`` sampled with a zero-order hold where ``K`` depends on frequency (:attr:`channel_map`); None
        for a constant ``K`` (``G_f`` is then ``K`` times :attr:`block`)."""
        return self._cache.get("channel_block")

    def channel_plant(self) -> PlantSpec:
        """``G_ch``: the channel's map (channel unit -> m), continuous: :attr:`channel_map`, or ``K`` times
        ``disturbance_map`` for a constant ``K``."""
        if self.channel_map is not None:
            return self.channel_map
        dm = self.disturbance_map
        return PlantSpec(tuple(np.asarray(dm.num) * self.gain.constant), dm.den, dm.delay)

    @property
    def block(self) -> DiscreteBlock:
        """``Gd`` sampled with a zero-order hold, with its analytic poles and zeros (:func:`plant_block`)."""
        return self._cache["block"]

    @property
    def q(self) -> DiscreteBlock | None:
        """The add-on DOB's ``Q`` as it flies (:func:`~ilcdob.discretize.q_block` on the airframe); None without."""
        if self.dob is None:
            return None
        if "q" not in self._cache:
            self._cache["q"] = q_block(self.dob, self.airframe, self.ts)
        return self._cache["q"]

    @property
    def G_d(self) -> ct.StateSpace:
        """``Gd``: disturbance (m/s^2) -> position (m), discrete; ``(1 - Q)`` times ``disturbance_map`` with the
        add-on DOB."""
        if self.q is None:
            return self.block.sys
        q = self.q.sys
        return ct.series(ct.ss(q.A, q.B, -q.C, 1.0 - q.D, q.dt), self.block.sys)

    @property
    def G_f(self) -> ct.StateSpace:
        """``Gf``: learning signal (channel unit) -> position (m), discrete: ``K Gd`` for a constant ``K``, the
        sampled channel map otherwise (module docstring)."""
        if self.channel_block is not None:
            return self.channel_block.sys
        s, k = self.block.sys, self.gain.constant
        return ct.ss(s.A, s.B, k * s.C, k * s.D, s.dt)

    @property
    def G_r(self) -> ct.StateSpace:
        """``T``: reference (m) -> position (m), discrete (module docstring).

        Raises
        ------
        SpecError
            No reference map off the position channel.
        """
        if "G_r" not in self._cache:
            if self.reference_map is not None:
                self._cache["G_r"] = _stable_block(self.reference_map, self.ts, self.name, "reference map").sys
            elif self.channel == "position":
                self._cache["G_r"] = self.G_f
            else:
                raise SpecError(f"vehicle {self.name!r}: its reference map (reference -> position as its flight "
                                f"stack flies it) is not known on the {self.channel!r} channel; identify it from a "
                                "flight of the reference alone and give it as `reference_map` (docs/closed_loop.md)")
        return self._cache["G_r"]

    @property
    def reference_source(self) -> str:
        """Where :attr:`G_r` comes from: ``"identified"`` or ``"channel map"``."""
        return "identified" if self.reference_map is not None else "channel map"

    @property
    def integrates(self) -> bool:
        """Whether the loop integrates: its disturbance map has a zero fixed at ``s = 0`` (a cascade's velocity
        integral, identified with ``--zero-at-origin``; :mod:`ilcdob.identification.origin_zero`)."""
        return len(self.disturbance_map.num) > 1 and self.disturbance_map.num[-1] == 0

    @property
    def nominal(self) -> "ChannelLoop":
        """The loop the learning assumes: the identified one itself."""
        return self

    def delta(self, w: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """The channel map's multiplicative uncertainty ``|Delta(jw)|`` at 3 standard deviations of its fit
        (:func:`~ilcdob.uncertainty.multiplicative_bound`), times ``scale``: ``Gd`` and ``Gf`` share it (``K`` is
        the controller's, known).

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.
        scale : float
            Multiplier (> 0) of the identified standard deviations.

        Returns
        -------
        numpy.ndarray
            One bound per frequency.

        Raises
        ------
        SpecError
            No identification, or a bad ``scale``.
        """
        ident = self.identification
        if ident is None:
            raise SpecError(f"vehicle {self.name!r}: its channel map has no identification (parameters and "
                            "covariance), so no uncertainty set; identify it (`ilcdob identify` on flights exciting its "
                            "channel, its model.json as `channel_map`) or state a bound (`ilcdob check --bound`)")
        if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
            raise SpecError(f"`scale`: got {scale!r}, expected a multiplier > 0 of the standard deviations")
        return scale * ident.bound(w, self.disturbance_map.delay)

    def poles(self) -> np.ndarray:
        """Poles of ``G_ch / K`` (z-plane, analytic); ``Gd`` has the add-on DOB's ``Q``'s besides."""
        return self.block.poles


def channel_loop(name: str, ts: float, channel: str, channel_map: PlantSpec, channel_gain: float | ChannelGain = 1.0,
                 airframe: PlantSpec | None = None, dob: DOBSpec | None = None,
                 identification: IdentificationSpec | None = None,
                 reference_map: PlantSpec | None = None) -> ChannelLoop:
    """The loop of a vehicle from its identified channel map ``G_ch`` (channel -> position).

    ``Gd = G_ch / K``, times ``1 - Q`` with the add-on DOB (module docstring); where ``K`` depends on frequency
    ``G_ch`` is kept beside it (:attr:`ChannelLoop.channel_map`).

    Parameters
    ----------
    name : str
    ts : float
        Setpoint period, s.
    channel : {"position", "velocity", "acceleration"}
    channel_map : PlantSpec
        The channel's fit (:func:`ilcdob.validation.channel_id.identify_channel`), channel unit -> m.
    channel_gain : float or ChannelGain
        ``K`` (module docstring): 1 on the acceleration channel, the controller's ``kp`` on the position
        channel and its ``kd`` on the velocity channel of a single loop, ``ChannelGain.cascade(...)`` on a
        cascade's.
    airframe : PlantSpec, optional
        The airframe's identified model (:attr:`ChannelLoop.airframe`).
    dob : DOBSpec, optional
        The add-on DOB the vehicle flew ``channel_map``'s flights with (:attr:`ChannelLoop.dob`); constant ``K``
        only.
    identification : IdentificationSpec, optional
        The fit's parameters and covariance (:attr:`ChannelLoop.identification`).
    reference_map : PlantSpec, optional
        ``T``, reference -> position, identified (:attr:`ChannelLoop.reference_map`).

    Returns
    -------
    ChannelLoop

    Raises
    ------
    SpecError
        A bad channel or gain, or a ``G_ch / K`` that is not strictly proper.
    UnstableLoopError
        The map is not stable.
    """
    gain = as_channel_gain(channel_gain)
    k = gain.constant
    if k is not None:
        num = [c / k for c in channel_map.num]
        return ChannelLoop(name, ts, channel, PlantSpec(num=num, den=list(channel_map.den), delay=channel_map.delay),
                           float(k), airframe, dob, identification, reference_map)
    num, den = np.polymul(channel_map.num, gain.den), np.polymul(channel_map.den, gain.num)
    try:
        gd = PlantSpec(num=tuple(num), den=tuple(den), delay=channel_map.delay)
    except SpecError as exc:
        raise SpecError(f"vehicle {name!r}: G_ch / K with {gain.describe()} is not a map from an acceleration to "
                        f"the position ({exc}); check the channel and its gains") from None
    return ChannelLoop(name, ts, channel, gd, gain, airframe, dob, identification, reference_map, channel_map)


@dataclass(frozen=True)
class ChannelSystemSpec:
    """A fleet's vehicle on its own controller (:mod:`ilcdob.fleet`'s ``channel`` systems): what a fleet file states.

    Attributes
    ----------
    name : str
        Unique name in the fleet (:func:`ilcdob.names.check_name`).
    channel : {"position", "velocity", "acceleration"}
        Where the learning signal enters the vehicle's setpoint.
    channel_map : PlantSpec
        The identified map from the channel (its unit, :data:`CHANNEL_UNITS`) to the position (m) with the
        vehicle's own loop closed (and its add-on DOB, with ``dob``): stable, continuous.
    channel_gain : float or ChannelGain
        ``K``: commanded acceleration (m/s^2) per unit of channel signal (module docstring); 1 on the
        acceleration channel.
    airframe : PlantSpec or None
        Commanded acceleration (m/s^2) -> position (m), identified; needed for the airframe and wind paths
        and for the add-on DOB.
    dob : DOBSpec or None
        The add-on DOB the vehicle flies (None: its own loop alone).
    identification : IdentificationSpec or None
        The channel map's fit (its Delta set).
    limits : LimitSpec or None
        What the vehicle can fly: bounds the acceleration its learning signal makes it command.
    sensor : SensorSpec or None
        Its position sensor's noise.
    reference_map : PlantSpec or None
        ``T``, reference (m) -> position (m), identified (:attr:`ChannelLoop.reference_map`).
    """

    name: str
    channel: str
    channel_map: PlantSpec
    channel_gain: float | ChannelGain = 1.0
    airframe: PlantSpec | None = None
    dob: DOBSpec | None = None
    identification: IdentificationSpec | None = None
    limits: LimitSpec | None = None
    sensor: SensorSpec | None = None
    reference_map: PlantSpec | None = None

    def __post_init__(self) -> None:
        check_name(self.name)
        check_channel(self.channel)
        try:
            as_channel_gain(self.channel_gain)
        except SpecError as exc:
            raise SpecError(f"system {self.name!r}: {exc}") from None
        if not isinstance(self.channel_map, PlantSpec):
            raise SpecError(f"system {self.name!r}: `channel_map`: got {type(self.channel_map).__name__}, expected "
                            "a PlantSpec (the identified map from the channel to the position)")
        for key, kind in (("limits", LimitSpec), ("sensor", SensorSpec)):
            value = getattr(self, key)
            if value is not None and not isinstance(value, kind):
                raise SpecError(f"system {self.name!r}: `{key}`: got {type(value).__name__}, expected a "
                                f"{kind.__name__} or None")

    def loop(self, ts: float) -> ChannelLoop:
        """The vehicle's :class:`ChannelLoop` at the setpoint period ``ts`` (s) (:func:`channel_loop`).

        Parameters
        ----------
        ts : float
            Setpoint period, s.

        Returns
        -------
        ChannelLoop

        Raises
        ------
        SpecError
            A bad gain, airframe or DOB.
        UnstableLoopError
            The channel map is not stable.
        """
        return channel_loop(self.name, ts, self.channel, self.channel_map, self.channel_gain, self.airframe,
                            self.dob, self.identification, self.reference_map)
