"""The paper's experimental pipeline on vehicles ilcdob did not model (docs/theory.md sections 4 and 6).

Any vehicle with the protocol of :mod:`ilcdob.vehicles.interface` (rotorpy's multirotors,
:mod:`ilcdob.vehicles.rotorpy_vehicle`, are the test bed) goes through what a lab does:

1. :func:`identify_vehicles`: per vehicle and axis, closed-loop flights with a rough outer loop (the
   PID alone, a chirp added to the axis's command, smoothed reference steps), fitted with each
   candidate model structure (:data:`STRUCTURES`) and held out on a second flight; the structure
   is chosen from the data (the best held-out fit; one with fewer parameters wins unless a larger
   one fits 1 point better). The paper assumes ``b0/(s^2 (s + a0))``; a vehicle whose drag damps
   its velocity needs one integrator and a drag pole.
2. :func:`run_vehicle_axes` (one axis: :func:`run_vehicle_laws`, one law: :func:`run_vehicle_scenario`):
   a scenario flown with every vehicle, no DOB, DOB only and the cyclic learning chain of
   :mod:`ilcdob.validation.reproduce` for every learning law, each learning signal computed from
   the previous flight's measured error as ``ilcdob design --trial`` does, every axis by its own
   models; the disturbance is the scenario's, either added to the command (the paper's) or a
   wind velocity through each airframe's drag (the scenario's signal scaled, or any wind such as
   :func:`dryden_gust`).

Units: s, m, m/s, m/s^2. The flights are :class:`~ilcdob.validation.simulate.Flight` records per
axis, so results, tables and figures are those of the other reproductions.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Mapping

import numpy as np
from scipy import signal as sps

from ilcdob.design.flown import DISTURBANCE_PATHS
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet, fleet_from_systems
from ilcdob.loop import LoopSystem, build_loop
from ilcdob.signals import FlightData, check_grid
from ilcdob.specs import DOBSpec, PIDSpec, PlantSpec, SystemSpec
from ilcdob.uncertainty import ModelStructure
from ilcdob.vehicles.interface import AXES, Vehicle, fly_vehicle

from .reproduce import ScenarioResult, SystemResult, check_iterations, learning_chain, pair_designs
from .scenarios import Scenario, check_order
from .simulate import Flight

__all__ = ["STRUCTURES", "VehicleFit", "identify_vehicles", "run_vehicle_axes", "run_vehicle_laws",
           "run_vehicle_scenario", "rough_loop", "dryden_gust", "MakeVehicle", "LawPath"]

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
        Held-out fit (%) of every candidate structure, by ``repr``-like label ``"3p1i"``.
    """

    name: str
    structure: ModelStructure
    plant: PlantSpec
    fits: dict[str, float]

    @property
    def fit(self) -> float:
        """Held-out fit of the chosen structure, %."""
        return self.fits[_label(self.structure)]


def _label(st: ModelStructure) -> str:
    return f"{st.n_poles}p{st.n_zeros}z{st.n_integrators}i"


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


def identify_vehicles(make: MakeVehicle, names: list[str], controllers: dict[str, PIDSpec],
                      dobs: dict[str, DOBSpec], ts: float, duration: float = 20.0,
                      axis: str = "x") -> tuple[Fleet, dict[str, VehicleFit]]:
    """Identify every vehicle's plant of one axis from its own flights and build the fleet of the fits (module
    docstring).

    Parameters
    ----------
    make : callable
        ``make(name, command_disturbance, wind, seed)``: a fresh vehicle (:data:`MakeVehicle`).
    names : list of str
        The vehicles.
    controllers, dobs : dict
        Per vehicle its PID and DOB for the fleet (the DOB's ``q_order`` raised to the chosen
        model's relative degree where it is lower, so that ``M = Q/P_hat`` is proper).
    ts : float
        Sample time, s.
    duration : float
        Length of each identification flight, s (two per vehicle: estimation and held out).
    axis : {"x", "y", "z"}
        The axis flown and identified (its chirp and steps; the others hold their start).

    Returns
    -------
    (Fleet, dict of str to VehicleFit)
        The fleet records its ``axis``.
    """
    from ilcdob.identification.tfest import tfest

    if axis not in AXES:
        raise SpecError(f"`axis`: got {axis!r}, expected one of {list(AXES)}")
    systems, fits = [], {}
    for name in names:
        est = _chirp_flight(make, name, ts, 0, duration, axis)
        val = _chirp_flight(make, name, ts, 1, duration, axis)
        results = {}
        for st in STRUCTURES:
            fit = tfest(est, "u", "y", st, validation=val)
            results[_label(st)] = (fit.fit_validation, st, PlantSpec(tuple(fit.num), tuple(fit.den), fit.delay))
        best = max(results.values(), key=lambda v: v[0])
        chosen = next(v for v in results.values() if v[0] >= best[0] - 1.0)  # fewest parameters within 1 point
        fits[name] = VehicleFit(name, chosen[1], chosen[2], {k: v[0] for k, v in results.items()})
        relative_degree = chosen[1].n_poles - chosen[1].n_zeros  # M = Q/P_hat must stay proper
        dob = dobs[name] if dobs[name].q_order >= relative_degree else replace(dobs[name], q_order=relative_degree)
        systems.append(SystemSpec(name, chosen[2], controllers[name], dob))
    return replace(fleet_from_systems(systems, ts), axis=axis), fits


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


#: A learning law flown by :func:`run_vehicle_laws`: (law, path), ``law`` of :mod:`ilcdob.design.laws`
#: (paper or exact-reference), ``path`` where it assumes the disturbance acts (:mod:`ilcdob.design.flown`).
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
        Reference (x, and y of the lateral paths; z holds the start), disturbance and learning order.
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
    pos, acc = sc.trajectory(t)
    pos[:, 2] = 0.0  # positions are measured from the start, which hovers at the path's altitude
    for i, ax in enumerate(AXES):
        if ax not in fleets:  # as the paper's x-only flights: axes not learned hold the start
            pos[:, i] = acc[:, i] = 0.0
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

    def flight(name: str, mode: str, k: int, d_f: dict | None = None) -> dict[str, Flight]:
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

    base = {name: (flight(name, "no_dob", 0), flight(name, "dob", 1)) for name in order}
    out: dict[LawPath, dict[str, ScenarioResult]] = {}
    for law, path in laws:
        designs = {ax: pair_designs(fleets[ax], {}, law, pos[:, AXES.index(ax)], acc[:, AXES.index(ax)], "auto", path)
                   for ax in axes}
        count = {name: 2 for name in order}  # after the two baseline flights

        def step(src: str, tgt: str, prev: dict[str, Flight]) -> dict[str, Flight]:
            count[tgt] += 1
            d_f = {ax: designs[ax](src, tgt).learning(prev[ax].e, prev[ax].d_f).d_f for ax in axes}
            return flight(tgt, "dob", count[tgt] - 1, d_f)

        learning, chain = learning_chain(order, iterations, base[order[0]][1], step)
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
        Where the learning law assumes the disturbance acts (:mod:`ilcdob.design.flown`).
    law : str
        Learning law (paper or exact-reference).

    Returns
    -------
    ScenarioResult
    """
    return run_vehicle_laws(fleet, make, sc, iterations, laws=[(law, path)], wind=wind, order=order)[(law, path)]
