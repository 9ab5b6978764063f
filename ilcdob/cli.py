"""Command-line interface: a thin layer over the public API.

``ilcdob reproduce [--fleet FILE] [--scenarios 1,2,3,4] [--iterations 3] --out DIR``
runs the paper's validation on a fleet (default: the built-in three UAVs) and writes
``DIR/results.json``, the figures and ``DIR/README.md``.
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ilcdob`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "reproduce":
            return _reproduce(args)
    except IlcdobError as exc:
        print(f"ilcdob: error: {exc}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command!r}")
    return 2


if __name__ == "__main__":
    sys.exit(main())
