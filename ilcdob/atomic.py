"""Atomic file output: write to a temporary file in the target folder, then rename.

A crash or an exception mid-write leaves the previous file (or none), never a half-written
one: ``os.replace`` is atomic on POSIX and Windows within one file system. A temporary left by
a killed writer (``.NAME.tmp-<pid>-...``) is removed by the next write of the same file.
"""

from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

__all__ = ["atomic_path", "write_text_atomic", "write_json_atomic", "current_umask", "stale_entries"]


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


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Context manager: a temporary path beside ``path``, renamed to ``path`` on success.

    Parameters
    ----------
    path : str or Path
        The file to write; its folder is created if missing.

    Yields
    ------
    Path
        A temporary file in the same folder (same suffix) to write to. When the ``with``
        block ends normally it replaces ``path`` (with the usual file mode); when it raises,
        the temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    prefix = f".{path.name}.tmp-"
    for stale in stale_entries(path.parent, prefix):
        stale.unlink(missing_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f"{prefix}{os.getpid()}-", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~current_umask())  # mkstemp makes 0600; give the file the usual mode
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


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
