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
bound that drift while keeping several periods of the slowest excitation.

Nothing is written here: :func:`identify_fleet` returns a :class:`FleetIdentification` whose
:meth:`~FleetIdentification.files` maps every output file (flights as CSV and Parquet, so the
same data can be re-fitted with ``ilcdob identify``; ``model.json``; fit figures; the fleet
file of the models) to its content. docs/identification.md describes the fit.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

from ilcdob.errors import FleetError
from ilcdob.fleet import Fleet
from ilcdob.fleet_io import fleet_to_toml
from ilcdob.names import file_name
from ilcdob.signals import FlightData, segments
from ilcdob.specs import PlantSpec, SystemSpec
from ilcdob.uncertainty import ModelStructure
from ilcdob.vehicles.quadrotor import TABLE_I, QuadrotorParams, fly, table_i_vehicles

from .excitation import Chirp, StepSequence
from .results import TFEstimate
from .tfest import FitOptions, tfest

__all__ = ["VehicleIdentification", "FleetIdentification", "identify_vehicle", "identify_fleet",
           "identified_systems", "segments", "PLANT_STRUCTURE", "IDENTIFICATION_SOURCE"]

#: Commanded acceleration -> position: double integrator behind one attitude lag.
PLANT_STRUCTURE = ModelStructure(n_poles=3, n_zeros=0, n_integrators=2)
INPUT, OUTPUT = "acc_cmd", "x"

#: ``source`` of the identification tables written for the identified plants.
IDENTIFICATION_SOURCE = "synthetic step + chirp flights of the nonlinear vehicle (ilcdob.identification.fleet_id)"

#: Window of each fitted segment, s (own initial state; :func:`ilcdob.signals.segments`).
SEGMENT_S = 10.0


@dataclass(frozen=True)
class VehicleIdentification:
    """The flights and the fit of one vehicle.

    Attributes
    ----------
    name : str
        The vehicle's name in the fleet.
    estimate : TFEstimate
        The fitted plant.
    estimation : tuple of FlightData
        The step and chirp flights fitted (``metadata["experiment"]``: ``"steps"``, ``"chirp"``).
    validation : tuple of FlightData
        The held-out flights (``"steps-validation"``, ``"chirp-validation"``).
    """

    name: str
    estimate: TFEstimate
    estimation: tuple[FlightData, ...]
    validation: tuple[FlightData, ...]


def _check_table_i(fleet: Fleet, names: list[str]) -> None:
    """FleetError unless every name in ``names`` has a nonlinear vehicle of Table I."""
    unknown = [n for n in names if n not in TABLE_I]
    if unknown:
        raise FleetError(f"{fleet.source}: system(s) {unknown}: the nonlinear vehicles exist for "
                         f"{', '.join(TABLE_I)} only (paper Table I); name the fleet's systems "
                         f"{'/'.join(TABLE_I)}, or identify your own flight logs with `ilcdob identify`")


def identify_vehicle(name: str, fleet: Fleet, seed: int = 0, noise_std: float = 0.003,
                     progress: Callable[[int, int, str], None] | None = None,
                     vehicle: QuadrotorParams | None = None) -> VehicleIdentification:
    """Fly the estimation and validation experiments of ``name`` and fit its plant.

    Parameters
    ----------
    name : str
        The system of ``fleet`` whose controller flies the experiments.
    fleet : Fleet
        Supplies the system's PID and the sample time.
    seed : int
        Seed of the first flight's noise; the other three use ``seed + 1 .. seed + 3``.
    noise_std : float
        Standard deviation of the white position-sensor noise, m.
    progress : callable, optional
        ``progress(done, total, what)`` after the flights (1 of 2) and after the fit
        (2 of 2); None: silent.
    vehicle : QuadrotorParams, optional
        The nonlinear vehicle flown (default: the Table I vehicle ``name``).

    Returns
    -------
    VehicleIdentification
    """
    say = progress if progress is not None else (lambda done, total, what: None)
    fleet.loop(name)  # unknown names: a FleetError listing the fleet's systems
    if vehicle is None:
        _check_table_i(fleet, [name])
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
    say(1, 2, f"{name}: flew 4 experiments ({sum(len(f) for f in (step_est, chirp_est, step_val, chirp_val))} "
              "samples)")
    est = tfest(segments([step_est, chirp_est], SEGMENT_S), INPUT, OUTPUT, PLANT_STRUCTURE, FitOptions(delay=0.0),
                validation=segments([step_val, chirp_val], SEGMENT_S))
    say(2, 2, f"{name}: fit {est.fit_estimation:.2f} % (estimation), {est.fit_validation:.2f} % (validation)")
    return VehicleIdentification(name, est, (step_est, chirp_est), (step_val, chirp_val))


