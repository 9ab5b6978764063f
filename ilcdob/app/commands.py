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
| :func:`design_to_folder` | ``design`` | filters.json, filters.h/.c, README.md, bode.png, lifted.npz, learning_signal.csv |
| :func:`learn_to_folder` | ``learn`` | learning_signal.csv/.bin/.h, learning.json |
| :func:`check_to_json` | ``check`` | the check as JSON: exact worst case, paper's condition |
| :func:`compare_to_folder` | ``compare`` | compare.json, compare.txt, compare_ratios.png |
| :func:`extensions_to_folder` | ``extensions`` | extensions.json, README.md |
| :func:`campaign_to_folder` | ``campaign`` | samples.jsonl (resumable), campaign.json, campaign.txt, figure |
| :func:`add_to_fleet` | ``fleet add`` | the fleet file |
| :func:`report_to_html` | ``report`` | one self-contained HTML file |
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilcdob.atomic import remove_folders
from ilcdob.errors import FleetError, SignalError, SpecError
from ilcdob.inputs import MAX_LOG_BYTES, check_input, read_bytes, read_json

from .html import build_report, report_files
from .output import OutputError, OutputFolder, Provenance, check_output_path, verify_manifest, write_file

if TYPE_CHECKING:  # python-control and the loop models load with the first command that needs a fleet
    from ilcdob.fleet import Fleet

__all__ = ["Progress", "fleet_and_hash", "reproduce_to_folder", "identify_to_json",
           "identify_fleet_to_folder", "design_to_folder", "design_shortfalls", "check_to_json", "compare_to_folder", "extensions_to_folder", "campaign_to_folder",
           "add_to_fleet", "report_to_html", "LogClock", "IdentifyInputs", "learn_to_folder", "TrialColumns"]

#: ``progress(done, total, what)``: called as long work advances.
Progress = Callable[[int, int, str], None]


def fleet_and_hash(path: str | Path | None, axis: str = "x") -> tuple[Fleet, str]:
    """The fleet of a ``--fleet`` option (None: the built-in fleet) and the SHA-256 of its file.

    Parameters
    ----------
    path : str or Path or None
        Fleet TOML file.
    axis : {"x", "y", "z"}
        The axis (``--axis``): y and z come from the file's per-axis sections (:mod:`ilcdob.fleet`);
        the built-in fleet has the x axis only.
    """
    if axis != "x" and not path:
        raise SpecError(f"`--axis {axis}`: the built-in fleet describes the x axis only (the paper's); give a "
                        f"--fleet file with [system.{axis}] sections")
    from ilcdob.fleet import DEFAULT_FLEET_PATH, default_fleet, load_fleet

    fleet = load_fleet(path, axis) if path else default_fleet()
    data = read_bytes(path if path else DEFAULT_FLEET_PATH, "fleet file", error=FleetError)
    return fleet, hashlib.sha256(data).hexdigest()


def _provenance(command: str, argv: Sequence[str] | None, fleet_hash: str | None = None,
                law: str | None = None) -> Provenance:
    return Provenance(command, list(argv or []), fleet_hash, law)


@dataclass(frozen=True)
class _Output:
    """The output folder of one command run: checked before any work, written as a unit after it.

    Attributes
    ----------
    command : str
        The command, recorded in ``manifest.json``.
    out : str or Path or None
        The folder (None: the run writes nothing, e.g. ``compare`` without ``--out``).
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.
    """

    command: str
    out: str | Path | None
    overwrite: bool = False
    argv: Sequence[str] | None = None

    def check(self, inputs: dict[str, Any] | None = None, resumable: Sequence[str] = ()) -> Path | None:
        """Check the folder before any work (:func:`check_output_path`); returns the path to write (None: none).

        Parameters
        ----------
        inputs : dict, optional
            The run's inputs by option name, which the folder must neither be, hold nor lie in.
        resumable : sequence of str
            File names of an unfinished run that the folder may hold (a campaign's sample store).

        Raises
        ------
        OutputError
            The folder cannot be written (see :func:`check_output_path`).
        """
        if self.out is None:
            return None
        return check_output_path(self.out, folder=True, overwrite=self.overwrite, resumable=resumable, inputs=inputs)

    def check_and_load(self, fleet: str | Path | None, axis: str = "x",
                       inputs: dict[str, Any] | None = None) -> tuple[Fleet, str]:
        """:meth:`check` (``fleet`` among the inputs, first), then the fleet and its hash (:func:`fleet_and_hash`).

        Parameters
        ----------
        fleet : str or Path or None
            Fleet TOML (None: the built-in fleet).
        axis : {"x", "y", "z"}
            The axis loaded.
        inputs : dict, optional
            The run's other inputs by option name.
        """
        self.check({"--fleet": fleet, **(inputs or {})})
        return fleet_and_hash(fleet, axis)

    def write(self, *maps: dict[str, Any], digest: str | None = None, law: str | None = None,
              keep: Sequence[str] = ()) -> None:
        """Write the content maps into the folder as one unit (:class:`OutputFolder`); nothing without a folder.

        Parameters
        ----------
        *maps : dict of str to content
            File name -> content (:mod:`ilcdob.app.output`).
        digest : str, optional
            SHA-256 of the fleet file, recorded in ``manifest.json``.
        law : str, optional
            The learning law, recorded in ``manifest.json``.
        keep : sequence of str
            Files of the existing folder carried into the new one.
        """
        if self.out is None:
            return
        provenance = _provenance(self.command, self.argv, digest, law)
        with OutputFolder(self.out, provenance, overwrite=self.overwrite, keep=keep) as folder:
            for files in maps:
                folder.add_all(files)


#: Most learning iterations of ``reproduce`` (the paper flies 3).
MAX_ITERATIONS = 100
#: Seconds of one learning iteration of one scenario on one core, by plant: every system flown once more
#: (rotorpy: with every law in each of its three disturbances). Measured: linear, 3 against 1 iteration of
#: the four scenarios; nonlinear, 2 against 1 of scenario 1; rotorpy estimated from its default run (24 min
#: on 2 cores).
ITERATION_SECONDS = {"linear": 0.1, "nonlinear": 1.1, "rotorpy": 190.0}
#: Most processes of ``reproduce --plant rotorpy --workers`` per usable core.
WORKERS_PER_CORE = 2


