"""ilcdob: learning among systems with mismatched dynamics (DOB + ILC for fleets).

Argument parsing and dispatch only: every command is a use case of
:mod:`ilcdob.app.commands`, which Python users can call directly. Exit status: 0 success;
1 a check that ran and did not hold (``check``; ``identify --min-fit``; a learning signal beyond
the acceleration limit with ``design --on-limit refuse``); 2 bad input or
usage; 3 a solver or numerical failure, or an internal error (a bug: reported in one line);
130 Ctrl-C and 143 SIGTERM, each after the run's cleanup (:class:`Terminated`).
"""

from __future__ import annotations

import argparse
import errno
import math
import signal
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import NoReturn

from ilcdob.errors import IlcdobError, LearningLimitError, NumericalError

from .output import version

__all__ = ["main", "build_parser"]

_LAW = ("learning law: paper (the Theorem's filters; default), exact-reference (keeps the reference term), "
        "multi-source (every earlier system's trial at once; reproduce only)")
_EXAMPLES = {
    "reproduce": "ilcdob reproduce --out reports/paper",
    "identify": "ilcdob identify flight.csv --input acc_cmd --output x --poles 3 --integrators 2 --delay auto "
                "--out model.json",
    "identify-fleet": "ilcdob identify-fleet --out identified/",
    "design": "ilcdob design --from UAV1 --to UAV2 --out uav1_uav2/",
    "learn": "ilcdob learn uav1_trial.csv --design uav1_uav2/ --reference ref --position x --out uav2_next/",
    "check": "ilcdob check --fleet identified/identified_fleet.toml",
    "compare": "ilcdob compare --scenario 1 --out compare/",
    "extensions": "ilcdob extensions --out extensions/",
    "campaign": "ilcdob campaign --samples 200 --out campaign/",
    "report": "ilcdob report reports/paper reports/compare --out report.html",
    "fleet": "ilcdob fleet add my_fleet.toml --name UAV4 --model model.json --kp 3 --ki 0.3 --kd 2.4 "
             "--q-order 3 --q-time-constant 0.15",
}


#: Most starts of ``identify`` (each runs the Levenberg-Marquardt search again, up to --max-iter iterations).
MAX_STARTS = 20
#: Most Levenberg-Marquardt iterations per start of ``identify``.
MAX_LM_ITERATIONS = 10_000
#: Choices of ``design``, ``compare`` and ``learn --fir-unattainable``: ``ilcdob.design.fir.UNATTAINABLE`` (not imported here, so that
#: ``--help`` stays fast; a test keeps the two equal).
FIR_UNATTAINABLE = ("no-harm", "refuse")


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors end, like every other error, in one ``ilcdob: error:`` line (exit 2)."""

    def error(self, message: str) -> NoReturn:
        command = self.prog.removeprefix("ilcdob").strip()
        where = f"`{command}`: " if command else ""
        self.exit(2, f"ilcdob: error: {where}{' '.join(message.split())} (see `{self.prog} --help`)\n")


class _Defaults(argparse.HelpFormatter):
    """States every default that the help text does not already state (None/False: nothing to state)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if "default" in text or default is None or default is False or default == argparse.SUPPRESS \
                or not action.option_strings:
            return text
        shown = ",".join(map(str, default)) if isinstance(default, list) else default
        return f"{text} (default: {shown})"


def _globals(p: argparse.ArgumentParser, default: object) -> None:
    """--quiet and --debug, accepted before and after the command name."""
    p.add_argument("--quiet", action="store_true", default=default,
                   help="no progress bars, notes or warnings on stderr (errors, and a learning signal clipped at "
                        "the acceleration limit, are still reported)")
    p.add_argument("--debug", action="store_true", default=default, help="show the traceback of an error")


def _sub(sub, name: str, text: str) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=text, description=text, epilog=f"example: {_EXAMPLES[name]}",
                       formatter_class=_Defaults)
    _globals(p, argparse.SUPPRESS)
    return p


def _common(p: argparse.ArgumentParser, out: str | None, fleet: bool = True, law: bool = False) -> None:
    if fleet:
        p.add_argument("--fleet", help="fleet TOML file (default: the built-in fleet of the paper's three UAVs)")
    if law:
        p.add_argument("--law", default="paper", help=_LAW)  # states its default
    if out is not None:
        p.add_argument("--out", required=out != "optional", default=None, help=out if out != "optional"
                       else "output folder (default: print only)")
        p.add_argument("--overwrite", action="store_true", help="replace a non-empty folder ilcdob did not write")


