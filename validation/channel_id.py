"""Identifying a vehicle's learning channel: the map from a signal added to its setpoint to its position, with
the vehicle on its own controller (:mod:`ilcdob.vehicles.closed_loop`).

Per vehicle, axis and channel two closed-loop flights hover at the start with a chirp added to the channel
(an estimation flight sweeping up from 0.05 Hz to 2 Hz, a held-out one sweeping down, each with its own
sensor noise): no ilcdob controller is in the loop, the vehicle's own holds it. Each candidate structure
of :data:`CHANNEL_STRUCTURES` is fitted with :func:`~ilcdob.identification.tfest.tfest` (output error,
closed-loop data: the chirp is the only input the fit sees, and the loop's response to the noise is what
the held-out flight scores) and the one with the best held-out fit is chosen, one with fewer parameters
winning unless a larger one fits 1 point better. The fit is the channel map ``G_ch`` (channel -> position):
on the acceleration channel it is also the map of an acceleration added to the command, on the
position channel the loop's complementary sensitivity.

Where the vehicle reports the acceleration its controller commanded (a flight stack's log: PX4's
acceleration setpoint; :attr:`~ilcdob.vehicles.closed_loop.ClosedLoopTrial.command`), the same two
flights also identify the airframe, commanded acceleration -> position, with one integrator
(:data:`AIRFRAME_STRUCTURES`): its slowest real pole is the airframe's drag per unit mass, what a
wind velocity acts through (the wind law, docs/closed_loop.md). In simulation the controller acts on
the true state, so the commanded acceleration carries none of the sensor noise and the output-error
fit is unbiased; on a real vehicle the estimator's noise reaches it through the loop.

Units: s, m, and the channel's unit (:data:`~ilcdob.channel_loop.CHANNEL_UNITS`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.fleet import AXES
from ilcdob.signals import FlightData, check_grid
from ilcdob.specs import IdentificationSpec, PlantSpec
from ilcdob.uncertainty import ModelStructure
from ilcdob.vehicles.closed_loop import ClosedLoopVehicle, fly_closed_loop
from ilcdob.channel_loop import CHANNEL_UNITS, check_channel
from ilcdob.design.maps.flown import rigid_body_split

from .vehicle_chain import fit_candidates

__all__ = ["CHANNEL_STRUCTURES", "AIRFRAME_STRUCTURES", "CHIRP_AMPLITUDE", "ChannelFit", "identify_channel",
           "channel_flight", "MakeClosedLoop", "GainCheck", "check_channel_gain"]

#: Candidate structures of a channel map, fewest free parameters first: the vehicle's loop holds its position,
#: so no integrator; a second-order position loop (2 poles), with its attitude lag (3), with the zero its
#: derivative or feed-forward path puts in (1 zero), and one pole and zero more (4 poles, 2 zeros).
CHANNEL_STRUCTURES = (ModelStructure(n_poles=2), ModelStructure(n_poles=3), ModelStructure(n_poles=3, n_zeros=1),
                      ModelStructure(n_poles=4, n_zeros=1), ModelStructure(n_poles=4, n_zeros=2))
#: Candidate structures of the airframe (commanded acceleration -> position): the rigid body's integrator and
#: drag pole with the attitude loop's lag (3 poles), a second lag pole, and the zero an attitude loop's
#: derivative puts in.
AIRFRAME_STRUCTURES = (ModelStructure(n_poles=3, n_integrators=1), ModelStructure(n_poles=4, n_integrators=1),
                       ModelStructure(n_poles=4, n_zeros=1, n_integrators=1))
#: Chirp amplitude per channel (m, m/s, m/s^2): a few centimetres of motion for a multirotor's loop.
CHIRP_AMPLITUDE = {"position": 0.1, "velocity": 0.2, "acceleration": 1.0}
#: ``make(name, seed) -> ClosedLoopVehicle``: a fresh vehicle at rest, ``seed`` its sensor noise's.
MakeClosedLoop = Callable[[str, int], ClosedLoopVehicle]

_F_LOW, _F_HIGH = 0.05, 2.0  # chirp band, Hz: a multirotor position loop closes below 1 Hz


@dataclass(frozen=True)
class ChannelFit:
    """The identified channel map of one vehicle's axis.

    Attributes
    ----------
    name, axis, channel : str
        The vehicle, the axis (``"x"``, ``"y"``, ``"z"``) and the channel.
    structure : ModelStructure
        The structure chosen (module docstring).
    plant : PlantSpec
        Its fit, channel unit -> m (continuous time, a delay in s).
    fit_estimation, fit_validation : float
        Fit (%) of the chosen structure on the estimation and the held-out flight.
    fits : dict of str to float
        Held-out fit (%) of every candidate, by ``"<poles>p<zeros>z"``.
    airframe : PlantSpec or None
        Where the flights logged the commanded acceleration: the airframe's fit, m/s^2 -> m (module docstring).
    airframe_fit : float or None
        Its held-out fit, %.
    identification : IdentificationSpec or None
        The chosen fit's parameters and covariance: the channel map's Delta set. The chirp is added outside
        the loop and the sensor noise does not reach it, so the output-error fit and its covariance are those
        of open-loop data.
    """

    name: str
    axis: str
    channel: str
    structure: ModelStructure
    plant: PlantSpec
    fit_estimation: float
    fit_validation: float
    fits: dict[str, float]
    airframe: PlantSpec | None = None
    airframe_fit: float | None = None
    identification: IdentificationSpec | None = None

    @property
    def drag(self) -> float | None:
        """The airframe's drag per unit mass, 1/s: its fit's slowest real pole besides the integrator (None
        without an airframe fit or where it has no such pole; a design through the airframe then says why)."""
        if self.airframe is None:
            return None
        try:
            return float(rigid_body_split(self.airframe, self.name)[2][1])
        except SpecError:
            return None


def _label(st: ModelStructure) -> str:
    return f"{st.n_poles}p{st.n_zeros}z"


def channel_flight(make: MakeClosedLoop, name: str, ts: float, channel: str, axis: str, seed: int,
                   duration: float, up: bool = True) -> FlightData:
    """One identification flight (module docstring): hover, a chirp on ``channel`` of ``axis``.

    Parameters
    ----------
    make : callable
        :data:`MakeClosedLoop`.
    name : str
        The vehicle.
    ts : float
        Setpoint period, s (the vehicle's).
    channel : {"position", "velocity", "acceleration"}
    axis : {"x", "y", "z"}
    seed : int
        Its sensor noise's seed.
    duration : float
        Length, s (a whole number of ``ts``).
    up : bool
        Sweep up from 0.05 Hz to 2 Hz (else down).

    Returns
    -------
    FlightData
        Signals ``u`` (the chirp, the channel's unit) and ``y`` (measured position on ``axis``, m); where the
        vehicle reports it, ``command`` (its controller's commanded acceleration on ``axis``, m/s^2).
    """
    check_channel(channel)
    if axis not in AXES:
        raise SpecError(f"`axis`: got {axis!r}, expected one of {list(AXES)}")
    check_grid(duration, ts, f"the channel flight of {name}")
    n = int(round(duration / ts))
    t = np.arange(n) * ts
    f0, f1 = (_F_LOW, _F_HIGH) if up else (_F_HIGH, _F_LOW)
    u = CHIRP_AMPLITUDE[channel] * np.sin(2 * np.pi * (f0 * t + (f1 - f0) * t ** 2 / (2 * duration)))
    u *= np.clip(t / 1.0, 0.0, 1.0)  # faded in over 1 s: the trial starts hovering at rest
    vehicle = make(name, seed)
    if abs(vehicle.ts - ts) > 1e-12 * ts:
        raise SpecError(f"`ts`: {ts} s, but vehicle {name!r} steps {vehicle.ts} s")
    trial = fly_closed_loop(vehicle, np.zeros((n, 3)), learning={axis: u}, channel=channel)
    i = AXES.index(axis)
    signals, units = {"u": u, "y": trial.y_meas[:, i]}, {"u": CHANNEL_UNITS[channel], "y": "m"}
    if trial.command is not None:
        signals["command"], units["command"] = trial.command[:, i], "m/s^2"
    return FlightData(t, signals, units, source=f"{name} {axis} {channel} chirp")


def identify_channel(make: MakeClosedLoop, name: str, ts: float, channel: str, axis: str = "x",
                     duration: float = 30.0, structures: Sequence[ModelStructure] = CHANNEL_STRUCTURES,
                     zero_at_origin: bool = False) -> ChannelFit:
    """Identify the channel map of one vehicle's axis (module docstring).

    Parameters
    ----------
    make : callable
        :data:`MakeClosedLoop`.
    name : str
        The vehicle.
    ts : float
        Setpoint period, s.
    channel : {"position", "velocity", "acceleration"}
    axis : {"x", "y", "z"}
    duration : float
        Length of each of the two flights, s.
    structures : sequence of ModelStructure
        Candidates, fewest parameters first.
    zero_at_origin : bool
        The loop integrates (a cascade's velocity integral on the acceleration channel): one zero of the
        channel map fixed at s = 0 (:func:`~ilcdob.validation.vehicle_chain.fit_candidates`).

    Returns
    -------
    ChannelFit

    Raises
    ------
    SpecError
        A bad channel, axis, duration or sample time; no candidate.
    """
    if not structures:
        raise SpecError("`structures`: got none, expected at least one candidate structure")
    est = channel_flight(make, name, ts, channel, axis, 0, duration, up=True)
    val = channel_flight(make, name, ts, channel, axis, 1, duration, up=False)
    candidates, chosen = fit_candidates(est, val, structures, zero_at_origin)
    airframe = airframe_fit = None
    if "command" in est.signals:
        _, body = fit_candidates(_command_flight(est), _command_flight(val), AIRFRAME_STRUCTURES)
        airframe, airframe_fit = body.plant, body.fit_validation
    return ChannelFit(name, axis, channel, chosen.structure, chosen.plant, chosen.fit_estimation,
                      chosen.fit_validation, {_label(c.structure): c.fit_validation for c in candidates},
                      airframe, airframe_fit, chosen.identification)


def _command_flight(flight: FlightData) -> FlightData:
    """The flight as the airframe's data: the commanded acceleration as its input ``u``."""
    return FlightData(flight.t, {"u": flight.signals["command"], "y": flight.signals["y"]},
                      {"u": "m/s^2", "y": "m"}, source=f"{flight.source}, commanded acceleration")


@dataclass(frozen=True)
class GainCheck:
    """Whether a setpoint channel's fit is its acceleration channel's times a constant ``K`` (:func:`check_channel_gain`).

    Attributes
    ----------
    w : numpy.ndarray
        Frequencies, rad/s.
    mismatch : numpy.ndarray
        ``|G_setpoint / (K G_acceleration) - 1|`` on ``w``.
    bound : numpy.ndarray
        What the two fits' uncertainty allows there: the sum of their 3-sigma bounds (times ``slack``).
    gain : float
        The ``K`` checked.
    """

    w: np.ndarray
    mismatch: np.ndarray
    bound: np.ndarray
    gain: float

    @property
    def holds(self) -> bool:
        """The constant ``K`` is within the fits' uncertainty at every frequency checked."""
        return bool(np.all(self.mismatch <= self.bound))

    @property
    def worst_w(self) -> float:
        """Where the mismatch is largest against its bound, rad/s."""
        return float(self.w[int(np.argmax(self.mismatch - self.bound))])

    def __repr__(self) -> str:
        k = int(np.argmax(self.mismatch - self.bound))
        return (f"<GainCheck K = {self.gain:g}: {'holds' if self.holds else 'FAILS'}; at {self.w[k]:.3g} rad/s "
                f"mismatch {self.mismatch[k]:.3g} against {self.bound[k]:.3g}>")


def _response(plant: PlantSpec, w: np.ndarray) -> np.ndarray:
    s = 1j * w
    return np.polyval(plant.num, s) / np.polyval(plant.den, s) * np.exp(-s * plant.delay)


def check_channel_gain(setpoint: ChannelFit, acceleration: ChannelFit, gain: float, w: np.ndarray | None = None,
                       slack: float = 1.0) -> GainCheck:
    """Check on data the assumption of a setpoint channel: ``G_setpoint = K G_acceleration`` with a constant ``K``.

    A single position/velocity loop (rotorpy's SE3, a Crazyflie's Mellinger controller without its integral)
    passes a setpoint offset to the command through ``kp`` (or ``kd``) alone, so its position-channel fit is its
    acceleration-channel fit times ``K`` at every frequency. A cascade (PX4, ArduPilot: a position P over a
    velocity PID) does not: its ``K`` depends on frequency, and ``Gd = G_setpoint / K`` is wrong; such a vehicle
    learns on its acceleration channel (docs/closed_loop.md, "Identifying the channel map").

    Parameters
    ----------
    setpoint, acceleration : ChannelFit
        The same vehicle's and axis's fits on a setpoint channel and on the acceleration channel.
    gain : float
        The ``K`` assumed (> 0).
    w : array_like, optional
        Frequencies, rad/s (default: 60 log-spaced over the chirps' band, 0.05 to 2 Hz).
    slack : float
        Multiplier (> 0) of the bound the fits' uncertainty allows.

    Returns
    -------
    GainCheck

    Raises
    ------
    SpecError
        Fits of other vehicles or axes, channels other than a setpoint's and the acceleration, fits without an
        identification, a bad gain, slack or grid.
    """
    if (setpoint.name, setpoint.axis) != (acceleration.name, acceleration.axis):
        raise SpecError(f"`acceleration`: a fit of {acceleration.name!r} axis {acceleration.axis}, expected the same "
                        f"vehicle and axis as `setpoint` ({setpoint.name!r} axis {setpoint.axis})")
    if setpoint.channel == "acceleration" or acceleration.channel != "acceleration":
        raise SpecError(f"`setpoint`, `acceleration`: got channels {setpoint.channel!r} and {acceleration.channel!r}, "
                        "expected a position or velocity fit and an acceleration fit")
    for what, value in (("gain", gain), ("slack", slack)):
        if isinstance(value, bool) or not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
            raise SpecError(f"`{what}`: got {value!r}, expected a number > 0")
    if setpoint.identification is None or acceleration.identification is None:
        raise SpecError("`setpoint`, `acceleration`: both fits need their identification (covariance) for the bound")
    w = np.geomspace(2 * np.pi * _F_LOW, 2 * np.pi * _F_HIGH, 60) if w is None else np.asarray(w, float)
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w) & (w > 0)):
        raise SpecError("`w`: expected frequencies > 0 rad/s")
    ratio = _response(setpoint.plant, w) / (gain * _response(acceleration.plant, w))
    bound = slack * (setpoint.identification.bound(w, setpoint.plant.delay)
                     + acceleration.identification.bound(w, acceleration.plant.delay))
    return GainCheck(w, np.abs(ratio - 1.0), bound, float(gain))
