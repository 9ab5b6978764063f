"""Keeping the third-party log parsers (pyulog, pymavlink) bounded and quiet on damaged files.

A damaged or hostile log must end in a clear error in bounded time, and what a parser prints
about it must not reach the console:

* :class:`BudgetedFile` -- the file as pyulog reads it, refusing to deliver more than a budget
  of bytes in all (:func:`read_budget`). pyulog resynchronises on garbage one byte at a time,
  and for each byte reads the message length the garbage announces (up to 64 KiB): 1 MiB of
  ``0xFF`` costs it 64 GiB of reads, minutes to hours. A log that is not damaged is read about
  once (twice when pyulog scans for a sync marker), so the budget costs valid files nothing and
  stops the resynchronisation after a bounded, file-size-proportional amount of work.
* :func:`captured_output` -- everything printed while a parser runs, by Python (``print``,
  counted) and by compiled code (pymavlink's indexer writes a ``bad header`` line straight to
  file descriptor 2 for every damaged byte: discarded), kept off the console.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from dataclasses import dataclass
from typing import Any, Iterator

__all__ = ["READ_BUDGET_FACTOR", "READ_BUDGET_SLACK", "ReadBudgetExceeded", "BudgetedFile", "read_budget",
           "CapturedOutput", "captured_output"]

#: A parse may read this many times the file's size ...
READ_BUDGET_FACTOR = 16
#: ... plus this many bytes (room for pyulog to resynchronise past a few damaged blocks of a valid log).
READ_BUDGET_SLACK = 256 * 2**20


def read_budget(size: int) -> int:
    """The bytes a parse of a ``size``-byte file may read in all.

    Parameters
    ----------
    size : int
        The file's size, bytes.

    Returns
    -------
    int
        ``READ_BUDGET_FACTOR * size + READ_BUDGET_SLACK``.
    """
    return READ_BUDGET_FACTOR * int(size) + READ_BUDGET_SLACK


class ReadBudgetExceeded(Exception):
    """A parse read more than its budget (:func:`read_budget`).

    Deliberately not a ``ValueError``, ``IndexError`` or ``struct.error``: pyulog treats those as
    a damaged message and carries on; this one ends the parse.

    Parameters
    ----------
    read : int
        Bytes read so far.
    size : int
        The file's size, bytes.
    position : int
        Where in the file the parse was when the budget ran out.
    """

    def __init__(self, read: int, size: int, position: int) -> None:
        super().__init__(f"read {read} bytes of a {size}-byte file, at byte {position}")
        self.read, self.size, self.position = read, size, position


class BudgetedFile:
    """A binary file opened for reading that raises :class:`ReadBudgetExceeded` once more than
    :func:`read_budget` of its size has been read.

    Offers what pyulog uses of a file object: ``read``, ``seek``, ``tell`` and ``close``.

    Parameters
    ----------
    path : str
        The file.
    """

    def __init__(self, path: str) -> None:
        self._fh: Any = open(path, "rb")  # noqa: SIM115 - closed by close() (pyulog closes what it reads)
        self.size = os.fstat(self._fh.fileno()).st_size
        self.budget = read_budget(self.size)
        self.consumed = 0

    def read(self, n: int = -1) -> bytes:
        """Up to ``n`` bytes (all the rest when ``n`` < 0), counted against the budget.

        Parameters
        ----------
        n : int
            Bytes wanted.
        """
        data = self._fh.read(n)
        self.consumed += len(data)
        if self.consumed > self.budget:
            raise ReadBudgetExceeded(self.consumed, self.size, self._fh.tell())
        return data

    def seek(self, offset: int, whence: int = 0) -> int:
        """Move to ``offset`` (``whence`` as for :meth:`io.IOBase.seek`); returns the new position.

        Parameters
        ----------
        offset : int
        whence : int
        """
        return self._fh.seek(offset, whence)

    def tell(self) -> int:
        """The current position."""
        return self._fh.tell()

    def close(self) -> None:
        """Close the file."""
        self._fh.close()

    def __enter__(self) -> "BudgetedFile":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class CapturedOutput:
    """What was printed under :func:`captured_output`.

    Attributes
    ----------
    lines : int
        Lines printed from Python.
    first : str or None
        The first of them, stripped.
    """

    lines: int = 0
    first: str | None = None

    def add(self, text: str) -> None:
        """Count the lines of ``text``.

        Parameters
        ----------
        text : str
        """
        if not text.strip():
            return
        self.lines += text.count("\n") or 1
        if self.first is None:
            self.first = text.strip().splitlines()[0]


class _Sink(io.TextIOBase):
    """A text stream that counts what is written to it."""

    def __init__(self, out: CapturedOutput) -> None:
        self.out = out

    def writable(self) -> bool:
        return True

    def write(self, s: str) -> int:
        self.out.add(s)
        return len(s)


@contextlib.contextmanager
def _descriptors_discarded() -> Iterator[None]:
    """File descriptors 1 and 2 onto the null device (what compiled code writes there).

    Not a pipe whose lines a thread counts: compiled code that writes while holding the GIL blocks
    on a full pipe, and the thread would need the GIL to empty it.
    """
    for stream in (sys.stdout, sys.stderr, sys.__stdout__, sys.__stderr__):
        with contextlib.suppress(Exception):
            stream.flush()
    saved: list[int] = []
    try:
        saved += [os.dup(1)]
        saved += [os.dup(2)]
        null = os.open(os.devnull, os.O_WRONLY)
    except OSError:  # no such descriptors (a detached process): nothing can be printed there either
        for fd in saved:
            os.close(fd)
        yield
        return
    try:
        try:
            os.dup2(null, 1)
            os.dup2(null, 2)
        finally:
            os.close(null)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)


@contextlib.contextmanager
def captured_output() -> Iterator[CapturedOutput]:
    """Swallow everything printed inside the block: ``print`` to ``sys.stdout`` and ``sys.stderr``
    (counted), and what compiled code writes to file descriptors 1 and 2 (discarded).

    Yields
    ------
    CapturedOutput
        The lines printed from Python, filled in as the block runs.
    """
    out = CapturedOutput()
    sink = _Sink(out)
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink), _descriptors_discarded():
        yield out
