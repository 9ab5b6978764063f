"""Atomic file output: write to a temporary file in the target folder, then rename.

A crash or an exception mid-write leaves the previous file (or none), never a half-written
one: ``os.replace`` is atomic on POSIX and Windows within one file system. Folders created for
the file are removed again when the write fails, so a failure leaves the previous state. A
temporary left by a killed writer (``.NAME.tmp-<pid>-...``) is removed by the next write of the
same file.

A read-modify-write of a file that several processes may edit at once (a fleet file that two
``ilcdob fleet add`` extend) takes :func:`locked` around the read and the write: an exclusive
advisory lock (``fcntl.flock``) on the file's folder, so the second process reads the file only
after the first has replaced it, and no edit is lost. The lock is on the folder, not on the
file, because the atomic write replaces the file (a lock on the old file would not exclude a
process that opens the new one); it leaves nothing behind and is released by the system when the
process ends, however it ends.
"""

from __future__ import annotations

import errno
import json
import os
import stat
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

from .errors import IlcdobError, OutputError
from .inputs import file_kind

try:
    import fcntl
except ImportError:  # Windows: no advisory locks (see locked)
    fcntl = None  # type: ignore[assignment]

__all__ = ["atomic_path", "check_replaceable", "write_text_atomic", "write_json_atomic", "current_umask",
           "stale_entries",
           "make_folders", "remove_folders", "locked", "LockTimeoutError", "LOCK_TIMEOUT_S"]

#: How long :func:`locked` waits for another process's lock, s.
LOCK_TIMEOUT_S = 60.0


class LockTimeoutError(IlcdobError, TimeoutError):
    """Another process held the lock of :func:`locked` for longer than the timeout."""


def make_folders(folder: str | Path) -> list[Path]:
    """Create ``folder`` and its missing parents; returns the folders created, outermost first.

    Parameters
    ----------
    folder : str or Path
        The folder to exist afterwards.

    Returns
    -------
    list of Path
        The folders this call created (empty when ``folder`` existed), for
        :func:`remove_folders` when the work they were made for fails.
    """
    folder = Path(folder).absolute()
    missing = []
    p = folder
    while not p.exists() and p.parent != p:
        missing.append(p)
        p = p.parent
    created = []
    for p in reversed(missing):
        try:
            p.mkdir()
        except FileExistsError:  # made by another process meanwhile: not ours to remove
            continue
        created.append(p)
    return created


def remove_folders(created: list[Path]) -> None:
    """Remove folders made by :func:`make_folders`, innermost first, each only while it is empty.

    Parameters
    ----------
    created : list of Path
        What :func:`make_folders` returned.
    """
    for p in reversed(created):
        try:
            p.rmdir()
        except OSError:
            break  # not empty (something else was written there meanwhile) or gone: keep the rest


@contextmanager
def locked(path: str | Path, *, timeout: float = LOCK_TIMEOUT_S) -> Iterator[None]:
    """Context manager: an exclusive advisory lock for a read-modify-write of ``path``.

    The lock is ``fcntl.flock`` on ``path``'s folder (see the module docstring), which must
    exist. Every writer that edits ``path`` through this lock waits for the others; readers
    are not blocked (the file is replaced atomically). Without ``fcntl`` (Windows) there is no
    lock. A file system whose folders cannot be locked (some network file systems) is locked
    through a file ``.<name>.lock`` beside ``path`` instead, which then stays.

    Parameters
    ----------
    path : str or Path
        The file about to be read, changed and written.
    timeout : float
        How long to wait for another process's lock, s.

    Raises
    ------
    LockTimeoutError
        Another process held the lock for longer than ``timeout``.
    """
    if fcntl is None:
        yield
        return
    path = Path(path)
    folder = path.absolute().parent
    fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # can folders be locked here at all?
            fcntl.flock(fd, fcntl.LOCK_UN)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EACCES):
                os.close(fd)
                fd = os.open(folder / f".{path.name}.lock", os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0),
                             0o666)
        deadline = time.monotonic() + timeout
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError as exc:
                if exc.errno not in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EACCES):
                    raise
            if time.monotonic() >= deadline:
                raise LockTimeoutError(f"{path}: another process has been editing this file for {timeout:g} s (its "
                                       "folder is locked); try again when it has finished")
            time.sleep(0.02)
        yield
    finally:
        os.close(fd)  # releases the lock


