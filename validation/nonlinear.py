"""The paper's validation flown on the nonlinear 6-DOF quadrotors, with identified models.

The paper validates twice: in simulation with exact models and in flight, where the
models are identified and therefore wrong. This module gives the second kind of evidence
without hardware: the nonlinear vehicles of :mod:`ilcdob.vehicles.quadrotor` are the
"real vehicles" and the pipeline is the paper's (Sec. IV):

1. fly step and chirp experiments with every vehicle and identify its plant
   ``P_hat(s) = b0 / (s^2 (s + a0))`` (:class:`StepChirpExperiments`, through the fleet
   identification of every vehicle, :func:`ilcdob.validation.vehicle_chain.identify_vehicles`);
2. build every loop (PID ``C``, ``Q``, ``M = Q/P_hat``) and the closed-form learning filters
   of the Theorem (paper Sec. III, :func:`ilcdob.design.closed_form_filters`) from the
   identified models;
3. fly the four scenarios with no DOB, only DOB and learning iterations 1..n, passed around
   the fleet cyclically as in :mod:`ilcdob.validation.reproduce` (the chain of
   :mod:`ilcdob.validation.vehicle_chain`: :func:`~ilcdob.validation.vehicle_chain.fly_baselines`,
   :func:`~ilcdob.validation.vehicle_chain.fly_learning`).

Each vehicle is a :class:`~ilcdob.vehicles.quadrotor_vehicle.QuadrotorVehicle` flown by
:func:`~ilcdob.vehicles.interface.fly_vehicle`, as rotorpy's multirotors are. The outer loop of one
vehicle (x axis, the loop of paper Sec. II), at the flight computer's rate ``Ts`` (the fleet's sample
time), is the same control law as the linear loop's (:class:`ilcdob.controller.OuterLoopController`
over ``C``, ``Q``, ``M``) stepped sample by sample with the nonlinear vehicle in between::

    x_m[k]   = x(t_k) + n[k]                       (position sensor, white noise n)
    u1[k]    = C{r - x_m}[k] + a_ref[k]            (a_ref if the PID feeds it forward)
    d_hat[k] = M{x_m}[k] - Q{u2}[k]                (DOB)
    u2[k]    = u1[k] - d_hat[k] - d_f[k]           held over [t_k, t_k + Ts)

``u2`` is the vehicle's commanded x acceleration and nothing else: the wind ``d(t)`` and the
vehicle's own noise (:class:`ilcdob.specs.NoiseSpec`) act on the airframe as an external
force ``m d(t)``, evaluated at the vehicle's inner (integration) rate; the vehicle limits the
command's tilt and the DOB sees the command it applied. y and z are held at 0 by their own
PIDs alone (no DOB), as in :func:`~ilcdob.vehicles.quadrotor.fly`. Every trial starts
from hover at rest at the origin with every controller state at zero, which is consistent:
each scenario starts with ``r = 0``, ``dr/dt = 0`` and ``d = 0``.

Tracking error and RMSE are those of the *true* position (``e = r - x``); the controller,
the DOB and the learning only see the measured position ``x_m``, as on a real vehicle.

Each learning flight flies the signal that ``ilcdob design`` computes from the previous
flight's *measured* error (:meth:`ilcdob.design.pair.PairDesign.learning`): the learning law
``law`` through the learning band chosen from that trial (:mod:`ilcdob.design.filters.band`), with the
airframe correction for wind on the rigid body (:mod:`ilcdob.design.maps.flown`) and the learning
vehicle's acceleration limit (:mod:`ilcdob.design.law.limit`).

Disturbance estimate against the truth: ``d_hat + d_f`` is a command-side signal (what
the vehicle must be commanded to cancel the wind), the true disturbance is the airframe's
acceleration ``d``. They are compared as airframe accelerations, the estimate passed
through the model's attitude chain: ``rmse(A_hat{d_hat + d_f} - d)``
(:attr:`NonlinearFlight.rmse_dhat`).
"""

from __future__ import annotations

import math
import time
import tomllib
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import signal as sps

