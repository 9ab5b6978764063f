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

__all__ = ["atomic_path", "write_text_atomic", "write_json_atomic"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _remove_stale(folder: Path, prefix: str) -> None:
    """Remove temporaries ``<prefix><pid>-*`` of writers that were killed (their pid is gone)."""
    for p in folder.glob(f"{prefix}*"):
        pid = p.name[len(prefix):].split("-", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            p.unlink(missing_ok=True)
        except PermissionError:
            pass  # another user's live process


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
    _remove_stale(path.parent, prefix)
    fd, tmp = tempfile.mkstemp(prefix=f"{prefix}{os.getpid()}-", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
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