def _duration(seconds: float) -> str:
    """``seconds`` in the largest unit that keeps it at least 1 (s, min, h, days)."""
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def _check_reproduce_counts(iterations: object, n_scenarios: int, plant: str, seed: object,
                            workers: int | None) -> None:
    """``reproduce``'s counts: iterations within :data:`MAX_ITERATIONS` (the message states what they would
    take), a seed >= 0, workers within :data:`WORKERS_PER_CORE` per usable core."""
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise SpecError(f"`--iterations`: got {iterations!r}, expected an integer >= 1")
    if iterations > MAX_ITERATIONS:
        each = ITERATION_SECONDS[plant]
        raise SpecError(f"`--iterations`: got {iterations}, expected 1 to {MAX_ITERATIONS} learning iterations (the "
                        f"paper flies 3): each flies every system of each scenario once more, about {each:g} s per "
                        f"scenario on one core with the {plant} plant, so {iterations} iterations of "
                        f"{n_scenarios} scenario(s) would take about {_duration(iterations * n_scenarios * each)}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SpecError(f"`seed`: got {seed!r}, expected an integer >= 0")
    if workers is not None:
        cores = len(os.sched_getaffinity(0))
        if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= WORKERS_PER_CORE * cores:
            raise SpecError(f"`--workers`: got {workers!r}, expected 1 to {WORKERS_PER_CORE * cores} processes "
                            f"({WORKERS_PER_CORE} per usable core, {cores} here): more than the cores only share them")


def reproduce_to_folder(out: str | Path, *, fleet: str | Path | None = None, scenarios: Sequence[int] = (1, 2, 3, 4),
                        iterations: int = 3, plant: str = "linear", seed: int = 0, law: str = "paper",
                        figures: bool = True, overwrite: bool = False, progress: Progress | None = None,
                        argv: Sequence[str] | None = None, order: Sequence[str] | None = None,
                        sensor_noise: float | None = None, bandwidth: object = "auto",
                        workers: int | None = None, figure_workers: int | None = None,
                        controller: str = "ilcdob", vehicles: str | Path | None = None) -> Any:
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
    plant : {"linear", "nonlinear", "rotorpy"}
        linear: the fleet's models; nonlinear: identify and fly the 6-DOF quadrotors; rotorpy: identify
        and fly rotorpy's multirotors in the paper's disturbance and in wind, every law
        (:mod:`ilcdob.validation.vehicle_reproduction`; no fleet file, law, order or band).
    seed : int
        Seed of the sensor noise (rotorpy: of the Dryden turbulence).
    law : str
        Learning law (:mod:`ilcdob.design.law.laws`; the nonlinear plant: paper or exact-reference).
    figures : bool
        Write the PNG figures.
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    progress : callable, optional
        ``progress(done, total, what)``.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.
    order : sequence of str, optional
        Learning order by system name, flown in every scenario
        (:func:`ilcdob.validation.scenarios.check_order`); None: each scenario's (scenario 4
        flies the 1st, 3rd, 2nd system of a three-system fleet, the others the file order).
    sensor_noise : float, optional
        White position-sensor noise of every flight, m (default: 0 on the linear plant,
        0.5 mm on the nonlinear one).
    bandwidth : "auto", float or None
        The learning band (:mod:`ilcdob.design.filters.band`).
    workers : int, optional
        Processes flying the scenarios; the rotorpy plant only (default 1).
    figure_workers : int, optional
        Processes building and rendering the figures (:class:`ilcdob.validation.figures.FigureRenderer`;
        default one per usable core): on the linear plant the fleet's figures while the first
        scenario flies and each scenario's while the next flies, the others once every scenario is flown.
    controller : {"ilcdob", "own"}
        Who flies the vehicles' position loop: ilcdob's PID + DOB, or (``plant="rotorpy"`` only) rotorpy's own
        SE3 controller with the learning on a setpoint channel (:mod:`ilcdob.validation.channel_reproduction`;
        no fleet file, law, order, band or workers).
    vehicles : str or Path, optional
        With ``plant="rotorpy"``: a TOML file of the run's airframes
        (:func:`ilcdob.validation.channel_reproduction.load_vehicles`; default rotorpy's and, with
        ``controller="own"``, one of ours); ``position_gains`` only with ``controller="own"``.

    Returns
    -------
    ReproductionResult or ChannelReproduction

    Raises
    ------
    SpecError
        Bad settings, or options the chosen plant and controller take none of (``vehicles`` off rotorpy).
    """
    if vehicles is not None and plant != "rotorpy":
        raise SpecError(f"`--vehicles`: got {str(vehicles)!r}; a vehicles file gives the airframes of "
                        "--plant rotorpy (the linear and nonlinear plants fly a fleet: --fleet)")
    run = _Reproduction(list(scenarios), iterations, plant, seed, law, figures, order, sensor_noise, bandwidth,
                        workers, figure_workers, progress, controller).checked()
    output = _Output("reproduce", out, overwrite, argv)
    if run.controller == "own":
        return run.fly_own(output, fleet, vehicles)
    return run.fly_vehicles(output, fleet, vehicles) if plant == "rotorpy" else run.fly_fleet(output, fleet)


def _vehicle_airframes(path: str | Path) -> dict[str, Any]:
    """``VehicleSettings`` fields of a vehicles file for ilcdob's controller: the names and complete airframes.

    Raises
    ------
    SpecError
        A vehicle with ``position_gains``: ilcdob's PID flies the position loop (rotorpy's SE3 only its attitude).
    """
    from ilcdob.validation.channel_reproduction import load_vehicles

    chosen = load_vehicles(path)
    gains = [v.name for v in chosen if v.position_gains is not None]
    if gains:
        raise SpecError(f"{path}: vehicles {gains} give `position_gains`, but with --controller ilcdob ilcdob's PID + "
                        "DOB flies the position loop and rotorpy's SE3 controller only the attitude; remove them, or "
                        "fly --controller own")
    return {"vehicles": tuple(v.name for v in chosen), "airframes": {v.name: v.airframe for v in chosen}}


@dataclass(frozen=True)
class _Reproduction:
    """The settings of one ``reproduce`` run: :func:`reproduce_to_folder`'s parameters but its folder's and fleet."""

    scenarios: list[int]
    iterations: int
    plant: str
    seed: int
    law: str
    figures: bool
    order: Sequence[str] | None
    sensor_noise: float | None
    bandwidth: object
    workers: int | None
    figure_workers: int | None
    progress: Progress | None
    controller: str = "ilcdob"

    def checked(self) -> _Reproduction:
        """The settings with the law's name checked (:func:`ilcdob.design.law.laws.check_law`).

        Raises
        ------
        SpecError
            A bad law, plant, count, seed or number of workers, before any work.
        """
        from ilcdob.design.law.laws import check_law
        from ilcdob.validation.figures import render_workers

        law = check_law(self.law, "--law")
        render_workers(self.figure_workers, name="figure_workers")  # a bad count fails before the run
        if self.plant not in ("linear", "nonlinear", "rotorpy"):
            raise SpecError(f"`plant`: got {self.plant!r}, expected 'linear', 'nonlinear' or 'rotorpy'")
        if self.controller not in ("ilcdob", "own"):
            raise SpecError(f"`--controller`: got {self.controller!r}, expected 'ilcdob' (its PID + DOB flies the "
                            "vehicles) or 'own' (the vehicle's own controller, --plant rotorpy)")
        if self.controller == "own" and self.plant != "rotorpy":
            raise SpecError(f"`--controller own`: needs --plant rotorpy (got {self.plant!r}): the linear and nonlinear "
                            "plants are ilcdob's own loop; rotorpy's vehicles fly their SE3 controller")
        if self.workers is not None and self.plant != "rotorpy":
            raise SpecError(f"`--workers`: got {self.workers}, but only `--plant rotorpy` flies in parallel (plant "
                            f"{self.plant!r})")
        _check_reproduce_counts(self.iterations, len(self.scenarios), self.plant, self.seed, self.workers)
        return replace(self, law=law)

    def _noise(self) -> dict[str, float]:
        return {} if self.sensor_noise is None else {"sensor_noise_std": self.sensor_noise}

    def _given(self, fleet: str | Path | None, *more: tuple[str, object]) -> list[str]:
        """The options given that a run flying its own vehicles takes none of: fleet, order, a law other than the
        paper's, a band other than ``auto``, and ``more`` (option, value) pairs."""
        opts = (("--fleet", fleet), ("--order", self.order), ("--law", None if self.law == "paper" else self.law),
                ("--bandwidth", None if self.bandwidth == "auto" else self.bandwidth), *more)
        return [opt for opt, value in opts if value is not None]

    def fly_vehicles(self, output: _Output, fleet: str | Path | None, vehicles: str | Path | None = None) -> Any:
        """``--plant rotorpy``: identify and fly rotorpy's multirotors, write the folder; returns the result.

        Parameters
        ----------
        output : _Output
            The reproduction folder.
        fleet : str or Path or None
            Must be None: the vehicles are rotorpy's.
        vehicles : str or Path, optional
            The run's airframes (:func:`~ilcdob.validation.channel_reproduction.load_vehicles`; default rotorpy's
            crazyflie, hummingbird and PX4 set).

        Raises
        ------
        SpecError
            A fleet, order, law or band given: the run flies its own vehicles with every law; a vehicles file with
            ``position_gains`` (ilcdob's PID flies the position loop).
        """
        given = self._given(fleet)
        if given:
            raise SpecError(f"`--plant rotorpy` takes no {', '.join(given)}: it flies its own vehicles with every law "
                            "and the band chosen from each trial")
        output.check({} if vehicles is None else {"--vehicles": vehicles})
        from ilcdob.validation.figures import FigureRenderer
        from ilcdob.validation.vehicle_reproduction import VehicleSettings, reproduce_vehicles

        chosen = {} if vehicles is None else _vehicle_airframes(vehicles)
        settings = VehicleSettings(dryden_seed=self.seed, workers=self.workers or 1, **chosen, **self._noise())
        res = reproduce_vehicles(self.scenarios, self.iterations, settings, progress=self.progress)
        with FigureRenderer(self.figure_workers) as renderer:
            content = _report(res, self.figures, renderer)
        output.write(content, law=res.law)
        return res

    def fly_own(self, output: _Output, fleet: str | Path | None, vehicles: str | Path | None = None) -> Any:
        """``--plant rotorpy --controller own``: identify rotorpy's vehicles' channels and fly the scenarios on their
        own SE3 controllers (:func:`~ilcdob.validation.channel_reproduction.reproduce_channels`), write the folder.

        Parameters
        ----------
        output : _Output
            The reproduction folder.
        fleet : str or Path or None
            Must be None: the vehicles are the run's.
        vehicles : str or Path, optional
            The run's airframes (:func:`~ilcdob.validation.channel_reproduction.load_vehicles`; default rotorpy's
            and one of ours).

        Returns
        -------
        ChannelReproduction

        Raises
        ------
        SpecError
            A fleet, order, law, band or workers given.
        """
        given = self._given(fleet, ("--workers", self.workers))
        if given:
            raise SpecError(f"`--controller own` takes no {', '.join(given)}: it flies its own vehicles with the "
                            "paper's law and the wind law, the band chosen from each trial, in one process")
        output.check({} if vehicles is None else {"--vehicles": vehicles})
        from ilcdob.validation.channel_reproduction import ChannelSettings, load_vehicles, reproduce_channels

        chosen = {} if vehicles is None else {"vehicles": load_vehicles(vehicles)}
        settings = ChannelSettings(dryden_seed=self.seed, **chosen, **({} if self.sensor_noise is None else
                                                                       {"sensor_noise_std": self.sensor_noise}))
        res = reproduce_channels(self.scenarios, self.iterations, settings, progress=self.progress)
        output.write(res.files(self.figures), law="paper")
        return res

    def fly_fleet(self, output: _Output, fleet: str | Path | None) -> Any:
        """The linear or nonlinear plant: fly the fleet's scenarios, write the folder; returns the result.

        Parameters
        ----------
        output : _Output
            The reproduction folder.
        fleet : str or Path or None
            Fleet TOML (None: the built-in fleet).

        Raises
        ------
        SpecError
            The multi-source law on the nonlinear plant, a bad band or order.
        """
        from ilcdob.design.filters.band import check_bandwidth
        from ilcdob.validation.figures import FigureRenderer
        from ilcdob.validation.scenarios import check_order

        if self.plant == "nonlinear" and self.law == "multi-source":
            raise SpecError("`--law multi-source` with `--plant nonlinear`: the nonlinear vehicles learn one pair at a "
                            "time (the airframe correction is per pair); use --law paper or exact-reference, or "
                            "--plant linear")
        bandwidth = check_bandwidth(self.bandwidth, None)
        flt, digest = output.check_and_load(fleet)
        flt.require_paper_loops("`ilcdob reproduce`")
        check_bandwidth(bandwidth, flt.sample_time)  # a corner, against the fleet's Nyquist frequency
        order = None if self.order is None else check_order(flt.names, self.order, "--order")
        with FigureRenderer(self.figure_workers) as renderer:
            if self.plant == "nonlinear":
                from ilcdob.validation.nonlinear import NonlinearSettings, reproduce_nonlinear

                settings = NonlinearSettings(seed=self.seed, bandwidth=bandwidth, **self._noise())
                res = reproduce_nonlinear(flt if fleet else None, self.scenarios, self.iterations, settings,
                                          progress=self.progress, order=order, law=self.law)
            else:
                res = self._fly_linear(flt, bandwidth, order, renderer)
            content = _report(res, self.figures, renderer)
        output.write(content, digest=digest, law=res.law)
        return res

    def _fly_linear(self, flt: Fleet, bandwidth: object, order: list[str] | None, renderer: Any) -> Any:
        """The linear plant, each scenario's figures rendered while the next one flies."""
        from ilcdob.validation.figures import fleet_figures, scenario_figures
        from ilcdob.validation.reproduce import reproduce

        def flown(sr: Any) -> None:  # its figures are rendered while the next scenario flies
            renderer.submit(scenario_figures(sr, self.iterations, pending=True))

        if self.figures:  # the fleet's figures while the first scenario flies
            renderer.submit(fleet_figures(flt, pending=True))
        return reproduce(flt, self.scenarios, self.iterations, law=self.law, progress=self.progress, order=order,
                         sensor_noise_std=0.0 if self.sensor_noise is None else self.sensor_noise, seed=self.seed,
                         bandwidth=bandwidth, on_scenario=flown if self.figures else None)


def _report(res: Any, figures: bool, renderer: Any) -> dict[str, Any]:
    """The reproduction folder's content (:meth:`ReproductionResult.files` and :func:`report_files`), every
    figure built and rendered to PNG by ``renderer`` (:class:`ilcdob.validation.figures.FigureRenderer`)."""
    if figures:
        from ilcdob.validation.figures import reproduction_figures

        files = res.files(reproduction_figures(res, pending=True))
    else:
        files = res.files()
    report = report_files(res.fleet, [sr.order for sr in res.scenarios], figures=figures, pending=True)
    clash = sorted(set(files) & set(report))
    if clash:
        raise RuntimeError(f"reproduction report: {clash} written twice (results and report inputs)")
    return renderer.finish({**files, **report})


