"""Reading the files a user names: fleet TOML, ``model.json``, result-folder JSON, flight logs.

Every input file is opened here, with the same checks before a byte is read:

* it is a **regular file** (a symbolic link is followed to one): a folder, a FIFO (named pipe),
  a character or block device (``/dev/zero``, a terminal) or a socket is refused, naming what
  it is. The check is made on the path (:func:`os.stat`, which opens nothing) and again on the
  open file, which is opened without blocking, so a FIFO can never hang a command;
* it is at most a stated size: :data:`MAX_DOCUMENT_BYTES` for TOML and JSON documents (fleet
  files, ``model.json``, the JSON of result folders: ilcdob writes them at a few hundred kB at
  most) and :data:`MAX_LOG_BYTES` for flight logs (CSV, Parquet, ULog, DataFlash). The limit is
  stated in the message;
* a text document is UTF-8 (the message names the first byte that is not, and its offset).

Documents are then parsed by :func:`parse_json` / :func:`parse_toml` (or read and parsed in one
step by :func:`read_json` / :func:`read_toml`), which also refuse

* a number beyond the range of a float (an integer such as ``10**400`` or a literal such as
  ``1e400``, which would become ``inf``): no value of a fleet, a model or a result needs one,
  and arithmetic on it would fail far from the file;
* nesting deeper than :data:`MAX_NESTING` arrays and tables (ilcdob's documents nest fewer
  than ten; thousands of levels would exhaust the parser's stack).

Each function raises the error class its caller passes (``error=``, default
:class:`InputFileError`), so a fleet file's problem stays a :class:`~ilcdob.errors.FleetError`
and a model file's a :class:`~ilcdob.errors.ModelFileError`; every message starts with the path
and says what is valid. All of them are :class:`~ilcdob.errors.IlcdobError` subclasses: the
command line reports them in one line with exit status 2.
"""

from __future__ import annotations

import json
import math
import os
import stat
import sys
import tomllib
from pathlib import Path
from typing import Any

from .errors import IlcdobError

__all__ = ["MAX_DOCUMENT_BYTES", "MAX_LOG_BYTES", "MAX_NESTING", "InputFileError", "file_kind", "check_input",
           "read_bytes", "read_text", "parse_json", "parse_toml", "read_json", "read_toml"]

#: Largest TOML or JSON document read, bytes (8 MiB).
MAX_DOCUMENT_BYTES = 8 * 2**20
#: Largest flight log read, bytes (512 MiB).
MAX_LOG_BYTES = 512 * 2**20
#: Deepest nesting of arrays and tables (objects) in a TOML or JSON document.
MAX_NESTING = 64

_FLOAT_MAX = int(sys.float_info.max)
_MAX_INT_DIGITS = 400  # longer integer literals are beyond float range without converting them


class InputFileError(IlcdobError, ValueError):
    """An input file cannot be read: missing, not a regular file, too large, not UTF-8, not
    valid JSON/TOML, or holding a number or a nesting beyond the stated limits."""


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, for messages ("a folder", "a FIFO (named pipe)", ...).

    Parameters
    ----------
    mode : int
        ``st_mode`` of :func:`os.stat` or :func:`os.lstat`.

    Returns
    -------
    str
        "a regular file", "a folder", "a symbolic link", "a FIFO (named pipe)", "a character
        device", "a block device", "a socket" or "a special file".
    """
    for test, kind in ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a folder"),
                       (stat.S_ISLNK, "a symbolic link"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return "a special file"


def _mib(n: int) -> str:
    return f"{n / 2**20:.0f} MiB" if n % 2**20 == 0 else f"{n / 2**20:.1f} MiB"


def _check_stat(st: os.stat_result, path: str | os.PathLike, what: str, limit: int,
                error: type[Exception]) -> None:
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{path}: cannot read {what}: it is {file_kind(st.st_mode)}, not a regular file (reading "
                    f"one could block or never end); give the path of the {what} itself")
    if st.st_size > limit:
        raise error(f"{path}: cannot read {what}: {st.st_size} bytes ({_mib(st.st_size)}) is more than the "
                    f"{_mib(limit)} read at most for a {what}; check that this is the right file")


def check_input(path: str | os.PathLike, what: str, *, limit: int = MAX_DOCUMENT_BYTES,
                error: type[Exception] = InputFileError) -> int:
    """Check, without opening it, that ``path`` is a regular file of at most ``limit`` bytes.

    For inputs read by other libraries from a path (Parquet, ULog, DataFlash); files read
    here go through :func:`read_bytes`, which checks the open file too.

    Parameters
    ----------
    path : str or os.PathLike
        The file (a symbolic link is followed).
    what : str
        What the file is, for messages ("fleet file", "flight log", ...).
    limit : int
        Largest size accepted, bytes.
    error : type of Exception
        The exception raised (called with the message).

    Returns
    -------
    int
        The file's size, bytes.

    Raises
    ------
    error
        The file cannot be stat'ed (missing, no permission), is not a regular file, or is
        larger than ``limit``.
    """
    try:
        st = os.stat(path)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror})") from None
    _check_stat(st, path, what, limit, error)
    return st.st_size


def read_bytes(path: str | os.PathLike, what: str, *, limit: int = MAX_DOCUMENT_BYTES,
               error: type[Exception] = InputFileError) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The file (a symbolic link is followed).
    what : str
        What the file is, for messages.
    limit : int
        Largest size accepted, bytes.
    error : type of Exception
        The exception raised (called with the message).

    Returns
    -------
    bytes

    Raises
    ------
    error
        As :func:`check_input`; also a file that grows past ``limit`` while it is read.
    """
    check_input(path, what, limit=limit, error=error)  # a FIFO or a device is refused before it is opened
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror})") from None
    try:
        with os.fdopen(fd, "rb") as fh:
            _check_stat(os.fstat(fh.fileno()), path, what, limit, error)  # the file opened, not the path
            data = fh.read(limit + 1)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    if len(data) > limit:
        raise error(f"{path}: cannot read {what}: it grew past the {_mib(limit)} read at most for a {what} while "
                    "it was read; read it again when nothing writes to it")
    return data


