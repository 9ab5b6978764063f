"""Command-line interface: a thin layer over the public API.

``ilcdob reproduce [--fleet FILE] [--scenarios 1,2,3,4] [--iterations 3] [--plant linear|nonlinear]
[--law paper|exact-reference|multi-source] --out DIR`` runs the paper's validation on a fleet
(default: the built-in three UAVs) and writes ``DIR/results.json``, the figures and
``DIR/README.md``; ``--plant nonlinear`` flies it on the nonlinear quadrotors with identified
models (``ilcdob.validation.nonlinear``). ``--law`` (also on ``design``, ``compare`` and
``campaign``) chooses the learning law (``ilcdob.design.laws``); a command a law cannot apply
to refuses it and says why.

``ilcdob identify FILE [FILE ...] --input COL --output COL [--time COL] --poles N [--zeros M]
[--integrators K] [--delay auto|SECONDS] [--validate FILE ...] --out model.json [--plot DIR]``
fits a continuous-time transfer function to flight data (CSV, Parquet, PX4 ULog with
TOPIC.FIELD, ArduPilot DataFlash with MESSAGE.FIELD) and writes ``model.json``.

``ilcdob campaign [--fleet FILE] --samples N [--scheduler tcp://HOST:PORT] --out DIR`` flies every
design through every scenario over N sampled true plants on Dask and writes ratio statistics
(``DIR/campaign.json``); run it again to resume (``ilcdob.validation.campaign``).

``ilcdob report DIR [DIR ...] --out report.html`` writes one self-contained HTML report from
output folders of ``reproduce``, ``compare`` and ``campaign`` (see ``ilcdob.app.html``).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from ilcdob.errors import IlcdobError
from ilcdob.fleet import default_fleet, load_fleet

__all__ = ["main", "build_parser"]


_LAW_HELP = ("learning law: paper (the Theorem's filters, default), exact-reference (the same with the reference "
             "term (1 - G_r) r kept), multi-source (every earlier system's trial at once); see ilcdob.design.laws")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"got {text!r}, expected an integer >= 1")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``ilcdob`` command."""
    parser = argparse.ArgumentParser(prog="ilcdob", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rep = sub.add_parser("reproduce", help="run the paper's four scenarios and write results + figures")
    rep.add_argument("--fleet", help="fleet TOML file (default: built-in paper fleet)")
    rep.add_argument("--scenarios", default="1,2,3,4", help="comma-separated scenario ids (default 1,2,3,4)")
    rep.add_argument("--iterations", type=_positive_int, default=3, help="learning iterations (default 3)")
    rep.add_argument("--out", required=True, help="output folder")
    rep.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    rep.add_argument("--plant", choices=("linear", "nonlinear"), default="linear",
                     help="linear: the fleet's models (default); nonlinear: identify and fly the nonlinear "
                          "6-DOF quadrotors (Table I vehicles)")
    rep.add_argument("--seed", type=int, default=0, help="--plant nonlinear: seed of the sensor noise (default 0)")
    rep.add_argument("--law", default="paper", help=_LAW_HELP)

    idf = sub.add_parser("identify", help="fit a continuous-time transfer function to flight data")
    idf.add_argument("files", nargs="+", help="estimation data: .csv, .parquet, .ulg or .bin")
    idf.add_argument("--input", required=True, help="input signal: COLUMN, TOPIC.FIELD (ULog) or MESSAGE.FIELD")
    idf.add_argument("--output", required=True, help="output signal, same forms as --input")
    idf.add_argument("--time", default=None, help="time column of CSV/Parquet files (default: time), in s")
    idf.add_argument("--time-unit", choices=("s", "ms", "us", "ns"), default=None,
                     help="unit of the CSV/Parquet time column (default: the file's '# units:' line, else s)")
    idf.add_argument("--poles", type=_positive_int, required=True, help="number of poles, integrators included")
    idf.add_argument("--zeros", type=int, default=0, help="number of zeros (default 0)")
    idf.add_argument("--integrators", type=int, default=0, help="poles fixed at s = 0 (default 0)")
    idf.add_argument("--delay", default="0", help="input delay in s, or 'auto' to estimate it (default 0)")
    idf.add_argument("--max-delay", type=float, default=0.3,
                     help="upper bound of the delay search, s (default 0.3; below half the shortest file)")
    idf.add_argument("--trend", default="0",
                     help="per-file output trend estimated with the model: 'none', or a polynomial degree 0-5 "
                          "(0 = offset, the default; 1 = offset + slope; higher for slow drift)")
    idf.add_argument("--time-limit", type=float, default=None,
                     help="wall-time limit of the fit, s: the best model so far is written, with its status "
                          "(default: none)")
    idf.add_argument("--validate", nargs="*", default=[], help="held-out data files")
    idf.add_argument("--start", type=float, default=None, help="segment start, s (log clock)")
    idf.add_argument("--stop", type=float, default=None, help="segment end, s (log clock)")
    idf.add_argument("--out", required=True, help="model.json to write")
    idf.add_argument("--plot", default=None, help="folder for the compare/residual/Bode figures")

    des = sub.add_parser("design", help="design the learning filters of one system from another")
    des.add_argument("--fleet", help="fleet TOML file (default: built-in paper fleet)")
    des.add_argument("--from", dest="source", required=True, help="system learned from (j-1)")
    des.add_argument("--to", dest="target", required=True, help="system that learns (j)")
    des.add_argument("--method", default="closed-form",
                     help="closed-form, fir, norm-optimal, robust or robust-set (default closed-form; robust "
                          "needs --trial; robust-set: closed form + FIR guaranteed over the whole Delta set)")
    des.add_argument("--rho", type=float, default=0.95,
                     help="robust: guaranteed improvement ||e_k|| <= rho ||e'_k|| on every model; robust-set: "
                          "on every plant of the Delta set, capped at 1 (default 0.95)")
    des.add_argument("--samples", type=_positive_int, default=8,
                     help="fir/robust: Delta-set samples per system (default 8)")
    des.add_argument("--bound", type=float, default=None,
                     help="fir/robust: multiplicative uncertainty bound instead of the identified covariance")
    des.add_argument("--n", type=_positive_int, default=None,
                     help="trial length in samples for lifted matrices (default: the trial's, else 500)")
    des.add_argument("--law", default="paper",
                     help=_LAW_HELP + "; exact-reference needs --trial with a reference column (m) and, for "
                          "controllers with acceleration feed-forward, an acceleration column (m/s^2); "
                          "multi-source is refused (one pair, one trial)")
    des.add_argument("--trial", default=None,
                     help="CSV of the previous system's trial: columns time (s), error (m), learning (m/s^2)")
    des.add_argument("--c-prefix", default=None,
                     help="prefix of the C functions and macros in filters.h/filters.c (default "
                          "ilcdob_<from>_<to>_, lower case); a C identifier, e.g. uav1_uav2_")
    des.add_argument("--c-float", action="store_true",
                     help="also emit float versions (*_apply_f) of the C functions, with their measured error")
    des.add_argument("--out", required=True, help="output folder")

    cmp = sub.add_parser("compare", help="fly every learning design through a scenario, nominal and over the "
                                         "Delta set, and tabulate RMSE, worst case, order and design time")
    cmp.add_argument("--fleet", help="fleet TOML file (default: built-in paper fleet)")
    cmp.add_argument("--scenario", type=_positive_int, required=True, help="scenario id 1-4")
    cmp.add_argument("--methods", default="closed-form,fir,norm-optimal,robust",
                     help="comma-separated designs (default: these four; robust-set too on request)")
    cmp.add_argument("--samples", type=_positive_int, default=8, help="Delta-set samples per system (default 8)")
    cmp.add_argument("--bound", type=float, default=None,
                     help="multiplicative uncertainty bound instead of the identified covariance")
    cmp.add_argument("--scale", type=float, default=1.0, help="scale of the identified standard deviations")
    cmp.add_argument("--rho", type=float, default=0.95, help="robust: guaranteed improvement factor (default 0.95)")
    cmp.add_argument("--duration", type=float, default=None, help="fly only the first SECONDS of the scenario")
    cmp.add_argument("--seed", type=int, default=0, help="seed of the Delta-set draw (default 0)")
    cmp.add_argument("--law", default="paper", help=_LAW_HELP + " (multi-source refused: one pair, one trial)")
    cmp.add_argument("--out", default=None, help="folder for compare.json, compare.txt and compare_ratios.png")

    ext = sub.add_parser("extensions", help="beyond the paper: exact reference term and learning from every "
                                            "earlier system, per scenario")
    ext.add_argument("--fleet", help="fleet TOML file (default: built-in paper fleet)")
    ext.add_argument("--scenarios", default="1,2,3,4", help="comma-separated scenario ids (default 1,2,3,4)")
    ext.add_argument("--out", required=True, help="folder for extensions.json and README.md")

    cpg = sub.add_parser("campaign", help="Monte Carlo campaign on Dask: every design and scenario over sampled "
                                          "true plants; ratio statistics per method (resumable)")
    cpg.add_argument("--fleet", help="fleet TOML file (default: built-in paper fleet)")
    cpg.add_argument("--samples", type=_positive_int, required=True, help="number of samples (true plant per vehicle)")
    cpg.add_argument("--scheduler", default=None, help="Dask scheduler tcp://HOST:PORT (default: a local cluster)")
    cpg.add_argument("--workers", type=_positive_int, default=None,
                     help="local cluster: worker processes (default: the cores)")
    cpg.add_argument("--methods", default="closed-form,fir,norm-optimal,robust",
                     help="comma-separated designs (default: these four; robust-set too on request)")
    cpg.add_argument("--scenarios", default="1,2,3,4", help="comma-separated scenario ids (default 1,2,3,4)")
    cpg.add_argument("--scale", type=float, default=1.0,
                     help="scale of the identified standard deviations for the true plants (> 1: beyond them)")
    cpg.add_argument("--bound", type=float, default=None,
                     help="multiplicative uncertainty bound instead of the identified covariance")
    cpg.add_argument("--robust-models", type=int, default=1,
                     help="robust SOCP: Delta samples per system besides the nominal pair (default 1; its time "
                          "per trial grows linearly with 1 + this)")
    cpg.add_argument("--rho", type=float, default=0.95, help="robust: guaranteed improvement factor (default 0.95)")
    cpg.add_argument("--duration", type=float, default=None, help="fly only the first SECONDS of each scenario")
    cpg.add_argument("--seed", type=int, default=0, help="campaign seed (default 0)")
    cpg.add_argument("--law", default="paper", help=_LAW_HELP + " (multi-source refused: one pair, one trial)")
    cpg.add_argument("--out", required=True, help="folder for samples.jsonl, campaign.json, campaign.txt and "
                                                  "campaign_ratios.png; run again to resume")

    chk = sub.add_parser("check", help="the Theorem's condition |Delta| < |1 + P C|/2 per pair and frequency")
    chk.add_argument("--fleet", help="fleet TOML file (default: built-in paper fleet)")
    chk.add_argument("--order", default=None, help="learning order, comma-separated names (default: file order)")
    chk.add_argument("--bound", type=float, default=None,
                     help="multiplicative uncertainty bound for every system (default: identified covariance)")
    chk.add_argument("--scale", type=float, default=1.0, help="scale of the identified standard deviations")
    chk.add_argument("--out", default=None, help="write the check as JSON here")

    rpt = sub.add_parser("report", help="one self-contained HTML report from reproduce/compare/campaign folders")
    rpt.add_argument("dirs", nargs="+", help="folders holding results.json, compare.json or campaign.json")
    rpt.add_argument("--out", required=True, help="HTML file to write")
    rpt.add_argument("--fleet", default=None, help="fleet TOML for results whose own fleet file is not found")

    ifl = sub.add_parser("identify-fleet", help="fly synthetic step/chirp experiments with the nonlinear "
                                                "vehicles and identify every plant of the fleet")
    ifl.add_argument("--fleet", help="fleet TOML file (default: built-in paper fleet)")
    ifl.add_argument("--seed", type=int, default=0, help="seed of the sensor noise (default 0)")
    ifl.add_argument("--out", required=True, help="folder for flights (CSV, Parquet), models, figures and "
                                                  "identified_fleet.toml")

    flt = sub.add_parser("fleet", help="edit fleet files: add a system flying an identified model.json")
    flt_sub = flt.add_subparsers(dest="fleet_command", required=True)
    fad = flt_sub.add_parser("add", help="add a system whose plant is a model.json of `ilcdob identify` (creates "
                                         "the fleet file if needed); the fleet is validated before it is written")
    fad.add_argument("fleet_file", metavar="FLEET.toml", help="fleet file to create or append to")
    fad.add_argument("--name", required=True, help="name of the new system (unique in the fleet)")
    fad.add_argument("--model", required=True, help="model.json of `ilcdob identify`; stored relative to the fleet file")
    fad.add_argument("--kp", type=float, required=True, help="PID proportional gain, 1/s^2")
    fad.add_argument("--ki", type=float, required=True, help="PID integral gain, 1/s^3")
    fad.add_argument("--kd", type=float, required=True, help="PID derivative gain, 1/s")
    fad.add_argument("--derivative-filter", type=float, default=0.05,
                     help="time constant of the derivative low-pass, s (default 0.05)")
    fad.add_argument("--q-order", type=_positive_int, required=True, help="order of the DOB low-pass Q")
    fad.add_argument("--q-time-constant", type=float, required=True, help="time constant of Q, s")
    fad.add_argument("--sample-time", type=float, default=None,
                     help="new fleet file: sample time in s (default: the model.json's sample_time); an existing "
                          "file keeps its own")
    return parser


def _reproduce(args: argparse.Namespace) -> int:
    from ilcdob.design.laws import check_law
    from ilcdob.errors import SpecError
    from ilcdob.app.output import write_reproduction
    from ilcdob.validation.reproduce import reproduce
    from ilcdob.validation.scenarios import parse_scenarios

    ids = parse_scenarios(args.scenarios)
    law = check_law(args.law, "--law")
    if args.plant == "nonlinear" and law != "paper":
        raise SpecError(f"`--law {law}` with `--plant nonlinear`: the nonlinear reproduction flies the paper's law "
                        "with its flight-implementation additions (robustness filter, learning gain, airframe "
                        "correction; ilcdob.validation.nonlinear) and has no other law; use --plant linear, or "
                        "--law paper")
    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    start = time.perf_counter()
    if args.plant == "nonlinear":
        from ilcdob.atomic import write_text_atomic
        from ilcdob.validation.nonlinear import NonlinearSettings, reproduce_nonlinear

        res = reproduce_nonlinear(fleet if args.fleet else None, ids, args.iterations,
                                  NonlinearSettings(seed=args.seed))
        write_text_atomic(Path(args.out) / "identified_fleet.toml", res.identified_toml)
    else:
        res = reproduce(fleet, ids, args.iterations, law=law)
    path = write_reproduction(res, args.out, figures=not args.no_figures)
    print(f"wrote {path} ({time.perf_counter() - start:.1f} s, law {res.law})", file=sys.stderr)
    for sr in res.scenarios:
        for name in sr.order:
            m = sr.systems[name].metrics()
            print(f"scenario {sr.scenario.id} {name:>8}: RMSE no DOB {m['rmse_no_dob']:.4f} m, "
                  f"DOB {m['rmse_dob']:.4f} m, learning "
                  + ", ".join(f"{v:.5f}" for v in m["rmse_learning"]) + " m")
    return 0


def _identify(args: argparse.Namespace) -> int:
    from ilcdob.atomic import write_json_atomic
    from ilcdob.errors import SpecError
    from ilcdob.identification.loaders import load_flight
    from ilcdob.uncertainty import ModelStructure
    from ilcdob.identification.tfest import FitOptions, tfest

    if args.delay == "auto":
        delay: float | str = "auto"
    else:
        try:
            delay = float(args.delay)
        except ValueError:
            raise SpecError(f"`--delay`: got {args.delay!r}, expected 'auto' or a number of seconds >= 0") from None
    if args.trend == "none":
        trend: int | None = None
    else:
        try:
            trend = int(args.trend)
        except ValueError:
            raise SpecError(f"`--trend`: got {args.trend!r}, expected 'none' or a polynomial degree 0-5") from None
    structure = ModelStructure(args.poles, args.zeros, args.integrators)
    fields = {"u": args.input, "y": args.output}
    say = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    kw = {"start": args.start, "stop": args.stop}
    if args.time is not None:
        kw["time"] = args.time
    if args.time_unit is not None:
        logs = [f for f in [*args.files, *args.validate] if Path(f).suffix.lower() not in (".csv", ".parquet", ".pq")]
        if logs:
            raise SpecError(f"`--time-unit`: given with {logs[0]}; a flight log carries its own clock, so "
                            "--time-unit applies to .csv/.parquet files only")
        kw["units"] = {"time": args.time_unit}
    est_data = [load_flight(f, fields, **kw) for f in args.files]
    val_data = [load_flight(f, fields, **kw) for f in args.validate]
    for fd in est_data + val_data:
        gaps = fd.metadata.get("gaps") or []
        if gaps:
            say(f"{fd.source}: {len(gaps)} dropout(s) in the time stamps, each piece fitted with its own initial "
                "condition: " + ", ".join(f"{a:.6g} to {b:.6g} s" for a, b in gaps))
    say(f"fitting {structure.n_params} parameters to {sum(len(d) for d in est_data)} samples "
        f"from {len(est_data)} file(s)")
    est = tfest(est_data, "u", "y", structure, FitOptions(delay=delay, max_delay=args.max_delay, trend=trend,
                                                         time_limit=args.time_limit),
                validation=val_data or None, progress=say)
    data = est.to_dict()
    data["signals"] = {"input": args.input, "output": args.output}
    data["files"] = {"estimation": list(args.files), "validation": list(args.validate)}
    write_json_atomic(args.out, data)
    print(est.summary())
    if est.solver.get("status") != "converged":
        say(f"note: the fit stopped at its {est.solver.get('status')}; model.json holds the best model found "
            "(solver.status)")
    if args.plot:
        from ilcdob.identification.plots import plot_fit

        for path in plot_fit(est, est_data, val_data, args.plot):
            say(f"wrote {path}")
    say(f"wrote {args.out}")
    return 0


def _csv_header(path: str) -> list[str]:
    """Column names of a CSV file (first line that is neither blank nor a ``#`` comment); [] if unreadable."""
    try:
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    return [c.strip().strip('"') for c in line.split(",")]
    except OSError:
        return []  # load_csv reports the missing file
    return []


def _design(args: argparse.Namespace) -> int:
    import json

    import numpy as np

    from ilcdob.atomic import atomic_path
    from ilcdob.design.c_export import check_c_prefix, write_design_folder
    from ilcdob.design.laws import check_law
    from ilcdob.design.pair import design_pair, fleet_delta_sets
    from ilcdob.design.robust import RobustOptions
    from ilcdob.errors import SpecError
    from ilcdob.signals import FlightData
    from ilcdob.identification.loaders import load_csv

    if args.c_prefix is not None:
        check_c_prefix(args.c_prefix)
    law = check_law(args.law, "--law")
    if law == "multi-source":
        raise SpecError("`--law multi-source`: it learns from the trials of every earlier system at once, and "
                        "`ilcdob design` makes one pair's filters from one trial of --from; use `ilcdob reproduce "
                        "--law multi-source` for a learning chain, or ilcdob.design.multi_source.multi_source_learning "
                        "with every trial")
    if law == "exact-reference" and not args.trial:
        raise SpecError("`--law exact-reference`: the law needs the reference trajectory of the trial; give --trial "
                        "CSV with columns time (s), error (m), learning (m/s^2), reference (m) and, for controllers "
                        "with acceleration feed-forward, acceleration (m/s^2)")
    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    columns = {"e": "error", "d_f": "learning"}
    if law == "exact-reference":
        columns["r"] = "reference"
        if "acceleration" in _csv_header(args.trial):
            columns["a"] = "acceleration"
    trial = load_csv(args.trial, columns) if args.trial else None
    if trial is not None and abs(trial.ts - fleet.sample_time) > 1e-9:
        from ilcdob.errors import SignalError

        raise SignalError(f"{args.trial}: sample time {trial.ts} s differs from the fleet's {fleet.sample_time} s")
    if args.method == "robust" and trial is None:
        raise SpecError("`--method robust`: the robust learning signal is an SOCP solved per trial; give the "
                        "previous system's trial with --trial CSV (columns time, error, learning)")
    n = args.n or (len(trial) if trial is not None else None)
    deltas = None
    if args.method in ("fir", "robust", "robust-set"):
        deltas = fleet_delta_sets(fleet, [args.source, args.target], k=args.samples, bound=args.bound)
    reference = {}
    if law == "exact-reference":
        reference = {"reference": trial["r"], "acceleration": trial["a"] if "a" in trial.signals else None}
    design = design_pair(fleet, args.source, args.target, args.method, n=n, deltas=deltas,
                         robust=RobustOptions(rho=args.rho) if args.method in ("robust", "robust-set") else None,
                         law=law,
                         **reference)
    from pathlib import Path

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if "L1" not in design.filters and (args.c_prefix is not None or args.c_float):
        print(f"ilcdob: note: method {args.method} has no L1/L2 filters; no C code written "
              "(--c-prefix/--c-float ignored)", file=sys.stderr)
    arrays = design.lifted
    if trial is not None and design.robust is not None:
        terms = design.reference
        res = design.robust.design(terms.error_in(trial["e"]) if terms else trial["e"], trial["d_f"])
        df = terms.signal_out(res.d_f) if terms else res.d_f
        design.filters["trial"] = {"worst_ratio": res.worst_ratio, "ratios": res.ratios.tolist(), "rho": res.rho,
                                   "status": res.status, "solve_time_s": res.solve_time}
        arrays = {"d_f": res.d_f, "ratios": res.ratios, "predicted_errors": res.errors}
    elif trial is not None:
        df = design.learn(trial["e"], trial["d_f"])
    others = []
    if arrays is not None:
        with atomic_path(out / "lifted.npz") as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
        others.append("lifted.npz")
    if trial is not None:
        FlightData(trial.t, {"learning": df}, {"learning": "m/s^2"},
                   source=f"learning signal of {args.target} from {args.trial}").to_csv(out / "learning_signal.csv")
        others.append("learning_signal.csv")
    if design.reference is not None:
        FlightData(trial.t, {"e_ref_source": design.reference.source_error, "correction": design.reference.correction},
                   {"e_ref_source": "m", "correction": "m/s^2"},
                   source=f"reference terms of {args.source} -> {args.target} for {args.trial}"
                   ).to_csv(out / "reference_terms.csv")
        others.append("reference_terms.csv")
        print(f"wrote {out / 'learning_signal.csv'}", file=sys.stderr)
    written = write_design_folder(out, design.filters, others, prefix=args.c_prefix, float_variant=args.c_float)
    print(json.dumps({k: v for k, v in written.items() if k not in ("L1", "L2")}))
    names = ["filters.h", "filters.c"] if "c" in written else []
    print(f"wrote {', '.join(str(out / n) for n in [*names, 'README.md', 'filters.json'])}", file=sys.stderr)
    return 0


def _compare(args: argparse.Namespace) -> int:
    from ilcdob.design.robust import RobustOptions
    from ilcdob.validation.compare import CompareOptions, compare_designs, write_comparison
    from ilcdob.validation.scenarios import parse_scenarios

    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    (sid,) = parse_scenarios(str(args.scenario))
    opts = CompareOptions(samples=args.samples, bound=args.bound, scale=args.scale, seed=args.seed,
                          duration=args.duration, robust=RobustOptions(rho=args.rho), law=args.law)
    cmp = compare_designs(fleet, sid, [m.strip() for m in args.methods.split(",")], opts)
    print(cmp.table(), end="")
    if args.out:
        write_comparison(cmp, args.out, rho=args.rho)
        print(f"wrote {args.out}/compare.json", file=sys.stderr)
    return 0


def _extensions(args: argparse.Namespace) -> int:
    from dataclasses import asdict
    from pathlib import Path

    from ilcdob.atomic import write_json_atomic, write_text_atomic
    from ilcdob.validation.extensions import extensions_study, format_extensions
    from ilcdob.validation.scenarios import parse_scenarios

    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    rows = extensions_study(fleet, parse_scenarios(args.scenarios))
    table = format_extensions(rows)
    out = Path(args.out)
    write_json_atomic(out / "extensions.json", {"fleet": fleet.source, "units": "ratio ||e_j|| / ||e'_j||",
                                                "scenarios": [asdict(r) for r in rows]})
    write_text_atomic(out / "README.md", "# Beyond the paper\n\nGenerated by `ilcdob extensions --out "
                      f"{args.out}` (see `validation/beyond.py` for the set-up).\n\n" + table)
    print(table, end="")
    return 0


def _campaign(args: argparse.Namespace) -> int:
    from ilcdob.validation.campaign import CampaignOptions, run_campaign
    from ilcdob.validation.scenarios import parse_scenarios

    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    opts = CampaignOptions(samples=args.samples, seed=args.seed, scale=args.scale, bound=args.bound,
                           scenarios=tuple(parse_scenarios(args.scenarios)),
                           methods=tuple(m.strip() for m in args.methods.split(",")), duration=args.duration,
                           robust_models=args.robust_models, rho=args.rho, law=args.law)
    result = run_campaign(fleet, opts, args.out, scheduler=args.scheduler, workers=args.workers)
    print(result.table(), end="")
    print(f"wrote {args.out}/campaign.json ({result.wall_time_s:.0f} s)", file=sys.stderr)
    return 0


def _check(args: argparse.Namespace) -> int:
    from ilcdob.atomic import write_json_atomic
    from ilcdob.design.pair import fleet_delta_sets
    from ilcdob.design.theorem import format_theorem_table, theorem_check

    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    order = [s.strip() for s in args.order.split(",")] if args.order else fleet.names
    for name in order:
        fleet.loop(name)  # unknown names: a clear error
    deltas = fleet_delta_sets(fleet, order, k=8, bound=args.bound, scale=args.scale)
    checks = theorem_check(fleet, order, deltas)
    print(format_theorem_table(checks))
    if args.out:
        write_json_atomic(args.out, {"order": order, "pairs": [c.to_dict() for c in checks]})
    return 0


def _identify_fleet(args: argparse.Namespace) -> int:
    from ilcdob.identification.fleet_id import identify_fleet

    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    say = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    results = identify_fleet(fleet, args.out, seed=args.seed, progress=say)
    for name, vid in results.items():
        print(f"{name}: {vid.estimate.summary()}")
    say(f"wrote {args.out}/identified_fleet.toml")
    return 0


def _fleet(args: argparse.Namespace) -> int:
    from ilcdob.errors import SpecError
    from ilcdob.fleet_io import add_system
    from ilcdob.identified import load_model
    from ilcdob.specs import DOBSpec, PIDSpec

    path = Path(args.fleet_file)
    created = not path.exists()
    model_ts = load_model(args.model).sample_time
    try:
        controller = PIDSpec(args.kp, args.ki, args.kd, args.derivative_filter)
        dob = DOBSpec(args.q_order, args.q_time_constant)
    except SpecError as exc:
        raise SpecError(f"{path}: system {args.name!r} (--kp/--ki/--kd/--derivative-filter, --q-order/"
                        f"--q-time-constant): {exc}; nothing written") from exc
    fleet = add_system(path, args.name, args.model, controller, dob, sample_time=args.sample_time)
    if created:
        origin = "--sample-time" if args.sample_time is not None else f"the sample_time of {args.model}"
        print(f"created {path} with sample time {fleet.sample_time:g} s (from {origin})", file=sys.stderr)
    if model_ts != fleet.sample_time:
        print(f"note: {args.model} was identified from data sampled at {model_ts:g} s; the fleet runs at "
              f"{fleet.sample_time:g} s (the continuous-time model is discretised at the fleet's)", file=sys.stderr)
    print(f"added {args.name} to {path}: systems {fleet.names}", file=sys.stderr)
    return 0


def _report(args: argparse.Namespace) -> int:
    from ilcdob.app.html import ReportOptions, write_report

    path = write_report(args.dirs, args.out, ReportOptions(fleet=args.fleet))
    print(f"wrote {path}", file=sys.stderr)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ilcdob`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "reproduce":
            return _reproduce(args)
        if args.command == "identify":
            return _identify(args)
        if args.command == "identify-fleet":
            return _identify_fleet(args)
        if args.command == "design":
            return _design(args)
        if args.command == "check":
            return _check(args)
        if args.command == "compare":
            return _compare(args)
        if args.command == "campaign":
            return _campaign(args)
        if args.command == "extensions":
            return _extensions(args)
        if args.command == "report":
            return _report(args)
        if args.command == "fleet":
            return _fleet(args)
    except IlcdobError as exc:
        print(f"ilcdob: error: {exc}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command!r}")
    return 2


if __name__ == "__main__":
    sys.exit(main())