def current_umask() -> int:
    """The process's file-creation mask (read without changing it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def stale_entries(folder: Path, prefix: str) -> list[Path]:
    """Entries ``<prefix><pid>-*`` of ``folder`` left by writers that were killed (their pid is gone).

    Parameters
    ----------
    folder : Path
        Where the writers put their temporaries.
    prefix : str
        The temporaries' name prefix, followed by the writer's pid and ``-``.
    """
    stale = []
    for p in folder.glob(f"{prefix}*"):
        pid = p.name[len(prefix):].split("-", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            stale.append(p)
        except PermissionError:
            pass  # another user's live process
    return stale


def check_replaceable(path: str | Path, what: str = "output file") -> None:
    """Refuse to write ``path`` when it exists as something other than a regular file.

    A device (``/dev/null``, a terminal), a FIFO or a socket given as an output would be
    replaced by a regular file (:func:`atomic_path` renames over it), which breaks whatever used
    the node; a folder cannot be replaced by a file. A symbolic link is judged by its target.

    Parameters
    ----------
    path : str or Path
        The file about to be written.
    what : str
        What it is, for messages.

    Raises
    ------
    OutputError
        ``path`` (or the target of a link ``path``) is a folder, a device, a FIFO or a socket.
    """
    try:
        st = os.stat(path)
    except OSError:
        return  # missing, a dangling link or an unreadable parent: the write itself says so
    if not stat.S_ISREG(st.st_mode):
        raise OutputError(f"{what} {path}: is {file_kind(st.st_mode)}, not a regular file; results are written to "
                          "regular files only, never over a folder, device, FIFO or socket: give another path")


@contextmanager
def atomic_path(path: str | Path, *, mode: int | None = None) -> Iterator[Path]:
    """Context manager: a temporary path beside ``path``, renamed to ``path`` on success.

    Parameters
    ----------
    path : str or Path
        The file to write; its folder is created if missing. An existing ``path`` that is not a
        regular file (a device, FIFO, socket or folder) is refused (:func:`check_replaceable`).
    mode : int, optional
        The file's permission bits (default: ``0o666`` less the umask, as ``open`` gives).

    Yields
    ------
    Path
        A temporary file in the same folder (same suffix) to write to. When the ``with``
        block ends normally it replaces ``path`` (with the usual file mode); when it raises,
        the temporary file and the folders created for it are removed and ``path`` is left
        as it was.

    Raises
    ------
    OutputError
        ``path`` exists and is not a regular file.
    """
    path = Path(path)
    check_replaceable(path)
    created = make_folders(path.parent)
    done = False
    try:
        prefix = f".{path.name}.tmp-"
        for stale in stale_entries(path.parent, prefix):
            stale.unlink(missing_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f"{prefix}{os.getpid()}-", suffix=path.suffix, dir=path.parent)
        os.close(fd)
        tmp_path = Path(tmp)
        try:
            yield tmp_path
            os.chmod(tmp_path, 0o666 & ~current_umask() if mode is None else mode)  # mkstemp makes 0600
            os.replace(tmp_path, path)
            done = True
        finally:
            if tmp_path.exists():
                tmp_path.unlink()
    finally:
        if not done:
            remove_folders(created)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically.

    Parameters
    ----------
    path : str or Path
        The file to write (its folder is created if missing).
    text : str
        The whole content.
    """
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json_atomic(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON to ``path`` atomically.

    Parameters
    ----------
    path : str or Path
        The file to write (its folder is created if missing).
    data : object
        Anything :func:`json.dumps` accepts; written with an indent of 2 and a final newline.
    """
    write_text_atomic(path, json.dumps(data, indent=2) + "\n")
