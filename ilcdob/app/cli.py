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
import signal
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from ilcdob.errors import IlcdobError, LearningLimitError, NumericalError

from . import options
from .options import COMMANDS, GLOBAL_FLAGS, Flag, flags_of
from .output import version

__all__ = ["main", "build_parser"]

#: ``identify``'s limits and the ``--fir-unattainable`` choices (:mod:`.options`), importable from here as before.
MAX_STARTS, MAX_LM_ITERATIONS, FIR_UNATTAINABLE = options.MAX_STARTS, options.MAX_LM_ITERATIONS, options.FIR_UNATTAINABLE


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors end, like every other error, in one ``ilcdob: error:`` line (exit 2)."""

    def error(self, message: str) -> NoReturn:
        command = self.prog.removeprefix("ilcdob").strip()
        where = f"`{command}`: " if command else ""
        self.exit(2, f"ilcdob: error: {where}{' '.join(message.split())} (see `{self.prog} --help`)\n")


class _DeferredHelp(str):
    """A help text made when it is first shown: until then its value is a placeholder.

    Parameters
    ----------
    make : callable
        Returns the text (:attr:`ilcdob.app.options.Flag.help`); called once, by :class:`_Defaults`.
    """

    def __new__(cls, make: Callable[[], str]) -> _DeferredHelp:
        text = super().__new__(cls, "(shown by --help)")
        text.make = make
        return text


class _Defaults(argparse.HelpFormatter):
    """States every default that the help text does not already state (None/False: nothing to state), and
    makes a :class:`_DeferredHelp` when its option is shown."""

    def _format_action(self, action: argparse.Action) -> str:
        if isinstance(action.help, _DeferredHelp):
            action.help = action.help.make()
        return super()._format_action(action)

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if "default" in text or default is None or default is False or default == argparse.SUPPRESS \
                or not action.option_strings:
            return text
        shown = ",".join(map(str, default)) if isinstance(default, list) else default
        return f"{text} (default: {shown})"


def _add(parser: argparse.ArgumentParser, flags: Sequence[Flag], **extra: Any) -> None:
    """Add ``flags`` to ``parser`` (an option of a mutually exclusive group to that group); ``extra``: keyword
    arguments of every ``add_argument`` (the subcommands' ``default=SUPPRESS`` of --quiet and --debug)."""
    groups: dict[str, argparse._MutuallyExclusiveGroup] = {}
    for flag in flags:
        if flag.group is not None and flag.group not in groups:
            groups[flag.group] = parser.add_mutually_exclusive_group()
        where = parser if flag.group is None else groups[flag.group]
        text = flag.help if isinstance(flag.help, str) else _DeferredHelp(flag.help)
        where.add_argument(*flag.names, help=text, **{**flag.arguments(), **extra})


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``ilcdob`` command: :data:`ilcdob.app.options.COMMANDS`, each flag added once.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = _Parser(prog="ilcdob", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"ilcdob {version()}")
    _add(parser, GLOBAL_FLAGS)
    below = {"": parser.add_subparsers(dest="command", required=True, metavar="COMMAND")}
    for command in COMMANDS:
        parent, _, name = command.name.rpartition(" ")
        description = command.help + command.more if command.describe else None
        p = below[parent].add_parser(name, help=command.help, description=description,
                                     epilog=f"example: {command.example}", formatter_class=_Defaults)
        _add(p, GLOBAL_FLAGS, default=argparse.SUPPRESS)
        _add(p, flags_of(command))
        if command.subcommands:
            below[command.name] = p.add_subparsers(dest=command.subcommands, required=True)
    return parser


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
