"""The paper's experiments on rotorpy's multirotors: ``ilcdob reproduce --plant rotorpy``.

rotorpy (MIT licence, the ``[rotorpy]`` extra; :mod:`ilcdob.vehicles.rotorpy_vehicle`) stands in
for flight: its rotor aerodynamics, motors and attitude control are nobody's here. Three of its
vehicles of different size fly the pipeline of :mod:`ilcdob.validation.vehicle_chain`:

1. identification flights in still air, the structure chosen from the data;
2. the four scenarios, each in three disturbances:

   * ``paper``: the scenario's disturbance added to every vehicle's acceleration command (the
     paper's virtual disturbance), learned with the paper's law and with ``exact-reference``;
   * ``wind``: the same signal as a wind velocity (``wind_gain`` m/s per m/s^2) through each
     airframe's drag;
   * ``dryden``: Dryden turbulence around a mean wind (:func:`~ilcdob.validation.vehicle_chain.dryden_gust`),
     the same realisation in every trial;

   the winds learned with the paper's law as is (it assumes the disturbance on the command) and
   with the wind law (``path="wind"``: the wind velocity is what the vehicles share, mapped through
   each identified drag, docs/theory.md section 6), with either law's reference handling.

Reported as the other reproductions (``README.md``, ``results.json``, figures of the paper's
disturbance with the paper's law), with the full RMSE tables of every disturbance and law and
the acceptance of each figure.
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ilcdob.design.maps.closed_form import closed_form_filters
from ilcdob.errors import SpecError
from ilcdob.fleet import fleet_from_systems
from ilcdob.fleet_io import fleet_to_toml
from ilcdob.specs import DOBSpec, PIDSpec, check_noise_std

from .reproduce import ReproductionResult, ScenarioResult, check_iterations
from .scenarios import Scenario, scenario
from .vehicle_chain import LawPath, VehicleFit, dryden_gust, identify_vehicles, run_vehicle_laws

__all__ = ["ROTORPY_FLEET", "DISTURBANCES", "VehicleSettings", "VehicleReproduction", "reproduce_vehicles"]

#: The vehicles flown by default: rotorpy's crazyflie (0.03 kg), hummingbird (0.5 kg) and PX4 SIH quad (1.0 kg).
ROTORPY_FLEET = ("crazyflie", "hummingbird", "px4")
#: rotorpy's PX4 SIH parameter set has no rotor drag (``k_d = 0``, quadratic body drag only): in still air
#: below 1 m/s it has no measurable drag, so the wind it meets cannot be identified from its flights (its drag
#: pole comes out at 0.008 / 5.6 = 0.0015 1/s, a time constant of 11 min). Real rotors have rotor drag
#: (blade flapping and induced drag, linear in airspeed); this gives the PX4 set the hummingbird's
#: coefficient (1.19e-4 kg/rad) rounded: 0.28 1/s of drag per unit mass at hover, between the crazyflie's and
#: the hummingbird's.
PX4_ROTOR_DRAG = {"k_d": 1.0e-4}
#: Disturbance -> the (law, path) pairs flown in it (:data:`~ilcdob.validation.vehicle_chain.LawPath`).
DISTURBANCES: dict[str, tuple[LawPath, ...]] = {
    "paper": (("paper", "command"), ("exact-reference", "command")),
    "wind": (("paper", "command"), ("paper", "wind"), ("exact-reference", "wind")),
    "dryden": (("paper", "command"), ("paper", "wind"), ("exact-reference", "wind")),
}
#: What each disturbance is, for the report.
DISTURBANCE_TEXT = {
    "paper": "the scenario's disturbance added to the acceleration command, as in the paper",
    "wind": "the scenario's disturbance as a wind velocity through each airframe's drag",
    "dryden": "Dryden turbulence (MIL-F-8785C, low altitude) around a mean wind through each airframe's drag",
}


def _label(lp: LawPath) -> str:
    return lp[0] if lp[1] == "command" else f"{lp[0]}, {lp[1]} path"


@dataclass(frozen=True)
class VehicleSettings:
    """Settings of the rotorpy reproduction.

    Attributes
    ----------
    vehicles : tuple of str
        Names of rotorpy parameter sets (:data:`~ilcdob.vehicles.rotorpy_vehicle.ROTORPY_VEHICLES`) or of
        ``airframes``, at least two.
    ts : float
        Outer-loop sample time, s.
    sensor_noise_std : float
        White position-sensor noise per axis, m (default 0.5 mm, motion-capture grade).
    wind_gain : float
        The ``wind`` disturbance: m/s of wind per m/s^2 of the scenario's disturbance.
    dryden_wind_20ft : float
        The ``dryden`` disturbance: mean wind at 20 ft, m/s (its intensities scale with it).
    dryden_seed : int
        Seed of the Dryden turbulence (one realisation per scenario, flown in every trial).
    disturbances : tuple of str
        Keys of :data:`DISTURBANCES` to fly; ``paper`` is always flown.
    params : dict of str to dict
        Per vehicle, changes to rotorpy's parameter set. Default: rotor drag for the PX4 set
        (:data:`PX4_ROTOR_DRAG`).
    workers : int
        Processes flying the scenarios (>= 1).
    airframes : dict of str to dict
        A lab's own airframes by vehicle name: complete rotorpy parameter sets
        (:func:`~ilcdob.vehicles.rotorpy_vehicle.airframe_parameters`; ``reproduce --vehicles FILE``,
        :func:`~ilcdob.validation.channel_reproduction.load_vehicles`). ``params`` does not apply to them.
    """

    vehicles: tuple[str, ...] = ROTORPY_FLEET
    ts: float = 0.01
    sensor_noise_std: float = 0.0005
    wind_gain: float = 2.0
    dryden_wind_20ft: float = 2.0
    dryden_seed: int = 0
    disturbances: tuple[str, ...] = ("paper", "wind", "dryden")
    params: dict[str, dict] = field(default_factory=lambda: {"px4": dict(PX4_ROTOR_DRAG)})
    workers: int = 1
    airframes: dict[str, dict] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from ilcdob.vehicles.rotorpy_vehicle import ROTORPY_VEHICLES

        names = tuple(self.vehicles)
        bad = [n for n in names if n not in ROTORPY_VEHICLES and n not in self.airframes]
        if len(names) < 2 or bad or len(set(names)) != len(names):
            raise SpecError(f"`vehicles`: got {list(names)}, expected two or more distinct names of "
                            f"{sorted(ROTORPY_VEHICLES)} or of `airframes` ({sorted(self.airframes)})")
        object.__setattr__(self, "vehicles", names)
        dist = tuple(dict.fromkeys(("paper", *self.disturbances)))
        if any(d not in DISTURBANCES for d in dist):
            raise SpecError(f"`disturbances`: got {list(self.disturbances)}, expected names of {list(DISTURBANCES)}")
        object.__setattr__(self, "disturbances", dist)
        object.__setattr__(self, "sensor_noise_std", check_noise_std(self.sensor_noise_std, "sensor_noise_std"))
        for name, lo in (("ts", 0.001), ("wind_gain", 0.0), ("dryden_wind_20ft", 0.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (np.isfinite(v) and v > lo):
                raise SpecError(f"`{name}`: got {v!r}, expected a number > {lo:g}")
        for name, lo in (("dryden_seed", 0), ("workers", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise SpecError(f"`{name}`: got {v!r}, expected an integer >= {lo}")
        if not isinstance(self.params, dict) or not all(isinstance(v, dict) for v in self.params.values()):
            raise SpecError(f"`params`: got {self.params!r}, expected a dict of vehicle name -> dict of rotorpy "
                            "parameters")

    def make(self, name: str, command: Callable | None, wind: Callable | None, seed: int):
        """A fresh rotorpy vehicle (:data:`~ilcdob.validation.vehicle_chain.MakeVehicle`).

        Parameters
        ----------
        name : str
            Vehicle name.
        command, wind : callable or None
            Command disturbance (m/s^2) and wind (m/s), ``t -> (3,)``.
        seed : int
            Seed of the sensor noise.

        Returns
        -------
        RotorpyVehicle
        """
        from ilcdob.vehicles.rotorpy_vehicle import RotorpyVehicle

        own = self.airframes.get(name)
        frame = {"airframe": own} if own is not None else {"params": self.params.get(name)}
        return RotorpyVehicle(name, self.ts, command_disturbance=command, wind=wind, noise_std=self.sensor_noise_std,
                              seed=seed, **frame)


def _fly(settings: VehicleSettings, systems: list, sc: Scenario, disturbance: str,
         iterations: int) -> tuple[dict[LawPath, ScenarioResult], float]:
    """One scenario in one disturbance, every law (a process pool's job: the fleet rebuilt from its specs)."""
    t0 = time.perf_counter()
    fleet = fleet_from_systems(systems, settings.ts)
    if disturbance == "dryden":
        wind = dryden_gust(sc.duration + 1.0, settings.ts, settings.dryden_wind_20ft, seed=settings.dryden_seed + sc.id)
    else:
        wind = settings.wind_gain if disturbance == "wind" else None
    res = run_vehicle_laws(fleet, settings.make, sc, iterations, laws=list(DISTURBANCES[disturbance]), wind=wind)
    return res, time.perf_counter() - t0


@dataclass(frozen=True)
class VehicleReproduction(ReproductionResult):
    """The rotorpy reproduction: :class:`~ilcdob.validation.reproduce.ReproductionResult` of the paper's
    disturbance and law (``scenarios``; its figures), plus every disturbance and law.

    Attributes
    ----------
    fleet, scenarios, iterations, filters, elapsed_s, law, sensor_noise_std, bandwidth, identified_toml
        As in :class:`~ilcdob.validation.reproduce.ReproductionResult`.
    settings : VehicleSettings
    fits : dict of str to VehicleFit
        Each vehicle's identification.
    runs : dict
        Disturbance -> law label -> list of ScenarioResult (one per scenario).
    """

    settings: VehicleSettings = field(default_factory=VehicleSettings)
    fits: dict[str, VehicleFit] = field(default_factory=dict)
    runs: dict[str, dict[str, list[ScenarioResult]]] = field(default_factory=dict)

    def acceptance(self) -> list[dict[str, object]]:
        """Each acceptance figure of the run: what, the value measured, its limit and whether it is met.

        * identification: held-out fit of the chosen structure >= 95 % per vehicle;
        * paper's disturbance, hover (scenario 1): learning 1 / DOB-only <= 0.01 per vehicle;
        * paper's disturbance, every scenario: the better law's learning 1 / DOB-only <= 0.02 per vehicle;
        * every wind: the wind law (the better of its two) at every iteration <= 0.5 of DOB-only per vehicle.
        """
        def row(what: str, value: float, limit: float) -> dict[str, object]:  # a ratio at most its limit
            return {"what": what, "value": value, "limit": limit, "passed": bool(value <= limit)}

        rows = [{"what": f"held-out fit, {name} ({_structure(f)})", "value": f.fit, "limit": 95.0,
                 "passed": bool(f.fit >= 95.0)} for name, f in self.fits.items()]

        def ratios(dist: str, label: str, sid: int, name: str) -> list[float]:
            sr = next(s for s in self.runs[dist][label] if s.scenario.id == sid)
            m = sr.systems[name].metrics()
            return [v / m["rmse_dob"] for v in m["rmse_learning"]]

        for sr in self.runs.get("paper", {}).get("paper", []):
            for name in sr.order:
                if sr.scenario.id == 1:
                    rows.append(row(f"paper's disturbance, scenario 1, {name}: learning 1 / DOB (paper law)",
                                    ratios("paper", "paper", 1, name)[0], 0.01))
                best = min((ratios("paper", lab, sr.scenario.id, name)[0], lab) for lab in self.runs["paper"])
                rows.append(row(f"paper's disturbance, scenario {sr.scenario.id}, {name}: learning 1 / DOB "
                                f"({best[1]} law, the better)", best[0], 0.02))
        for dist in self.runs:
            labels = [_label(lp) for lp in DISTURBANCES[dist] if lp[1] == "wind"]
            if dist == "paper" or not labels:
                continue
            for sr in self.runs[dist][labels[0]]:
                for name in sr.order:
                    best = min((max(ratios(dist, lab, sr.scenario.id, name)), lab) for lab in labels)
                    rows.append(row(f"{dist}, scenario {sr.scenario.id}, {name}: worst iteration / DOB ({best[1]})",
                                    best[0], 0.5))
        return rows

    def to_dict(self) -> dict[str, object]:
        """``results.json``: the schema of :meth:`ReproductionResult.to_dict` with ``"plant": "rotorpy"``,
        the identification, every disturbance's runs and the acceptance."""
        data = super().to_dict()
        data["plant"] = "rotorpy"
        s = self.settings
        data["settings"] = {"vehicles": list(s.vehicles), "wind_gain_m_s_per_m_s2": s.wind_gain,
                            "dryden_wind_20ft_m_s": s.dryden_wind_20ft, "dryden_seed": s.dryden_seed}
        if s.airframes:
            from ilcdob.vehicles.rotorpy_vehicle import airframe_summary

            data["settings"]["airframes"] = {n: airframe_summary(a) for n, a in s.airframes.items()}
        data["identification"] = {name: {"structure": _structure(f), "held_out_fit_percent": f.fits,
                                         "num": list(f.plant.num), "den": list(f.plant.den)}
                                  for name, f in self.fits.items()}
        data["runs"] = {dist: {lab: [sr.to_dict() for sr in srs] for lab, srs in laws.items()}
                        for dist, laws in self.runs.items()}
        data["acceptance"] = self.acceptance()
        return data

    def markdown_plant(self) -> list[str]:
        """The description, identification, tables of every disturbance and law, and the acceptance (Markdown)."""
        from ilcdob.vehicles.rotorpy_vehicle import airframe_summary

        s = self.settings
        lines = [
            f"**Plant: rotorpy.** rotorpy's multirotors ({', '.join(s.vehicles)}; its rotor aerodynamics, motors "
            f"and geometric attitude control, nothing of ilcdob's vehicle models"
            + "".join(f"; {name} with {', '.join(f'{k} = {v:g}' for k, v in p.items())}"
                      for name, p in s.params.items() if name in s.vehicles and name not in s.airframes and p)
            + "".join(f"; {name} an airframe of the run's own ({a['mass_kg']:.3g} kg, inertias "
                      f"{', '.join(f'{i:.3g}' for i in a['inertia_kg_m2'])} kg m^2, arm {a['arm_m']:.3g} m)"
                      for name, a in ((n, airframe_summary(s.airframes[n])) for n in s.vehicles if n in s.airframes))
            + ") fly every trial; ilcdob's outer "
            f"loop (PID + DOB + learning signal, x axis; y and z held by their PIDs) runs at {s.ts} s with "
            f"{1e3 * s.sensor_noise_std:g} mm of white position-sensor noise. Models identified from still-air "
            "flights with the structure chosen from the data (`identified_fleet.toml`); closed-form filters "
            "from the models; each learning signal is what `ilcdob design --trial` computes from the previous "
            f"flight; {self.iterations} learning iterations. Winds: {s.wind_gain:g} m/s per m/s^2 of the "
            f"scenario's disturbance; Dryden around a {s.dryden_wind_20ft:g} m/s mean wind at 20 ft, faded in "
            "over 5 s. "
            + ("rotorpy's PX4 parameter set has no rotor drag (k_d = 0), so its flights in still air show no drag "
               "and the wind law cannot learn from it; it is given rotor drag as every real rotor has "
               "(`PX4_ROTOR_DRAG` in `ilcdob.validation.vehicle_reproduction`). "
               if "px4" in s.vehicles and "px4" not in s.airframes and s.params.get("px4") == PX4_ROTOR_DRAG else "")
            + "The table below and the figures are the paper's disturbance with the paper's law; the "
            "full tables follow. Regenerate with `ilcdob reproduce --plant rotorpy --out <dir>` (needs "
            "`pip install 'ilcdob[rotorpy]'`).",
            "", "### Identification (held-out fit, %)", "",
            "| vehicle | chosen | " + " | ".join(next(iter(self.fits.values())).fits) + " | model P(s) |",
            "|---|---|" + "---|" * len(next(iter(self.fits.values())).fits) + "---|",
        ]
        for name, f in self.fits.items():
            model = (f"({' '.join(f'{v:.4g}' for v in f.plant.num)}) / ({' '.join(f'{v:.4g}' for v in f.plant.den)})")
            lines.append(f"| {name} | {_structure(f)} | " + " | ".join(f"{v:.2f}" for v in f.fits.values())
                         + f" | {model} |")
        for dist, laws in self.runs.items():
            lines += ["", f"### Disturbance: {dist} ({DISTURBANCE_TEXT[dist]})", "",
                      "Tracking RMSE in mm and learning / DOB-only per iteration:", "",
                      "| scenario | vehicle | law | no DOB | DOB only | " + " | ".join(
                          f"learning {i + 1}" for i in range(self.iterations)) + " | " + " | ".join(
                          f"{i + 1} / DOB" for i in range(self.iterations)) + " |",
                      "|---|---|---|---|---|" + "---|" * (2 * self.iterations)]
            for srs in zip(*laws.values()):
                for name in srs[0].order:
                    for lab, sr in zip(laws, srs):
                        m = sr.systems[name].metrics()
                        lines.append(f"| {sr.scenario.id} | {name} | {lab} | {1e3 * m['rmse_no_dob']:.2f} | "
                                     f"{1e3 * m['rmse_dob']:.2f} | "
                                     + " | ".join(f"{1e3 * v:.3f}" for v in m["rmse_learning"]) + " | "
                                     + " | ".join(f"{v / m['rmse_dob']:.4f}" for v in m["rmse_learning"]) + " |")
        lines += ["", "### Acceptance", "", "| figure | measured | limit | met |", "|---|---|---|---|"]
        for row in self.acceptance():
            lines.append(f"| {row['what']} | {row['value']:.4g} | {row['limit']:g} | "
                         f"{'yes' if row['passed'] else 'NO'} |")
        return lines


def _structure(f: VehicleFit) -> str:
    st = f.structure
    return f"{st.n_poles} poles, {st.n_zeros} zeros, {st.n_integrators} integrator{'s' * (st.n_integrators != 1)}"


def reproduce_vehicles(scenario_ids: list[int] = (1, 2, 3, 4), iterations: int = 3,
                       settings: VehicleSettings | None = None,
                       progress: Callable[[int, int, str], None] | None = None,
                       scenarios: list[Scenario] | None = None) -> VehicleReproduction:
    """Identify the rotorpy vehicles, design and fly every scenario in every disturbance (module docstring).

    Parameters
    ----------
    scenario_ids : list of int
        Scenarios to fly (1-4).
    iterations : int
        Learning iterations (>= 1).
    settings : VehicleSettings, optional
        Default: ``VehicleSettings()``.
    progress : callable, optional
        ``progress(done, total, what)`` after the identification and after each scenario and disturbance.
    scenarios : list of Scenario, optional
        Fly these instead of ``scenario_ids`` (e.g. shortened copies, for tests).

    Returns
    -------
    VehicleReproduction
    """
    settings = settings if settings is not None else VehicleSettings()
    if not isinstance(settings, VehicleSettings):
        raise SpecError(f"`settings`: got {type(settings).__name__}, expected a VehicleSettings")
    check_iterations(iterations)
    scs = list(scenarios) if scenarios is not None else [scenario(sid) for sid in scenario_ids]
    jobs = [(sc, dist) for dist in settings.disturbances for sc in scs]
    total = 1 + len(jobs)
    say = progress if progress is not None else (lambda done, total_, what: None)
    start = time.perf_counter()
    names = list(settings.vehicles)
    # the paper's Table I gains for every vehicle; the DOB's Q order is raised to the model's relative degree
    fleet, fits = identify_vehicles(settings.make, names, {n: PIDSpec(2.5, 0.3, 2.2, 0.05) for n in names},
                                    {n: DOBSpec(3, 0.2) for n in names}, settings.ts)
    say(1, total, "identified " + ", ".join(f"{n} {f.fit:.1f} %" for n, f in fits.items()))
    systems = list(fleet.systems)
    runs: dict[str, dict[str, list[ScenarioResult]]] = {d: {_label(lp): [] for lp in DISTURBANCES[d]}
                                                        for d in settings.disturbances}
    results: list = [None] * len(jobs)

    def record(i: int, res: dict, seconds: float, done: int) -> None:
        results[i] = res
        sc, dist = jobs[i]
        say(1 + done, total, f"scenario {sc.id} ({sc.title}), disturbance {dist}: {seconds:.0f} s")

    if settings.workers > 1:
        with ProcessPoolExecutor(settings.workers) as pool:
            futures = [pool.submit(_fly, settings, systems, sc, dist, iterations) for sc, dist in jobs]
            for done, fut in enumerate(as_completed(futures), 1):
                record(futures.index(fut), *fut.result(), done)
    else:
        for i, (sc, dist) in enumerate(jobs):
            record(i, *_fly(settings, systems, sc, dist, iterations), i + 1)
    for (sc, dist), res in zip(jobs, results):
        for lp, sr in res.items():
            runs[dist][_label(lp)].append(sr)
    filters = {pair: closed_form_filters(fleet.loop(pair[0]), fleet.loop(pair[1]))
               for sr in runs["paper"]["paper"] for pair in sr.chain}
    return VehicleReproduction(fleet=fleet, scenarios=runs["paper"]["paper"], iterations=iterations, filters=filters,
                               elapsed_s=time.perf_counter() - start, sensor_noise_std=settings.sensor_noise_std,
                               settings=settings, fits=fits, runs=runs,
                               identified_toml=fleet_to_toml(settings.ts, systems))