def _pos(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"got {text!r}, expected an integer >= 1")
    return value


def _count(maximum: int, why: str) -> Callable[[str], int]:
    """An argument type: an integer from 1 to ``maximum`` (``why``: what each one costs)."""
    def count(text: str) -> int:
        value = _pos(text)
        if value > maximum:
            raise argparse.ArgumentTypeError(f"got {text!r}, expected an integer from 1 to {maximum}: {why}")
        return value

    return count


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"got {text!r}, expected a seed: an integer >= 0")
    return value


def _fit_percent(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value <= 100):
        raise argparse.ArgumentTypeError(f"got {text!r}, expected a fit in % (a finite number <= 100: 100 is a "
                                         "perfect fit, below 0 the model fits worse than the output's mean)")
    return value


def _poles(text: str) -> list[int]:
    lo, sep, hi = text.partition("..")
    try:
        first, last = int(lo), int(hi if sep else lo)
    except ValueError:
        first = last = 0
    if first < 1 or last < first or last - first > 8:
        raise argparse.ArgumentTypeError(f"got {text!r}, expected a number of poles >= 1, or a range A..B "
                                         "(1 <= A <= B <= A + 8) to compare orders")
    return list(range(first, last + 1))


def _axis_option(p: argparse.ArgumentParser, design: bool = False) -> None:
    p.add_argument("--axis", choices=("x", "y", "z"), default=None if design else "x",
                   help="axis" + (" (default x, or the --design's)" if design else "") + ": x (the paper's), or "
                        "y / z from the fleet file's [system.y] / [system.z] sections")


def _ids(text: str) -> list[int]:
    from ilcdob.validation.scenarios import parse_scenarios

    try:
        return parse_scenarios(text)
    except IlcdobError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _names(text: str) -> list[str]:
    return [n.strip() for n in text.split(",")]


