"""What the ``ilcdob`` commands show on the console: progress bars, notes, summaries, errors.

:func:`run_command` maps parsed arguments onto the use cases of :mod:`ilcdob.app.commands`
and prints their results: tables and summaries on stdout (for pipes), progress, notes and
warnings on stderr (silenced by ``--quiet``; a warning, SciPy's or Dask's too, as one
``ilcdob: warning:`` line, never its raw text), one ``ilcdob: error:`` line per failure, last.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
import time
from pathlib import Path
from typing import Any

from ilcdob.errors import LearningEndWarning, LearningLimitWarning, SpecError

from . import commands as uc

__all__ = ["CheckFailed", "Console", "run_command"]


#: Without a terminal, progress is logged as plain lines at most this often, s.
LOG_EVERY_S = 10.0


class CheckFailed(Exception):
    """A check ran and its condition does not hold (exit status 1)."""


class Console:
    """Progress bars (tqdm, on stderr), notes and error lines.

    Parameters
    ----------
    quiet : bool
        No progress bars, notes or warnings (errors, and a learning signal clipped at the
        acceleration limit, are still printed).
    """

    def __init__(self, quiet: bool = False) -> None:
        self.quiet = quiet
        self._bar: Any = None
        self._logged = -float("inf")
        self._warned: set[str] = set()

    def note(self, text: str) -> None:
        """Print a note on stderr (unless quiet).

        Parameters
        ----------
        text : str
            The note.
        """
        if not self.quiet:
            self.close()
            print(text, file=sys.stderr, flush=True)

    def error(self, text: str, tb: str | None = None, kind: str = "error") -> None:
        """Print ``ilcdob: <kind>: <text>`` (and a traceback) on stderr.

        Parameters
        ----------
        text : str
            The message.
        tb : str, optional
            Traceback text (``--debug``).
        kind : str
            ``error``, or ``check`` for a check that did not hold.
        """
        self.close()
        if tb:
            print(tb, file=sys.stderr, end="")
        print(f"ilcdob: {kind}: {text}", file=sys.stderr, flush=True)

    def warning(self, message: Warning | str, category: type[Warning], filename: str = "") -> None:
        """Print a warning as one ``ilcdob: warning:`` line on stderr.

        ilcdob's own :class:`~ilcdob.errors.LearningLimitWarning` (a learning signal was clipped) and
        :class:`~ilcdob.errors.LearningEndWarning` (spikes at a trial's ends) are always printed; any other
        warning (SciPy's ``LinAlgWarning`` or ``BadCoefficients``, Dask's, ...) once per distinct text with
        its category and package, and not at all when quiet.

        Parameters
        ----------
        message : Warning or str
            The warning.
        category : type
            Its class.
        filename : str
            The file that issued it (names the package).
        """
        text = " ".join(str(message).split())
        if issubclass(category, (LearningLimitWarning, LearningEndWarning)):
            self.error(text, kind="warning")
            return
        line = f"{text} ({category.__name__} in {_package(filename)})"
        if self.quiet or line in self._warned:
            return
        self._warned.add(line)
        self.error(line, kind="warning")

    def internal_error(self, exc: BaseException, tb: str | None = None) -> None:
        """Print ``ilcdob: error: internal error: <type>: <message>`` for an unexpected exception (a bug).

        Parameters
        ----------
        exc : BaseException
            The exception that escaped the command.
        tb : str, optional
            Traceback text (``--debug``).
        """
        self.error(f"internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback; please "
                   "report it)", tb=tb)

    def progress(self, done: int, total: int, what: str) -> None:
        """The ``progress(done, total, what)`` callback of the use cases: a bar with ETA on a
        terminal; elsewhere (logs, CI) a plain line at most every :data:`LOG_EVERY_S` seconds.

        Parameters
        ----------
        done, total : int
            Work units finished and in all (``total`` 0: a remark, printed as a note).
        what : str
            The unit of work being done.
        """
        if self.quiet:
            return
        if total <= 0:
            self.note(what)
            return
        if not sys.stderr.isatty():
            now = time.monotonic()
            if done >= total or now - self._logged >= LOG_EVERY_S:
                self._logged = now
                print(f"[{done}/{total}] {what}", file=sys.stderr, flush=True)
            return
        from tqdm import tqdm

        if self._bar is None or self._bar.total != total or done < self._bar.n:
            self.close()
            self._bar = tqdm(total=total, file=sys.stderr, dynamic_ncols=True, leave=False,
                             bar_format="{desc} {n}/{total} |{bar}| {elapsed}<{remaining}")
        self._bar.set_description_str(what[:60], refresh=False)
        self._bar.update(done - self._bar.n)
        if done >= total:
            self.close()

    def close(self) -> None:
        """End the progress bar, if one is shown."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def _package(filename: str) -> str:
    """The module a warning came from (``scipy.linalg._basic``, ``ilcdob.loop``), else its file's name."""
    for name, module in list(sys.modules.items()):
        if getattr(module, "__file__", None) == filename:
            return name
    parts = Path(filename).parts
    for marker in ("site-packages", "dist-packages"):
        if marker in parts[:-1]:
            return parts[parts.index(marker) + 1].removesuffix(".py")
    return Path(filename).name or "unknown"


def _reproduce(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    start = time.perf_counter()
    res = uc.reproduce_to_folder(a.out, fleet=a.fleet, scenarios=a.scenarios, iterations=a.iterations,
                                 plant=a.plant, seed=a.seed, law=a.law, figures=not a.no_figures,
                                 overwrite=a.overwrite, progress=con.progress, argv=argv, order=a.order,
                                 sensor_noise=a.sensor_noise, bandwidth=a.bandwidth, workers=a.workers,
                                 controller=a.controller, vehicles=a.vehicles)
    if a.controller == "own":
        con.note(f"wrote {a.out} ({time.perf_counter() - start:.1f} s, the vehicles' own controllers)")
        for r in res.runs:
            for name in r.order:
                print(f"scenario {r.scenario} {r.channel:>12} {r.disturbance:>6} {r.law:>7} {name:>12}: no learning "
                      f"{r.baseline_rmse[name]:.4f} m, learning / no learning "
                      + ", ".join(f"{v:.4f}" for v in r.ratios[name]))
        return 0
    con.note(f"wrote {a.out} ({time.perf_counter() - start:.1f} s, law {res.law})")
    for sr in res.scenarios:
        for name in sr.order:
            m = sr.systems[name].metrics()
            print(f"scenario {sr.scenario.id} {name:>8}: RMSE no DOB {m['rmse_no_dob']:.4f} m, DOB "
                  f"{m['rmse_dob']:.4f} m, learning " + ", ".join(f"{v:.5f}" for v in m["rmse_learning"]) + " m")
    return 0


def _number(text: str, name: str, valid: str, allowed: tuple[str, ...], kind: type) -> Any:
    if text in allowed:
        return None if text == "none" else text
    try:
        return kind(text)
    except ValueError:
        raise SpecError(f"`{name}`: got {text!r}, expected {valid}") from None


def _identify(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    from ilcdob.identification.tfest import FitOptions
    from ilcdob.uncertainty import ModelStructure

    delay = _number(a.delay, "--delay", "'auto' or a number of seconds >= 0", ("auto",), float)
    trend = _number(a.trend, "--trend", "'none' or a polynomial degree 0-5", ("none",), int)
    structure = [ModelStructure(n, a.zeros, a.integrators) for n in a.poles]
    options = FitOptions(delay=delay, max_delay=a.max_delay, trend=trend, time_limit=a.time_limit, starts=a.starts,
                         max_iter=a.max_iter, stable=not a.allow_unstable,
                         outlier_sigmas=None if a.keep_outliers else FitOptions.outlier_sigmas)
    inputs = uc.IdentifyInputs(a.input, a.output, a.segment, time=a.time, time_unit=a.time_unit, start=a.start,
                               stop=a.stop, resample=a.resample)
    with warnings.catch_warnings():  # the note below states a fit stopped short, with the options that help
        warnings.filterwarnings("ignore", message="tfest stopped", category=RuntimeWarning)
        est, est_data, val_data = uc.identify_to_json(a.files, inputs, structure, options, a.out,
                                                      validate=a.validate, plot=a.plot, progress=con.progress,
                                                      argv=argv, zero_at_origin=a.zero_at_origin)
    steps = sorted({fd.metadata["rate_change"]["from_ts"] for fd in est_data + val_data
                    if "rate_change" in fd.metadata})
    if steps:
        con.note(f"--resample {a.resample:g} s: files logged every {', '.join(f'{v:g}' for v in steps)} s resampled "
                 "(scipy.signal.resample_poly: anti-aliased, each end continued by its trend)")
    if a.segment is not None:
        con.note(f"--segment {a.segment:g} s: {len(est_data)} estimation and {len(val_data)} held-out windows, "
                 "each fitted with its own initial condition")
    noted = set()  # the windows of one file carry its dropouts: list them once
    for fd in est_data + val_data:
        gaps = fd.metadata.get("gaps") or []
        if gaps and fd.source not in noted:
            noted.add(fd.source)
            con.note(f"{fd.source}: {len(gaps)} dropout(s) in the time stamps, each piece fitted with its own "
                     "initial condition: " + ", ".join(f"{lo:.6g} to {hi:.6g} s" for lo, hi in gaps))
    if len(a.poles) > 1:
        print("order comparison (fit %, AIC = N ln(sigma^2) + 2 k):")
        for row in est.solver["order_comparison"]:
            print(f"  {row['poles']} poles: estimation {row['fit_estimation']:.2f}, held-out "
                  + ("-" if row["fit_validation"] is None else f"{row['fit_validation']:.2f}")
                  + f", AIC {row['aic']:.1f}" + ("  <- chosen" if row["chosen"] else "")
                  + ("" if not row["not_identified"] else "  (not identified: " + "; ".join(row["not_identified"]) + ")"))
    print(est.summary())
    if est.solver.get("status") != "converged":
        why = {"max_iter": "at its iteration limit (--max-iter)", "time_limit": "at its time limit (--time-limit)",
               "numerical": "where its sensitivities overflowed (a model the constraints cannot fit well: for an "
                            "open-loop unstable plant try --allow-unstable; else fewer poles)"}
        status = est.solver.get("status")
        con.note(f"note: the fit stopped {why.get(status, status)}; {a.out} holds the best model found "
                 "(solver.status)")
    con.note(f"wrote {a.out}" + (f" and {a.plot}" if a.plot else ""))
    if a.min_fit is not None:
        fit = est.fit_validation if val_data else est.fit_estimation
        which = "held-out" if val_data else "estimation (no --validate files)"
        if not fit >= a.min_fit:
            raise CheckFailed(f"--min-fit: {which} fit {fit:.2f} % is below {a.min_fit:g} % ({a.out} written)")
    return 0


def _design(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    _, written = uc.design_to_folder(
        a.out, a.source, a.target, fleet=a.fleet, method=a.method, rho=a.rho, samples=a.samples, bound=a.bound,
        n=a.n, law=a.law, trial=a.trial, c_prefix=a.c_prefix, c_float=a.c_float, bandwidth=a.bandwidth,
        disturbance=a.disturbance, on_limit=a.on_limit, overwrite=a.overwrite, argv=argv, axis=a.axis,
        fir_unattainable=a.fir_unattainable, lifted=a.lifted, progress=con.progress)
    band = written.get("band", {})
    cutoff = band.get("cutoff_rad_s")
    con.note(f"ilcdob: learning band {'off' if cutoff is None else f'{cutoff:.4g} rad/s'} ({band.get('reason', '')})")
    summary = {k: v for k, v in written.items()
               if k not in ("L1", "L2", "band", "disturbance", "closed_form", "law_maps", "F")}
    summary["band"] = {k: written["band"][k] for k in ("cutoff_rad_s", "source", "reason")}
    summary["disturbance"] = written["disturbance"]["at"]
    print(json.dumps(summary, indent=2))  # what was written, for a reader and for a script (json.loads)
    con.note(f"wrote {a.out}")
    short = uc.design_shortfalls(written)
    if short:
        raise CheckFailed(f"design written to {a.out}, but the improvement is not guaranteed: {'; '.join(short)}")
    return 0


def _learn(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    columns = uc.TrialColumns(error=a.error, reference=a.reference, position=a.position, learning=a.learning,
                              time=a.time, time_unit=a.time_unit, start=a.start, stop=a.stop, resample=a.resample)
    _, summary = uc.learn_to_folder(a.out, a.trial, columns, source=a.source, target=a.target, fleet=a.fleet,
                                    design=a.design, method=a.method, bandwidth=a.bandwidth, on_limit=a.on_limit,
                                    overwrite=a.overwrite, argv=argv, axis=a.axis,
                                    fir_unattainable=a.fir_unattainable, disturbance=a.disturbance,
                                    progress=con.progress)
    print(json.dumps({k: summary[k] for k in ("from", "to", "axis", "filters", "trial", "learning_signal", "limit")},
                     indent=2))
    con.note(f"wrote {a.out}")
    return 0


def _check(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    import math

    from ilcdob.design.checks.channel import ChannelPairCheck, format_channel_table
    from ilcdob.design.checks.theorem import EXACT_TOL, format_theorem_table

    order = [s.strip() for s in a.order.split(",")] if a.order else None
    checks = uc.check_to_json(a.out, fleet=a.fleet, order=order, bound=a.bound, scale=_given(a.scale, 1.0),
                              bandwidth=a.bandwidth, argv=argv, axis=a.axis, progress=con.progress)
    if checks and isinstance(checks[0], ChannelPairCheck):
        print(format_channel_table(checks))
        failing = [f"{c.source} -> {c.target} (exact worst ratio {c.worst_ratio:.4g} at {c.worst_w:.4g} rad/s)"
                   for c in checks if not c.holds]
        if failing:
            raise CheckFailed(f"learning with its band can make the error worse: improvement not guaranteed for "
                              f"{', '.join(failing)} (exact worst case over the stated set > 1 + {EXACT_TOL:g})")
        return 0
    print(format_theorem_table(checks))
    disagree = [f"{c.source} -> {c.target}" for c in checks if not c.agrees]
    if disagree:
        con.note(f"ilcdob: note: the paper's first-order condition and the exact worst case disagree for "
                 f"{', '.join(disagree)}; the verdict follows the exact worst case")
    failing = [f"{c.source} -> {c.target} (exact worst ratio "
               f"{'unbounded' if not math.isfinite(c.exact_worst) else f'{c.exact_worst:.4g}'} at "
               f"{c.exact_worst_w:.4g} rad/s)" if not c.guaranteed else
               f"{c.source} -> {c.target} (ratio {c.known_worst:.4g} at {c.known_worst_w:.4g} rad/s for the stated "
               f"plant, outside the stated set)" for c in checks if not c.holds_exact]
    if failing:
        raise CheckFailed(f"learning with its band can make the error worse: improvement not guaranteed for "
                          f"{', '.join(failing)} (exact worst case over the stated set, or for a stated plant, > 1 + {EXACT_TOL:g})")
    return 0


def _given(value: Any, default: Any) -> Any:
    """An option's value, or its default when it was not given (None)."""
    return default if value is None else value


def _used_by(option: str, value: Any, methods: list[str], users: tuple[str, ...]) -> None:
    """Refuse an option that none of ``methods`` uses (given: not None)."""
    if value is not None and not set(users) & set(methods):
        which = f"{users[0]} does" if len(users) == 1 else f"{' and '.join(users)} do"
        raise SpecError(f"`{option}` {value!r}: none of the methods {', '.join(methods)} uses it, only {which}; omit "
                        f"{option}, or add {'it' if len(users) == 1 else 'one of them'} to --methods")


def _robust_set_rho(rho: float | None, methods: list[str]) -> None:
    """robust-set guarantees ``|e_j| <= rho |e'_j|`` on every plant: rho above 1 is no guarantee."""
    if rho is not None and "robust-set" in methods and not (math.isfinite(rho) and 0 < rho <= 1):
        raise SpecError(f"`--rho`: got {rho!r}, expected a guaranteed improvement factor in (0, 1] with robust-set "
                        "among the methods (1: never worse than without learning)")


def _compare(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    from ilcdob.design.sets.delta import check_scale
    from ilcdob.design.methods.fir import FIROptions
    from ilcdob.design.methods import DEFAULT_METHODS
    from ilcdob.design.methods.robust import RobustOptions
    from ilcdob.validation.compare import CompareOptions
    from ilcdob.validation.scenarios import SCENARIOS

    methods = list(a.methods or DEFAULT_METHODS)
    _used_by("--rho", a.rho, methods, ("robust", "robust-set"))
    _used_by("--fir-unattainable", a.fir_unattainable, methods, ("fir",))
    _robust_set_rho(a.rho, methods)
    scenario = SCENARIOS.get(a.scenario)
    if a.duration is not None and scenario is not None and a.duration > scenario.duration:
        raise SpecError(f"`--duration`: got {a.duration:g} s, but scenario {a.scenario} lasts {scenario.duration:g} s; "
                        "give a shorter duration, or omit --duration to fly all of it")
    opts = CompareOptions(samples=a.samples, bound=a.bound, scale=check_scale(_given(a.scale, 1.0), a.bound),
                          seed=a.seed, duration=a.duration, robust=RobustOptions(rho=_given(a.rho, 0.95)), law=a.law,
                          fir=None if a.fir_unattainable is None else FIROptions(unattainable=a.fir_unattainable))
    cmp = uc.compare_to_folder(a.out, a.scenario, opts, fleet=a.fleet, methods=a.methods, overwrite=a.overwrite,
                               progress=con.progress, argv=argv)
    print(cmp.table(), end="")
    if a.out:
        con.note(f"wrote {a.out}")
    return 0


def _extensions(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    result = uc.extensions_to_folder(a.out, fleet=a.fleet, scenarios=a.scenarios, overwrite=a.overwrite, argv=argv)
    print(result.table(), end="")
    return 0


def _campaign(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    from ilcdob.design.methods import DEFAULT_METHODS
    from ilcdob.validation.campaign import CampaignOptions

    methods = list(a.methods or DEFAULT_METHODS)
    _used_by("--rho", a.rho, methods, ("robust", "robust-set"))
    _used_by("--robust-models", a.robust_models, methods, ("robust",))
    _used_by("--delta-set", a.delta_set, methods, ("robust-set",))
    opts = CampaignOptions(samples=a.samples, seed=a.seed, scale=_given(a.scale, 1.0), bound=a.bound,
                           scenarios=tuple(a.scenarios), methods=tuple(methods), duration=a.duration,
                           robust_models=_given(a.robust_models, 1), rho=_given(a.rho, 0.95), law=a.law,
                           delta_set=_given(a.delta_set, "structured"), margin=a.margin)
    result = uc.campaign_to_folder(a.out, opts, fleet=a.fleet, scheduler=a.scheduler, workers=a.workers,
                                   scheduler_file=a.scheduler_file, tls_ca_file=a.tls_ca_file,
                                   tls_cert=a.tls_cert, tls_key=a.tls_key, overwrite=a.overwrite, progress=con.progress,
                                   dashboard=con.note if a.dashboard else None, argv=argv)
    print(result.table(), end="")
    con.note(f"wrote {a.out} ({result.wall_time_s:.0f} s)")
    return 0


def _identify_fleet(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    result = uc.identify_fleet_to_folder(a.out, fleet=a.fleet, seed=a.seed, overwrite=a.overwrite,
                                         progress=con.progress, argv=argv)
    for name, vid in result.results.items():
        print(f"{name}: {vid.estimate.summary()}")
    con.note(f"wrote {a.out}")
    return 0


def _limit_specs(a: argparse.Namespace, path: object) -> tuple[Any, Any]:
    """``fleet add``'s --tilt / --thrust-to-weight / --acceleration-limit and --sensor-noise as specs (None: not
    given)."""
    from ilcdob.specs import LimitSpec, SensorSpec

    given = {"tilt": a.tilt, "thrust_to_weight": a.thrust_to_weight, "acceleration": a.acceleration_limit}
    try:
        limits = LimitSpec(**given) if any(v is not None for v in given.values()) else None
        sensor = None if a.sensor_noise is None else SensorSpec(a.sensor_noise)
    except SpecError as exc:
        raise SpecError(f"{path}: system {a.name!r} (--tilt/--thrust-to-weight/--acceleration-limit, "
                        f"--sensor-noise): {exc}; nothing written") from exc
    return limits, sensor


def _fleet(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    from pathlib import Path

    from ilcdob.identified import load_model
    from ilcdob.specs import DOBSpec, PIDSpec

    path = Path(a.fleet_file)
    created = not path.exists()
    load_model(a.model)  # an unreadable model is refused before the options are checked
    pid = {"--kp": a.kp, "--ki": a.ki, "--kd": a.kd, "--derivative-filter": a.derivative_filter}
    own = {"--channel-gain": a.channel_gain, "--cascade-gains": a.cascade_gains,
           "--cascade-gains-from": a.cascade_gains_from, "--airframe": a.airframe, "--reference-map": a.reference_map}
    if a.channel is not None and any(v is not None for v in pid.values()):
        raise SpecError(f"{', '.join(k for k, v in pid.items() if v is not None)}: a system with --channel flies "
                        "its own controller, described by its identified channel map; ilcdob's PID gains would be "
                        "ignored: omit them; nothing written")
    if a.channel is None and any(v is not None for v in own.values()):
        raise SpecError(f"{', '.join(k for k, v in own.items() if v is not None)}: only for a vehicle on its own "
                        "controller (give --channel); nothing written")
    gains = [k for k in ("--channel-gain", "--cascade-gains", "--cascade-gains-from") if own[k] is not None]
    if len(gains) > 1:
        raise SpecError(f"{', '.join(gains)}: give one (a constant K, or a cascade's gains); nothing written")
    if a.cascade_axis is not None and a.cascade_gains_from is None:
        raise SpecError("--cascade-axis: only with --cascade-gains-from; nothing written")
    cascade = a.cascade_gains
    if a.cascade_gains_from is not None:
        from ilcdob.identification.loaders.ulog import px4_cascade_gains

        _, read = px4_cascade_gains(a.cascade_gains_from, a.channel, _given(a.cascade_axis, "x"))
        cascade = dict(zip(("position_p", "velocity_p", "velocity_i"), read.values()))
        con.note(f"read {', '.join(f'{k} = {v:g}' for k, v in read.items())} from {a.cascade_gains_from}")
    needed = ([] if a.channel is not None else ["--kp", "--ki", "--kd"]) + ["--q-order", "--q-time-constant"]
    given = {"--q-order": a.q_order, "--q-time-constant": a.q_time_constant, **pid}
    missing = [k for k in needed if given[k] is None and (a.channel is None or given["--q-order"] is not None
                                                         or given["--q-time-constant"] is not None)]
    if missing:
        raise SpecError(f"{', '.join(missing)}: required for " + ("the add-on DOB" if a.channel else
                        "ilcdob's PID + DOB loop (or give --channel for a vehicle on its own controller)")
                        + "; nothing written")
    try:
        dob = None if a.q_order is None else DOBSpec(a.q_order, a.q_time_constant)
        controller = None if a.channel else PIDSpec(a.kp, a.ki, a.kd, _given(a.derivative_filter, 0.05))
    except SpecError as exc:
        raise SpecError(f"{path}: system {a.name!r} (--kp/--ki/--kd/--derivative-filter, --q-order/"
                        f"--q-time-constant): {exc}; nothing written") from exc
    limits, sensor = _limit_specs(a, path)
    if a.channel is not None:
        fleet = uc.add_to_fleet(path, a.name, a.model, None, dob, sample_time=a.sample_time, channel=a.channel,
                                channel_gain=_given(cascade, a.channel_gain), airframe=a.airframe,
                                reference_map=a.reference_map, limits=limits, sensor=sensor)
    else:
        fleet = uc.add_to_fleet(path, a.name, a.model, controller, dob, sample_time=a.sample_time, limits=limits,
                                sensor=sensor)
    if created:
        origin = "--sample-time" if a.sample_time is not None else f"the sample_time of {a.model}"
        con.note(f"created {path} with sample time {fleet.sample_time:g} s (from {origin})")
    con.note(f"added {a.name} to {path}: systems {fleet.names}")
    return 0


def _report(a: argparse.Namespace, argv: list[str], con: Console) -> int:
    con.note(f"wrote {uc.report_to_html(a.dirs, a.out, progress=con.progress)}")
    return 0


_COMMANDS = {"reproduce": _reproduce, "identify": _identify, "identify-fleet": _identify_fleet, "design": _design,
             "learn": _learn,
             "check": _check, "compare": _compare, "campaign": _campaign, "extensions": _extensions,
             "report": _report, "fleet": _fleet}


def run_command(args: argparse.Namespace, argv: list[str], console: Console) -> int:
    """Run the command of parsed ``args`` and print its results; returns the exit status.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (:func:`ilcdob.app.cli.build_parser`).
    argv : list of str
        The raw arguments, recorded with the outputs.
    console : Console
        Where progress and notes go.
    """
    def one_line(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        console.warning(message, category, filename)  # no raw warning text, nothing at all with --quiet

    try:
        with warnings.catch_warnings():
            warnings.showwarning = one_line
            return _COMMANDS[args.command](args, argv, console)
    finally:
        console.close()