from ilcdob.design.filters.band import check_bandwidth
from ilcdob.design.maps.flown import model_attitude
from ilcdob.design.law.laws import DEFAULT_LAW, check_law
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet, default_fleet, fleet_from_dict
from ilcdob.fleet_io import fleet_to_toml
from ilcdob.identification.fleet_id import VehicleIdentification, identified_systems, identify_vehicle
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal
from ilcdob.specs import check_noise_std
from ilcdob.vehicles.interface import fly_vehicle
from ilcdob.vehicles.quadrotor import QuadrotorParams, table_i_vehicles
from ilcdob.vehicles.quadrotor_vehicle import QuadrotorVehicle

from .reproduce import (FLIGHT_ARRAYS, ReproductionResult, ScenarioResult, SystemResult, check_flights_memory,
                        check_iterations, pair_designs)
from .scenarios import Scenario, check_order, scenario
from .simulate import Flight, rmse
from .vehicle_chain import VehicleFit, fly_baselines, fly_learning, identify_vehicles

__all__ = ["NonlinearSettings", "NonlinearFlight", "NonlinearReproduction", "StepChirpExperiments", "fly_loop",
           "run_nonlinear_scenario", "reproduce_nonlinear"]


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
    bandwidth : "auto", float or None
        The learning band's corner (:mod:`ilcdob.design.filters.band`): ``"auto"`` (default) chooses
        it from each trial learned from, a number states it in rad/s, ``None`` flies the
        Theorem's filters unfiltered.
    airframe_disturbance : bool
        Learn with the wind's true path (it acts on the airframe): the correction
        ``W = A_hat_{j-1}/A_hat_j`` of :func:`~ilcdob.design.maps.flown.airframe_path_filter`
        (default). ``False`` flies the paper's law as is, which assumes the wind at the
        command input.
    learning_gain : float
        ``gamma`` in (0, 1]: the share of the newly reconstructed error learned per flight
        (:meth:`~ilcdob.design.pair.PairDesign.learning`). 1 (default) is the Theorem's law,
        which reaches its fixed point in one pass; a smaller gain changes the path to the
        same floor, not the floor.
    inner_rate_hz : float
        Integration and inner-loop rate of the vehicles, Hz (a multiple of ``1/Ts``).
    """

    sensor_noise_std: float = 0.0005
    seed: int = 0
    identify: bool = True
    bandwidth: object = "auto"
    airframe_disturbance: bool = True
    learning_gain: float = 1.0
    inner_rate_hz: float = 500.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensor_noise_std", check_noise_std(self.sensor_noise_std, "sensor_noise_std"))
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise SpecError(f"`seed`: got {self.seed!r}, expected an integer >= 0")
        if not isinstance(self.airframe_disturbance, bool):
            raise SpecError(f"`airframe_disturbance`: got {self.airframe_disturbance!r}, expected True or False")
        if not isinstance(self.identify, bool):
            raise SpecError(f"`identify`: got {self.identify!r}, expected True or False")
        object.__setattr__(self, "bandwidth", check_bandwidth(self.bandwidth, None, "bandwidth"))
        g = self.learning_gain
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not (0.0 < g <= 1.0):
            raise SpecError(f"`learning_gain`: got {g!r}, expected a number in (0, 1]")
        object.__setattr__(self, "learning_gain", float(g))
        r = self.inner_rate_hz
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not (math.isfinite(r) and r >= 50):
            raise SpecError(f"`inner_rate_hz`: got {r!r}, expected a rate >= 50 Hz")

    def to_dict(self) -> dict[str, object]:
        """The settings as plain JSON types (the ``settings`` of a report)."""
        return {"sensor_noise_std_m": self.sensor_noise_std, "seed": int(self.seed),
                "identify": self.identify,
                "bandwidth_rad_s": self.bandwidth,
                "airframe_disturbance": self.airframe_disturbance, "learning_gain": self.learning_gain,
                "inner_rate_hz": self.inner_rate_hz}


@dataclass(frozen=True)
class NonlinearFlight(Flight):
    """One trial of a nonlinear vehicle: a :class:`~ilcdob.validation.simulate.Flight` whose
    ``y``/``e`` are the *true* position and error and ``d`` the disturbance as it acts on the
    airframe (force / mass, wind + the vehicle's noise), plus what the flight computer saw.

    Attributes
    ----------
    system, mode, t, r, d_hat, d_f, u2
        As in :class:`~ilcdob.validation.simulate.Flight` (``u2``: the command sent, after
        the tilt limit).
    y, e : array, m
        *True* position and tracking error ``r - y``.
    d : array, m/s^2
        The disturbance acting on the airframe at ``t_k`` (wind + the vehicle's noise).
    y_meas, e_meas : array, m
        Measured position ``x_m`` (true position + sensor noise) and tracking error
        ``r - x_m`` (what the learning uses).
    d_est : array, m/s^2
        The total estimate ``d_hat + d_f`` (command side) expressed as the acceleration it
        stands for on the airframe: ``A_hat{d_hat + d_f}`` with the model's attitude chain
        ``A_hat = s^2 P_hat`` under zero-order hold (:func:`~ilcdob.design.maps.flown.model_attitude`).
    saturated : int
        Samples at which the tilt limit cut the commanded acceleration (``u2`` is the
        command actually sent).
    """

    d_est: np.ndarray = field(default_factory=lambda: np.zeros(0))
    saturated: int = 0

    @property
    def rmse_dhat(self) -> float:
        """RMSE of the disturbance estimate against the true disturbance, m/s^2:
        ``rmse(A_hat{d_hat + d_f} - d)`` (both as accelerations of the airframe)."""
        return rmse(self.d_est - self.d)


def fly_loop(vehicle: QuadrotorParams, loop: LoopSystem, r: object, disturbance: object,
             d_f: object | None = None, mode: str = "dob", a_ref: object | None = None,
             noise_std: float = 0.0, rng: np.random.Generator | None = None) -> NonlinearFlight:
    """Fly one trial of the nonlinear ``vehicle`` under ``loop``'s outer loop (see module
    docstring; the loop of paper Sec. II with the vehicle in place of ``P``): the vehicle as a
    :class:`~ilcdob.vehicles.quadrotor_vehicle.QuadrotorVehicle` through
    :func:`~ilcdob.vehicles.interface.fly_vehicle`, x under ``loop``, y and z under their PIDs alone.

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
    noise_std = check_noise_std(noise_std, "noise_std")
    if noise_std > 0 and not isinstance(rng, np.random.Generator):
        raise SpecError(f"`rng`: got {rng!r}, expected a numpy.random.Generator when noise_std > 0")
    ts = loop.ts
    r = as_signal(r, "r")
    n = r.size
    if n < 2:
        raise SpecError(f"`r`: got {n} sample(s), expected a trial of at least 2 samples")
    if not callable(disturbance):
        raise SpecError(f"`disturbance`: got {type(disturbance).__name__}, expected a vectorised callable "
                        "of time (s) returning m/s^2")
    # the vehicle checks its inner rate against ts and evaluates the disturbance on its inner grid, n samples at once
    airframe = QuadrotorVehicle(vehicle, ts, disturbance=disturbance, noise_std=noise_std,
                                seed=rng if rng is not None else 0, horizon=n)
    t = np.arange(n) * ts
    d_out = as_signal(np.broadcast_to(np.asarray(disturbance(t), float), t.shape), "disturbance")
    ab, aa, adelay = model_attitude(loop)
    df = np.zeros(n) if d_f is None else as_signal(d_f, "d_f", n)
    if mode == "no_dob" and np.any(df):
        raise SpecError("`d_f`: a learning signal needs the DOB loop (mode='dob')")
    aff = np.zeros(n)
    if a_ref is not None and loop.spec.controller.acceleration_feedforward:
        aff = as_signal(a_ref, "a_ref", n)
    # x: the control law; y and z held at 0 by their PIDs alone (y: the fleet's PID, z: the vehicle's)
    trial = fly_vehicle(airframe, {"x": loop, "y": loop.spec.controller, "z": vehicle.z_controller}, {"x": r},
                        learning={"x": df}, feedforward={"x": aff}, dob=mode == "dob", n=n)
    y = np.array([p[0] for p in airframe.truth])
    ym, dh, u2 = trial.y_meas[:, 0].copy(), trial.d_hat[:, 0].copy(), trial.applied[:, 0].copy()
    est = sps.lfilter(ab, aa, dh + df)
    if adelay:
        est = np.concatenate([np.zeros(adelay), est[:-adelay]])
    return NonlinearFlight(system=loop.name, mode=mode, t=t, r=r, y=y, e=r - y, d=d_out, d_hat=dh,
                           d_f=df, u2=u2, y_meas=ym, e_meas=r - ym, d_est=est,
                           saturated=airframe.saturated)


@dataclass(frozen=True)
class StepChirpExperiments:
    """The in-house quadrotors' identification experiments, for
    :func:`~ilcdob.validation.vehicle_chain.identify_vehicles`: per vehicle the paper's step and chirp
    flights under the fleet's own PID, fitted with ``P_hat(s) = b0 / (s^2 (s + a0))``
    (:func:`ilcdob.identification.fleet_id.identify_vehicle`).

    Attributes
    ----------
    fleet : Fleet
        Supplies each vehicle's PID and the sample time.
    vehicles : dict
        Fleet name -> the nonlinear vehicle flown.
    seed : int
        Vehicle ``i`` flies with seed ``seed + 10 i``.
    noise_std : float
        Standard deviation of the white position-sensor noise, m.
    axis : str
        ``"x"``: the paper's experiments fly x.
    """

    fleet: Fleet
    vehicles: dict
    seed: int = 0
    noise_std: float = 0.0005
    axis: str = "x"

    def fit(self, name: str, index: int) -> VehicleFit:
        """The flights and the fit of one vehicle.

        Parameters
        ----------
        name : str
            The vehicle (a system of :attr:`fleet`).
        index : int
            Its place among the vehicles identified: it flies seed ``seed + 10 index``.

        Returns
        -------
        VehicleFit
            Its ``record`` is the vehicle's :class:`~ilcdob.identification.fleet_id.VehicleIdentification`.
        """
        vid = identify_vehicle(name, self.fleet, seed=int(self.seed) + 10 * index, noise_std=self.noise_std,
                               vehicle=self.vehicles[name])
        spec = identified_systems(self.fleet, {name: vid})[self.fleet.names.index(name)]  # the fleet file's record
        est = vid.estimate
        return VehicleFit(name, est.structure, spec.plant, {VehicleFit.label(est.structure): est.fit_validation},
                          est.fit_estimation, spec.identification, vid)


def _identify(fleet: Fleet, vehicles: dict[str, QuadrotorParams], settings: NonlinearSettings,
              progress: Callable[[int, int, str], None] | None = None
              ) -> tuple[Fleet, dict[str, VehicleIdentification], str]:
    """Identify every vehicle (:class:`StepChirpExperiments` through
    :func:`~ilcdob.validation.vehicle_chain.identify_vehicles`) and build the fleet of the models: each
    system has the identified ``P_hat`` as its plant (so its loop's ``M = Q/P_hat`` and its learning
    filters use the model); controllers, DOBs and noises are ``fleet``'s. Source:
    ``"identified_fleet.toml"``.

    Returns
    -------
    (Fleet, dict, str)
        The fleet of the models (as its fleet file loads), the identification of every vehicle, and
        the fleet file of the models (TOML text, :func:`ilcdob.fleet_io.fleet_to_toml`).
    """
    experiments = StepChirpExperiments(fleet, vehicles, settings.seed, settings.sensor_noise_std)
    models, fits = identify_vehicles(experiments, fleet.names, None, None, fleet.sample_time, base=fleet,
                                     progress=progress, source="identified_fleet.toml")
    header = (f"# Identified from synthetic step + chirp flights of the nonlinear vehicles "
              f"(ilcdob.validation.nonlinear, seed {settings.seed}, sensor noise "
              f"{settings.sensor_noise_std:g} m); controllers, DOBs and noises from {fleet.source}")
    text = fleet_to_toml(fleet.sample_time, models.systems, header=header)
    return (fleet_from_dict(tomllib.loads(text), "identified_fleet.toml"), {n: f.record for n, f in fits.items()},
            text)


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


def _rng(settings: NonlinearSettings, sid: int, index: int, trial: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(settings.seed), 1000 + sid, index, trial]))


