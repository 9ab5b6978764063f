"""Command-line interface: a thin layer over the public API.

``ilcdob reproduce [--fleet FILE] [--scenarios 1,2,3,4] [--iterations 3] --out DIR``
runs the paper's validation on a fleet (default: the built-in three UAVs) and writes
``DIR/results.json``, the figures and ``DIR/README.md``.

``ilcdob identify FILE [FILE ...] --input COL --output COL [--time COL] --poles N [--zeros M]
[--integrators K] [--delay auto|SECONDS] [--validate FILE ...] --out model.json [--plot DIR]``
fits a continuous-time transfer function to flight data (CSV, Parquet, PX4 ULog with
TOPIC.FIELD, ArduPilot DataFlash with MESSAGE.FIELD) and writes ``model.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from .errors import IlcdobError
from .fleet import default_fleet, load_fleet

__all__ = ["main", "build_parser"]


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

    idf = sub.add_parser("identify", help="fit a continuous-time transfer function to flight data")
    idf.add_argument("files", nargs="+", help="estimation data: .csv, .parquet, .ulg or .bin")
    idf.add_argument("--input", required=True, help="input signal: COLUMN, TOPIC.FIELD (ULog) or MESSAGE.FIELD")
    idf.add_argument("--output", required=True, help="output signal, same forms as --input")
    idf.add_argument("--time", default=None, help="time column of CSV/Parquet files (default: time), in s")
    idf.add_argument("--poles", type=_positive_int, required=True, help="number of poles, integrators included")
    idf.add_argument("--zeros", type=int, default=0, help="number of zeros (default 0)")
    idf.add_argument("--integrators", type=int, default=0, help="poles fixed at s = 0 (default 0)")
    idf.add_argument("--delay", default="0", help="input delay in s, or 'auto' to estimate it (default 0)")
    idf.add_argument("--max-delay", type=float, default=0.3, help="upper bound of the delay search, s")
    idf.add_argument("--validate", nargs="*", default=[], help="held-out data files")
    idf.add_argument("--start", type=float, default=None, help="segment start, s (log clock)")
    idf.add_argument("--stop", type=float, default=None, help="segment end, s (log clock)")
    idf.add_argument("--out", required=True, help="model.json to write")
    idf.add_argument("--plot", default=None, help="folder for the compare/residual/Bode figures")

    ifl = sub.add_parser("identify-fleet", help="fly synthetic step/chirp experiments with the nonlinear "
                                                "vehicles and identify every plant of the fleet")
    ifl.add_argument("--fleet", help="fleet TOML file (default: built-in paper fleet)")
    ifl.add_argument("--seed", type=int, default=0, help="seed of the sensor noise (default 0)")
    ifl.add_argument("--out", required=True, help="folder for flights (CSV, Parquet), models, figures and "
                                                  "identified_fleet.toml")
    return parser


def _reproduce(args: argparse.Namespace) -> int:
    from .report import write_reproduction
    from .validation.reproduce import reproduce
    from .validation.scenarios import parse_scenarios

    ids = parse_scenarios(args.scenarios)
    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    start = time.perf_counter()
    res = reproduce(fleet, ids, args.iterations)
    path = write_reproduction(res, args.out, figures=not args.no_figures)
    print(f"wrote {path} ({time.perf_counter() - start:.1f} s)", file=sys.stderr)
    for sr in res.scenarios:
        for name in sr.order:
            m = sr.systems[name].metrics()
            print(f"scenario {sr.scenario.id} {name:>8}: RMSE no DOB {m['rmse_no_dob']:.4f} m, "
                  f"DOB {m['rmse_dob']:.4f} m, learning "
                  + ", ".join(f"{v:.5f}" for v in m["rmse_learning"]) + " m")
    return 0


def _identify(args: argparse.Namespace) -> int:
    from .atomic import write_json_atomic
    from .errors import SpecError
    from .identification.loaders import load_flight
    from .identification.model import ModelStructure
    from .identification.tfest import FitOptions, tfest

    if args.delay == "auto":
        delay: float | str = "auto"
    else:
        try:
            delay = float(args.delay)
        except ValueError:
            raise SpecError(f"`--delay`: got {args.delay!r}, expected 'auto' or a number of seconds >= 0") from None
    structure = ModelStructure(args.poles, args.zeros, args.integrators)
    fields = {"u": args.input, "y": args.output}
    kw = {"start": args.start, "stop": args.stop}
    if args.time is not None:
        kw["time"] = args.time
    est_data = [load_flight(f, fields, **kw) for f in args.files]
    val_data = [load_flight(f, fields, **kw) for f in args.validate]
    say = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    say(f"fitting {structure.n_params} parameters to {sum(len(d) for d in est_data)} samples "
        f"from {len(est_data)} file(s)")
    est = tfest(est_data, "u", "y", structure, FitOptions(delay=delay, max_delay=args.max_delay),
                validation=val_data or None, progress=say)
    data = est.to_dict()
    data["signals"] = {"input": args.input, "output": args.output}
    data["files"] = {"estimation": list(args.files), "validation": list(args.validate)}
    write_json_atomic(args.out, data)
    print(est.summary())
    if args.plot:
        from .identification.plots import plot_fit

        for path in plot_fit(est, est_data, val_data, args.plot):
            say(f"wrote {path}")
    say(f"wrote {args.out}")
    return 0


def _identify_fleet(args: argparse.Namespace) -> int:
    from .identification.fleet_id import identify_fleet

    fleet = load_fleet(args.fleet) if args.fleet else default_fleet()
    say = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    results = identify_fleet(fleet, args.out, seed=args.seed, progress=say)
    for name, vid in results.items():
        print(f"{name}: {vid.estimate.summary()}")
    say(f"wrote {args.out}/identified_fleet.toml")
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
    except IlcdobError as exc:
        print(f"ilcdob: error: {exc}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command!r}")
    return 2


if __name__ == "__main__":
    sys.exit(main())
