"""Identify a fleet's plant models from synthetic flights of the nonlinear vehicles.

For every vehicle (:func:`~ilcdob.vehicles.quadrotor.table_i_vehicles`), flown under
its own outer-loop PID from the fleet file (closed loop, as the paper's vehicles fly):

* estimation: a reference-step flight (5 cm steps: larger ones make the PID's derivative
  kick hit the tilt limit) and an acceleration-chirp flight (injection on the x command,
  0.1 -> 2 Hz, 1.5 m/s^2);
* validation (held out): a step flight with other levels and a chirp of another band;

then fits ``P(s) = b0 / (s^2 (s + a0))`` (3 poles, 2 of them integrators) jointly to all
estimation data, from commanded x acceleration (m/s^2) to measured x position (m). Each
flight is cut into 10 s segments, each with its own estimated initial state: a simulation-
error fit of a double integrator over a long record lets tiny low-frequency mismatches
(drag, tilt nonlinearity) accumulate into position drift that swamps the fit; 10 s windows
bound that drift while keeping several periods of the slowest excitation. The flights are
written as CSV and Parquet, so the same data can be re-fitted with ``ilcdob identify``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ilcdob.atomic import write_json_atomic, write_text_atomic
from ilcdob.fleet import Fleet
from ilcdob.specs import IdentificationSpec, PlantSpec
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure
from ilcdob.vehicles.quadrotor import QuadrotorParams, fly, table_i_vehicles

from .excitation import Chirp, StepSequence
from .results import TFEstimate
from .tfest import FitOptions, tfest

__all__ = ["VehicleIdentification", "identify_vehicle", "identify_fleet", "fleet_toml", "segments",
           "PLANT_STRUCTURE"]

#: Commanded acceleration -> position: double integrator behind one attitude lag.
PLANT_STRUCTURE = ModelStructure(n_poles=3, n_zeros=0, n_integrators=2)
INPUT, OUTPUT = "acc_cmd", "x"


SEGMENT_S = 10.0  # s, window of each fitted segment (own initial state)


def segments(flights: list[FlightData], length: float = SEGMENT_S) -> list[FlightData]:
    """Cut flights into consecutive windows of ``length`` seconds (the tail shorter than half
    a window is merged into the last one)."""
    out = []
    for fd in flights:
        starts = np.arange(fd.t[0], fd.t[-1] - 0.5 * length + 1e-9, length)
        for i, t0 in enumerate(starts):
            stop = fd.t[-1] if i == len(starts) - 1 else t0 + length - 0.5 * fd.ts
            out.append(fd.segment(t0, stop))
    return out


@dataclass(frozen=True)
class VehicleIdentification:
    """The flights and the fit of one vehicle."""

    name: str
    estimate: TFEstimate
    estimation: tuple[FlightData, ...]
    validation: tuple[FlightData, ...]


def identify_vehicle(name: str, fleet: Fleet, seed: int = 0, noise_std: float = 0.003,
                     progress: Callable[[str], None] | None = None,
                     vehicle: QuadrotorParams | None = None) -> VehicleIdentification:
    """Fly the estimation and validation experiments of ``name`` and fit its plant.

    ``vehicle`` is the nonlinear vehicle flown (default: the Table I vehicle ``name``).
    """
    say = progress or (lambda msg: None)
    params = vehicle if vehicle is not None else table_i_vehicles()[name]
    spec = next(s for s in fleet.systems if s.name == name)
    ts = fleet.sample_time
    step_est = fly(params, spec, 30.0, ts, reference=StepSequence((0, 0.05, -0.05, 0.03, -0.03, 0.0), 5.0).signal,
                   noise_std=noise_std, seed=seed, experiment="steps")
    chirp_est = fly(params, spec, 40.0, ts, injection=Chirp(0.1, 2.0, 40.0, 1.5, fade=2.0).signal,
                    noise_std=noise_std, seed=seed + 1, experiment="chirp")
    step_val = fly(params, spec, 30.0, ts, reference=StepSequence((0, -0.04, 0.05, -0.02, 0.03, 0.0), 5.0).signal,
                   noise_std=noise_std, seed=seed + 2, experiment="steps-validation")
    chirp_val = fly(params, spec, 30.0, ts, injection=Chirp(0.15, 1.5, 30.0, 1.2, fade=2.0).signal,
                    noise_std=noise_std, seed=seed + 3, experiment="chirp-validation")
    say(f"{name}: flew 4 experiments ({sum(len(f) for f in (step_est, chirp_est, step_val, chirp_val))} samples)")
    est = tfest(segments([step_est, chirp_est]), INPUT, OUTPUT, PLANT_STRUCTURE, FitOptions(delay=0.0),
                validation=segments([step_val, chirp_val]), progress=say)
    say(f"{name}: fit {est.fit_estimation:.2f} % (estimation), {est.fit_validation:.2f} % (validation)")
    return VehicleIdentification(name, est, (step_est, chirp_est), (step_val, chirp_val))


def identify_fleet(fleet: Fleet, out: str | Path | None = None, seed: int = 0,
                   progress: Callable[[str], None] | None = None) -> dict[str, VehicleIdentification]:
    """Identify every vehicle of ``fleet``; with ``out``, write flights, models and figures."""
    results = {}
    for i, name in enumerate(fleet.names):
        results[name] = identify_vehicle(name, fleet, seed=seed + 10 * i, progress=progress)
    if out is not None:
        from .plots import plot_fit

        out = Path(out)
        for name, vid in results.items():
            folder = out / name
            for fd in vid.estimation + vid.validation:
                stem = fd.metadata.get("experiment", "flight")
                fd.to_csv(folder / f"{stem}.csv")
                fd.to_parquet(folder / f"{stem}.parquet")
            write_json_atomic(folder / "model.json", vid.estimate.to_dict())
            plot_fit(vid.estimate, list(vid.estimation), list(vid.validation), folder)
        write_text_atomic(out / "identified_fleet.toml", fleet_toml(fleet, results))
    return results


def _fmt(values) -> str:
    return "[" + ", ".join(f"{float(v):.10g}" for v in values) + "]"


def fleet_toml(fleet: Fleet, results: dict[str, VehicleIdentification], header: str = "") -> str:
    """The fleet file with every identified plant replacing the original one."""
    lines = [header.rstrip()] if header else []
    lines += [f"sample_time = {fleet.sample_time}   # s", ""]
    for spec in fleet.systems:
        vid = results.get(spec.name)
        plant = spec.plant
        ident = None
        if vid is not None:
            e = vid.estimate
            plant = PlantSpec(tuple(e.num), tuple(e.den), e.delay)
            ident = IdentificationSpec(e.structure.n_poles, e.structure.n_zeros, e.structure.n_integrators,
                                       tuple(e.theta), tuple(map(tuple, e.covariance)), e.delay_estimated,
                                       e.fit_estimation, e.fit_validation or float("nan"),
                                       "synthetic step + chirp flights of the nonlinear vehicle (ilcdob.identification.fleet_id)")
        c, q, n = spec.controller, spec.dob, spec.noise
        lines += ["[[system]]", f'name = "{spec.name}"',
                  f"plant = {{ num = {_fmt(plant.num)}, den = {_fmt(plant.den)} }}",
                  f"delay = {plant.delay:.6g}",
                  f"controller = {{ kp = {c.kp:g}, ki = {c.ki:g}, kd = {c.kd:g}, derivative_filter = {c.derivative_filter:g}"
                  + ("" if c.acceleration_feedforward else ", acceleration_feedforward = false") + " }",
                  f"dob = {{ q_order = {q.q_order}, q_time_constant = {q.q_time_constant:g} }}",
                  f"noise = {{ amplitude = {n.amplitude:g}, frequency = {n.frequency:g}, phase = {n.phase:g} }}"]
        if ident is not None:
            cov = "[" + ", ".join(_fmt(r) for r in ident.covariance) + "]"
            lines.append(
                f"identification = {{ poles = {ident.poles}, zeros = {ident.zeros}, integrators = {ident.integrators}, "
                f"parameters = {_fmt(ident.parameters)}, covariance = {cov}, "
                f"delay_estimated = {'true' if ident.delay_estimated else 'false'}, "
                f"fit_estimation = {ident.fit_estimation:.4f}, fit_validation = {ident.fit_validation:.4f}, "
                f'source = "{ident.source}" }}')
        if spec.uncertainty is not None:
            lines.append(f"uncertainty = {{ bound = {spec.uncertainty.bound:g} }}")
        lines.append("")
    return "\n".join(lines)