def run_nonlinear_scenario(fleet: Fleet, vehicles: dict[str, QuadrotorParams], sc: Scenario,
                           iterations: int = 3, filters: dict | None = None,
                           settings: NonlinearSettings | None = None, law: str = DEFAULT_LAW,
                           order: list[str] | None = None) -> ScenarioResult:
    """Fly one scenario with every nonlinear vehicle: no DOB, only DOB, ``iterations``
    learning trials passed around the fleet in ``sc``'s order (the chain of
    :mod:`ilcdob.validation.reproduce`), each learning signal from the previous flight's
    *measured* error as ``ilcdob design`` computes it (module docstring).

    Parameters
    ----------
    fleet : Fleet
        Loops built from the models (identified plants).
    vehicles : dict or None
        Fleet name -> nonlinear vehicle (None: :func:`~ilcdob.vehicles.quadrotor.table_i_vehicles`).
    sc : Scenario
        The scenario flown (reference, wind, learning order).
    iterations : int
        Learning trials per system (>= 1).
    filters : dict, optional
        Cache of closed-form filters keyed by (source, target), filled as needed.
    settings : NonlinearSettings, optional
        Default: ``NonlinearSettings()``.
    law : {"paper", "exact-reference"}
        Learning law (:mod:`ilcdob.design.law.laws`).
    order : list of str, optional
        Learning order by system name (:func:`~ilcdob.validation.scenarios.check_order`);
        None (default): the scenario's.

    Returns
    -------
    ScenarioResult
        Every system's no-DOB, DOB-only and learning flights (:class:`NonlinearFlight`).
    """
    check_iterations(iterations)
    if not isinstance(sc, Scenario):
        raise SpecError(f"`sc`: got {type(sc).__name__}, expected a Scenario")
    settings = settings if settings is not None else NonlinearSettings()
    vehicles = _check_vehicles(fleet, vehicles, settings.inner_rate_hz)
    filters = {} if filters is None else filters
    ts = fleet.sample_time
    t = sc.time(ts)
    r = sc.reference(t)
    a_ref = sc.acceleration(t)
    order = sc.order(fleet.names) if order is None else check_order(fleet.names, order)
    specs = {s.name: s for s in fleet.systems}
    index = {name: i for i, name in enumerate(fleet.names)}

    def dist(name: str) -> Callable[[np.ndarray], np.ndarray]:
        noise = specs[name].noise
        return lambda tt: sc.disturbance(tt) + noise(tt)

    def flight(name: str, mode: str, trial: int, d_f: np.ndarray | None) -> NonlinearFlight:
        """Flight ``trial`` of ``name`` (:data:`~ilcdob.validation.vehicle_chain.FlyTrial`; its noise seed)."""
        return fly_loop(vehicles[name], fleet.loop(name), r, dist(name), d_f=d_f, mode=mode, a_ref=a_ref,
                        noise_std=settings.sensor_noise_std, rng=_rng(settings, sc.id, index[name], trial))

    if check_law(law) == "multi-source":
        raise SpecError("`law`: the nonlinear reproduction learns one pair at a time (the airframe correction "
                        "is per pair); use 'paper' or 'exact-reference'")
    base = fly_baselines(order, flight)
    pair_design = pair_designs(fleet, filters, law, r, a_ref, settings.bandwidth,
                               "airframe" if settings.airframe_disturbance else "command")

    def signal(src: str, tgt: str, prev: NonlinearFlight) -> np.ndarray:
        return pair_design(src, tgt).learning(prev.e_meas, prev.d_f, gain=settings.learning_gain).d_f

    learning, chain = fly_learning(order, iterations, base, flight, signal)
    systems = {name: SystemResult(base[name][0], base[name][1], tuple(learning[name])) for name in order}
    return ScenarioResult(scenario=sc, order=order, systems=systems, chain=chain)