def read_text(path: str | os.PathLike, what: str, *, limit: int = MAX_DOCUMENT_BYTES,
              error: type[Exception] = InputFileError, hint: str | None = None) -> str:
    """The UTF-8 text of a regular file of at most ``limit`` bytes.

    Parameters
    ----------
    path : str or os.PathLike
        The file (a symbolic link is followed).
    what : str
        What the file is, for messages.
    limit : int
        Largest size accepted, bytes.
    error : type of Exception
        The exception raised (called with the message).
    hint : str, optional
        The next step, appended to the message of a file that is not UTF-8.

    Returns
    -------
    str

    Raises
    ------
    error
        As :func:`read_bytes`, or the bytes are not UTF-8 (the message names the first bad
        byte and its offset).
    """
    data = read_bytes(path, what, limit=limit, error=error)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a UTF-8 text file (byte {data[exc.start]:#04x} at offset {exc.start}); a {what} "
                    f"is UTF-8 text{_next(hint)}") from None


def _next(hint: str | None) -> str:
    return f"; {hint}" if hint else ""


class _Beyond:
    """A number literal beyond float range, kept as text until :func:`_check_document` reports it."""

    __slots__ = ("text",)

    def __init__(self, text: str) -> None:
        self.text = text


def _parse_int(text: str) -> Any:
    return _Beyond(text) if len(text) > _MAX_INT_DIGITS else int(text)


def _parse_float(text: str) -> Any:
    value = float(text)
    if math.isinf(value) and text.lstrip("+-").lower() not in ("inf", "infinity"):
        return _Beyond(text)  # 1e400: a finite literal that overflows
    return value


def _number(text: str) -> str:
    digits = sum(c.isdigit() for c in text)
    shown = text if len(text) <= 24 else f"{text[:12]}...{text[-6:]}"
    return f"{shown} ({digits} digits)"


def _check_document(data: Any, source: str | os.PathLike, what: str, error: type[Exception],
                    hint: str | None) -> None:
    """Refuse numbers beyond float range and nesting deeper than :data:`MAX_NESTING` (iteratively)."""
    stack: list[tuple[Any, str, int]] = [(data, "", 0)]
    while stack:
        value, where, depth = stack.pop()
        if isinstance(value, (dict, list)):
            if depth + 1 > MAX_NESTING:
                shown = where if len(where) <= 60 else f"{where[:40]}...{where[-16:]}"
                raise error(f"{source}: arrays and tables nested deeper than {MAX_NESTING} levels (at {shown}); a "
                            f"{what} nests a few levels{_next(hint)}")
            items = (value.items() if isinstance(value, dict) else enumerate(value))
            for key, item in items:
                if isinstance(value, dict):
                    k = str(key) if len(str(key)) <= 30 else f"{str(key)[:27]}..."
                    loc = f"{where}.{k}" if where else k
                else:
                    loc = f"{where}[{key}]"
                stack.append((item, loc, depth + 1))
            continue
        beyond = value.text if isinstance(value, _Beyond) else (
            str(value) if isinstance(value, int) and not isinstance(value, bool) and abs(value) > _FLOAT_MAX
            else None)
        if beyond is not None:
            raise error(f"{source}: {where or '(top level)'} = {_number(beyond)} is beyond the range of a float "
                        f"(magnitude at most {sys.float_info.max:.3g}); no value of a {what} needs such a "
                        f"number{_next(hint)}")


def parse_json(text: str, source: str | os.PathLike, what: str = "JSON document", *,
               error: type[Exception] = InputFileError, hint: str | None = None) -> Any:
    """Parse JSON text, refusing numbers beyond float range and deep nesting.

    Parameters
    ----------
    text : str
        The document.
    source : str or os.PathLike
        Where it came from, first in messages.
    what : str
        What the document is, for messages.
    error : type of Exception
        The exception raised (called with the message).
    hint : str, optional
        The next step, appended to the messages.

    Returns
    -------
    object
        The parsed document (``NaN``/``Infinity`` literals are parsed as Python's json does).

    Raises
    ------
    error
        Not valid JSON, a number beyond float range, or nesting deeper than :data:`MAX_NESTING`.
    """
    try:
        data = json.loads(text, parse_int=_parse_int, parse_float=_parse_float)
    except RecursionError:
        raise error(f"{source}: arrays and objects nested deeper than {MAX_NESTING} levels (deeper than the JSON "
                    f"parser can follow); a {what} nests a few levels{_next(hint)}") from None
    except json.JSONDecodeError as exc:
        raise error(f"{source}: not valid JSON: {exc}{_next(hint)}") from None
    _check_document(data, source, what, error, hint)
    return data


def parse_toml(text: str, source: str | os.PathLike, what: str = "TOML document", *,
               error: type[Exception] = InputFileError, hint: str | None = None) -> dict[str, Any]:
    """Parse TOML text, refusing numbers beyond float range and deep nesting.

    Parameters
    ----------
    text : str
        The document.
    source : str or os.PathLike
        Where it came from, first in messages.
    what : str
        What the document is, for messages.
    error : type of Exception
        The exception raised (called with the message).
    hint : str, optional
        The next step, appended to the messages.

    Returns
    -------
    dict
        The parsed table (TOML's ``inf`` and ``nan`` are kept as floats).

    Raises
    ------
    error
        Not valid TOML, a number beyond float range, or nesting deeper than :data:`MAX_NESTING`.
    """
    try:
        data = tomllib.loads(text, parse_float=_parse_float)
    except RecursionError:
        raise error(f"{source}: arrays and tables nested deeper than {MAX_NESTING} levels (deeper than the TOML "
                    f"parser can follow); a {what} nests a few levels{_next(hint)}") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML: {exc}{_next(hint)}") from None
    except ValueError as exc:  # an integer literal of thousands of digits (int() refuses to convert it)
        raise error(f"{source}: an integer beyond the range of a float ({exc}); no value of a {what} needs such a "
                    f"number{_next(hint)}") from None
    _check_document(data, source, what, error, hint)
    return data


def read_json(path: str | os.PathLike, what: str, *, limit: int = MAX_DOCUMENT_BYTES,
              error: type[Exception] = InputFileError, hint: str | None = None) -> Any:
    """Read and parse a JSON file (:func:`read_text`, then :func:`parse_json`).

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        What the file is, for messages ("model file", "result file", ...).
    limit : int
        Largest size accepted, bytes.
    error : type of Exception
        The exception raised (called with the message).
    hint : str, optional
        The next step, appended to the messages about the content.

    Returns
    -------
    object
        The parsed document.

    Raises
    ------
    error
        As :func:`read_text` and :func:`parse_json`.
    """
    return parse_json(read_text(path, what, limit=limit, error=error, hint=hint), Path(path), what, error=error,
                      hint=hint)


def read_toml(path: str | os.PathLike, what: str, *, limit: int = MAX_DOCUMENT_BYTES,
              error: type[Exception] = InputFileError, hint: str | None = None) -> dict[str, Any]:
    """Read and parse a TOML file (:func:`read_text`, then :func:`parse_toml`).

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        What the file is, for messages ("fleet file", ...).
    limit : int
        Largest size accepted, bytes.
    error : type of Exception
        The exception raised (called with the message).
    hint : str, optional
        The next step, appended to the messages about the content.

    Returns
    -------
    dict
        The parsed table.

    Raises
    ------
    error
        As :func:`read_text` and :func:`parse_toml`.
    """
    return parse_toml(read_text(path, what, limit=limit, error=error, hint=hint), Path(path), what, error=error,
                      hint=hint)