@dataclass(frozen=True, kw_only=True)
class LogClock:
    """Where a flight file's samples are read: its time column and segment (keyword-only fields).

    Attributes
    ----------
    time : str or None
        Time column of CSV/Parquet files (None: ``time``).
    time_unit : str or None
        Unit of that column: s, ms, us or ns (None: the file's ``# units:`` line, else s).
    start, stop : float or None
        Segment of the log, s on its clock.
    resample : float or None
        Sample time every file is resampled to, s (:meth:`ilcdob.signals.FlightData.resampled`: anti-aliased,
        recorded in ``metadata["rate_change"]``); None: as logged.
    """

    time: str | None = None
    time_unit: str | None = None
    start: float | None = None
    stop: float | None = None
    resample: float | None = None

    def load_fields(self, files: Sequence[str | Path], fields: dict[str, str]) -> list[Any]:
        """Load ``files`` as FlightData with ``fields`` (signal name -> column or selector).

        Parameters
        ----------
        files : sequence of str or Path
            .csv, .parquet, .ulg or .bin files.
        fields : dict of str to str
            Signal name -> CSV/Parquet column, ULog ``TOPIC.FIELD`` or DataFlash ``MESSAGE.FIELD``.

        Returns
        -------
        list of FlightData
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
        data = [load_flight(f, fields, **kw) for f in files]
        return data if self.resample is None else [fd.resampled(self.resample) for fd in data]


@dataclass(frozen=True)
class IdentifyInputs(LogClock):
    """How to read the flight files of :func:`identify_to_json` (and, keyword-only, :class:`LogClock`'s fields).

    Attributes
    ----------
    input, output : str
        Input and output signal: CSV/Parquet column, ULog ``TOPIC.FIELD`` or DataFlash
        ``MESSAGE.FIELD``.
    segment : float or None
        Cut every loaded file (estimation and held-out alike) into consecutive windows of this
        many seconds, each fitted with its own initial condition (:func:`ilcdob.signals.segments`:
        a last piece of at most half a window joins the window before it). None: each file whole.

    Raises
    ------
    SpecError
        ``input`` and ``output`` name the same signal, or ``segment`` is not a finite number > 0.
    """

    input: str
    output: str
    segment: float | None = None

    def __post_init__(self) -> None:
        if self.input == self.output:
            raise SpecError(f"`--input` and `--output`: both name {self.input!r}; a model from a signal to itself "
                            "is the identity: name the command (input) and the response (output)")
        if self.segment is not None:
            from ilcdob.signals import segments

            segments([], self.segment, name="--segment")  # the value alone; window sizes once the files are read

    def load(self, files: Sequence[str | Path]) -> list[Any]:
        """Load ``files`` as FlightData with signals ``u`` and ``y``.

        Parameters
        ----------
        files : sequence of str or Path
            .csv, .parquet, .ulg or .bin files.
        """
        return self.load_fields(files, {"u": self.input, "y": self.output})


def _identify_outputs(files: Sequence[str | Path], validate: Sequence[str | Path], out: str | Path,
                      plot: str | Path | None) -> tuple[Path, Path | None]:
    """``identify``'s model file and figure folder, checked against the flight files and each other."""
    logs = {"flight file": list(files), "--validate": list(validate)}
    out = check_output_path(out, folder=False, inputs=logs)
    if plot is not None:
        plot = check_output_path(plot, folder=True, inputs=logs, option="--plot")
        if Path(os.path.realpath(out)).is_relative_to(os.path.realpath(plot)):
            raise OutputError(f"`--out` ({out}): lies inside `--plot` ({plot}), a folder that is replaced as a whole; "
                              "write the model beside the figure folder, not in it")
    return out, plot


def _order_fitter(est_data: list[Any], val_data: list[Any], structures: list[Any],
                  progress: Progress | None) -> Callable[[Any, Any], Any]:
    """``fit(structure, options)`` on ``identify``'s data; with several orders each progress line names its order."""
    from ilcdob.identification.tfest import tfest

    def fit(st: Any, opts: Any) -> Any:  # several orders: each progress line names the one it fits
        named = progress
        if progress is not None and len(structures) > 1:
            counts = [(st.n_poles, "pole"), (st.n_zeros, "zero")] + ([(st.n_integrators, "integrator")]
                                                                       if st.n_integrators else [])
            label = (", ".join(f"{k} {word}{'s' if k != 1 else ''}" for k, word in counts)
                     + (", from the fit it contains" if opts.initial is not None else ""))
            named = lambda done, total, what: progress(done, total, f"{label}: {what}")  # noqa: E731
        return tfest(est_data, "u", "y", st, opts, validation=val_data or None, progress=named)

    return fit


def identify_to_json(files: Sequence[str | Path], inputs: IdentifyInputs, structure: Any, options: Any, out: str | Path,
                     *, validate: Sequence[str | Path] = (), plot: str | Path | None = None,
                     progress: Progress | None = None, argv: Sequence[str] | None = None,
                     zero_at_origin: bool = False) -> Any:
    """Fit a continuous-time transfer function to flight files and write ``model.json``.

    Parameters
    ----------
    files : sequence of str or Path
        Estimation data.
    inputs : IdentifyInputs
        Signals and clock of the files.
    structure : ilcdob.uncertainty.ModelStructure or sequence of them
        Model orders; several: each is fitted and compared (:func:`~ilcdob.identification.orders.compare_orders`), the chosen one
        written with the comparison in ``solver["order_comparison"]``.
    options : ilcdob.identification.FitOptions
        Fit settings (delay, trend, limits).
    out : str or Path
        ``model.json`` to write (atomically); not one of the flight files, not inside ``plot``.
    validate : sequence of str or Path
        Held-out data files.
    plot : str or Path, optional
        Folder for the compare / residual / Bode figures, written as a unit with the model (staged and
        sealed, the model written, then the folder swapped in: a failed run, a full disk included, leaves neither).
    progress : callable, optional
        ``progress(done, total, what)``.
    argv : sequence of str, optional
        Command line, recorded in the model file.
    zero_at_origin : bool
        Fix one zero of the chosen fit at s = 0 (:func:`ilcdob.identification.origin_zero.with_zero_at_origin`).

    Returns
    -------
    tuple of (TFEstimate, list of FlightData, list of FlightData)
        The estimate, the estimation and the held-out data as fitted (the windows of
        ``inputs.segment``, else one FlightData per file).

    Raises
    ------
    SpecError
        A window of ``inputs.segment`` holds fewer samples than the fit needs
        (:func:`ilcdob.identification.tfest.min_samples`); ``zero_at_origin`` where the data refuse it.
    """
    from ilcdob.identification.orders import compare_orders, fit_orders
    from ilcdob.identification.origin_zero import with_zero_at_origin
    from ilcdob.identification.tfest import min_samples
    from ilcdob.signals import segments

    out, plot = _identify_outputs(files, validate, out, plot)
    structures = list(structure) if isinstance(structure, (list, tuple)) else [structure]
    est_data = inputs.load(files)
    val_data = inputs.load(validate)
    if inputs.segment is not None:
        need = max(min_samples(st) for st in structures)
        est_data = segments(est_data, inputs.segment, min_samples=need, name="--segment")
        val_data = segments(val_data, inputs.segment, min_samples=need, name="--segment")
    fit = _order_fitter(est_data, val_data, structures, progress)
    fits = fit_orders(fit, structures, options)
    est = compare_orders(fits, sum(len(fd) for fd in est_data)) if len(fits) > 1 else fits[0]
    est = with_zero_at_origin(est, est_data, val_data) if zero_at_origin else est
    prov = _provenance("identify", argv)
    data = est.to_dict()
    data["signals"] = {"input": inputs.input, "output": inputs.output}
    data["files"] = {"estimation": [str(f) for f in files], "validation": [str(f) for f in validate]}
    data["segment_s"] = None if inputs.segment is None else float(inputs.segment)
    data["resampled_to_s"] = None if inputs.resample is None else float(inputs.resample)
    data["provenance"] = prov.to_dict()
    if plot is None:
        write_file(out, data)
    else:  # both outputs or neither: the figures are staged and sealed, the model written, then the swap
        from ilcdob.identification.plots import fit_figures  # matplotlib: only when drawing

        with OutputFolder(plot, prov, option="--plot") as folder:
            folder.add_all(fit_figures(est, est_data, val_data, signals=(inputs.input, inputs.output)))
            folder.seal()
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

    output = _Output("identify-fleet", out, overwrite, argv)
    flt, digest = output.check_and_load(fleet)
    flt.require_paper_loops("`ilcdob identify-fleet`")
    result = identify_fleet(flt, seed=seed, progress=progress)
    output.write(result.files(), digest=digest)
    return result


def _csv_header(path: str | Path) -> list[str]:
    """Column names of a CSV file (first line that is neither blank nor a ``#`` comment); [] if unreadable."""
    try:
        check_input(path, "flight log", limit=MAX_LOG_BYTES)  # a FIFO or a device is not opened
    except ValueError:
        return []  # load_csv reports it
    try:
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    return [c.strip().strip('"') for c in line.split(",")]
    except (OSError, UnicodeDecodeError):
        return []  # load_csv reports it
    return []


def _refuse_unused(method: str, given: dict[str, Any]) -> None:
    """A :class:`SpecError` for the first option of ``given`` (None: not given) that ``method`` does not use
    (the options each method owns: :attr:`ilcdob.design.methods.Method.cli_options`)."""
    from ilcdob.design.methods import METHODS, method_named

    chosen = method_named(method, "--method")
    for option, value in given.items():
        users = [name for name, m in METHODS.items() if option in m.cli_options]
        if value is not None and option not in chosen.cli_options:
            shown = "" if value is True else f" {value!r}"
            which = users[0] if len(users) == 1 else ", ".join(users[:-1]) + f" and {users[-1]}"
            why = {"--c-prefix": " (the methods with C code)",
                   "--c-float": " (the methods with L1/L2 filters to give in float)"}.get(option, "")
            raise SpecError(f"`{option}`{shown}: --method {method} does not use it, only {which} "
                            f"{'does' if len(users) == 1 else 'do'}{why}; omit {option}, or choose "
                            f"{'that method' if len(users) == 1 else 'one of those methods'}")


@dataclass(frozen=True, kw_only=True)
class DesignOptions:
    """How :func:`design_to_folder` designs a pair: the ``ilcdob design`` options but the pair, fleet and folder.

    Attributes
    ----------
    method : str
        closed-form, fir, norm-optimal, robust or robust-set (:data:`ilcdob.design.methods.METHODS`).
    rho : float, optional
        robust and robust-set only: the guaranteed improvement factor (default 0.95; robust-set:
        in (0, 1], on every plant of the Delta set).
    samples : int, optional
        fir and robust only: Delta-set samples per system (default 8).
    bound : float, optional
        fir, robust and robust-set only: multiplicative uncertainty bound instead of the
        identified covariance.
    n : int, optional
        norm-optimal only: trial length in samples of its gains (default: the trial's, else 500).
    law : str
        Learning law (:mod:`ilcdob.design.law.laws`).
    trial : str or Path, optional
        CSV of the source's trial: time (s), error (m), learning (m/s^2) [, reference (m),
        acceleration (m/s^2)]; a sample at every ``k Ts``, or it is refused (:func:`_check_learning_trial`).
    c_prefix : str, optional
        closed-form, fir and robust-set only (the methods with C code): prefix of the C symbols.
    c_float : bool
        closed-form, fir and robust-set only: also emit float C functions.
    bandwidth : "auto", float or None
        The learning band's corner, rad/s (:mod:`ilcdob.design.filters.band`): ``"auto"`` chooses it
        from the trial (or the fleet without one); None or ``"off"``: no filter.
    disturbance : {"command", "airframe", "wind"}
        Where the disturbance acts (:mod:`ilcdob.design.maps.flown`).
    on_limit : {"clip", "refuse"}
        A learning signal beyond the target's acceleration limit: clip it (with a
        :class:`~ilcdob.design.law.limit.LearningLimitWarning`) or refuse it.
    axis : {"x", "y", "z"}
        The axis designed (the fleet file's section; filters.json records it, and so the default C
        prefix of y and z designs ends in the axis, :func:`ilcdob.design.export.c_export.default_c_prefix`).
    fir_unattainable : {"no-harm", "refuse"}, optional
        fir only: where no filter meets the margin ``|Te1| <= 1 - margin`` for every sampled model,
        keep only the no-harm promise there and warn (default, "no-harm"), or refuse the design
        (``refuse``: :class:`~ilcdob.design.methods.fir.FIRDesignError`, nothing written);
        :attr:`ilcdob.design.methods.fir.FIROptions.unattainable`.
    lifted : bool
        norm-optimal only: also write the N x N lifted matrices L1, L2 to lifted.npz (about 8 N^2
        numbers of memory while they are built; the compact law, Riccati gains, is always written).
    """

    method: str = "closed-form"
    rho: float | None = None
    samples: int | None = None
    bound: float | None = None
    n: int | None = None
    law: str = "paper"
    trial: str | Path | None = None
    c_prefix: str | None = None
    c_float: bool = False
    bandwidth: object = "auto"
    disturbance: str = "command"
    on_limit: str = "clip"
    axis: str = "x"
    fir_unattainable: str | None = None
    lifted: bool = False


def design_to_folder(out: str | Path, source: str, target: str, *, fleet: str | Path | None = None,
                     method: str = "closed-form", rho: float | None = None, samples: int | None = None,
                     bound: float | None = None, n: int | None = None, law: str = "paper",
                     trial: str | Path | None = None, c_prefix: str | None = None, c_float: bool = False,
                     bandwidth: object = "auto", disturbance: str = "command", on_limit: str = "clip",
                     overwrite: bool = False, argv: Sequence[str] | None = None, axis: str = "x",
                     fir_unattainable: str | None = None, lifted: bool = False,
                     progress: Progress | None = None) -> tuple[Any, dict[str, Any]]:
    """Design the learning filters of ``target`` from ``source`` and write the design folder.

    Written, as a unit: ``filters.json``, the C code (``filters.h``/``.c``,
    :func:`ilcdob.design.export.c_export.design_files`),
    ``README.md``, ``bode.png`` and, as the design has them, ``lifted.npz``, ``learning_signal.csv`` (with
    ``trial``) and ``reference_terms.csv`` (the exact-reference law).

    Parameters
    ----------
    out : str or Path
        Output folder, written as a unit.
    source, target : str
        Systems j-1 (learned from) and j (learning).
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    method, rho, samples, bound, n, law, trial, c_prefix, c_float, bandwidth, disturbance, on_limit, axis, \
fir_unattainable, lifted
        The design's options, each as :class:`DesignOptions` describes it (units, defaults, which methods use it).
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.
    progress : callable, optional
        ``progress(done, total, what)`` at each of the four steps (the design, its whole trials, the figures and
        code, the folder written).

    Returns
    -------
    tuple of (PairDesign, dict)
        The design and the ``filters.json`` content written.

    Raises
    ------
    SpecError
        Besides bad values: an option the method does not use (its ``cli_options``), refused
        rather than ignored; all checked before the fleet or the trial is read.
    SignalError
        The trial misses samples, holds values beyond :data:`MAX_TRIAL_VALUE`, is sampled unlike the fleet,
        or is too short for ``bandwidth="auto"``.
    ilcdob.design.methods.fir.FIRDesignError
        ``fir_unattainable="refuse"`` and the margin cannot be met (the message names the bands).
    """
    from ilcdob.design.export.c_export import design_files

    options = DesignOptions(method=method, rho=rho, samples=samples, bound=bound, n=n, law=law, trial=trial,
                            c_prefix=c_prefix, c_float=c_float, bandwidth=bandwidth, disturbance=disturbance,
                            on_limit=on_limit, axis=axis, fir_unattainable=fir_unattainable, lifted=lifted)
    chosen, options = _checked_design_options(options)
    output = _Output("design", out, overwrite, argv)
    flt, digest = output.check_and_load(fleet, options.axis, {"--trial": options.trial})
    say = progress or (lambda *_: None)
    data = _design_trial(options, chosen, flt)
    say(0, 4, f"designing {source} -> {target} ({chosen.name})")
    design = _pair_design(flt, source, target, chosen, options, data)
    filters = {**design.filters, "axis": options.axis}
    say(1, 4, "flying whole trials of the stated set")
    if chosen.name in _WHOLE_TRIAL_METHODS and options.law == "paper" and options.disturbance == "command":
        from ilcdob.design.checks.whole_trial import pair_whole_trial

        entry = pair_whole_trial(flt, design, source, target)
        if entry is not None:
            filters["whole_trial"] = entry
    say(2, 4, "drawing the Bode figure, writing the C code")
    others = _design_outputs(design, data, filters, flt, source, target, options)
    files, written = design_files(filters, list(others), prefix=options.c_prefix, float_variant=options.c_float)
    say(3, 4, f"writing {out}")
    output.write(others, files, digest=digest, law=options.law)
    say(4, 4, f"wrote {out}")
    return design, written


#: Methods whose written law ``design`` flies on whole trials over the stated set (robust-set records its own; the
#: norm-optimal and robust designs claim nothing beyond their trial and models).
_WHOLE_TRIAL_METHODS = ("closed-form", "fir")


def design_shortfalls(filters: dict[str, Any]) -> list[str]:
    """What a written design does not guarantee: its learning band's verdict and its whole trials.

    Parameters
    ----------
    filters : dict
        ``filters.json`` as written (:func:`design_to_folder`).

    Returns
    -------
    list of str
        One line per shortfall (empty: the design keeps what it claims): the band's reason where it says the
        improvement is not guaranteed (docs/theory.md section 6), and a ``whole_trial`` entry whose worst
        trial exceeds the design's claim (robust-set).
    """
    out = []
    reason = str((filters.get("band") or {}).get("reason", ""))
    if "not guaranteed" in reason:
        out.append(f"learning band: {reason}")
    trials = filters.get("whole_trial") or {}
    if trials.get("guaranteed") is False:
        out.append(f"whole trials of {trials['duration_s']:g} s: ||e_j|| / ||e'_j|| reaches {trials['ratio']:.4g} "
                   f"({trials['worst_plant']}, {trials['worst_disturbance']}), above the {trials['claimed']:.4g} "
                   "claimed per frequency")
    return out


def _checked_design_options(o: DesignOptions) -> tuple[Any, DesignOptions]:
    """The method of ``o`` and ``o`` with its defaults filled in (rho 0.95, 8 samples, the law's name checked).

    Raises
    ------
    SpecError
        A bad value, an option the method does not use, or a law ``ilcdob design`` cannot make
        (multi-source; exact-reference without a trial).
    """
    from ilcdob.design.export.c_export import check_c_prefix
    from ilcdob.design.sets.delta import MAX_DELTA_SAMPLES
    from ilcdob.design.methods.fir import UNATTAINABLE
    from ilcdob.design.law.laws import check_law
    from ilcdob.design.methods import method_named
    from ilcdob.design.methods.norm_optimal import check_norm_optimal_size

    if o.c_prefix is not None:
        check_c_prefix(o.c_prefix)
    chosen = method_named(o.method, "--method")
    if o.n is not None:
        check_norm_optimal_size(o.n, None, o.lifted and "--lifted" in chosen.cli_options, "--n", "--lifted")
    if o.samples is not None and "--samples" in chosen.cli_options and o.samples > MAX_DELTA_SAMPLES:
        raise SpecError(f"`--samples`: got {o.samples}, expected 1 to {MAX_DELTA_SAMPLES} Delta-set samples per "
                        f"system: every sample is a closed loop that --method {o.method} builds, flies and "
                        "constrains on")
    _refuse_unused(o.method, {"--rho": o.rho, "--samples": o.samples, "--bound": o.bound, "--n": o.n,
                              "--c-prefix": o.c_prefix, "--c-float": True if o.c_float else None,
                              "--fir-unattainable": o.fir_unattainable, "--lifted": True if o.lifted else None})
    if o.fir_unattainable is not None and o.fir_unattainable not in UNATTAINABLE:
        raise SpecError(f"`--fir-unattainable`: got {o.fir_unattainable!r}, expected one of {list(UNATTAINABLE)} "
                        "(no-harm: keep only the no-harm promise where the margin cannot be met, and warn; "
                        "refuse: stop with the bands named)")
    chosen.check_options({"--rho": o.rho, "--trial": o.trial})
    law = check_law(o.law, "--law")
    if law == "multi-source":
        raise SpecError("`--law multi-source`: it learns from the trials of every earlier system at once, and "
                        "`ilcdob design` makes one pair's filters from one trial of --from; use `ilcdob reproduce "
                        "--law multi-source` for a learning chain, or "
                        "ilcdob.design.law.multi_source.multi_source_learning "
                        "with every trial")
    if law == "exact-reference" and not o.trial:
        raise SpecError("`--law exact-reference`: the law needs the reference trajectory of the trial; give --trial "
                        "CSV with columns time (s), error (m), learning (m/s^2), reference (m) and, for controllers "
                        "with acceleration feed-forward, acceleration (m/s^2)")
    return chosen, replace(o, rho=0.95 if o.rho is None else o.rho, samples=8 if o.samples is None else o.samples,
                           law=law)


def _design_trial(o: DesignOptions, chosen: Any, flt: Fleet) -> Any:
    """The source's trial of ``o`` (None: none given), loaded and checked against the fleet and ``o.n``.

    Returns
    -------
    FlightData or None
        Signals ``e`` (m), ``d_f`` (m/s^2) and, for the exact-reference law, ``r`` (m) and ``a``
        (m/s^2, when the file has an acceleration column).

    Raises
    ------
    SignalError
        Missing samples, values beyond :data:`MAX_TRIAL_VALUE`, a sample time other than the fleet's.
    SpecError
        ``o.n`` other than the trial's length, or a trial too long for the norm-optimal law.
    """
    from ilcdob.design.methods.norm_optimal import check_norm_optimal_size
    from ilcdob.identification.loaders import load_csv

    if not o.trial:
        return None
    columns = {"e": "error", "d_f": "learning"}
    if o.law == "exact-reference":
        columns["r"] = "reference"
        if "acceleration" in _csv_header(o.trial):
            columns["a"] = "acceleration"
    data = load_csv(o.trial, columns)
    _check_learning_trial(data, o.trial, options=False)
    what = {"e": ("error", "m"), "d_f": ("learning signal", "m/s^2"), "r": ("reference", "m"),
            "a": ("acceleration", "m/s^2")}
    _check_trial_values(o.trial, {f"{what[key][0]} (column `{column}`)": (data[key], what[key][1])
                                  for key, column in columns.items()})
    _check_trial_rate(o.trial, data.ts, flt.sample_time, "the fleet's",
                      "log the trial at the fleet's rate (or resample it to that rate first)")
    if o.n is not None and o.n != len(data):
        raise SpecError(f"`--n`: got {o.n}, but the trial {o.trial} has {len(data)} samples; the learning signal is "
                        f"computed for the whole trial, so its matrices must be {len(data)} long: omit --n or give "
                        f"--n {len(data)}")
    if o.n is None:
        check_norm_optimal_size(len(data), None, o.lifted and "--lifted" in chosen.cli_options, "--trial", "--lifted")
    return data


def _pair_design(flt: Fleet, source: str, target: str, chosen: Any, o: DesignOptions, data: Any) -> Any:
    """The pair's design (:func:`ilcdob.design.pair.design_pair`), its learning band fixed to the trial's when
    ``data`` is a trial and the band is chosen from one (``bandwidth="auto"``)."""
    from ilcdob.design.methods.fir import FIROptions
    from ilcdob.design.law.laws import law_for
    from ilcdob.design.methods import MethodSettings
    from ilcdob.design.pair import design_pair, design_with_band, fleet_delta_sets

    deltas = fleet_delta_sets(flt, [source, target], k=o.samples, bound=o.bound) if chosen.needs_delta_sets else None
    settings = MethodSettings(n=o.n or (len(data) if data is not None else None), lifted=o.lifted,
                              rho=o.rho if "--rho" in chosen.cli_options else None, deltas=deltas,
                              fir=FIROptions(unattainable=o.fir_unattainable) if o.fir_unattainable is not None
                              else None)
    law = o.law
    if data is not None:
        law = law_for(o.law, data["r"] if "r" in data.signals else None,
                      data["a"] if "a" in data.signals else None, "--law")
    design = design_pair(flt, source, target, chosen.configured(settings), law=law, band=o.bandwidth,
                         disturbance=o.disturbance, on_limit=o.on_limit)
    if data is not None and design.choose is not None:  # fix the band (filters.json, C code) to the trial's
        _check_noise_samples(o.trial, len(data))
        e_in = design.reference.error_in(data["e"]) if design.reference is not None else data["e"]
        design = design_with_band(design, design.band_for(e_in, data["d_f"]))
    return design


def _design_outputs(design: Any, data: Any, filters: dict[str, Any], flt: Fleet, source: str, target: str,
                    o: DesignOptions) -> dict[str, Any]:
    """The design folder's files besides filters.json, C code and README.md: lifted.npz, learning_signal.csv,
    reference_terms.csv, bode.png and filters.mat, as the design has them. With a trial (``data``), also sets
    ``filters["trial"]``, the learning signal's summary (:func:`_learn_from_trial`)."""
    from ilcdob.design.checks.figure import pair_bode_figure
    from ilcdob.signals import FlightData

    others: dict[str, Any] = {}
    arrays = design.lifted
    if data is not None:
        filters["trial"], d_f, socp_arrays = _learn_from_trial(design, data, o.trial)
        arrays = socp_arrays if socp_arrays is not None else arrays
    if arrays is not None:
        others["lifted.npz"] = lambda path, a=arrays: np.savez(path, **a)
    if data is not None:
        others["learning_signal.csv"] = FlightData(
            data.t, {"learning": d_f}, {"learning": signal_unit(design.filters)[0]},
            source=f"learning signal of {target} from {o.trial}").to_csv
    if design.reference is not None:
        others["reference_terms.csv"] = FlightData(
            data.t, {"e_ref_source": design.reference.source_error, "correction": design.reference.correction},
            {"e_ref_source": "m", "correction": design.reference.unit},
            source=f"reference terms of {source} -> {target} for {o.trial}").to_csv
    others["bode.png"] = pair_bode_figure(flt, source, target, design.band, o.method)
    if "L1" in filters and "L2" in filters:
        from ilcdob.design.export.objects import design_to_mat

        others["filters.mat"] = lambda path: design_to_mat(filters, path, "filters.json")
    return others


def signal_unit(filters: dict[str, Any]) -> tuple[str, str]:
    """The unit of the learning signal a design makes (its target's channel; m/s^2 for ilcdob's loop) and that
    unit as a JSON key suffix (``"m_s2"``, ``"m_s"``, ``"m"``).

    Parameters
    ----------
    filters : dict
        ``filters.json`` content.

    Returns
    -------
    tuple of (str, str)
    """
    from ilcdob.channel_loop import CHANNEL_UNITS

    unit = CHANNEL_UNITS[filters.get("channel", "acceleration")]
    return unit, unit.replace("/", "_").replace("^", "")


def signal_summary(d_f: np.ndarray, filters: dict[str, Any]) -> dict[str, Any]:
    """A learning signal's peak and RMS in its unit, and its ends against its interior
    (:func:`~ilcdob.design.filters.trial_edges.end_peaks`, warned about where an end is flagged).

    Parameters
    ----------
    d_f : numpy.ndarray
        The learning signal.
    filters : dict
        The design's ``filters.json`` content (unit, sample time, band).

    Returns
    -------
    dict
        ``peak_<unit>``, ``rms_<unit>`` and ``ends``.
    """
    from ilcdob.design.filters.trial_edges import end_peaks

    unit, key = signal_unit(filters)
    n = d_f.size
    ends = end_peaks(d_f, float(filters["sample_time"]))
    ends.warn(unit, band_off=(filters.get("band") or {}).get("cutoff_rad_s") is None)
    return {f"peak_{key}": float(np.max(np.abs(d_f))) if n else 0.0,
            f"rms_{key}": float(np.sqrt(np.mean(d_f ** 2))) if n else 0.0, "ends": ends.to_dict()}


def _learn_from_trial(design: Any, data: Any, trial: str | Path) -> tuple[dict[str, Any], np.ndarray, Any]:
    """The learning signal of ``design`` on the source's trial.

    Returns
    -------
    tuple of (dict, numpy.ndarray, dict or None)
        The ``trial`` entry of filters.json (file, samples, the signal's peak and RMS in m/s^2, its
        limit report, the robust SOCP's result), the signal (m/s^2) and, for the robust method, the
        arrays of lifted.npz (``d_f``, ``ratios``, ``predicted_errors``; None otherwise).
    """
    socp: list[Any] = []  # the robust SOCP's result on the (band-filtered) trial

    def robust_learn(e: np.ndarray, df: np.ndarray) -> np.ndarray:
        socp.append(design.robust.design(e, df))
        return socp[-1].d_f

    signal = design.learning(data["e"], data["d_f"], learn=robust_learn if design.robust is not None else None)
    d_f = signal.d_f
    info: dict[str, Any] = {"file": str(trial), "samples": len(data),
                            "learning_signal": signal_summary(d_f, design.filters)}
    if signal.limit is not None:
        info["limit"] = signal.limit.to_dict()
    if not socp:
        return info, d_f, None
    res = socp[-1]
    info.update({"worst_ratio": res.worst_ratio, "ratios": res.ratios.tolist(), "rho": res.rho, "status": res.status,
                 "solve_time_s": res.solve_time, "horizon_samples": int(res.d_f.size)})
    return info, d_f, {"d_f": d_f, "ratios": res.ratios, "predicted_errors": res.errors}


#: Largest magnitude of a trial's error (m) or learning signal (m/s^2) accepted: a million km
#: (or km/s^2) is no flight, and squares of larger values overflow the limit check's RMS.
MAX_TRIAL_VALUE = 1e9


def _check_learning_trial(data: Any, path: str | Path, options: bool = True) -> None:
    """Refuse a recorded trial to learn from whose time stamps miss samples.

    ILC relates sample k of one trial to sample k of the next, so a trial must hold a sample at
    every ``k Ts``; the loaders' resampling fills a gap with a straight line, which no vehicle flew.
    A step of the original stamps longer than :data:`ilcdob.signals.SAMPLE_GAP_FACTOR` median steps
    inside the trial (:meth:`ilcdob.signals.FlightData.missing_samples`) is refused; repeated and
    decreasing stamps the loaders refuse already.

    Parameters
    ----------
    data : FlightData
        The loaded trial.
    path : str or Path
        Its file, for the message.
    options : bool
        Whether the command cuts the trial with ``--start``/``--stop`` (``learn``; ``design --trial``
        reads the whole file), for the message.

    Raises
    ------
    SignalError
        Samples are missing: the message names the first gap (the stamps on either side, the
        samples missing), how many gaps there are, and the parts without any.
    """
    gaps = data.missing_samples()
    if not gaps:
        return
    ts = data.ts
    origin = float(data.metadata.get("time_origin_s", 0.0))  # the file's clock, where --start/--stop are read
    digits = max(0, 2 - int(np.floor(np.log10(ts))))

    def at(v: float) -> str:
        return f"{v + origin:.{digits}f}".rstrip("0").rstrip(".")

    def count(lo: float, hi: float) -> int:
        return int(round((hi - lo) / ts)) + 1

    lo, hi, missing = gaps[0]
    where = f"at t = {at(lo + ts)} s" if missing == 1 else f"from t = {at(lo + ts)} to {at(hi - ts)} s"
    edges = [v for g in gaps for v in g[:2]][1:] + [float(data.t[-1])]  # after each gap, to the next or the end
    a, b = max(zip(edges[::2], edges[1::2]), key=lambda part: part[1] - part[0])  # the longest
    a, b = max(a, float(data.t[0])), min(b, float(data.t[-1]))
    first, later = count(float(data.t[0]), lo), count(a, b)
    parts = []
    if first >= 2:
        parts.append(f"{f'--stop {at(lo)}' if options else f'the part up to {at(lo)} s'} keeps the {first} samples "
                     "from the trial's start, where they were flown")
    if later >= 2:
        parts.append(f"a later part ({f'--start {at(a)} --stop {at(b)}' if options else f'{at(a)} to {at(b)} s'}, "
                     f"the longest: {later} samples) starts in mid-flight, so its learning signal starts with a "
                     "transient and the next vehicle must fly it from that time of the reference")
    raise SignalError(
        f"{path}: {len(gaps)} gap(s) in the time stamps, {sum(g[2] for g in gaps)} sample(s) of {ts:g} s missing in "
        f"all; the first: no sample {where} ({missing} missing between the stamps {at(lo)} s and {at(hi)} s). A "
        "trial to learn from needs a sample at every k Ts: ILC relates sample k of this trial to sample k of the "
        "next, and across a gap there is only the straight line the loader draws. Fly the trial again, or cut "
        f"{'it with --start/--stop' if options else 'the file'} to a part without gaps, which the learning signal "
        "then covers alone" + (": " + "; ".join(parts) if parts else ""))


@dataclass(frozen=True)
class TrialColumns(LogClock):
    """Which signals of a recorded trial :func:`learn_to_folder` reads (and, keyword-only, :class:`LogClock`'s fields).

    Attributes
    ----------
    error : str or None
        Tracking error ``r - y`` of the source, m: CSV/Parquet column, ULog ``TOPIC.FIELD`` or
        DataFlash ``MESSAGE.FIELD``.
    reference, position : str or None
        Instead of ``error``: reference and measured position, m (the error is their difference).
    learning : str or None
        The learning signal the source flew, m/s^2 (None: it flew none).

    Raises
    ------
    SpecError
        Neither ``error`` nor both ``reference`` and ``position``, or both ways at once.
    """

    error: str | None = None
    reference: str | None = None
    position: str | None = None
    learning: str | None = None

    def __post_init__(self) -> None:
        by_position = self.reference is not None or self.position is not None
        if self.error is not None and by_position:
            raise SpecError("`--error` and `--reference`/`--position`: give the error column, or the reference and "
                            "position columns it is computed from, not both")
        if self.error is None and (self.reference is None or self.position is None):
            raise SpecError("the source's tracking error: give --error COLUMN, or --reference COLUMN and --position "
                            "COLUMN (error = reference - position, m)")

    def load(self, path: str | Path) -> tuple[Any, np.ndarray, np.ndarray]:
        """The trial, its error (m) and the learning signal flown (m/s^2, zeros if none).

        Parameters
        ----------
        path : str or Path
            .csv, .parquet, .ulg or .bin file.
        """
        fields = {"e": self.error} if self.error is not None else {"r": self.reference, "y": self.position}
        if self.learning is not None:
            fields["d_f"] = self.learning
        data = self.load_fields([path], fields)[0]
        _check_learning_trial(data, path)
        e = np.asarray(data["e"] if self.error is not None else data["r"] - data["y"], float)
        df = np.asarray(data["d_f"], float) if self.learning is not None else np.zeros(len(data))
        error = f"column `{self.error}`" if self.error is not None else f"`{self.reference}` - `{self.position}`"
        signals = {f"error ({error})": (e, "m")}
        if self.learning is not None:
            signals[f"learning signal (column `{self.learning}`)"] = (df, "m/s^2")
        _check_trial_values(path, signals)
        return data, e, df


def _check_trial_values(path: str | Path, signals: dict[str, tuple[np.ndarray, str]]) -> None:
    """Refuse a trial signal beyond :data:`MAX_TRIAL_VALUE` (``signals``: what -> (values, unit)), naming the file."""
    for name, (values, unit) in signals.items():
        big = np.flatnonzero(np.abs(values) > MAX_TRIAL_VALUE)
        if big.size:
            raise SignalError(f"{path}: the {name} is {float(values[big[0]]):.4g} {unit} at sample {big[0]} "
                              f"({big.size} sample(s) beyond {MAX_TRIAL_VALUE:g} {unit}); a flown trial's values "
                              "are far smaller: check the column and its units")


def _check_noise_samples(trial: str | Path, n: int) -> None:
    """Refuse a trial too short for ``--bandwidth auto`` to estimate its noise floor, naming the file."""
    from ilcdob.design.filters.band import NOISE_SAMPLES

    if n < NOISE_SAMPLES:
        raise SignalError(f"{trial}: {n} samples; `--bandwidth auto` chooses the learning band from the trial's "
                          f"noise floor, which needs at least {NOISE_SAMPLES} samples: give a longer trial, or "
                          "--bandwidth RAD_S (or off)")


def learn_to_folder(out: str | Path, trial: str | Path, columns: TrialColumns, *, source: str | None = None,
                    target: str | None = None, fleet: str | Path | None = None, design: str | Path | None = None,
                    method: str = "closed-form", bandwidth: object = "auto", on_limit: str = "clip",
                    overwrite: bool = False, argv: Sequence[str] | None = None,
                    axis: str | None = None, fir_unattainable: str | None = None, disturbance: str = "command",
                    progress: Progress | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """The next vehicle's learning signal from a recorded trial of the previous one (the paper's law).

    Computed from the filters' coefficients exactly as the emitted C function ``<prefix>learn``
    runs them (:func:`ilcdob.design.law.apply_learning`), then checked against the learning
    vehicle's acceleration limit. The filters are a design folder's ``filters.json``
    (``design``), or designed here from the fleet (``method``, the learning band fixed to the
    trial as ``ilcdob design --trial`` does).

    Written, as a unit: ``learning_signal.csv`` (time, s; learning, m/s^2), ``learning_signal.bin``
    (the samples as little-endian float64), ``learning_signal.h`` (a C array with its length and
    sample time), ``learning.json`` (what was computed from what) and ``manifest.json``.

    Parameters
    ----------
    out : str or Path
        Output folder.
    trial : str or Path
        The source's recorded trial (.csv, .parquet, .ulg, .bin): a sample at every ``k Ts``, or it is
        refused (:func:`_check_learning_trial`: missing samples; the loaders: repeated or decreasing stamps).
    columns : TrialColumns
        Its signals.
    source, target : str, optional
        Systems j-1 and j (required without ``design``; checked against it with one).
    fleet : str or Path, optional
        Fleet TOML (None: the built-in fleet); refused with ``design``.
    design : str or Path, optional
        A folder written by ``ilcdob design`` (closed-form or fir: filters with L1/L2). Checked
        against its ``manifest.json`` (an edited, added or missing file is refused, naming it;
        a folder without one is used and labelled "provenance unknown") and its ``filters.json``
        type-checked (:func:`ilcdob.design.export.c_export.check_filters`).
    method : str
        Design method without ``design``: closed-form or fir (other than the default: refused with ``design``).
    bandwidth : "auto", float or None
        The learning band without ``design`` (:mod:`ilcdob.design.filters.band`; other than "auto": refused with
        ``design``).
    on_limit : {"clip", "refuse"}
        A signal beyond the limit: clip it (with a warning) or refuse it (no folder written).
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    argv : sequence of str, optional
        Command line, recorded in ``manifest.json``.
    axis : {"x", "y", "z"}, optional
        The axis learned (default x; with ``design``: checked against its filters.json).
    fir_unattainable : {"no-harm", "refuse"}, optional
        ``method="fir"`` without ``design``: :attr:`ilcdob.design.methods.fir.FIROptions.unattainable` (refused with
        ``design`` or another method).
    disturbance : {"command", "airframe", "wind"}
        Where the disturbance acts (:func:`ilcdob.design.pair.design_pair`); refused with ``design``.
    progress : callable, optional
        ``progress(done, total, what)`` at each step (the filters, the signal, the folder written).

    Returns
    -------
    (numpy.ndarray, dict)
        The learning signal (m/s^2) and the ``learning.json`` content.
    """
    say = progress or (lambda *_: None)
    output = _Output("learn", out, overwrite, argv)
    output.check({"trial": trial, "--fleet": fleet, "--design": design})
    data, e, df_prev = columns.load(trial)
    say(0, 2, f"the filters: {'from ' + str(design) if design is not None else 'designed from the fleet'}")
    filters, source, target, origin, digest = _learn_filters(
        design, trial, data, e, df_prev, source=source, target=target, fleet=fleet, axis=axis, method=method,
        bandwidth=bandwidth, on_limit=on_limit, fir_unattainable=fir_unattainable, disturbance=disturbance)
    say(1, 2, f"the learning signal of {target} from {source}'s trial ({len(data)} samples)")
    d_f, report = _learning_signal(filters, origin, trial, data, e, df_prev, on_limit,
                                   f"learning signal of {target} from {source}")
    files, summary = _learning_files(filters, origin, source, target, trial, columns, data, d_f, report)
    output.write(files, digest=digest, law="paper")
    say(2, 2, f"wrote {out}")
    return d_f, summary


def _check_trial_rate(trial: str | Path, got: float, want: float, whose: str, remedy: str) -> None:
    """SignalError naming both sample times (s) and ``remedy`` where a trial's differs from ``whose``."""
    if abs(got - want) > 1e-9:
        raise SignalError(f"{trial}: sample time {got:g} s differs from {whose} {want:g} s; {remedy}")


def _learn_filters(design: str | Path | None, trial: str | Path, data: Any, e: np.ndarray, df_prev: np.ndarray, *,
                   source: str | None, target: str | None, fleet: str | Path | None, axis: str | None, method: str,
                   bandwidth: object, on_limit: str, fir_unattainable: str | None,
                   disturbance: str) -> tuple[dict[str, Any], Any, Any, str, str | None]:
    """The filters ``learn`` runs, with the pair, where they come from and the fleet file's SHA-256 (None for a
    design folder): a folder's (the options that design here refused), else designed here from the fleet."""
    if design is not None:
        _refuse_with_design(fleet=fleet, method=method, bandwidth=bandwidth, fir_unattainable=fir_unattainable,
                            disturbance=disturbance)
        return (*_filters_of_folder(design, source, target, axis), None)
    filters, origin, digest = _filters_designed_here(
        trial, data, e, df_prev, source=source, target=target, fleet=fleet, axis=axis, method=method,
        bandwidth=bandwidth, on_limit=on_limit, fir_unattainable=fir_unattainable, disturbance=disturbance)
    return filters, source, target, origin, digest


def _refuse_with_design(*, fleet: str | Path | None, method: str, bandwidth: object,
                        fir_unattainable: str | None, disturbance: str = "command") -> None:
    """Refuse ``learn --design`` with the options that design here (its filters.json fixes filters and band)."""
    from ilcdob.design.methods import DEFAULT_METHOD

    ignored = [name for name, given in (("--fleet", fleet is not None), ("--method", method != DEFAULT_METHOD),
                                        ("--bandwidth", bandwidth != "auto"),
                                        ("--fir-unattainable", fir_unattainable is not None),
                                        ("--disturbance", disturbance != "command")) if given]
    if ignored:
        raise SpecError(f"`--design`: its filters.json fixes the filters and their band; {', '.join(ignored)} "
                        "would be ignored: give either --design, or --fleet/--method/--bandwidth to design here")


def _filters_of_folder(design: str | Path, source: str | None, target: str | None,
                       axis: str | None) -> tuple[dict[str, Any], Any, Any, str]:
    """The filters of a design folder, checked against its manifest and the pair and axis asked for.

    Returns
    -------
    tuple of (dict, str, str, str)
        Its ``filters.json``, the systems j-1 and j it was designed for, and where the filters come from
        (for learning.json: the folder's name, "provenance unknown" without a manifest).

    Raises
    ------
    SpecError
        ``filters.json`` is missing or malformed, or designed for another pair or axis.
    ManifestError
        A file of the folder was edited, added or is missing.
    """
    from ilcdob.design.export.c_export import check_filters

    path = Path(design) / "filters.json"
    manifest = verify_manifest(design)  # an edited or added file is refused, naming it
    filters = check_filters(read_json(path, "filters.json of --design", error=SpecError,
                                      hint="give a folder written by `ilcdob design`"), str(path))
    for name, given, key in (("--from", source, "from"), ("--to", target, "to")):
        if given is not None and given != filters.get(key):
            raise SpecError(f"`{name}`: got {given!r}, but {path} was designed {filters.get('from')!r} -> "
                            f"{filters.get('to')!r}")
    if axis is not None and axis != filters.get("axis", "x"):
        raise SpecError(f"`--axis`: got {axis!r}, but {path} was designed for axis {filters.get('axis', 'x')!r}")
    origin = f"filters.json of {Path(design).name}" + ("" if manifest else " (no manifest: provenance unknown)")
    return filters, filters.get("from"), filters.get("to"), origin


def _filters_designed_here(trial: str | Path, data: Any, e: np.ndarray, df_prev: np.ndarray, *, source: str | None,
                           target: str | None, fleet: str | Path | None, axis: str | None, method: str,
                           bandwidth: object, on_limit: str, fir_unattainable: str | None,
                           disturbance: str = "command") -> tuple[dict[str, Any], str, str]:
    """The pair's filters designed from the fleet, the learning band fixed to the trial (``e``, m; ``df_prev``, m/s^2).

    Returns
    -------
    tuple of (dict, str, str)
        The filters (``filters.json`` content), where they come from (for learning.json) and the
        fleet file's SHA-256.

    Raises
    ------
    SpecError
        No pair named, a method other than closed-form or fir options, a bad ``fir_unattainable``.
    SignalError
        The trial is sampled unlike the fleet, or too short for ``bandwidth="auto"``.
    """
    if source is None or target is None:
        raise SpecError("`--from` and `--to`: name the system learned from and the one that learns "
                        "(or give --design FOLDER)")
    from ilcdob.design.methods.fir import UNATTAINABLE, FIROptions
    from ilcdob.design.methods import MethodSettings, method_named
    from ilcdob.design.pair import design_pair, design_with_band

    _refuse_unused(method, {"--fir-unattainable": fir_unattainable})
    if fir_unattainable is not None and fir_unattainable not in UNATTAINABLE:
        raise SpecError(f"`--fir-unattainable`: got {fir_unattainable!r}, expected one of {list(UNATTAINABLE)}")
    flt, digest = fleet_and_hash(fleet, axis or "x")
    _check_trial_rate(trial, data.ts, flt.sample_time, "the fleet's",
                      f"resample the trial to the fleet's rate (--resample {flt.sample_time:g})")
    chosen = method_named(method, "--method")
    if fir_unattainable is not None:
        chosen = chosen.configured(MethodSettings(fir=FIROptions(unattainable=fir_unattainable)))
    made = design_pair(flt, source, target, chosen, band=bandwidth, on_limit=on_limit, disturbance=disturbance)
    if made.choose is not None:
        _check_noise_samples(trial, e.size)
        made = design_with_band(made, made.band_for(e, df_prev))
    where = "" if disturbance == "command" else f", disturbance {disturbance}"
    return {**made.filters, "axis": axis or "x"}, f"designed here ({method}{where})", digest


def _learning_signal(filters: dict[str, Any], origin: str, trial: str | Path, data: Any, e: np.ndarray,
                     df_prev: np.ndarray, on_limit: str, what: str) -> tuple[np.ndarray, Any]:
    """The paper's law run from ``filters`` on the trial, as the C function ``<prefix>learn`` runs it, then
    the target's acceleration limit (``what``: the signal, for the limit's message).

    Returns
    -------
    tuple of (numpy.ndarray, LimitReport or None)
        The learning signal (m/s^2) and what the limit did to it.

    Raises
    ------
    SpecError
        Filters of another law, or without L1/L2 filters or robust-set law maps.
    SignalError
        The trial is sampled unlike the filters.
    LearningLimitError
        ``on_limit="refuse"`` and the signal exceeds the limit.
    """
    from ilcdob.design.law import apply_learning
    from ilcdob.design.law.limit import enforce_limit
    from ilcdob.specs import LimitSpec

    if filters.get("law", "paper") != "paper" or not ("L1" in filters and "L2" in filters or "law_maps" in filters):
        raise SpecError(f"the filters ({origin}): method {filters.get('method')!r}, law {filters.get('law')!r}; "
                        "`ilcdob learn` computes the paper's law from L1/L2 filters (closed-form or fir designs) "
                        "or from a robust-set design's `law_maps`")
    ts = float(filters["sample_time"])
    _check_trial_rate(trial, data.ts, ts, "the filters'",
                      f"resample the trial to the design's rate (--resample {ts:g}) or design at the trial's")
    d_f = apply_learning(filters, e, df_prev)
    limit = (filters.get("limit") or {}).get("acceleration_m_s2")
    return enforce_limit(d_f, None if limit is None else LimitSpec(acceleration=float(limit)), on_limit, what)


def _learning_files(filters: dict[str, Any], origin: str, source: Any, target: Any, trial: str | Path,
                    columns: TrialColumns, data: Any, d_f: np.ndarray,
                    report: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """The learn folder's content (learning_signal.csv/.bin/.h, learning.json) and the learning.json content."""
    from ilcdob.design.export.c_export import default_c_prefix, signal_header
    from ilcdob.signals import FlightData

    n = d_f.size
    ts = float(filters["sample_time"])
    axis = filters.get("axis", "x")
    unit, _ = signal_unit(filters)
    prefix = (filters.get("c") or {}).get("prefix") or default_c_prefix(str(source), str(target), axis)
    summary = {"from": source, "to": target, "axis": axis, "filters": origin, "method": filters.get("method"),
               "law": "paper",
               "trial": {"file": Path(trial).name, "samples": n, "sample_time_s": ts,
                         "error": (f"column {columns.error}" if columns.error is not None
                                   else f"{columns.reference} - {columns.position}"),
                         "learning_flown": columns.learning},
               "computes": "ilcdob.design.law.apply_learning (what the C function <prefix>learn runs), then "
                           "the acceleration limit" + ("" if "channel" not in filters else
                                                     f" (on the {filters['channel']} channel: unit {unit})"),
               "band": {k: (filters.get("band") or {}).get(k) for k in ("cutoff_rad_s", "source", "reason")},
               "learning_signal": signal_summary(d_f, filters),
               "limit": None if report is None else report.to_dict(),
               "files": {"learning_signal.csv": f"time (s), learning ({unit})",
                         "learning_signal.bin": f"{n} little-endian float64 samples, {unit}",
                         "learning_signal.h": f"static const double {prefix}df[{n}], {unit}"},
               "units": {"learning": unit, "time": "s"}}
    files = {"learning_signal.csv": FlightData(data.t, {"learning": d_f}, {"learning": unit},
                                               source=f"learning signal of {target} from {Path(trial).name}").to_csv,
             "learning_signal.bin": d_f.astype("<f8").tobytes(), "learning_signal.h": signal_header(prefix, d_f, ts),
             "learning.json": summary}
    return files, summary


def check_to_json(out: str | Path | None, *, fleet: str | Path | None = None, order: Sequence[str] | None = None,
                  bound: float | None = None, scale: float = 1.0, samples: int = 8, bandwidth: object = "auto",
                  argv: Sequence[str] | None = None, axis: str = "x", progress: Progress | None = None) -> list[Any]:
    """Will learning help? Per pair and frequency the exact worst-case error ratio of the law as
    applied (closed-form filters with each pair's learning band) over the Delta set's disc, the
    ratio for a stated plant, and the paper's first-order condition (paper Sec. III), optionally
    as JSON (:mod:`ilcdob.design.checks.theorem`).

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
        Scale of the identified standard deviations (> 0; 1 with ``bound``, which replaces them:
        :func:`ilcdob.design.sets.delta.check_scale`).
    samples : int
        Sampled plants per Delta set.
    bandwidth : "auto", float or None
        The learning band of every pair's law (:mod:`ilcdob.design.filters.band`; "auto": chosen from
        the fleet's sensor noise, limits and the same Delta sets).
    argv : sequence of str, optional
        Command line, recorded in the file.
    axis : {"x", "y", "z"}
        The axis checked (the fleet file's section).
    progress : callable, optional
        ``progress(done, total, what)`` before the Delta sets and before the exact worst cases.

    Returns
    -------
    list of PairCheck
    """
    from ilcdob.design.pair import fleet_delta_sets, pair_band
    from ilcdob.design.checks.theorem import EXACT_TOL, learning_pairs, theorem_check

    if out is not None:
        check_output_path(out, folder=False, inputs={"--fleet": fleet})
    flt, digest = fleet_and_hash(fleet, axis)
    order = list(order) if order else flt.names
    for name in order:
        flt.loop(name)  # unknown names: a clear error
    if set(order) & set(flt.own_controller):
        return _check_channel_fleet(out, flt, order, digest, bound=bound, scale=scale, bandwidth=bandwidth, argv=argv)
    say = progress or (lambda *_: None)
    pairs = learning_pairs(flt.names, order)
    say(0, 2, f"the Delta sets and learning bands of {len(pairs)} pair(s)")
    deltas = fleet_delta_sets(flt, order, k=samples, bound=bound, scale=scale)
    bands = {(s, t): pair_band(flt, s, t, bandwidth, deltas=deltas) for s, t in pairs}
    say(1, 2, f"the exact worst case of {len(pairs)} pair(s) over their Delta sets")
    checks = theorem_check(flt, order, deltas, bands=bands)
    say(2, 2, "checked")
    if out is not None:
        _write_check(out, order, all(c.holds_exact for c in checks), checks, argv, digest,
                     rule="improvement guaranteed for a pair when the exact worst case of |e_j / e'_j| over "
                          "|Delta| <= W (and for a stated plant's Delta) is <= 1 + "
                          f"{EXACT_TOL:g} at every checked frequency; the paper's first-order "
                          "condition |Delta| < |1 + P C|/2 is reported beside it (paper_first_order)",
                     units={"w": "rad/s", "ratios": "1 (|e_j| / |e'_j| per frequency)",
                            "delta, bound": "1 (relative model error |P/P_hat - 1|)"})
    return checks


def _write_check(out: str | Path, order: list[str], holds: bool, checks: list[Any], argv: Sequence[str] | None,
                 digest: str | None, *, rule: str, units: dict[str, str]) -> None:
    """The JSON file of ``ilcdob check``: order, verdict and its rule, units, every pair, provenance."""
    write_file(out, {"order": order, "verdict": "holds" if holds else "fails", "verdict_rule": rule, "units": units,
                     "pairs": [c.to_dict() for c in checks],
                     "provenance": _provenance("check", argv, digest).to_dict()})


def _check_channel_fleet(out: str | Path | None, flt: Fleet, order: list[str], digest: str, *, bound: float | None,
                         scale: float, bandwidth: object, argv: Sequence[str] | None) -> list[Any]:
    """:func:`check_to_json` for a fleet with a vehicle on its own controller: every pair of ``order`` by
    :func:`ilcdob.design.checks.channel.channel_check`, with the band its design flies."""
    from ilcdob.design.checks.channel import channel_check
    from ilcdob.design.checks.theorem import EXACT_TOL, learning_pairs
    from ilcdob.design.pair import design_pair

    checks = [channel_check(flt.loop(s), flt.loop(t), band=design_pair(flt, s, t, band=bandwidth).band,
                            scale=scale, bound=bound) for s, t in learning_pairs(flt.names, order)]
    if out is not None:
        _write_check(out, order, all(c.holds for c in checks), checks, argv, digest,
                     rule="improvement guaranteed for a pair when the exact worst case of |e_j / e'_j| = |1 - F| + "
                          f"|F| W over the source's Delta set |Delta| <= W is <= 1 + {EXACT_TOL:g} at every checked "
                          "frequency (vehicles on their own controller: the learner's model error cancels)",
                     units={"w": "rad/s", "worst": "1 (|e_j| / |e'_j| per frequency)",
                            "bound": "1 (relative error of the source's identified map)"})
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
        Designs to compare (default: :data:`ilcdob.design.methods.DEFAULT_METHODS`).
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
    from ilcdob.design.methods import DEFAULT_METHODS
    from ilcdob.validation.compare import compare_designs

    output = _Output("compare", out, overwrite, argv)
    flt, digest = output.check_and_load(fleet)  # no folder (out None): the fleet alone
    flt.require_paper_loops("`ilcdob compare`")
    cmp = compare_designs(flt, scenario, list(methods or DEFAULT_METHODS), options, progress=progress)
    if out is not None:
        from ilcdob.validation.figures import comparison_figure

        figure = comparison_figure(cmp, options.robust.rho if options.robust else None)
        output.write(cmp.files({"compare_ratios.png": figure}), digest=digest, law=options.law)
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

    output = _Output("extensions", out, overwrite, argv)
    flt, digest = output.check_and_load(fleet)
    flt.require_paper_loops("`ilcdob extensions`")
    result = extensions_study(flt, list(scenarios))
    output.write(result.files(out=str(out)), digest=digest)
    return result


@dataclass(frozen=True)
class _StoreState:
    """What a campaign folder held before a run: put back when the run fails before a sample is stored."""

    out: Path
    missing: tuple[Path, ...]  # the folder and those of its parents that did not exist, outermost first
    names: tuple[str, ...]  # the store's file names
    had: frozenset[str]  # those present before

    @classmethod
    def of(cls, out: Path, names: Sequence[str]) -> _StoreState:
        missing = []
        p = out.absolute()
        while not p.exists() and p.parent != p:
            missing.append(p)
            p = p.parent
        return cls(out, tuple(reversed(missing)), tuple(names), frozenset(n for n in names if (out / n).exists()))

    def restore(self, samples: str) -> None:
        store = self.out / samples
        if samples not in self.had and store.is_file() and store.stat().st_size > 0:
            return  # samples were flown and stored: kept for the resume (the error says so)
        for name in self.names:
            if name not in self.had:
                (self.out / name).unlink(missing_ok=True)
        remove_folders(list(self.missing))  # each only while empty


def campaign_to_folder(out: str | Path, options: Any, *, fleet: str | Path | None = None,
                       scheduler: str | None = None, workers: int | None = None, overwrite: bool = False,
                       progress: Progress | None = None, dashboard: Callable[[str], None] | None = None,
                       argv: Sequence[str] | None = None, scheduler_file: str | Path | None = None,
                       tls_ca_file: str | Path | None = None, tls_cert: str | Path | None = None,
                       tls_key: str | Path | None = None) -> Any:
    """Monte Carlo campaign on Dask; resumable: run it again on the same folder to continue.

    Parameters
    ----------
    out : str or Path
        Output folder: the sample store is appended in place while the campaign runs; the
        summary files are written as a unit with it at the end. A campaign that fails before
        a sample is stored (a bad option, an unreachable scheduler, a full disk) leaves the
        folder as it was (a folder it created is removed); stored samples are kept, for the
        same command to resume.
    options : ilcdob.validation.campaign.CampaignOptions
        Samples, methods, scenarios, Delta set, law.
    fleet : str or Path or None
        Fleet TOML (None: the built-in fleet).
    scheduler : str, optional
        Dask scheduler ``tcp://HOST:PORT`` or ``tls://HOST:PORT`` (default: a local cluster).
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
    scheduler_file : str or Path, optional
        Instead of ``scheduler``: the file ``dask scheduler --scheduler-file`` writes.
    tls_ca_file, tls_cert, tls_key : str or Path, optional
        TLS files of a ``tls://`` scheduler: CA certificate, client certificate, its key.

    Returns
    -------
    CampaignResult
    """
    from ilcdob.validation.campaign import SAMPLES_FILE, STORE_FILES, run_campaign

    output = _Output("campaign", out, overwrite, argv)
    out = output.check({"--fleet": fleet}, resumable=STORE_FILES)  # a link resolved: the store is appended there
    flt, digest = fleet_and_hash(fleet)
    flt.require_paper_loops("`ilcdob campaign`")
    before = _StoreState.of(out, STORE_FILES)
    try:
        result = run_campaign(flt, options, out, scheduler=scheduler, workers=workers, progress=progress,
                              dashboard=dashboard, scheduler_file=scheduler_file, tls_ca_file=tls_ca_file,
                              tls_cert=tls_cert, tls_key=tls_key)
    except BaseException:
        before.restore(SAMPLES_FILE)
        raise
    from ilcdob.validation.figures import campaign_figure

    replace(output, out=out).write(result.files({"campaign_ratios.png": campaign_figure(result)}), digest=digest,
                                   law=options.law, keep=STORE_FILES)
    return result


def add_to_fleet(fleet_file: str | Path, name: str, model: str | Path, controller: Any, dob: Any,
                 sample_time: float | None = None, channel: str | None = None,
                 channel_gain: float | dict[str, Any] | None = None,
                 airframe: str | Path | None = None, reference_map: str | Path | None = None,
                 limits: Any = None, sensor: Any = None) -> Fleet:
    """Add a system flying an identified ``model.json`` to a fleet file (created if needed): ilcdob's PID + DOB
    loop, or with ``channel`` a vehicle on its own controller (:func:`ilcdob.fleet_io.add_channel_system`).

    Parameters
    ----------
    fleet_file : str or Path
        Fleet TOML to create or append to; written atomically after the new fleet validates.
    name : str
        Name of the new system.
    model : str or Path
        ``model.json`` of ``ilcdob identify``.
    controller : ilcdob.specs.PIDSpec or None
        The system's PID (None with ``channel``).
    dob : ilcdob.specs.DOBSpec or None
        The system's DOB low-pass (with ``channel``: its add-on DOB, or None).
    sample_time : float, optional
        New fleet file: sample time in s (default: the model's).
    channel : {"position", "velocity", "acceleration"}, optional
        A vehicle on its own controller learning through this channel; ``model`` is its channel map.
    channel_gain : float or dict, optional
        With ``channel``: ``K``, m/s^2 per channel unit, or a fleet file's ``channel_gain`` table (a cascade's
        gains, :mod:`ilcdob.fleet`).
    airframe : str or Path, optional
        With ``channel``: the airframe's ``model.json``.
    reference_map : str or Path, optional
        With ``channel``: the reference map's ``model.json`` (reference -> position).
    limits : ilcdob.specs.LimitSpec, optional
        The vehicle's acceleration limit.
    sensor : ilcdob.specs.SensorSpec, optional
        Its position sensor's noise.

    Returns
    -------
    Fleet
    """
    from ilcdob.fleet_io import add_channel_system, add_system

    inputs = {"--model": model, **{k: v for k, v in (("--airframe", airframe), ("--reference-map", reference_map))
                                   if v is not None}}
    check_output_path(fleet_file, folder=False, inputs=inputs, option="FLEET.toml")
    if channel is not None:
        return add_channel_system(fleet_file, name, model, channel, channel_gain=channel_gain, airframe=airframe,
                                  dob=dob, sample_time=sample_time, reference_map=reference_map, limits=limits,
                                  sensor=sensor)
    return add_system(fleet_file, name, model, controller, dob, sample_time=sample_time, limits=limits, sensor=sensor)


def report_to_html(dirs: Sequence[str | Path], out: str | Path, progress: Progress | None = None) -> Path:
    """One self-contained HTML report from output folders of reproduce, compare and campaign.

    Parameters
    ----------
    dirs : sequence of str or Path
        Output folders.
    out : str or Path
        HTML file to write (atomically).
    progress : callable, optional
        ``progress(done, total, what)`` per section.

    Returns
    -------
    Path
    """
    check_output_path(out, folder=False, inputs={"folder": list(dirs)})
    return write_file(out, build_report(list(dirs), progress=progress))