@dataclass(frozen=True)
class NonlinearReproduction(ReproductionResult):
    """A :class:`~ilcdob.validation.reproduce.ReproductionResult` flown on the nonlinear
    vehicles; ``fleet`` holds the identified models.

    Attributes
    ----------
    fleet, scenarios, iterations, filters, elapsed_s, law, sensor_noise_std, bandwidth, identified_toml
        As in :class:`~ilcdob.validation.reproduce.ReproductionResult`; ``fleet`` holds the
        models flown, ``law`` is ``"paper"`` or ``"exact-reference"`` (the sensor noise and
        band of the run are in ``settings``).
    settings : NonlinearSettings
        The settings of the run.
    vehicles : dict
        Fleet name -> the nonlinear vehicle flown.
    identification : dict
        Fleet name -> :class:`~ilcdob.identification.fleet_id.VehicleIdentification`
        (empty when ``settings.identify`` is False).
    """

    settings: NonlinearSettings = field(default_factory=NonlinearSettings)
    vehicles: dict = field(default_factory=dict)
    identification: dict = field(default_factory=dict)

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
            + f"filters designed from the models; {self.iterations} learning iterations. Each learning signal is "
            "what `ilcdob design --trial` computes from the previous flight: the closed-form filters through "
            "the learning band "
            + ("chosen from that flight's measured error" if s.bandwidth == "auto" else
               ("switched off" if s.bandwidth is None else f"stated at {s.bandwidth:g} rad/s"))
            + " (`ilcdob.design.filters.band`)"
            + (", with the airframe-wind correction (`ilcdob.design.maps.flown`)" if s.airframe_disturbance else "")
            + f", learning gain {s.learning_gain:g}. Tracking RMSE: true position; disturbance "
            "estimate: A_hat{d_hat + d_f} against the wind + noise acceleration on the airframe. Regenerate "
            "with `ilcdob reproduce --plant nonlinear"
            + ("" if self.law == DEFAULT_LAW else f" --law {self.law}")
            + " --out <dir>`; numbers are in `results.json`.",
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
                        progress: Callable[[int, int, str], None] | None = None,
                        scenarios: list[Scenario] | None = None, law: str = DEFAULT_LAW,
                        order: list[str] | None = None) -> NonlinearReproduction:
    """Identify the vehicles, design the filters and fly the scenarios (module docstring).

    Nothing is written: the fleet file of the models is returned as
    :attr:`NonlinearReproduction.identified_toml`.

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
        Default: ``NonlinearSettings()``.
    vehicles : dict, optional
        Fleet name -> :class:`~ilcdob.vehicles.quadrotor.QuadrotorParams` (default:
        :func:`~ilcdob.vehicles.quadrotor.table_i_vehicles`).
    progress : callable, optional
        ``progress(done, total, what)`` after each step: every identified vehicle (when
        ``settings.identify``), then every scenario flown; ``what`` describes the step.
        None (default): silent.
    scenarios : list of Scenario, optional
        Fly these instead of ``scenario_ids`` (e.g. shortened copies, for tests).
    law : {"paper", "exact-reference"}
        Learning law (:mod:`ilcdob.design.law.laws`).
    order : list of str, optional
        Learning order by system name, flown in every scenario
        (:func:`~ilcdob.validation.scenarios.check_order`); None (default): each scenario's.

    Returns
    -------
    NonlinearReproduction
    """
    settings = settings if settings is not None else NonlinearSettings()
    if not isinstance(settings, NonlinearSettings):
        raise SpecError(f"`settings`: got {type(settings).__name__}, expected a NonlinearSettings")
    check_iterations(iterations)
    base = fleet if fleet is not None else default_fleet()
    if not isinstance(base, Fleet):
        raise SpecError(f"`fleet`: got {type(base).__name__}, expected a Fleet or None")
    vehicles = _check_vehicles(base, vehicles, settings.inner_rate_hz)
    order = None if order is None else check_order(base.names, order)
    scs = list(scenarios) if scenarios is not None else [scenario(sid) for sid in scenario_ids]
    check_flights_memory(base.sample_time, scs, len(base.names if order is None else order), iterations,
                         FLIGHT_ARRAYS + 1)  # and d_est
    n_ident = len(base.names) if settings.identify else 0
    total = n_ident + len(scs)
    say = progress if progress is not None else (lambda done, total_, what: None)
    start = time.perf_counter()
    if settings.identify:
        models, ident, toml_text = _identify(base, vehicles, settings, lambda done, _, what: say(done, total, what))
    else:
        models, ident = base, {}
        toml_text = fleet_to_toml(base.sample_time, identified_systems(base, {}))
    filters: dict = {}
    results = []
    for i, sc in enumerate(scs, 1):
        t0 = time.perf_counter()
        results.append(run_nonlinear_scenario(models, vehicles, sc, iterations, filters, settings, law, order))
        say(n_ident + i, total, f"scenario {sc.id} ({sc.title}, nonlinear): {time.perf_counter() - t0:.1f} s")
    return NonlinearReproduction(fleet=models, scenarios=results, iterations=iterations, filters=filters,
                                 elapsed_s=time.perf_counter() - start, settings=settings, vehicles=vehicles,
                                 identification=ident, identified_toml=toml_text, law=check_law(law),
                                 sensor_noise_std=settings.sensor_noise_std, bandwidth=settings.bandwidth)