def _methods(text: str) -> list[str]:
    methods = [m.strip() for m in text.split(",")]
    if not all(methods):
        raise argparse.ArgumentTypeError(f"got {text!r}, expected comma-separated design names without empty "
                                         "entries, e.g. closed-form,fir")
    return methods


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``ilcdob`` command."""
    parser = _Parser(prog="ilcdob", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"ilcdob {version()}")
    _globals(parser, False)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    p = _sub(sub, "reproduce", "run the paper's four scenarios; write results, figures and an index")
    _common(p, "output folder (written as a unit)", law=True)
    p.add_argument("--scenarios", type=_ids, default=[1, 2, 3, 4], help="comma-separated scenario ids")
    p.add_argument("--iterations", type=_pos, default=3, help="learning iterations")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--plant", choices=("linear", "nonlinear", "rotorpy"), default="linear",
                   help="linear: the fleet's models; nonlinear: identify and fly the 6-DOF quadrotors; rotorpy: "
                        "identify and fly rotorpy's multirotors in the paper's disturbance and in wind, every law "
                        "(needs the [rotorpy] extra)")
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor noise (rotorpy: of the Dryden turbulence)")
    p.add_argument("--workers", type=_pos, default=None,
                   help="processes flying the scenarios, --plant rotorpy only (default 1)")
    p.add_argument("--sensor-noise", type=float, default=None,
                   help="white position-sensor noise of every flight, m (default: 0 linear, 0.0005 nonlinear and "
                        "rotorpy)")
    _band_options(p)
    p.add_argument("--order", type=_names, default=None,
                   help="learning order of every scenario, comma-separated system names, each once, at least two "
                        "(default: scenario 4 flies the 1st, 3rd, 2nd system of a three-system fleet, the others "
                        "the file order)")
    p = _sub(sub, "identify", "fit a continuous-time transfer function to flight data; write model.json")
    p.description += (". Diagnostics (printed as notes, and in model.json's `diagnostics`): the estimated delay on a "
                      "bound of its search, poles or zeros beyond the Nyquist frequency, residuals that are not "
                      "white or that correlate with the input, an estimation file fitting far worse than the others "
                      "(per-file fits: `file_fits_percent`), samples left out as gross errors (--keep-outliers)")
    p.add_argument("files", nargs="+", help="estimation data: .csv, .parquet, .ulg or .bin")
    p.add_argument("--input", required=True, help="input signal: COLUMN, TOPIC.FIELD (ULog) or MESSAGE.FIELD")
    p.add_argument("--output", required=True, help="output signal, same forms as --input")
    _clock_options(p, "segment")
    p.add_argument("--poles", type=_poles, required=True,
                   help="number of poles, integrators included; a range A..B fits every order, prints their "
                        "estimation and held-out fits and AIC, and writes the chosen one (the fewest poles within "
                        "0.5 points of the best held-out fit; without --validate the lowest AIC)")
    p.add_argument("--zeros", type=int, default=0, help="number of zeros")
    p.add_argument("--integrators", type=int, default=0, help="poles fixed at s = 0")
    p.add_argument("--delay", default="0", help="input delay in s, or 'auto' to estimate it")
    p.add_argument("--max-delay", type=float, default=None,
                   help="upper bound of the delay search, s (default: a tenth of the shortest file)")
    p.add_argument("--trend", default="0", help="per-file output trend: 'none' or a polynomial degree 0-5")
    p.add_argument("--time-limit", type=float, default=None, help="wall-time limit of the fit, s (none)")
    p.add_argument("--starts", type=_count(MAX_STARTS, "each start runs the Levenberg-Marquardt search again, "
                                                    "up to --max-iter iterations over every sample"), default=2,
                   help="initial estimates (SRIVC, pole grid, frequency-domain fit) the search runs from; with "
                        "--delay auto each also profiles the delay")
    p.add_argument("--max-iter", type=_count(MAX_LM_ITERATIONS, "each iteration simulates the model and its "
                                                  "sensitivities over every sample (measured: 6.5 ms for 30,000 "
                                                  "samples, 5 poles, 2 zeros), so 10,000 iterations over a one-hour "
                                                  "log at 50 Hz take about 7 min per start; bound the wall time "
                                                  "with --time-limit"),
                   default=100, help="Levenberg-Marquardt iteration limit per start")
    p.add_argument("--allow-unstable", action="store_true",
                   help="let free poles enter the right half plane (an open-loop unstable plant; default: such "
                        "models are rejected during the fit)")
    p.add_argument("--keep-outliers", action="store_true",
                   help="keep every sample (default: samples more than 10 robust standard deviations off the first "
                        "fit, a glitch in a log, are left out, the record cut there, and named in the notes)")
    p.add_argument("--min-fit", type=_fit_percent, default=None,
                   help="exit 1 when the held-out fit (%%) is below this")
    p.add_argument("--validate", nargs="*", default=[], help="held-out data files")
    p.add_argument("--segment", type=float, default=None, metavar="SECONDS",
                   help="cut every file (estimation and --validate alike) into consecutive windows of SECONDS, each "
                        "fitted with its own initial condition; a last piece of at most half a window joins the one "
                        "before it (default: each file whole)")
    p.add_argument("--out", required=True, help="model.json to write")
    p.add_argument("--plot", default=None, help="folder for the compare/residual/Bode figures")
    p = _sub(sub, "design", "design the learning filters of one system from another; write filters and C code")
    _common(p, "output folder (written as a unit)", law=True)
    _axis_option(p)
    p.add_argument("--from", dest="source", required=True, help="system learned from (j-1)")
    p.add_argument("--to", dest="target", required=True, help="system that learns (j)")
    p.add_argument("--method", default="closed-form", help="closed-form, fir, norm-optimal, robust or robust-set")
    p.add_argument("--rho", type=float, default=None,
                   help="robust and robust-set only: guaranteed improvement factor (default 0.95)")
    p.add_argument("--samples", type=_pos, default=None,
                   help="fir and robust only: Delta-set samples per system (default 8)")
    p.add_argument("--bound", type=float, default=None,
                   help="fir, robust and robust-set only: multiplicative uncertainty bound (default: identified)")
    p.add_argument("--n", type=_pos, default=None,
                   help="norm-optimal only: trial length in samples (default: the trial's, else 500)")
    p.add_argument("--lifted", action="store_true",
                   help="norm-optimal only: also write the N x N lifted matrices L1, L2 to lifted.npz (about 8 N^2 "
                        "numbers of memory while built; default: the law as Riccati gains only, O(N))")
    p.add_argument("--fir-unattainable", choices=FIR_UNATTAINABLE, default=None,
                   help="fir only: where no filter meets |Te1| <= 0.9 for every sampled model, keep only the no-harm "
                        "promise there and warn (default: no-harm), or refuse the design (exit 2, bands named)")
    p.add_argument("--trial", default=None, help="CSV of the source's trial: time (s), error (m), learning (m/s^2)")
    p.add_argument("--c-prefix", default=None,
                   help="prefix of the C symbols (default: ilcdob_<from>_<to>_, then <axis>_ for y and z)")
    p.add_argument("--c-float", action="store_true", help="also emit float C functions, with their measured error")
    _band_options(p)
    p.add_argument("--disturbance", choices=("command", "airframe", "wind"), default="command",
                   help="where the disturbance acts: added to the command (the paper's loop), on the airframe (adds "
                        "the attitude-chain correction), or a wind velocity through each airframe's drag (also "
                        "scales by the ratio of the models' drag poles)")
    p.add_argument("--on-limit", choices=("clip", "refuse"), default="clip",
                   help="a learning signal beyond the fleet's acceleration limit of --to: clip it (with a warning) or "
                        "refuse it (exit 1)")
    p = _sub(sub, "learn", "the next vehicle's learning signal from a recorded trial of the previous one, computed as "
                           "the emitted C code computes it; writes it as CSV, binary and a C array")
    _common(p, "output folder (written as a unit)")
    _axis_option(p, design=True)
    p.add_argument("trial", help="the recorded trial of --from: .csv, .parquet, .ulg or .bin")
    p.add_argument("--from", dest="source", default=None, help="system learned from (j-1); read from --design if given")
    p.add_argument("--to", dest="target", default=None, help="system that learns (j); read from --design if given")
    p.add_argument("--design", default=None, help="a folder written by `ilcdob design` whose filters run (default: "
                                                  "design them here from the fleet)")
    p.add_argument("--method", default="closed-form", help="without --design: closed-form or fir")
    p.add_argument("--fir-unattainable", choices=FIR_UNATTAINABLE, default=None,
                   help="--method fir without --design: where no filter meets |Te1| <= 0.9 for every sampled model, "
                        "keep only the no-harm promise there (default: no-harm), or refuse (exit 2, bands named)")
    p.add_argument("--error", default=None, help="tracking error column, m: COLUMN, TOPIC.FIELD (ULog) or "
                                                 "MESSAGE.FIELD (DataFlash)")
    p.add_argument("--reference", default=None, help="instead of --error: reference position, m (same forms)")
    p.add_argument("--position", default=None, help="with --reference: measured position, m (same forms)")
    p.add_argument("--learning", default=None, help="learning signal the trial flew, m/s^2 (default: none)")
    _clock_options(p, "trial")
    _band_options(p)
    p.add_argument("--on-limit", choices=("clip", "refuse"), default="clip",
                   help="a learning signal beyond the acceleration limit of --to: clip it (with a warning) or refuse "
                        "it (exit 1)")
    p = _sub(sub, "check", "will learning help? per pair and frequency the exact worst case of the error ratio "
                           "|e_j/e'_j| over the Delta set (|Delta| <= W) for the law with its learning band, the "
                           "ratio for a stated plant, and the paper's first-order condition |Delta| < |1 + P C|/2 "
                           "beside it (exit 1: improvement not guaranteed, the exact worst case exceeds 1.01)")
    _common(p, None)
    _axis_option(p)
    p.add_argument("--order", default=None, help="learning order, comma-separated names (default: file order)")
    p.add_argument("--bound", type=float, default=None, help="multiplicative uncertainty bound (default: identified)")
    p.add_argument("--scale", type=float, default=None,
                   help="scale of the identified standard deviations (default 1; not with --bound)")
    _band_options(p)
    p.add_argument("--out", default=None, help="JSON file for the check (default: print only)")
    p = _sub(sub, "compare", "fly every design through a scenario, nominal and over the Delta set")
    _common(p, "optional", law=True)
    p.add_argument("--scenario", type=_pos, required=True, help="scenario id 1-4")
    p.add_argument("--methods", type=_methods, default=None, help="comma-separated designs (default: "
                   "closed-form,fir,norm-optimal,robust)")
    _delta_options(p)
    p.add_argument("--duration", type=float, default=None, help="fly the first SECONDS of the scenario (default: all)")
    p.add_argument("--seed", type=_seed, default=0, help="seed of the Delta-set draw")
    p.add_argument("--fir-unattainable", choices=FIR_UNATTAINABLE, default=None,
                   help="fir only: where no filter meets |Te1| <= 0.9 for every sampled model, keep only the no-harm "
                        "promise there (default: no-harm), or refuse the design (exit 2, bands named)")
    p = _sub(sub, "extensions", "the two extensions beyond the paper, per scenario")
    _common(p, "output folder (written as a unit)")
    p.add_argument("--scenarios", type=_ids, default=[1, 2, 3, 4], help="comma-separated scenario ids")
    p = _sub(sub, "campaign", "Monte Carlo campaign on Dask over sampled true plants (resumable)")
    _common(p, "output folder; run again to resume", law=True)
    p.add_argument("--samples", type=_pos, required=True, help="number of sampled true plants")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", default=None,
                       help="Dask scheduler tcp://HOST:PORT or tls://HOST:PORT (default: a local cluster)")
    where.add_argument("--scheduler-file", default=None,
                       help="the JSON file `dask scheduler --scheduler-file PATH` wrote (instead of --scheduler)")
    p.add_argument("--tls-ca-file", default=None, help="tls:// scheduler: the CA certificate (PEM)")
    p.add_argument("--tls-cert", default=None, help="tls:// scheduler: this client's certificate (PEM)")
    p.add_argument("--tls-key", default=None, help="tls:// scheduler: the client's private key (PEM; omit when "
                   "--tls-cert holds it)")
    p.add_argument("--workers", type=_pos, default=None, help="local cluster: worker processes (default: cores)")
    p.add_argument("--dashboard", action="store_true", help="print the Dask dashboard link")
    p.add_argument("--methods", type=_methods, default=None, help="comma-separated designs (default: "
                   "closed-form,fir,norm-optimal,robust)")
    p.add_argument("--scenarios", type=_ids, default=[1, 2, 3, 4], help="comma-separated scenario ids")
    _delta_options(p, samples=False)
    p.add_argument("--robust-models", type=int, default=None,
                   help="robust only: Delta samples per system in its SOCP (default 1)")
    p.add_argument("--delta-set", default=None, choices=["structured", "disc", "auto"],
                   help="robust-set: guarantee over the family the plants are drawn from (structured), the disc "
                        "|Delta| <= bound, or auto (default: structured)")
    p.add_argument("--margin", type=float, default=0.5,
                   help="redraw true plants whose disturbance response exceeds 1/MARGIN times the model's at some "
                        "frequency; robust-set guarantees over the same plants (default 0.5: within 6 dB; "
                        "0: every stable plant)")
    p.add_argument("--duration", type=float, default=None, help="fly the first SECONDS of each scenario (default: all)")
    p.add_argument("--seed", type=_seed, default=0, help="campaign seed")
    p = _sub(sub, "report", "one self-contained HTML report from reproduce/compare/campaign folders")
    p.add_argument("dirs", nargs="+", help="output folders of reproduce, compare or campaign")
    p.add_argument("--out", required=True, help="HTML file to write")
    p = _sub(sub, "identify-fleet", "fly step/chirp experiments with the nonlinear vehicles, identify every plant")
    _common(p, "output folder (written as a unit)")
    p.add_argument("--seed", type=_seed, default=0, help="seed of the sensor noise")
    p = _sub(sub, "fleet", "edit fleet files")
    fad = p.add_subparsers(dest="fleet_command", required=True).add_parser(
        "add", help="add a system flying an identified model.json (creates the fleet file if needed)",
        epilog=f"example: {_EXAMPLES['fleet']}", formatter_class=_Defaults)
    _globals(fad, argparse.SUPPRESS)
    fad.add_argument("fleet_file", metavar="FLEET.toml", help="fleet file to create or append to")
    fad.add_argument("--name", required=True, help="name of the new system")
    fad.add_argument("--model", required=True, help="model.json of `ilcdob identify`")
    for gain, unit in (("kp", "1/s^2"), ("ki", "1/s^3"), ("kd", "1/s")):
        fad.add_argument(f"--{gain}", type=float, required=True, help=f"PID gain {gain}, {unit}")
    fad.add_argument("--derivative-filter", type=float, default=0.05, help="derivative low-pass time constant, s")
    fad.add_argument("--q-order", type=_pos, required=True, help="order of the DOB low-pass Q")
    fad.add_argument("--q-time-constant", type=float, required=True, help="time constant of Q, s")
    fad.add_argument("--sample-time", type=float, default=None, help="new file: sample time, s (default: model's)")
    return parser


def _clock_options(p: argparse.ArgumentParser, segment: str) -> None:
    """--time, --time-unit, --start and --stop (``segment``: what the start and end are of)."""
    p.add_argument("--time", default=None, help="time column of CSV/Parquet files (default: time)")
    p.add_argument("--time-unit", choices=("s", "ms", "us", "ns"), default=None,
                   help="unit of that column (default: the file's '# units:' line, else s)")
    p.add_argument("--start", type=float, default=None, help=f"{segment} start, s (log clock)")
    p.add_argument("--stop", type=float, default=None, help=f"{segment} end, s (log clock)")


def _band_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bandwidth", default="auto",
                   help="corner of the learning band, rad/s; 'auto' chooses it from the trial's noise and the "
                        "models' trusted band (the fleet's sensor noise, limits and Delta sets without a trial); "
                        "'off': the Theorem's filters unfiltered")


def _delta_options(p: argparse.ArgumentParser, samples: bool = True) -> None:
    if samples:
        p.add_argument("--samples", type=_pos, default=8, help="Delta-set samples per system")
    p.add_argument("--bound", type=float, default=None, help="multiplicative uncertainty bound (default: identified)")
    p.add_argument("--scale", type=float, default=None,
                   help="scale of the identified standard deviations (default 1; not with --bound)")
    p.add_argument("--rho", type=float, default=None,
                   help="robust and robust-set only: guaranteed improvement factor (default 0.95)")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ilcdob`` command; returns the exit status.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments after ``ilcdob`` (default: ``sys.argv[1:]``).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    for stream in (sys.stdout, sys.stderr):  # a console that cannot show a character gets its escape, not a crash
        try:
            stream.reconfigure(errors="backslashreplace")
        except (AttributeError, ValueError, OSError):
            pass
    previous = _terminate_as_interrupt()
    try:
        return _main(argv)
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (Terminated): the outputs' cleanup has run
        name = "terminated" if isinstance(exc, Terminated) else "interrupted"
        sys.stderr.write(f"ilcdob: error: {name}; outputs of this run were not written (earlier outputs are "
                         "intact)\n")
        return 128 + (signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


#: Errors of a write that found no room: a full disk or quota, a file beyond the size limit.
_FULL = {errno.ENOSPC, errno.EFBIG, getattr(errno, "EDQUOT", errno.ENOSPC)}


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C so that every cleanup (staging folders,
    temporaries, locks) runs before the process ends."""


