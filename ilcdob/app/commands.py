"""The use cases behind the ``ilcdob`` commands, as plain functions for Python users too.

Each function checks its output location before any computation, runs the library, writes
its outputs through :mod:`ilcdob.app.output` (a folder as a unit, or one atomic file) and
returns the result object. Nothing here prints: long work reports through ``progress``
(``progress(done, total, what)``, None: silent), and :mod:`ilcdob.app.cli` turns results
into console lines. The library is imported inside each function, so that ``ilcdob --help``
and quick commands start without loading cvxpy, CasADi and Dask.

| function | command | writes |
|---|---|---|
| :func:`reproduce_to_folder` | ``reproduce`` | results.json, theorem.json, fleet.toml, figures, README.md |
| :func:`identify_to_json` | ``identify`` | model.json (+ a figure folder) |
| :func:`identify_fleet_to_folder` | ``identify-fleet`` | flights, models, figures, identified_fleet.toml |
| :func:`design_to_folder` | ``design`` | filters.json, filters.h/.c, README.md, lifted.npz, learning_signal.csv |
| :func:`check_to_json` | ``check`` | the Theorem check as JSON |
| :func:`compare_to_folder` | ``compare`` | compare.json, compare.txt, compare_ratios.png |
| :func:`extensions_to_folder` | ``extensions`` | extensions.json, README.md |
| :func:`campaign_to_folder` | ``campaign`` | samples.jsonl (resumable), campaign.json, campaign.txt, figure |
| :func:`add_to_fleet` | ``fleet add`` | the fleet file |
| :func:`report_to_html` | ``report`` | one self-contained HTML file |
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ilcdob.errors import SignalError, SpecError
from ilcdob.fleet import DEFAULT_FLEET_PATH, Fleet, default_fleet, load_fleet

from .html import build_report, report_files
from .output import OutputFolder, Provenance, check_output_path, write_file

__all__ = ["Progress", "fleet_and_hash", "reproduce_to_folder", "identify_to_json", "identify_fleet_to_folder",
           "design_to_folder", "check_to_json", "compare_to_folder", "extensions_to_folder", "campaign_to_folder",
           "add_to_fleet", "report_to_html", "IdentifyInputs"]

#: ``progress(done, total, what)``: called as long work advances.
Progress = Callable[[int, int, str], None]


def fleet_and_hash(path: str | Path | None) -> tuple[Fleet, str]:
    """The fleet of a ``--fleet`` option (None: the built-in fleet) and the SHA-256 of its file.

    Parameters
    ----------
    path : str or Path or None
        Fleet TOML file.
    """
    fleet = load_fleet(path) if path else default_fleet()
    data = Path(path if path else DEFAULT_FLEET_PATH).read_bytes()
    return fleet, hashlib.sha256(data).hexdigest()


def _provenance(command: str, argv: Sequence[str] | None, fleet_hash: str | None = None,
                law: str | None = None) -> Provenance:
    return Provenance(command, list(argv or []), fleet_hash, law)


def _write_folder(out: str | Path, provenance: Provenance, *maps: dict[str, Any], overwrite: bool = False,
                  keep: Sequence[str] = ()) -> None:
    """Write content maps into ``out`` as one unit (:class:`OutputFolder`)."""
    with OutputFolder(out, provenance, overwrite=overwrite, keep=keep) as folder:
        for files in maps:
            folder.add_all(files)


def reproduce_to_folder(out: str | Path, *, fleet: str | Path | None = None, scenarios: Sequence[int] = (1, 2, 3, 4),
                        iterations: int = 3, plant: str = "linear", seed: int = 0, law: str = "paper",
                        figures: bool = True, overwrite: bool = False, progress: Progress | None = None,
                        argv: Sequence[str] | None = None) -> Any:
    """Run the paper's scenarios on a fleet and write the reproduction folder (paper Sec. IV).

    Parameters
    ----------
    out : str or Path
        Output folder, written as a unit.
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    scenarios : sequence of int
        Scenario ids 1-4.
    iterations : int
        Learning iterations.
    plant : {"linear", "nonlinear"}
        linear: the fleet's models; nonlinear: identify and fly the 6-DOF quadrotors.
    seed : int
        Nonlinear plant: seed of the sensor noise.
    law : str
        Learning law (:mod:`ilcdob.design.laws`).
    figures : bool
        Write the PNG figures.
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    progress : callable, optional
        ``progress(done, total, what)``.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.

    Returns
    -------
    ReproductionResult
    """
    from ilcdob.design.laws import check_law

    law = check_law(law, "--law")
    if plant not in ("linear", "nonlinear"):
        raise SpecError(f"`plant`: got {plant!r}, expected 'linear' or 'nonlinear'")
    if plant == "nonlinear" and law != "paper":
        raise SpecError(f"`--law {law}` with `--plant nonlinear`: the nonlinear reproduction flies the paper's law "
                        "with its flight-implementation additions (ilcdob.design.flown) and has no other law; use "
                        "--plant linear, or --law paper")
    check_output_path(out, folder=True, overwrite=overwrite)
    flt, digest = fleet_and_hash(fleet)
    if plant == "nonlinear":
        from ilcdob.validation.nonlinear import NonlinearSettings, reproduce_nonlinear

        res = reproduce_nonlinear(flt if fleet else None, list(scenarios), iterations, NonlinearSettings(seed=seed),
                                  progress=progress)
    else:
        from ilcdob.validation.reproduce import reproduce

        res = reproduce(flt, list(scenarios), iterations, law=law, progress=progress)
    _write_folder(out, _provenance("reproduce", argv, digest, res.law), res.files(figures=figures),
                  report_files(res.fleet, [sr.order for sr in res.scenarios], figures=figures), overwrite=overwrite)
    return res


@dataclass(frozen=True)
class IdentifyInputs:
    """How to read the flight files of :func:`identify_to_json`.

    Attributes
    ----------
    input, output : str
        Input and output signal: CSV/Parquet column, ULog ``TOPIC.FIELD`` or DataFlash
        ``MESSAGE.FIELD``.
    time : str or None
        Time column of CSV/Parquet files (None: ``time``).
    time_unit : str or None
        Unit of that column: s, ms, us or ns (None: the file's ``# units:`` line, else s).
    start, stop : float or None
        Segment of the log, s on its clock.
    """

    input: str
    output: str
    time: str | None = None
    time_unit: str | None = None
    start: float | None = None
    stop: float | None = None

    def load(self, files: Sequence[str | Path]) -> list[Any]:
        """Load ``files`` as FlightData with signals ``u`` and ``y``.

        Parameters
        ----------
        files : sequence of str or Path
            .csv, .parquet, .ulg or .bin files.
        """
        from ilcdob.identification.loaders import load_flight

        kw: dict[str, Any] = {"start": self.start, "stop": self.stop}
        if self.time is not None:
            kw["time"] = self.time
        if self.time_unit is not None:
            logs = [f for f in files if Path(f).suffix.lower() not in (".csv", ".parquet", ".pq")]
            if logs:
                raise SpecError(f"`--time-unit`: given with {logs[0]}; a flight log carries its own clock, so "
                                "--time-unit applies to .csv/.parquet files only")
            kw["units"] = {"time": self.time_unit}
        return [load_flight(f, {"u": self.input, "y": self.output}, **kw) for f in files]


def identify_to_json(files: Sequence[str | Path], inputs: IdentifyInputs, structure: Any, options: Any, out: str | Path,
                     *, validate: Sequence[str | Path] = (), plot: str | Path | None = None,
                     progress: Progress | None = None, argv: Sequence[str] | None = None) -> Any:
    """Fit a continuous-time transfer function to flight files and write ``model.json``.

    Parameters
    ----------
    files : sequence of str or Path
        Estimation data.
    inputs : IdentifyInputs
        Signals and clock of the files.
    structure : ilcdob.uncertainty.ModelStructure
        Model orders.
    options : ilcdob.identification.FitOptions
        Fit settings (delay, trend, limits).
    out : str or Path
        ``model.json`` to write (atomically).
    validate : sequence of str or Path
        Held-out data files.
    plot : str or Path, optional
        Folder for the compare / residual / Bode figures (written as a unit).
    progress : callable, optional
        ``progress(done, total, what)``.
    argv : sequence of str, optional
        Command line, recorded in the model file.

    Returns
    -------
    tuple of (TFEstimate, list of FlightData, list of FlightData)
        The estimate, the estimation and the held-out data.
    """
    from ilcdob.identification.plots import fit_figures
    from ilcdob.identification.tfest import tfest

    check_output_path(out, folder=False)
    if plot is not None:
        check_output_path(plot, folder=True)
    est_data = inputs.load(files)
    val_data = inputs.load(validate)
    est = tfest(est_data, "u", "y", structure, options, validation=val_data or None, progress=progress)
    prov = _provenance("identify", argv)
    data = est.to_dict()
    data["signals"] = {"input": inputs.input, "output": inputs.output}
    data["files"] = {"estimation": [str(f) for f in files], "validation": [str(f) for f in validate]}
    data["provenance"] = prov.to_dict()
    if plot is not None:
        _write_folder(plot, prov, fit_figures(est, est_data, val_data))
    write_file(out, data)
    return est, est_data, val_data


def identify_fleet_to_folder(out: str | Path, *, fleet: str | Path | None = None, seed: int = 0,
                             overwrite: bool = False, progress: Progress | None = None,
                             argv: Sequence[str] | None = None) -> Any:
    """Fly step and chirp experiments with the nonlinear vehicles and identify every plant.

    Parameters
    ----------
    out : str or Path
        Output folder, written as a unit.
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    seed : int
        Seed of the sensor noise.
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    progress : callable, optional
        ``progress(done, total, what)``.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.

    Returns
    -------
    FleetIdentification
    """
    from ilcdob.identification.fleet_id import identify_fleet

    check_output_path(out, folder=True, overwrite=overwrite)
    flt, digest = fleet_and_hash(fleet)
    result = identify_fleet(flt, seed=seed, progress=progress)
    _write_folder(out, _provenance("identify-fleet", argv, digest), result.files(), overwrite=overwrite)
    return result


def _csv_header(path: str | Path) -> list[str]:
    """Column names of a CSV file (first line that is neither blank nor a ``#`` comment); [] if unreadable."""
    try:
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    return [c.strip().strip('"') for c in line.split(",")]
    except (OSError, UnicodeDecodeError):
        return []  # load_csv reports it
    return []


def design_to_folder(out: str | Path, source: str, target: str, *, fleet: str | Path | None = None,
                     method: str = "closed-form", rho: float = 0.95, samples: int = 8, bound: float | None = None,
                     n: int | None = None, law: str = "paper", trial: str | Path | None = None,
                     c_prefix: str | None = None, c_float: bool = False, overwrite: bool = False,
                     argv: Sequence[str] | None = None) -> tuple[Any, dict[str, Any]]:
    """Design the learning filters of ``target`` from ``source`` and write the design folder.

    Parameters
    ----------
    out : str or Path
        Output folder, written as a unit.
    source, target : str
        Systems j-1 (learned from) and j (learning).
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    method : str
        closed-form, fir, norm-optimal, robust or robust-set (:data:`ilcdob.design.pair.METHODS`).
    rho : float
        robust: guaranteed improvement; robust-set: on every plant of the Delta set.
    samples : int
        fir/robust: Delta-set samples per system.
    bound : float, optional
        Multiplicative uncertainty bound instead of the identified covariance.
    n : int, optional
        Trial length in samples for lifted matrices (default: the trial's, else 500).
    law : str
        Learning law (:mod:`ilcdob.design.laws`).
    trial : str or Path, optional
        CSV of the source's trial: time (s), error (m), learning (m/s^2) [, reference (m),
        acceleration (m/s^2)].
    c_prefix : str, optional
        Prefix of the C symbols.
    c_float : bool
        Also emit float C functions.
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.

    Returns
    -------
    tuple of (PairDesign, dict)
        The design and the ``filters.json`` content written.
    """
    from ilcdob.design.c_export import check_c_prefix, design_files
    from ilcdob.design.delta import MAX_DELTA_SAMPLES
    from ilcdob.design.laws import check_law
    from ilcdob.design.pair import design_pair, fleet_delta_sets
    from ilcdob.design.robust import RobustOptions
    from ilcdob.identification.loaders import load_csv
    from ilcdob.lifted import check_lifted_size
    from ilcdob.signals import FlightData

    if c_prefix is not None:
        check_c_prefix(c_prefix)
    if n is not None:
        check_lifted_size(n, "--n")
    if method in ("fir", "robust", "robust-set") and samples > MAX_DELTA_SAMPLES:
        raise SpecError(f"`--samples`: got {samples}, expected 1 to {MAX_DELTA_SAMPLES} Delta-set samples per system: "
                        f"every sample is a closed loop that --method {method} builds, flies and constrains on")
    law = check_law(law, "--law")
    if law == "multi-source":
        raise SpecError("`--law multi-source`: it learns from the trials of every earlier system at once, and "
                        "`ilcdob design` makes one pair's filters from one trial of --from; use `ilcdob reproduce "
                        "--law multi-source` for a learning chain, or ilcdob.design.multi_source.multi_source_learning "
                        "with every trial")
    if law == "exact-reference" and not trial:
        raise SpecError("`--law exact-reference`: the law needs the reference trajectory of the trial; give --trial "
                        "CSV with columns time (s), error (m), learning (m/s^2), reference (m) and, for controllers "
                        "with acceleration feed-forward, acceleration (m/s^2)")
    if method == "robust" and trial is None:
        raise SpecError("`--method robust`: the robust learning signal is an SOCP solved per trial; give the "
                        "previous system's trial with --trial CSV (columns time, error, learning)")
    check_output_path(out, folder=True, overwrite=overwrite)
    flt, digest = fleet_and_hash(fleet)
    columns = {"e": "error", "d_f": "learning"}
    if law == "exact-reference":
        columns["r"] = "reference"
        if "acceleration" in _csv_header(trial):
            columns["a"] = "acceleration"
    data = load_csv(trial, columns) if trial else None
    if data is not None and abs(data.ts - flt.sample_time) > 1e-9:
        raise SignalError(f"{trial}: sample time {data.ts} s differs from the fleet's {flt.sample_time} s")
    if data is not None and n is not None and n != len(data):
        raise SpecError(f"`--n`: got {n}, but the trial {trial} has {len(data)} samples; the learning signal is "
                        f"computed for the whole trial, so its matrices must be {len(data)} long: omit --n or give "
                        f"--n {len(data)}")
    n = n or (len(data) if data is not None else None)
    deltas = None
    if method in ("fir", "robust", "robust-set"):
        deltas = fleet_delta_sets(flt, [source, target], k=samples, bound=bound)
    reference = {}
    if law == "exact-reference":
        reference = {"reference": data["r"], "acceleration": data["a"] if "a" in data.signals else None}
    design = design_pair(flt, source, target, method, n=n, deltas=deltas,
                         robust=RobustOptions(rho=rho) if method in ("robust", "robust-set") else None,
                         law=law, **reference)
    filters = dict(design.filters)
    others: dict[str, Any] = {}
    arrays = design.lifted
    if data is not None and design.robust is not None:
        terms = design.reference
        res = design.robust.design(terms.error_in(data["e"]) if terms else data["e"], data["d_f"])
        d_f = terms.signal_out(res.d_f) if terms else res.d_f
        filters["trial"] = {"worst_ratio": res.worst_ratio, "ratios": res.ratios.tolist(), "rho": res.rho,
                            "status": res.status, "solve_time_s": res.solve_time}
        arrays = {"d_f": res.d_f, "ratios": res.ratios, "predicted_errors": res.errors}
    elif data is not None:
        d_f = design.learn(data["e"], data["d_f"])
    if arrays is not None:
        others["lifted.npz"] = lambda path, a=arrays: np.savez(path, **a)
    if data is not None:
        others["learning_signal.csv"] = FlightData(
            data.t, {"learning": d_f}, {"learning": "m/s^2"},
            source=f"learning signal of {target} from {trial}").to_csv
    if design.reference is not None:
        others["reference_terms.csv"] = FlightData(
            data.t, {"e_ref_source": design.reference.source_error, "correction": design.reference.correction},
            {"e_ref_source": "m", "correction": "m/s^2"},
            source=f"reference terms of {source} -> {target} for {trial}").to_csv
    files, written = design_files(filters, list(others), prefix=c_prefix, float_variant=c_float)
    _write_folder(out, _provenance("design", argv, digest, law), others, files, overwrite=overwrite)
    return design, written


def check_to_json(out: str | Path | None, *, fleet: str | Path | None = None, order: Sequence[str] | None = None,
                  bound: float | None = None, scale: float = 1.0, samples: int = 8,
                  argv: Sequence[str] | None = None) -> list[Any]:
    """The Theorem's condition per pair and frequency (paper Sec. III), optionally as JSON.

    Parameters
    ----------
    out : str or Path or None
        JSON file to write (None: none).
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    order : sequence of str, optional
        Learning order (default: file order).
    bound : float, optional
        Multiplicative uncertainty bound for every system (default: identified covariance).
    scale : float
        Scale of the identified standard deviations.
    samples : int
        Sampled plants per Delta set.
    argv : sequence of str, optional
        Command line, recorded in the file.

    Returns
    -------
    list of PairCheck
    """
    from ilcdob.design.pair import fleet_delta_sets
    from ilcdob.design.theorem import theorem_check

    if out is not None:
        check_output_path(out, folder=False)
    flt, digest = fleet_and_hash(fleet)
    order = list(order) if order else flt.names
    for name in order:
        flt.loop(name)  # unknown names: a clear error
    deltas = fleet_delta_sets(flt, order, k=samples, bound=bound, scale=scale)
    checks = theorem_check(flt, order, deltas)
    if out is not None:
        write_file(out, {"order": order, "pairs": [c.to_dict() for c in checks],
                         "provenance": _provenance("check", argv, digest).to_dict()})
    return checks


def compare_to_folder(out: str | Path | None, scenario: int, options: Any, *, fleet: str | Path | None = None,
                      methods: Sequence[str] | None = None, overwrite: bool = False,
                      progress: Progress | None = None, argv: Sequence[str] | None = None) -> Any:
    """Fly every learning design through a scenario, nominal and over the Delta set.

    Parameters
    ----------
    out : str or Path or None
        Output folder, written as a unit (None: nothing written).
    scenario : int
        Scenario id 1-4.
    options : ilcdob.validation.compare.CompareOptions
        Delta set, duration, robust settings, law.
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    methods : sequence of str, optional
        Designs to compare (default: :data:`ilcdob.design.pair.DEFAULT_METHODS`).
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    progress : callable, optional
        ``progress(done, total, what)``.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.

    Returns
    -------
    Comparison
    """
    from ilcdob.design.pair import DEFAULT_METHODS
    from ilcdob.validation.compare import compare_designs

    if out is not None:
        check_output_path(out, folder=True, overwrite=overwrite)
    flt, digest = fleet_and_hash(fleet)
    cmp = compare_designs(flt, scenario, list(methods or DEFAULT_METHODS), options, progress=progress)
    if out is not None:
        _write_folder(out, _provenance("compare", argv, digest, options.law),
                      cmp.files(rho=options.robust.rho if options.robust else None), overwrite=overwrite)
    return cmp


def extensions_to_folder(out: str | Path, *, fleet: str | Path | None = None, scenarios: Sequence[int] = (1, 2, 3, 4),
                         overwrite: bool = False, argv: Sequence[str] | None = None) -> Any:
    """Measure the two extensions beyond the paper (exact reference term, multi-source) per scenario.

    Parameters
    ----------
    out : str or Path
        Output folder, written as a unit.
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    scenarios : sequence of int
        Scenario ids 1-4.
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.

    Returns
    -------
    ExtensionsResult
    """
    from ilcdob.validation.extensions import extensions_study

    check_output_path(out, folder=True, overwrite=overwrite)
    flt, digest = fleet_and_hash(fleet)
    result = extensions_study(flt, list(scenarios))
    _write_folder(out, _provenance("extensions", argv, digest), result.files(out=str(out)), overwrite=overwrite)
    return result


def campaign_to_folder(out: str | Path, options: Any, *, fleet: str | Path | None = None,
                       scheduler: str | None = None, workers: int | None = None, overwrite: bool = False,
                       progress: Progress | None = None, dashboard: Callable[[str], None] | None = None,
                       argv: Sequence[str] | None = None) -> Any:
    """Monte Carlo campaign on Dask; resumable: run it again on the same folder to continue.

    Parameters
    ----------
    out : str or Path
        Output folder: the sample store is appended in place while the campaign runs; the
        summary files are written as a unit with it at the end.
    options : ilcdob.validation.campaign.CampaignOptions
        Samples, methods, scenarios, Delta set, law.
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    scheduler : str, optional
        Dask scheduler ``tcp://HOST:PORT`` (default: a local cluster).
    workers : int, optional
        Local cluster: worker processes.
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    progress : callable, optional
        ``progress(done, total, what)``.
    dashboard : callable, optional
        Called with a line naming the Dask dashboard link once the cluster is up.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.

    Returns
    -------
    CampaignResult
    """
    from ilcdob.validation.campaign import STORE_FILES, run_campaign

    check_output_path(out, folder=True, overwrite=overwrite, resumable=STORE_FILES)
    flt, digest = fleet_and_hash(fleet)
    result = run_campaign(flt, options, out, scheduler=scheduler, workers=workers, progress=progress,
                          dashboard=dashboard)
    _write_folder(out, _provenance("campaign", argv, digest, options.law), result.files(), overwrite=overwrite,
                  keep=STORE_FILES)
    return result


def add_to_fleet(fleet_file: str | Path, name: str, model: str | Path, controller: Any, dob: Any,
                 sample_time: float | None = None) -> Fleet:
    """Add a system flying an identified ``model.json`` to a fleet file (created if needed).

    Parameters
    ----------
    fleet_file : str or Path
        Fleet TOML to create or append to; written atomically after the new fleet validates.
    name : str
        Name of the new system.
    model : str or Path
        ``model.json`` of ``ilcdob identify``.
    controller : ilcdob.specs.PIDSpec
        The system's PID.
    dob : ilcdob.specs.DOBSpec
        The system's DOB low-pass.
    sample_time : float, optional
        New fleet file: sample time in s (default: the model's).

    Returns
    -------
    Fleet
    """
    from ilcdob.fleet_io import add_system

    check_output_path(fleet_file, folder=False)
    return add_system(fleet_file, name, model, controller, dob, sample_time=sample_time)


def report_to_html(dirs: Sequence[str | Path], out: str | Path) -> Path:
    """One self-contained HTML report from output folders of reproduce, compare and campaign.

    Parameters
    ----------
    dirs : sequence of str or Path
        Output folders.
    out : str or Path
        HTML file to write (atomically).

    Returns
    -------
    Path
    """
    check_output_path(out, folder=False)
    return write_file(out, build_report(dirs))