def identified_systems(fleet: Fleet, results: dict[str, VehicleIdentification]) -> tuple[SystemSpec, ...]:
    """The systems of ``fleet`` with every identified plant replacing the original one.

    A system with a result flies its identified ``P_hat`` as its plant (no separate model)
    and carries the fit as its ``identification`` (parameters, covariance, fits: the Delta
    set of docs/theory.md section 3); controller, DOB, noise and uncertainty bound stay
    ``fleet``'s. A system without a result is unchanged. Write them with
    :func:`ilcdob.fleet_io.fleet_to_toml`.

    Parameters
    ----------
    fleet : Fleet
        The fleet identified.
    results : dict
        System name -> :class:`VehicleIdentification` (any subset of the systems).

    Returns
    -------
    tuple of SystemSpec
        In ``fleet``'s order.
    """
    systems = []
    for spec in fleet.systems:
        vid = results.get(spec.name)
        if vid is not None:
            e = vid.estimate
            ident = e.identification_spec(IDENTIFICATION_SOURCE)
            spec = dataclasses.replace(spec, plant=PlantSpec(tuple(e.num), tuple(e.den), e.delay), model=None,
                                       identification=ident)
        systems.append(spec)
    return tuple(systems)


@dataclass(frozen=True)
class FleetIdentification:
    """The identification of every vehicle of a fleet (:func:`identify_fleet`).

    Attributes
    ----------
    fleet : Fleet
        The fleet identified (controllers, DOBs, noises).
    results : dict
        System name -> :class:`VehicleIdentification`, in the fleet's order.
    seed : int
        Seed of the experiments (vehicle ``i`` flies with ``seed + 10 i``).
    """

    fleet: Fleet
    results: dict[str, VehicleIdentification]
    seed: int = 0

    @property
    def identified_toml(self) -> str:
        """The fleet file with every identified plant (TOML text, :func:`identified_systems`)."""
        return fleet_to_toml(self.fleet.sample_time, identified_systems(self.fleet, self.results))

    def files(self, figures: bool = True) -> dict[str, object]:
        """Every output file of the identification, name -> content; nothing is written.

        Per vehicle ``NAME`` (every flight by its ``metadata["experiment"]``: ``steps``,
        ``chirp``, ``steps-validation``, ``chirp-validation``):

        * ``NAME/<experiment>.csv``, ``NAME/<experiment>.parquet``: the flight, as the
          callable writer :meth:`~ilcdob.signals.FlightData.to_csv` /
          :meth:`~ilcdob.signals.FlightData.to_parquet` taking the destination path;
        * ``NAME/model.json``: the fit (:meth:`~ilcdob.identification.results.TFEstimate.to_dict`);
        * with ``figures``, ``NAME/compare.png``, ``NAME/residuals.png``, ``NAME/bode.png``:
          the fit's figures (:func:`ilcdob.identification.plots.fit_figures`), as
          :class:`matplotlib.figure.Figure`;

        and ``identified_fleet.toml``, the fleet file of the models (:attr:`identified_toml`).

        Parameters
        ----------
        figures : bool
            Include the figures.

        Returns
        -------
        dict
            Relative file name (``/``-separated) -> ``str`` (text), ``dict`` (a JSON
            document), :class:`matplotlib.figure.Figure` (PNG) or a callable writing the
            file at the path it is given.
        """
        out: dict[str, object] = {}
        for name, vid in self.results.items():
            folder = file_name(name)  # a system name is data, never a path (the name rule makes this the name)
            for fd in vid.estimation + vid.validation:
                stem = file_name(fd.metadata.get("experiment", "flight"))
                out[f"{folder}/{stem}.csv"] = fd.to_csv
                out[f"{folder}/{stem}.parquet"] = fd.to_parquet
            out[f"{folder}/model.json"] = vid.estimate.to_dict()
            if figures:
                from .plots import fit_figures

                for fig_name, fig in fit_figures(vid.estimate, list(vid.estimation), list(vid.validation)).items():
                    out[f"{folder}/{fig_name}"] = fig
        out["identified_fleet.toml"] = self.identified_toml
        return out


def identify_fleet(fleet: Fleet, *, seed: int = 0,
                   progress: Callable[[int, int, str], None] | None = None) -> FleetIdentification:
    """Identify every vehicle of ``fleet`` from its step and chirp flights (module docstring).

    Nothing is written: :meth:`FleetIdentification.files` gives the output files.

    Parameters
    ----------
    fleet : Fleet
        The fleet whose vehicles are flown (Table I vehicles of the same names) under their
        own PIDs.
    seed : int
        Seed of the experiments; vehicle ``i`` (fleet order) flies with ``seed + 10 i``.
    progress : callable, optional
        ``progress(done, total, what)`` after each vehicle (``total``: the number of
        vehicles, ``what``: its fit); None (default): silent.

    Returns
    -------
    FleetIdentification
    """
    say = progress if progress is not None else (lambda done, total, what: None)
    _check_table_i(fleet, fleet.names)  # before any flight
    results = {}
    for i, name in enumerate(fleet.names):
        vid = identify_vehicle(name, fleet, seed=seed + 10 * i)
        results[name] = vid
        e = vid.estimate
        say(i + 1, len(fleet.names), f"{name}: fit {e.fit_estimation:.2f} % (estimation), "
                                     f"{e.fit_validation:.2f} % (validation)")
    return FleetIdentification(fleet, results, seed)