def _raise_terminated(signum: int, frame: object) -> NoReturn:
    raise Terminated(signum)


def _terminate_as_interrupt():
    """Turn SIGTERM into :class:`Terminated`; returns the previous handler (None: not installed,
    e.g. when called from a thread other than the main one)."""
    try:
        return signal.signal(signal.SIGTERM, _raise_terminated)
    except (ValueError, OSError):
        return None


def _main(argv: list[str]) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # usage errors (2), --help and --version (0): argparse has printed why
        return int(exc.code or 0)
    from .console import CheckFailed, Console, run_command  # the commands' imports: not for --help

    console = Console(quiet=args.quiet)
    try:
        return run_command(args, argv, console)
    except (CheckFailed, LearningLimitError) as exc:
        console.error(str(exc), kind="check")
        return 1
    except NumericalError as exc:
        console.error(str(exc), tb=traceback.format_exc() if args.debug else None)
        return 3
    except (IlcdobError, OSError) as exc:
        console.error(_os_message(exc, getattr(args, "out", None)), tb=traceback.format_exc() if args.debug else None)
        return 2
    except Exception as exc:  # a bug, not bad input: one line (--debug: the traceback), exit 3
        console.internal_error(exc, tb=traceback.format_exc() if args.debug else None)
        return 3


def _os_message(exc: BaseException, out: object = None) -> str:
    if isinstance(exc, OSError) and exc.errno in _FULL and not isinstance(exc, IlcdobError):
        where = f" while writing {exc.filename or out}" if (exc.filename or out) else ""
        return f"{exc.strerror or exc}{where}: free space on that disk (or raise the file size limit) and run again"
    if isinstance(exc, OSError) and not isinstance(exc, IlcdobError):
        where = f" ({exc.filename})" if exc.filename else ""
        return f"{exc.strerror or exc}{where}: check the path, its permissions and the free space"
    return str(exc)


if __name__ == "__main__":
    sys.exit(main())
