"""The ``ilcdob`` command line as data: every command and every option, declared once.

A :class:`Flag` describes one argument (its names, type, default, choices, help); a
:class:`Command` one subcommand (its help, example and the flags it takes, in the order
``--help`` lists them). An option several commands take is one module-level :class:`Flag`
(``FLEET``, ``LAW``, ``OUT_FOLDER``, ...) that each of them names; where a command words its
help differently, it names ``FLAG.but(help=...)``, the same option with that wording.
:func:`ilcdob.app.cli.build_parser` turns :data:`COMMANDS` into argparse parsers in one loop.

Nothing here imports the numerical stack, so that ``ilcdob --help`` stays fast; the one help
text read from the library, ``design --method``'s (:func:`method_help`, from the method
registry), is built when that help is shown.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["Flag", "Command", "COMMANDS", "GLOBAL_FLAGS", "MAX_STARTS", "MAX_LM_ITERATIONS", "FIR_UNATTAINABLE",
           "method_help", "flags_of"]

#: Most starts of ``identify`` (each runs the Levenberg-Marquardt search again, up to --max-iter iterations).
MAX_STARTS = 20
#: Most Levenberg-Marquardt iterations per start of ``identify``.
MAX_LM_ITERATIONS = 10_000
#: Choices of ``design``, ``compare`` and ``learn --fir-unattainable``: ``ilcdob.design.methods.fir.UNATTAINABLE`` (not
#: imported here, so that ``--help`` stays fast; a test keeps the two equal).
FIR_UNATTAINABLE = ("no-harm", "refuse")


# -- argument types: each turns the text of one argument into its value, or says what it expected --------------

def _number(text: str, kind: Callable[[str], Any], accept: Callable[[Any], bool], expected: str) -> Any:
    """``kind(text)`` when ``accept`` takes it, else an :class:`argparse.ArgumentTypeError` saying ``expected``."""
    try:
        value = kind(text)
    except ValueError:
        value = None
    if value is None or not accept(value):
        raise argparse.ArgumentTypeError(f"got {text!r}, expected {expected}")
    return value


def positive(text: str) -> int:
    """An integer >= 1.

    Raises
    ------
    argparse.ArgumentTypeError
        ``text`` is not such an integer.
    """
    return _number(text, int, lambda v: v >= 1, "an integer >= 1")


def count(maximum: int, why: str) -> Callable[[str], int]:
    """An argument type: an integer from 1 to ``maximum`` (``why``: what each one costs, for the message).

    Parameters
    ----------
    maximum : int
        Largest value accepted.
    why : str
        What each unit costs, stated when a value beyond ``maximum`` is refused.
    """
    def bounded(text: str) -> int:
        value = positive(text)
        if value > maximum:
            raise argparse.ArgumentTypeError(f"got {text!r}, expected an integer from 1 to {maximum}: {why}")
        return value

    return bounded


def seed(text: str) -> int:
    """A random seed: an integer >= 0.

    Raises
    ------
    argparse.ArgumentTypeError
        ``text`` is not such an integer.
    """
    return _number(text, int, lambda v: v >= 0, "a seed: an integer >= 0")


def relative_bound(text: str) -> float:
    """A multiplicative uncertainty bound: a relative error in (0, 1) (``|Delta(jw)| <= bound``).

    Raises
    ------
    argparse.ArgumentTypeError
        ``text`` is not such a number.
    """
    return _number(text, float, lambda v: 0 < v < 1, "a relative error in (0, 1), e.g. 0.3 for 30 %")


def sample_time(text: str) -> float:
    """A sample time, s: a finite number > 0.

    Raises
    ------
    argparse.ArgumentTypeError
        ``text`` is not such a number.
    """
    return _number(text, float, lambda v: math.isfinite(v) and v > 0, "a sample time, a number > 0 (s)")


def fit_percent(text: str) -> float:
    """A fit in %: a finite number <= 100 (100: a perfect fit; below 0: worse than the output's mean).

    Raises
    ------
    argparse.ArgumentTypeError
        ``text`` is not such a number.
    """
    return _number(text, float, lambda v: math.isfinite(v) and v <= 100,
                   "a fit in % (a finite number <= 100: 100 is a perfect fit, below 0 the model fits worse than the "
                   "output's mean)")


def poles(text: str) -> list[int]:
    """A number of poles ``N``, or a range ``A..B`` (``1 <= A <= B <= A + 8``) of orders to compare.

    Raises
    ------
    argparse.ArgumentTypeError
        ``text`` is neither.
    """
    lo, sep, hi = text.partition("..")
    try:
        first, last = int(lo), int(hi if sep else lo)
    except ValueError:
        first = last = 0
    if first < 1 or last < first or last - first > 8:
        raise argparse.ArgumentTypeError(f"got {text!r}, expected a number of poles >= 1, or a range A..B "
                                         "(1 <= A <= B <= A + 8) to compare orders")
    return list(range(first, last + 1))


def cascade_gains(text: str) -> dict[str, float]:
    """``KPP,KPV[,KIV]``: a cascade's position P, velocity P and velocity I gains (1/s, 1/s, 1/s^2), as a fleet
    file's ``channel_gain`` table (:meth:`ilcdob.channel_gain.ChannelGain.cascade`).

    Raises
    ------
    argparse.ArgumentTypeError
        Not two or three comma-separated numbers, or a gain out of range (the first two > 0, the third >= 0).
    """
    parts = [p.strip() for p in text.split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values) or min(values[:2], default=0) <= 0 \
            or (len(values) == 3 and values[2] < 0):
        raise argparse.ArgumentTypeError(f"got {text!r}, expected KPP,KPV[,KIV]: the position P and velocity P "
                                         "gains (> 0, 1/s) and optionally the velocity I gain (>= 0, 1/s^2), e.g. "
                                         "PX4's MPC_XY_P,MPC_XY_VEL_P_ACC,MPC_XY_VEL_I_ACC = 0.95,1.8,0.4")
    return dict(zip(("position_p", "velocity_p", "velocity_i"), values))


def scenario_ids(text: str) -> list[int]:
    """Comma-separated scenario ids (:func:`ilcdob.validation.scenarios.parse_scenarios`).

    Raises
    ------
    argparse.ArgumentTypeError
        An id that is not a scenario, with the parser's message.
    """
    from ilcdob.errors import IlcdobError
    from ilcdob.validation.scenarios import parse_scenarios

    try:
        return parse_scenarios(text)
    except IlcdobError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def names(text: str) -> list[str]:
    """Comma-separated names, each stripped of surrounding blanks."""
    return [n.strip() for n in text.split(",")]


def method_names(text: str) -> list[str]:
    """Comma-separated design method names, none empty (the names are checked when the command runs).

    Raises
    ------
    argparse.ArgumentTypeError
        An empty entry.
    """
    methods = [m.strip() for m in text.split(",")]
    if not all(methods):
        raise argparse.ArgumentTypeError(f"got {text!r}, expected comma-separated design names without empty "
                                         "entries, e.g. closed-form,fir")
    return methods


def method_help() -> str:
    """The help of ``design --method``, from the method registry (:data:`ilcdob.design.methods.METHODS`).

    Each method with the options only some methods use that it takes (its ``cli_options``) and
    the first sentence of its class docstring. Importing the registry loads the numerical stack
    (about 1.5 s of CPU), so this runs only when the help is shown (``ilcdob.app.cli._DeferredHelp``).

    Returns
    -------
    str
        The help text, ``%`` escaped for argparse.
    """
    from ilcdob.design.methods import METHODS

    def summary(doc: str | None) -> str:
        text = " ".join((doc or "").strip().split("\n\n")[0].split())
        text = re.sub(r"\s*\(:\w+:`[^`]*`\)", "", text)  # "(:mod:`.fir`)": a pointer for the API docs only
        text = re.sub(r":\w+:`~?\.?([^`]*)`", r"\1", text).replace("``", "").rstrip(".")
        return text[:1].lower() + text[1:] if text[1:2].islower() else text

    each = []
    for m in METHODS.values():
        uses = f" (with {', '.join(m.cli_options)})" if m.cli_options else ""
        each.append(f"{m.name}{uses}: {summary(type(m).__doc__)}")
    return ("design method; " + "; ".join(each)).replace("%", "%%")


# -- the data ----------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Flag:
    """One command-line argument: what :meth:`argparse.ArgumentParser.add_argument` is given.

    Attributes
    ----------
    names : tuple of str
        Option strings (``("--from",)``) or, for a positional argument, its one name.
    help : str or callable
        The help text (``%`` escaped as argparse wants); a callable returning it is called only
        when the help is shown (:func:`method_help`).
    type : callable, optional
        Turns the argument's text into its value (an argument type of this module, ``float``, ...).
    default : object
        Value when not given (None: argparse's default; a list is copied for every parser).
    action, nargs, metavar, dest : str, optional
        As for ``add_argument`` (None: argparse's default).
    choices : sequence of str, optional
        The values accepted.
    required : bool
        An option that must be given.
    group : str, optional
        Name of the mutually exclusive group the option belongs to, within its command.
    """

    names: tuple[str, ...]
    help: str | Callable[[], str]
    type: Callable[[str], Any] | None = None
    default: Any = None
    action: str | None = None
    choices: tuple[str, ...] | list[str] | None = None
    required: bool = False
    nargs: str | None = None
    metavar: str | None = None
    dest: str | None = None
    group: str | None = None

    def but(self, **changes: Any) -> Flag:
        """The same option with ``changes`` (a command's own wording of its help, its own default, ...).

        Parameters
        ----------
        **changes
            Fields of :class:`Flag` and their new values.
        """
        return dataclasses.replace(self, **changes)

    def arguments(self) -> dict[str, Any]:
        """The keyword arguments of ``add_argument`` but ``help`` (fields left at None are left out).

        Returns
        -------
        dict of str to object
        """
        kw = {k: getattr(self, k) for k in ("type", "default", "action", "choices", "nargs", "metavar", "dest")
              if getattr(self, k) is not None}
        if isinstance(self.default, list):
            kw["default"] = list(self.default)
        if self.required:
            kw["required"] = True
        return kw


def flag(*names: str, help: str | Callable[[], str], **fields: Any) -> Flag:  # noqa: A002 - argparse's name
    """A :class:`Flag` written as ``add_argument`` is called: ``flag("--seed", type=int, help=...)``.

    Parameters
    ----------
    *names : str
        Option strings, or the one name of a positional argument.
    help : str or callable
        The help text (:attr:`Flag.help`).
    **fields
        The other fields of :class:`Flag`.
    """
    return Flag(names, help, **fields)


@dataclass(frozen=True)
class Command:
    """One ``ilcdob`` subcommand.

    Attributes
    ----------
    name : str
        As typed: ``"design"``; a nested command with its parent, ``"fleet add"``.
    help : str
        The line of ``ilcdob --help``, also the start of the command's description.
    example : str
        A command line, the epilog of its ``--help``.
    flags : tuple
        Its arguments in the order ``--help`` lists them: :class:`Flag` objects, or tuples of
        them (an option group several commands take, e.g. :data:`FOLDER`).
    more : str
        Text that the description adds after ``help``.
    describe : bool
        Whether the command's ``--help`` shows a description (``fleet add``: the usage alone).
    subcommands : str, optional
        The commands below it are nested (``fleet``): the namespace attribute naming the one chosen.
    """

    name: str
    help: str
    example: str
    flags: tuple[Flag | tuple[Flag, ...], ...] = ()
    more: str = ""
    describe: bool = True
    subcommands: str | None = None


def flags_of(command: Command) -> list[Flag]:
    """The flags of ``command``, its option groups spelt out, in order.

    Parameters
    ----------
    command : Command
    """
    out: list[Flag] = []
    for item in command.flags:
        out.extend(item if isinstance(item, tuple) else (item,))
    return out


TIME = flag("--time", help="time column of CSV/Parquet files (default: time)")
TIME_UNIT = flag("--time-unit", choices=("s", "ms", "us", "ns"),
                 help="unit of that column (default: the file's '# units:' line, else s)")


DISTURBANCE = flag("--disturbance", choices=("command", "airframe", "wind"), default="command",
                   help="where the disturbance acts: added to the command (the paper's loop), on the airframe (adds "
                        "the attitude-chain correction), or a wind velocity through each airframe's drag (also scales "
                        "by the ratio of the models' drag poles)")
RESAMPLE = flag("--resample", type=sample_time, metavar="TS",
                help="resample every file to this sample time, s, anti-aliased (scipy.signal.resample_poly), e.g. "
                     "a log's rate to the fleet's (default: as logged)")


def _clock(what: str) -> tuple[Flag, ...]:
    """--time, --time-unit, --start, --stop and --resample (``what``: what the start and end are of)."""
    return (TIME, TIME_UNIT, flag("--start", type=float, help=f"{what} start, s (log clock)"),
            flag("--stop", type=float, help=f"{what} end, s (log clock)"), RESAMPLE)


# -- options several commands take ---------------------------------------------------------------------------------

#: --quiet and --debug: accepted before the command name (default False) and after it (not set there).
GLOBAL_FLAGS = (
    flag("--quiet", action="store_true", help="no progress bars, notes or warnings on stderr (errors, and a learning "
                                              "signal clipped at the acceleration limit, are still reported)"),
    flag("--debug", action="store_true", help="show the traceback of an error"),
)
FLEET = flag("--fleet", help="fleet TOML file (default: the built-in fleet of the paper's three UAVs)")
LAW = flag("--law", default="paper", help="learning law: paper (the Theorem's filters; default), exact-reference "
                                          "(keeps the reference term), multi-source (every earlier system's trial at "
                                          "once; reproduce only)")
OUT_FOLDER = flag("--out", required=True, help="output folder (written as a unit)")
OVERWRITE = flag("--overwrite", action="store_true", help="replace a non-empty folder ilcdob did not write")
#: The output folder of a command that writes one as a unit.
FOLDER = (OUT_FOLDER, OVERWRITE)
AXIS = flag("--axis", choices=("x", "y", "z"), default="x",
            help="axis: x (the paper's), or y / z from the fleet file's [system.y] / [system.z] sections")
SCENARIOS = flag("--scenarios", type=scenario_ids, default=[1, 2, 3, 4], help="comma-separated scenario ids")
METHOD_LIST = flag("--methods", type=method_names, help="comma-separated designs (default: "
                                                        "closed-form,fir,norm-optimal,robust)")
SAMPLES = flag("--samples", type=positive, default=8, help="Delta-set samples per system")
BOUND = flag("--bound", type=relative_bound, help="multiplicative uncertainty bound (default: identified)")
SCALE = flag("--scale", type=float, help="scale of the identified standard deviations (default 1; not with --bound)")
RHO = flag("--rho", type=float, help="robust and robust-set only: guaranteed improvement factor (default 0.95)")
BANDWIDTH = flag("--bandwidth", default="auto",
                 help="corner of the learning band, rad/s; 'auto' chooses it from the trial's noise and the models' "
                      "trusted band (the fleet's sensor noise, limits and Delta sets without a trial); 'off': the "
                      "Theorem's filters unfiltered")
SEED = flag("--seed", type=seed, default=0, help="seed of the sensor noise")
WORKERS = flag("--workers", type=positive, help="local cluster: worker processes (default: cores)")
DURATION = flag("--duration", type=float, help="fly the first SECONDS of each scenario (default: all)")
FIR_POLICY = flag("--fir-unattainable", choices=FIR_UNATTAINABLE,
                  help="fir only: where no filter meets |Te1| <= 0.9 for every sampled model, keep only the no-harm "
                       "promise there (default: no-harm), or refuse the design (exit 2, bands named)")
ON_LIMIT = flag("--on-limit", choices=("clip", "refuse"), default="clip",
                help="a learning signal beyond the acceleration limit of --to: clip it (with a warning) or refuse it "
                     "(exit 1)")
METHOD = flag("--method", default="closed-form", help=method_help)
SOURCE = flag("--from", dest="source", required=True, help="system learned from (j-1)")
TARGET = flag("--to", dest="target", required=True, help="system that learns (j)")


# -- the commands ----------------------------------------------------------------------------------------------------

_REPRODUCE = Command(
    "reproduce", "run the paper's four scenarios; write results, figures and an index",
    "ilcdob reproduce --out reports/paper", (
        FLEET, LAW, FOLDER, SCENARIOS,
        flag("--iterations", type=positive, default=3, help="learning iterations"),
        flag("--no-figures", action="store_true", help="skip the PNG figures"),
        flag("--plant", choices=("linear", "nonlinear", "rotorpy"), default="linear",
             help="linear: the fleet's models; nonlinear: identify and fly the 6-DOF quadrotors; rotorpy: identify "
                  "and fly rotorpy's multirotors in the paper's disturbance and in wind, every law (needs the "
                  "[rotorpy] extra)"),
        flag("--controller", choices=("ilcdob", "own"), default="ilcdob",
             help="who flies the position loop: ilcdob's PID + DOB, or (--plant rotorpy) the vehicles' own SE3 "
                  "controller, learning through a setpoint channel (acceleration and position)"),
        flag("--vehicles", metavar="FILE.toml",
             help="with --plant rotorpy: your airframes ([[vehicle]] tables: name, airframe to start from, params "
                  "and, with --controller own, position_gains; ilcdob.validation.channel_reproduction.load_vehicles)"),
        SEED.but(type=int, help="seed of the sensor noise (rotorpy: of the Dryden turbulence)"),
        WORKERS.but(help="processes flying the scenarios, --plant rotorpy only (default 1)"),
        flag("--sensor-noise", type=float, help="white position-sensor noise of every flight, m (default: 0 linear, "
                                                "0.0005 nonlinear and rotorpy)"),
        BANDWIDTH,
        flag("--order", type=names, help="learning order of every scenario, comma-separated system names, each "
                                         "once, at least two (default: scenario 4 flies the 1st, 3rd, 2nd system of "
                                         "a three-system fleet, the others the file order)")))

_IDENTIFY = Command(
    "identify", "fit a continuous-time transfer function to flight data; write model.json",
    "ilcdob identify flight.csv --input acc_cmd --output x --poles 3 --integrators 2 --delay auto --out model.json", (
        flag("files", nargs="+", help="estimation data: .csv, .parquet, .ulg or .bin"),
        flag("--input", required=True, help="input signal: COLUMN, TOPIC.FIELD (ULog) or MESSAGE.FIELD"),
        flag("--output", required=True, help="output signal, same forms as --input"),
        _clock("segment"),
        flag("--poles", type=poles, required=True,
             help="number of poles, integrators included; a range A..B fits every order, prints their estimation "
                  "and held-out fits and AIC, and writes the chosen one (the fewest poles within 0.5 points of the "
                  "best held-out fit; without --validate the lowest AIC)"),
        flag("--zeros", type=int, default=0, help="number of zeros"),
        flag("--integrators", type=int, default=0, help="poles fixed at s = 0"),
        flag("--zero-at-origin", action="store_true",
             help="one of the zeros fixed at s = 0: the map of a loop that integrates (a cascade's velocity "
                  "integral on the acceleration channel); refused where the fit's b0 is beyond 5 standard "
                  "deviations of 0"),
        flag("--delay", default="0", help="input delay in s, or 'auto' to estimate it"),
        flag("--max-delay", type=float, help="upper bound of the delay search, s (default: a tenth of the shortest "
                                             "file)"),
        flag("--trend", default="0", help="per-file output trend: 'none' or a polynomial degree 0-5"),
        flag("--time-limit", type=float, help="wall-time limit of the fit, s (none)"),
        flag("--starts", type=count(MAX_STARTS, "each start runs the Levenberg-Marquardt search again, up to "
                                                "--max-iter iterations over every sample"), default=2,
             help="initial estimates (SRIVC, pole grid, frequency-domain fit) the search runs from; with --delay "
                  "auto each also profiles the delay"),
        flag("--max-iter", type=count(MAX_LM_ITERATIONS, "each iteration simulates the model and its sensitivities "
                                                         "over every sample (measured: 6.5 ms for 30,000 samples, 5 "
                                                         "poles, 2 zeros), so 10,000 iterations over a one-hour log "
                                                         "at 50 Hz take about 7 min per start; bound the wall time "
                                                         "with --time-limit"),
             default=100, help="Levenberg-Marquardt iteration limit per start"),
        flag("--allow-unstable", action="store_true",
             help="let free poles enter the right half plane (an open-loop unstable plant; default: such models are "
                  "rejected during the fit)"),
        flag("--keep-outliers", action="store_true",
             help="keep every sample (default: samples more than 10 robust standard deviations off the first fit, a "
                  "glitch in a log, are left out, the record cut there, and named in the notes)"),
        flag("--min-fit", type=fit_percent, help="exit 1 when the held-out fit (%%) is below this"),
        flag("--validate", nargs="*", default=[], help="held-out data files"),
        flag("--segment", type=float, metavar="SECONDS",
             help="cut every file (estimation and --validate alike) into consecutive windows of SECONDS, each fitted "
                  "with its own initial condition; a last piece of at most half a window joins the one before it "
                  "(default: each file whole)"),
        OUT_FOLDER.but(help="model.json to write"),
        flag("--plot", help="folder for the compare/residual/Bode figures")),
    more=". Diagnostics (printed as notes, and in model.json's `diagnostics`): the estimated delay on a bound of its "
         "search, poles or zeros beyond the Nyquist frequency, residuals that are not white or that correlate with "
         "the input, an estimation file fitting far worse than the others (per-file fits: `file_fits_percent`), "
         "samples left out as gross errors (--keep-outliers)")

_DESIGN = Command(
    "design", "design the learning filters of one system from another; write filters and C code",
    "ilcdob design --from UAV1 --to UAV2 --out uav1_uav2/", (
        FLEET, LAW, FOLDER, AXIS, SOURCE, TARGET, METHOD, RHO,
        SAMPLES.but(default=None, help="fir and robust only: Delta-set samples per system (default 8)"),
        BOUND.but(help="fir, robust and robust-set only: multiplicative uncertainty bound (default: identified)"),
        flag("--n", type=positive, help="norm-optimal only: trial length in samples (default: the trial's, else 500)"),
        flag("--lifted", action="store_true",
             help="norm-optimal only: also write the N x N lifted matrices L1, L2 to lifted.npz (about 8 N^2 numbers "
                  "of memory while built; default: the law as Riccati gains only, O(N))"),
        FIR_POLICY.but(help="fir only: where no filter meets |Te1| <= 0.9 for every sampled model, keep only the "
                            "no-harm promise there and warn (default: no-harm), or refuse the design (exit 2, bands "
                            "named)"),
        flag("--trial", help="CSV of the source's trial: time (s), error (m), learning (m/s^2)"),
        flag("--c-prefix", help="prefix of the C symbols (default: ilcdob_<from>_<to>_, then <axis>_ for y and z)"),
        flag("--c-float", action="store_true", help="also emit float C functions, with their measured error"),
        BANDWIDTH,
        DISTURBANCE,
        ON_LIMIT.but(help="a learning signal beyond the fleet's acceleration limit of --to: clip it (with a warning) "
                          "or refuse it (exit 1)")))

_LEARN = Command(
    "learn", "the next vehicle's learning signal from a recorded trial of the previous one, computed as the emitted "
             "C code computes it; writes it as CSV, binary and a C array",
    "ilcdob learn uav1_trial.csv --design uav1_uav2/ --reference ref --position x --out uav2_next/", (
        FLEET, FOLDER,
        AXIS.but(default=None, help="axis (default x, or the --design's): x (the paper's), or y / z from the fleet "
                                    "file's [system.y] / [system.z] sections"),
        flag("trial", help="the recorded trial of --from: .csv, .parquet, .ulg or .bin"),
        SOURCE.but(required=False, help="system learned from (j-1); read from --design if given"),
        TARGET.but(required=False, help="system that learns (j); read from --design if given"),
        flag("--design", help="a folder written by `ilcdob design` whose filters run (default: design them here from "
                              "the fleet)"),
        METHOD.but(help="without --design: closed-form or fir"),
        FIR_POLICY.but(help="--method fir without --design: where no filter meets |Te1| <= 0.9 for every sampled "
                            "model, keep only the no-harm promise there (default: no-harm), or refuse (exit 2, bands "
                            "named)"),
        flag("--error", help="tracking error column, m: COLUMN, TOPIC.FIELD (ULog) or MESSAGE.FIELD (DataFlash)"),
        flag("--reference", help="instead of --error: reference position, m (same forms)"),
        flag("--position", help="with --reference: measured position, m (same forms)"),
        flag("--learning", help="learning signal the trial flew, m/s^2 (default: none)"),
        _clock("trial"), BANDWIDTH, DISTURBANCE.but(help="without --design: " + DISTURBANCE.help), ON_LIMIT))

_CHECK = Command(
    "check", "will learning help? per pair and frequency the exact worst case of the error ratio |e_j/e'_j| over the "
             "Delta set (|Delta| <= W) for the law with its learning band, the ratio for a stated plant, and the "
             "paper's first-order condition |Delta| < |1 + P C|/2 beside it (exit 1: improvement not guaranteed, the "
             "exact worst case exceeds 1.01)",
    "ilcdob check --fleet identified/identified_fleet.toml", (
        FLEET, AXIS, flag("--order", help="learning order, comma-separated names (default: file order)"),
        BOUND, SCALE, BANDWIDTH, flag("--out", help="JSON file for the check (default: print only)")))

_COMPARE = Command(
    "compare", "fly every design through a scenario, nominal and over the Delta set",
    "ilcdob compare --scenario 1 --out compare/", (
        FLEET, LAW, OUT_FOLDER.but(required=False, help="output folder (default: print only)"), OVERWRITE,
        flag("--scenario", type=positive, required=True, help="scenario id 1-4"),
        METHOD_LIST, SAMPLES, BOUND, SCALE, RHO,
        DURATION.but(help="fly the first SECONDS of the scenario (default: all)"),
        SEED.but(help="seed of the Delta-set draw"), FIR_POLICY))

_CAMPAIGN = Command(
    "campaign", "Monte Carlo campaign on Dask over sampled true plants (resumable)",
    "ilcdob campaign --samples 200 --out campaign/", (
        FLEET, LAW, OUT_FOLDER.but(help="output folder; run again to resume"), OVERWRITE,
        SAMPLES.but(default=None, required=True, help="number of sampled true plants"),
        flag("--scheduler", group="scheduler",
             help="Dask scheduler tcp://HOST:PORT or tls://HOST:PORT (default: a local cluster)"),
        flag("--scheduler-file", group="scheduler",
             help="the JSON file `dask scheduler --scheduler-file PATH` wrote (instead of --scheduler)"),
        flag("--tls-ca-file", help="tls:// scheduler: the CA certificate (PEM)"),
        flag("--tls-cert", help="tls:// scheduler: this client's certificate (PEM)"),
        flag("--tls-key", help="tls:// scheduler: the client's private key (PEM; omit when --tls-cert holds it)"),
        WORKERS, flag("--dashboard", action="store_true", help="print the Dask dashboard link"),
        METHOD_LIST, SCENARIOS, BOUND, SCALE, RHO,
        flag("--robust-models", type=int, help="robust only: Delta samples per system in its SOCP (default 1)"),
        flag("--delta-set", choices=["structured", "disc", "auto"],
             help="robust-set: guarantee over the family the plants are drawn from (structured), the disc |Delta| <= "
                  "bound, or auto (default: structured)"),
        flag("--margin", type=float, default=0.5,
             help="redraw true plants whose disturbance response exceeds 1/MARGIN times the model's at some "
                  "frequency; robust-set guarantees over the same plants (default 0.5: within 6 dB; 0: every stable "
                  "plant)"),
        DURATION, SEED.but(help="campaign seed")))

_FLEET_EXAMPLE = ("ilcdob fleet add my_fleet.toml --name UAV4 --model model.json --kp 3 --ki 0.3 --kd 2.4 --q-order 3 "
                  "--q-time-constant 0.15")
_FLEET_ADD = Command(
    "fleet add", "add a system flying an identified model.json (creates the fleet file if needed)", _FLEET_EXAMPLE, (
        flag("fleet_file", metavar="FLEET.toml", help="fleet file to create or append to"),
        flag("--name", required=True, help="name of the new system"),
        flag("--model", required=True, help="model.json of `ilcdob identify` (with --channel: fitted from the "
                                             "channel to the position, the vehicle's own loop closed)"),
        *(flag(f"--{gain}", type=float, help=f"PID gain {gain}, {unit} (ilcdob's loop: required)")
          for gain, unit in (("kp", "1/s^2"), ("ki", "1/s^3"), ("kd", "1/s"))),
        flag("--derivative-filter", type=float, help="derivative low-pass time constant, s (default 0.05)"),
        flag("--q-order", type=positive, help="order of the DOB low-pass Q (ilcdob's loop: required; with "
                                              "--channel: the add-on DOB the vehicle flies)"),
        flag("--q-time-constant", type=float, help="time constant of Q, s"),
        flag("--channel", choices=["position", "velocity", "acceleration"],
             help="a vehicle on its own controller, learning through this setpoint channel (instead of ilcdob's "
                  "PID + DOB)"),
        flag("--channel-gain", type=float, help="with --channel: K, m/s^2 commanded per channel unit (the "
                                                "controller's kp on position, kd on velocity; 1 on acceleration)"),
        flag("--cascade-gains", type=cascade_gains, metavar="KPP,KPV[,KIV]",
             help="with --channel position or velocity on a cascade (a position P over a velocity PI, as PX4's "
                  "and ArduPilot's): its gains, 1/s, 1/s, 1/s^2 (PX4: MPC_XY_P, MPC_XY_VEL_P_ACC, "
                  "MPC_XY_VEL_I_ACC); K(s) = KPP (KPV + KIV/s) on position, KPV + KIV/s on velocity"),
        flag("--cascade-gains-from", metavar="LOG.ulg",
             help="with --channel position or velocity on PX4: read --cascade-gains from the ULog's parameters "
                  "(MPC_XY_* for x and y, MPC_Z_* for z: --cascade-axis)"),
        flag("--cascade-axis", choices=["x", "y", "z"], help="with --cascade-gains-from: the axis (default x)"),
        flag("--airframe", help="with --channel: model.json of the airframe, commanded acceleration -> position"),
        flag("--reference-map", help="with --channel: model.json of the reference map, reference -> position as "
                                     "the flight stack flies it (the exact-reference law; default on the position "
                                     "channel: the channel map)"),
        flag("--sample-time", type=float, help="new file: sample time, s (default: model's)"),
        flag("--tilt", type=float, help="the vehicle's tilt limit, deg: its acceleration limit g tan(tilt), which a "
                                        "learning signal is checked against (or --thrust-to-weight, "
                                        "--acceleration-limit; default: none)"),
        flag("--thrust-to-weight", type=float, help="the vehicle's thrust-to-weight ratio (> 1): its acceleration "
                                                    "limit g sqrt(ratio^2 - 1)"),
        flag("--acceleration-limit", type=float, help="the vehicle's horizontal acceleration limit, m/s^2"),
        flag("--sensor-noise", type=float, help="white noise of its position sensor (1 sigma), m: sets the learning "
                                                "band without a trial (default: none)")),
    describe=False)

#: Every command, in the order ``ilcdob --help`` lists them (a nested one after its parent).
COMMANDS: tuple[Command, ...] = (
    _REPRODUCE, _IDENTIFY, _DESIGN, _LEARN, _CHECK, _COMPARE,
    Command("extensions", "the two extensions beyond the paper, per scenario", "ilcdob extensions --out extensions/",
            (FLEET, FOLDER, SCENARIOS)),
    _CAMPAIGN,
    Command("report", "one self-contained HTML report from reproduce/compare/campaign folders",
            "ilcdob report reports/paper reports/compare --out report.html",
            (flag("dirs", nargs="+", help="output folders of reproduce, compare or campaign"),
             OUT_FOLDER.but(help="HTML file to write"))),
    Command("identify-fleet", "fly step/chirp experiments with the nonlinear vehicles, identify every plant",
            "ilcdob identify-fleet --out identified/", (FLEET, FOLDER, SEED)),
    Command("fleet", "edit fleet files", _FLEET_EXAMPLE, subcommands="fleet_command"),
    _FLEET_ADD,
)
