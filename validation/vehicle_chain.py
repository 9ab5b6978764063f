"""The paper's experimental pipeline on vehicles ilcdob did not model (docs/theory.md sections 4 and 6).

Any vehicle with the protocol of :mod:`ilcdob.vehicles.interface` (rotorpy's multirotors,
:mod:`ilcdob.vehicles.rotorpy_vehicle`, are the test bed) goes through what a lab does:

1. :func:`identify_vehicles`: every vehicle's experiments flown and fitted, and the fleet of the fits
   built (the one way ilcdob identifies a fleet of vehicles; the experiments are a
   :class:`VehicleExperiments`). By default (:class:`ChirpExperiments`), per vehicle and axis,
   closed-loop flights with a rough outer loop (the PID alone, a chirp added to the axis's command,
   smoothed reference steps), fitted with each candidate model structure (:data:`STRUCTURES`) and
   held out on a second flight; the structure is chosen from the data (the best held-out fit; one
   with fewer parameters wins unless a larger one fits 1 point better). The paper assumes
   ``b0/(s^2 (s + a0))``; a vehicle whose drag damps its velocity needs one integrator and a drag
   pole. The in-house quadrotors fly the paper's step and chirp experiments instead
   (:class:`ilcdob.validation.nonlinear.StepChirpExperiments`).
2. :func:`run_vehicle_axes` (one axis: :func:`run_vehicle_laws`, one law: :func:`run_vehicle_scenario`):
   a scenario flown with every vehicle, no DOB, DOB only and the cyclic learning chain of
   :mod:`ilcdob.validation.reproduce` for every learning law (:func:`fly_baselines`,
   :func:`fly_learning`), each learning signal computed from the previous flight's measured error as
   ``ilcdob design --trial`` does, every axis by its own models; the disturbance is the scenario's,
   either added to the command (the paper's) or a wind velocity through each airframe's drag (the
   scenario's signal scaled, or any wind such as :func:`dryden_gust`). The nonlinear reproduction
   (:mod:`ilcdob.validation.nonlinear`) flies its chain through the same two functions and
   :func:`~ilcdob.vehicles.interface.fly_vehicle`.

Units: s, m, m/s, m/s^2. The flights are :class:`~ilcdob.validation.simulate.Flight` records per
axis, so results, tables and figures are those of the other reproductions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Protocol, Sequence, runtime_checkable

import numpy as np
from scipy import signal as sps

from ilcdob.design.maps.flown import DISTURBANCE_PATHS
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet, fleet_from_systems
from ilcdob.loop import LoopSystem, build_loop
from ilcdob.signals import FlightData, check_grid
from ilcdob.specs import DOBSpec, IdentificationSpec, PIDSpec, PlantSpec, SystemSpec
from ilcdob.uncertainty import ModelStructure
from ilcdob.vehicles.interface import AXES, Vehicle, fly_vehicle

from .reproduce import ScenarioResult, SystemResult, check_iterations, learning_chain, pair_designs
from .scenarios import Scenario, check_order
from .simulate import Flight

__all__ = ["STRUCTURES", "VehicleFit", "VehicleExperiments", "ChirpExperiments", "identify_vehicles",
           "fly_baselines", "fly_learning", "fit_candidates", "Candidate", "vehicle_reference", "run_vehicle_axes", "run_vehicle_laws",
           "run_vehicle_scenario",
           "rough_loop", "dryden_gust", "MakeVehicle", "FlyTrial", "LawPath"]

#: Candidate structures of an axis's plant, fewest free parameters first: the paper's two integrators and a pole
#: (2: gain and pole), one integrator with a drag pole and an attitude pole (3), and with one pole more (4).
STRUCTURES = (ModelStructure(n_poles=3, n_integrators=2), ModelStructure(n_poles=3, n_integrators=1),
              ModelStructure(n_poles=4, n_integrators=1))
#: ``make(name, command_disturbance, wind, seed) -> Vehicle``: a fresh vehicle (at rest) with these disturbances,
#: each a callable of time returning ``(3,)`` (m/s^2 on the command; m/s of wind) or None, and ``seed`` for its
#: sensor noise (every flight gets its own).
MakeVehicle = Callable[[str, Callable | None, Callable | None, int], Vehicle]


@dataclass(frozen=True)
class VehicleFit:
    """The identification of one vehicle.

    Attributes
    ----------
    name : str
    structure : ModelStructure
        The structure chosen.
    plant : PlantSpec
        Its fit.
    fits : dict of str to float
        Held-out fit (%) of every candidate structure, by label (:meth:`label`, e.g. ``"3p0z1i"``).
    fit_estimation : float
        Fit (%) of the chosen structure on the estimation flights (nan: not known).
    identification : IdentificationSpec or None
        What the fleet file keeps of the fit (parameters, covariance, fits: the Delta set of
        docs/theory.md section 3); None: the fleet keeps the plant alone.
    record : object
        What the experiments keep of their flights and fit (the in-house quadrotors':
        :class:`~ilcdob.identification.fleet_id.VehicleIdentification`); None: nothing.
    """

    name: str
    structure: ModelStructure
    plant: PlantSpec
    fits: dict[str, float]
    fit_estimation: float = math.nan
    identification: IdentificationSpec | None = None
    record: object = field(default=None, repr=False, compare=False)

    @property
    def fit(self) -> float:
        """Held-out fit of the chosen structure, %."""
        return self.fits[self.label(self.structure)]

    @staticmethod
    def label(st: ModelStructure) -> str:
        """The label of a structure in :attr:`fits`.

        Parameters
        ----------
        st : ModelStructure

        Returns
        -------
        str
            ``"<poles>p<zeros>z<integrators>i"``.
        """
        return f"{st.n_poles}p{st.n_zeros}z{st.n_integrators}i"


@runtime_checkable
class VehicleExperiments(Protocol):
    """How :func:`identify_vehicles` identifies a vehicle: its experiments flown and fitted.

    A structural type (:class:`ChirpExperiments`; the in-house quadrotors'
    :class:`~ilcdob.validation.nonlinear.StepChirpExperiments`).

    Parameters
    ----------
    *args, **kwargs
        None: a protocol is not instantiated.

    Attributes
    ----------
    axis : str
        The axis identified (``"x"``, ``"y"`` or ``"z"``): the fleet's.
    """

    axis: str

    def fit(self, name: str, index: int) -> VehicleFit:
        """Fly a vehicle's experiments and fit its plant.

        Parameters
        ----------
        name : str
            The vehicle.
        index : int
            Its place among the vehicles identified (for seeds).

        Returns
        -------
        VehicleFit
        """


def rough_loop(ts: float) -> LoopSystem:
    """The outer loop flown before a vehicle is identified: PID and DOB of a rough model 1/(s^2 (0.1 s + 1))
    (a multirotor's attitude loop lags 0.1-0.2 s); the identification flights fly its PID alone.

    Parameters
    ----------
    ts : float
        Sample time, s.

    Returns
    -------
    LoopSystem
    """
    spec = SystemSpec("rough", PlantSpec((1.0,), (0.1, 1.0, 0.0, 0.0)), PIDSpec(2.5, 0.3, 2.2, 0.05), DOBSpec(3, 0.2))
    return build_loop(spec, ts)


def _chirp_flight(make: MakeVehicle, name: str, ts: float, seed: int, duration: float, axis: str = "x") -> FlightData:
    loop = rough_loop(ts)  # checks ts
    check_grid(duration, ts, f"the chirp flight of {name}")
    n = int(round(duration / ts))
    t = np.arange(n) * ts
    inj = 0.5 * np.sin(2 * np.pi * (0.1 * t + (3.0 - 0.1) * t**2 / (2 * duration)))  # 0.1 -> 3 Hz
    # reference steps of 5 cm through a critically damped 0.3 s filter: a raw step kicks the PID's derivative
    # into multi-g commands that tilt and drop the heavier vehicles (px4: 15 cm in z), far from hover
    b, a = sps.bilinear([1.0], [0.09, 0.6, 1.0], 1.0 / ts)
    r = sps.lfilter(b, a, 0.05 * np.sign(np.sin(2 * np.pi * t / 10 + seed)))
    trial = fly_vehicle(make(name, None, None, seed), {"x": loop, "y": loop, "z": loop}, {axis: r},
                        feedforward={axis: inj}, dob=False)
    i = AXES.index(axis)
    return FlightData(t, {"u": trial.applied[:, i], "y": trial.y_meas[:, i]}, {"u": "m/s^2", "y": "m"})


@dataclass(frozen=True)
class ChirpExperiments:
    """The experiments of a vehicle nobody modelled (module docstring, step 1): two closed-loop flights of
    ``duration`` under :func:`rough_loop`'s PID (a chirp on ``axis``'s command, smoothed reference steps;
    seeds 0 and 1: estimation and held out), every structure of :data:`STRUCTURES` fitted and the one with
    the best held-out fit chosen (fewest parameters within 1 point).

    Attributes
    ----------
    make : callable
        ``make(name, command_disturbance, wind, seed)``: a fresh vehicle (:data:`MakeVehicle`).
    ts : float
        Sample time, s.
    duration : float
        Length of each flight, s.
    axis : {"x", "y", "z"}
        The axis flown and identified (its chirp and steps; the others hold their start).
    """

    make: MakeVehicle
    ts: float
    duration: float = 20.0
    axis: str = "x"

    def __post_init__(self) -> None:
        if self.axis not in AXES:
            raise SpecError(f"`axis`: got {self.axis!r}, expected one of {list(AXES)}")

    def fit(self, name: str, index: int) -> VehicleFit:
        """Both flights of a vehicle and the fit of every structure.

        Parameters
        ----------
        name : str
            Passed to ``make``.
        index : int
            Not used: every vehicle flies seeds 0 (estimation) and 1 (held out).

        Returns
        -------
        VehicleFit
            The structure with the best held-out fit (fewest parameters within 1 point).
        """
        est = _chirp_flight(self.make, name, self.ts, 0, self.duration, self.axis)
        val = _chirp_flight(self.make, name, self.ts, 1, self.duration, self.axis)
        candidates, chosen = fit_candidates(est, val, STRUCTURES)
        return VehicleFit(name, chosen.structure, chosen.plant,
                          {VehicleFit.label(c.structure): c.fit_validation for c in candidates}, chosen.fit_estimation)


@dataclass(frozen=True)
class Candidate:
    """One candidate structure fitted to a vehicle's flights (:func:`fit_candidates`).

    Attributes
    ----------
    structure : ModelStructure
    plant : PlantSpec
        Its fit ``u -> y``.
    fit_estimation, fit_validation : float
        Fit (%) on the estimation and on the held-out flight.
    identification : IdentificationSpec or None
        Its parameters and their covariance (the model's Delta set, :class:`~ilcdob.specs.IdentificationSpec`).
    """

    structure: ModelStructure
    plant: PlantSpec
    fit_estimation: float
    fit_validation: float
    identification: IdentificationSpec | None = None


def fit_candidates(est: FlightData, val: FlightData, structures: Sequence[ModelStructure],
                   zero_at_origin: bool = False) -> tuple[list[Candidate], Candidate]:
    """Fit every candidate structure to ``est`` (``u -> y``, output error), score it on ``val`` and choose one:
    the best held-out fit, a structure with fewer parameters winning unless a larger one fits 1 point better.

    Parameters
    ----------
    est, val : FlightData
        Estimation and held-out flights, signals ``u`` and ``y``.
    structures : sequence of ModelStructure
        Candidates, fewest parameters first (at least one).
    zero_at_origin : bool
        Fix one zero of every candidate at s = 0 (:func:`ilcdob.identification.origin_zero.with_zero_at_origin`):
        the candidates without a zero, with an integrator, or whose data refuse it are left out.

    Returns
    -------
    (list of Candidate, Candidate)
        Every candidate kept, in ``structures``' order, and the one chosen.

    Raises
    ------
    SpecError
        With ``zero_at_origin``, no candidate left.
    """
    from ilcdob.identification.origin_zero import with_zero_at_origin
    from ilcdob.identification.tfest import tfest

    candidates = []
    for st in structures:
        if zero_at_origin and (st.n_zeros < 1 or st.n_integrators):
            continue
        fit = tfest(est, "u", "y", st, validation=val)
        if zero_at_origin:
            try:
                fit = with_zero_at_origin(fit, [est], [val])
            except SpecError:
                continue
        candidates.append(Candidate(st, PlantSpec(tuple(fit.num), tuple(fit.den), fit.delay), fit.fit_estimation,
                                    fit.fit_validation, fit.identification_spec(f"{est.source}; held out: {val.source}")))
    if not candidates:
        raise SpecError(f"{est.source}: no candidate structure has a zero at s = 0 that the data allow (a zero, no "
                        "integrator, the fitted b0 within 5 standard deviations of 0): the loop does not integrate")
    best = max(c.fit_validation for c in candidates)
    return candidates, next(c for c in candidates if c.fit_validation >= best - 1.0)


def identify_vehicles(make: MakeVehicle | VehicleExperiments, names: Sequence[str],
                      controllers: Mapping[str, PIDSpec] | None, dobs: Mapping[str, DOBSpec] | None, ts: float,
                      duration: float | None = None, axis: str | None = None, *, base: Fleet | None = None,
                      progress: Callable[[int, int, str], None] | None = None,
                      source: str = "<memory>") -> tuple[Fleet, dict[str, VehicleFit]]:
    """Identify every vehicle's plant of one axis from its own flights and build the fleet of the fits (module
    docstring): the one way ilcdob identifies a fleet of vehicles, whatever flies the experiments.

    Per vehicle, in ``names``' order: its experiments' fit (:meth:`VehicleExperiments.fit`), then its system:
    the fitted plant as the plant (no separate model) and the fit's ``identification``, its PID and DOB (the
    DOB's ``q_order`` raised to the fitted model's relative degree where it is lower, so that ``M = Q/P_hat``
    is proper), everything else ``base``'s.

    Parameters
    ----------
    make : callable or VehicleExperiments
        The experiments; a :data:`MakeVehicle` ``make(name, command_disturbance, wind, seed)`` flies
        :class:`ChirpExperiments` with it.
    names : list of str
        The vehicles.
    controllers, dobs : dict or None
        Per vehicle its PID and DOB for the fleet (None: ``base``'s).
    ts : float
        Sample time, s.
    duration : float, optional
        With a ``MakeVehicle``: the length of each identification flight, s (default 20; two per vehicle:
        estimation and held out).
    axis : {"x", "y", "z"}, optional
        With a ``MakeVehicle``: the axis flown and identified (default ``"x"``). Experiments carry their own.
    base : Fleet, optional
        Supplies each system's noise, stated uncertainty, limits and sensor (default: none of them).
    progress : callable, optional
        ``progress(done, total, what)`` after each vehicle; None (default): silent.
    source : str
        The fleet's ``source`` (names it in messages).

    Returns
    -------
    (Fleet, dict of str to VehicleFit)
        The fleet records its ``axis``.
    """
    if isinstance(make, VehicleExperiments):
        if duration is not None or axis is not None:
            raise SpecError("`duration`, `axis`: given with experiments, which carry their own; pass a MakeVehicle "
                            "for the chirp experiments of that duration and axis")
        experiments = make
    else:
        experiments = ChirpExperiments(make, ts, 20.0 if duration is None else duration, axis or "x")
    if controllers is None or dobs is None:
        if base is None:
            raise SpecError("`controllers`, `dobs`: got None without a `base` fleet to take them from")
        given = {s.name: s for s in base.systems}
        controllers = controllers if controllers is not None else {n: given[n].controller for n in names}
        dobs = dobs if dobs is not None else {n: given[n].dob for n in names}
    kept = {s.name: s for s in base.systems} if base is not None else {}
    say = progress if progress is not None else (lambda done, total, what: None)
    systems, fits = [], {}
    for i, name in enumerate(names):
        fit = experiments.fit(name, i)
        relative_degree = fit.structure.n_poles - fit.structure.n_zeros  # M = Q/P_hat must stay proper
        dob = dobs[name] if dobs[name].q_order >= relative_degree else replace(dobs[name], q_order=relative_degree)
        if name in kept:
            systems.append(replace(kept[name], plant=fit.plant, controller=controllers[name], dob=dob, model=None,
                                   identification=fit.identification))
        else:
            systems.append(SystemSpec(name, fit.plant, controllers[name], dob, identification=fit.identification))
        fits[name] = fit
        estimation = "" if math.isnan(fit.fit_estimation) else f"{fit.fit_estimation:.2f} % (estimation), "
        say(i + 1, len(names), f"identified {name}: fit {estimation}{fit.fit:.2f} % (held out)")
    return replace(fleet_from_systems(systems, ts, source), axis=experiments.axis), fits


def dryden_gust(duration: float, ts: float, wind_20ft: float = 2.0, altitude: float = 1.0, seed: int = 0,
                onset: float = 5.0) -> Callable[[float], np.ndarray]:
    """A repeatable Dryden wind that rises from still air: MIL-F-8785C low-altitude turbulence
    (:meth:`~ilcdob.vehicles.dryden.DrydenWind.low_altitude`) around a mean wind along x, faded in
    over ``onset`` s by a raised cosine so that each trial starts hovering in still air.

    Parameters
    ----------
    duration, ts : float
        Length and sample time of the series, s.
    wind_20ft : float
        Mean wind at 20 ft, m/s (the model's intensities scale with it).
    altitude : float
        Height of the flight, m.
    seed : int
        Seed of the turbulence: the same seed is the same wind in every trial.
    onset : float
        Fade-in time, s (> 0).

    Returns
    -------
    callable
        ``wind(t) -> (3,)`` m/s, world frame.
    """
    from ilcdob.vehicles.dryden import DrydenWind

    if not (np.isfinite(onset) and onset > 0):
        raise SpecError(f"`onset`: got {onset!r}, expected a fade-in time > 0 s")
    field = DrydenWind.low_altitude(duration, ts, altitude, wind_20ft, seed=seed)
    t = np.arange(field.series.shape[0]) * ts
    field.series *= (0.5 - 0.5 * np.cos(np.pi * np.clip(t / onset, 0.0, 1.0)))[:, None]
    return field


#: ``flight(name, mode, k, d_f) -> flight record``: flight ``k`` of vehicle ``name`` in a scenario (0: no DOB,
#: 1: DOB only, 2, 3, ...: its learning flights, in :func:`fly_learning`'s order), ``mode`` ``"no_dob"`` or
#: ``"dob"``, ``d_f`` its learning signal (None for the first two).
FlyTrial = Callable[[str, str, int, object], object]


def fly_baselines(order: Sequence[str], flight: FlyTrial) -> dict[str, tuple[object, object]]:
    """Every vehicle's flights without DOB (flight 0) and with the DOB only (flight 1), in ``order``.

    Parameters
    ----------
    order : list of str
        The vehicles, in learning order.
    flight : callable
        :data:`FlyTrial`.

    Returns
    -------
    dict of str to (record, record)
        Per vehicle ``(no_dob, dob)``.
    """
    return {name: (flight(name, "no_dob", 0, None), flight(name, "dob", 1, None)) for name in order}


def fly_learning(order: Sequence[str], iterations: int, base: Mapping[str, tuple[object, object]], flight: FlyTrial,
                 signal: Callable[[str, str, object], object]) -> tuple[dict[str, list], list[tuple[str, str]]]:
    """The learning chain of :mod:`ilcdob.validation.reproduce` around ``order``, from the first vehicle's DOB-only
    flight in ``base``: each flight flies ``signal(source, target, previous_flight)``, a vehicle's ``j``-th
    learning flight being its flight ``j + 1`` (:data:`FlyTrial`).

    Parameters
    ----------
    order : list of str
        The vehicles, in learning order.
    iterations : int
        Learning flights per vehicle.
    base : mapping
        :func:`fly_baselines`' flights.
    flight : callable
        :data:`FlyTrial`.
    signal : callable
        ``signal(source, target, previous) -> d_f``: the learning signal the target flies.

    Returns
    -------
    learning : dict of str to list
        Each vehicle's learning flights, in order.
    chain : list of (str, str)
        (source, target) of every step.
    """
    count = {name: 1 for name in order}  # the last flight of each: its DOB-only one

    def step(src: str, tgt: str, prev: object) -> object:
        count[tgt] += 1
        return flight(tgt, "dob", count[tgt], signal(src, tgt, prev))

    return learning_chain(list(order), iterations, base[order[0]][1], step)


def vehicle_reference(sc: Scenario, t: np.ndarray, axes: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """The reference a vehicle flies in a scenario: the path from where the vehicle starts.

    A vehicle starts each trial hovering at rest at the path's altitude, its position measured from there
    (:mod:`ilcdob.vehicles.interface`), so the path is shifted to start at 0 on x and y (the diamond's y
    starts at -1 m: unshifted, every flight would begin with a 1 m step) and z holds the start.

    Parameters
    ----------
    sc : Scenario
    t : numpy.ndarray
        Sample times, s.
    axes : list of str
        The axes learned; the others hold the start (reference 0), as in the paper's x-only flights.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        Position (m) and acceleration (m/s^2), ``len(t) x 3``.
    """
    pos, acc = sc.trajectory(t)
    pos[:, 2] = 0.0
    pos[:, :2] -= pos[0, :2]
    for i, ax in enumerate(AXES):
        if ax not in axes:
            pos[:, i] = acc[:, i] = 0.0
    return pos, acc


#: A learning law flown by :func:`run_vehicle_laws`: (law, path), ``law`` of :mod:`ilcdob.design.law.laws`
#: (paper or exact-reference), ``path`` where it assumes the disturbance acts (:mod:`ilcdob.design.maps.flown`).
LawPath = tuple[str, str]


def run_vehicle_axes(fleets: Mapping[str, Fleet], make: MakeVehicle, sc: Scenario, iterations: int = 3, *,
                     laws: list[LawPath] = (("paper", "command"),), wind: float | Callable | None = None,
                     order: list[str] | None = None) -> dict[LawPath, dict[str, ScenarioResult]]:
    """Fly one scenario with every vehicle, learning every axis of ``fleets`` independently: no DOB and DOB only
    once, then ``iterations`` learning flights each with every learning law (module docstring).

    The axes share the flights: each learning flight flies every axis's learning signal, each computed by that
    axis's pair design from the previous flight's error on the axis. Axes without a fleet hold the start
    (reference 0) with the PID and DOB of the first fleet's loop and learn nothing.

    Parameters
    ----------
    fleets : mapping of str to Fleet
        Axis (``"x"``, ``"y"``, ``"z"``) -> the identified models of that axis (:func:`identify_vehicles`),
        the same vehicle names in each.
    make : callable
        ``make(name, command_disturbance, wind, seed)`` (:data:`MakeVehicle`); flight ``k`` of a vehicle
        in the scenario flies with seed ``1000 sc.id + 10 k`` plus its position in the fleet (sensor noise:
        the laws' learning flights meet the same noise).
    sc : Scenario
        Reference (x, and y of the lateral paths, both from the start: the path is flown from where the vehicle
        starts; z holds the start), disturbance and learning order.
    iterations : int
        Learning flights per vehicle and law (>= 1).
    laws : list of (str, str)
        The (law, path) pairs to fly (:data:`LawPath`).
    wind : float or callable, optional
        None: the scenario's disturbance is added to every vehicle's x command (the paper's). A
        number: it is a wind velocity along x instead, ``wind`` m/s per m/s^2 of the scenario's
        disturbance. A callable ``t -> (3,)``: this wind velocity (m/s), e.g. :func:`dryden_gust`.
        Winds act through each airframe's drag.
    order : list of str, optional
        Learning order (default: the scenario's).

    Returns
    -------
    dict of (str, str) to dict of str to ScenarioResult
        Per law and axis, the flights of that axis as :class:`~ilcdob.validation.simulate.Flight` (``d``:
        the command disturbance, the scenario's disturbance a scaled wind was made from, or the wind's
        component in m/s); the no-DOB and DOB-only flights are shared by the laws.
    """
    check_iterations(iterations)
    axes = [ax for ax in AXES if ax in fleets]
    if not axes or len(axes) != len(fleets):
        raise SpecError(f"`fleets`: got axes {list(fleets)}, expected a mapping with keys from {list(AXES)}")
    first = fleets[axes[0]]
    if any(fleets[ax].names != first.names or fleets[ax].sample_time != first.sample_time for ax in axes):
        raise SpecError("`fleets`: every axis needs the same vehicles and sample time")
    laws = [tuple(lp) for lp in laws]
    for law, path in laws:
        if law not in ("paper", "exact-reference") or path not in DISTURBANCE_PATHS:
            raise SpecError(f"`laws`: got ({law!r}, {path!r}), expected a law 'paper' or 'exact-reference' and a "
                            f"path of {DISTURBANCE_PATHS}")
    ts = first.sample_time
    t = sc.time(ts)
    pos, acc = vehicle_reference(sc, t, list(fleets))
    order = sc.order(first.names) if order is None else check_order(first.names, order)

    def along_x(scale: float) -> Callable:
        return lambda tt: np.array([scale * float(sc.disturbance(np.array([tt]))[0]), 0.0, 0.0])

    d = np.zeros((t.size, 3))
    d[:, 0] = sc.disturbance(t)  # the command disturbance, or the signal a scaled wind is made from
    if wind is None:
        command, air = along_x(1.0), None
    elif callable(wind):
        command, air = None, wind
        d = np.array([np.asarray(wind(tt), float).reshape(-1)[:3] for tt in t])
    elif isinstance(wind, (int, float)) and not isinstance(wind, bool) and np.isfinite(wind):
        command, air = None, along_x(float(wind))
    else:
        raise SpecError(f"`wind`: got {wind!r}, expected None, a gain in m/s per m/s^2 or a callable t -> (3,) m/s")

    def flight(name: str, mode: str, k: int, d_f: dict | None) -> dict[str, Flight]:
        """Flight ``k`` of a vehicle in the scenario (its seed; the laws' learning flights share them)."""
        loops = {ax: fleets.get(ax, first).loop(name) for ax in AXES}
        ff = {ax: acc[:, i] for i, ax in enumerate(AXES) if loops[ax].spec.controller.acceleration_feedforward}
        seed = 1000 * sc.id + 10 * k + first.names.index(name)
        trial = fly_vehicle(make(name, command, air, seed), loops, pos, learning=d_f, feedforward=ff or None,
                            dob=mode == "dob")
        return {ax: Flight(system=name, mode=mode, t=t, r=pos[:, i], y=trial.y_meas[:, i],
                           e=pos[:, i] - trial.y_meas[:, i], d=d[:, i], d_hat=trial.d_hat[:, i],
                           d_f=trial.d_f[:, i], u2=trial.command[:, i])
                for i, ax in enumerate(AXES) if ax in fleets}

    base = fly_baselines(order, flight)
    out: dict[LawPath, dict[str, ScenarioResult]] = {}
    for law, path in laws:
        designs = {ax: pair_designs(fleets[ax], {}, law, pos[:, AXES.index(ax)], acc[:, AXES.index(ax)], "auto", path)
                   for ax in axes}

        def signal(src: str, tgt: str, prev: dict[str, Flight]) -> dict[str, np.ndarray]:
            return {ax: designs[ax](src, tgt).learning(prev[ax].e, prev[ax].d_f).d_f for ax in axes}

        learning, chain = fly_learning(order, iterations, base, flight, signal)
        out[(law, path)] = {ax: ScenarioResult(scenario=sc, order=order, chain=chain, systems={
            name: SystemResult(base[name][0][ax], base[name][1][ax], tuple(f[ax] for f in learning[name]))
            for name in order}) for ax in axes}
    return out


def run_vehicle_laws(fleet: Fleet, make: MakeVehicle, sc: Scenario, iterations: int = 3, *,
                     laws: list[LawPath] = (("paper", "command"),), wind: float | Callable | None = None,
                     order: list[str] | None = None) -> dict[LawPath, ScenarioResult]:
    """One axis's flights of :func:`run_vehicle_axes` (the fleet's ``axis``; the paper's x by default).

    Parameters
    ----------
    fleet : Fleet
        The identified models of one axis.
    make, sc, iterations, laws, wind, order
        As in :func:`run_vehicle_axes`.

    Returns
    -------
    dict of (str, str) to ScenarioResult
    """
    res = run_vehicle_axes({fleet.axis: fleet}, make, sc, iterations, laws=laws, wind=wind, order=order)
    return {lp: per_axis[fleet.axis] for lp, per_axis in res.items()}


def run_vehicle_scenario(fleet: Fleet, make: MakeVehicle, sc: Scenario, iterations: int = 3, *,
                         wind: float | Callable | None = None, path: str = "command", law: str = "paper",
                         order: list[str] | None = None) -> ScenarioResult:
    """Fly one scenario with one learning law: :func:`run_vehicle_laws` with ``laws=[(law, path)]``.

    Parameters
    ----------
    fleet, make, sc, iterations, wind, order
        As in :func:`run_vehicle_laws`.
    path : {"command", "airframe", "wind"}
        Where the learning law assumes the disturbance acts (:mod:`ilcdob.design.maps.flown`).
    law : str
        Learning law (paper or exact-reference).

    Returns
    -------
    ScenarioResult
    """
    return run_vehicle_laws(fleet, make, sc, iterations, laws=[(law, path)], wind=wind, order=order)[(law, path)]
