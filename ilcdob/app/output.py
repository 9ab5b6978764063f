"""The one results writer of every ``ilcdob`` command.

A command's output is a *content map* (file name -> content) built by the library
(``files()`` of a result object) and written here, in one of two ways:

* :class:`OutputFolder` -- a folder written as a unit. Files go into a fresh staging folder
  beside the target; when the command has succeeded, ``manifest.json`` (what produced the
  folder and the SHA-256 of every file) is written last and the staging folder takes the
  place of the target in one step (Linux: ``renameat2(RENAME_EXCHANGE)``; elsewhere two
  renames, with a window of a few microseconds in which the target is absent). A failure or a
  kill at any point leaves the previous complete folder or the new complete folder, never a
  mix, and no file of an earlier run that the new run does not write survives. Staging
  folders of killed runs are removed by the next run into the same place.
* :func:`write_file` -- one file, written atomically (temporary file + rename).

Content types: ``str`` (UTF-8 text), ``bytes``, ``dict``/``list`` (a JSON document, standard
JSON: a non-finite number is refused with its location, never written as ``NaN`` or
``Infinity``), a matplotlib ``Figure`` (PNG at :data:`FIGURE_DPI`, or the suffix's format), or a
callable taking the destination path (for writers that need a path, e.g. ``np.savez``).

A folder that is not empty and holds no ``manifest.json`` of ilcdob was not written by
ilcdob; it is replaced only with ``overwrite=True`` (``--overwrite``), so a mistyped
``--out`` never deletes a user's files.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import hashlib
import json
import math
import os
import shutil
import sys
import tempfile
import uuid
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any

from ilcdob.atomic import atomic_path, current_umask, stale_entries
from ilcdob.errors import IlcdobError

__all__ = ["FIGURE_DPI", "MANIFEST", "OutputError", "OutputFolder", "Provenance", "check_output_path",
           "file_sha256", "json_text", "read_manifest", "version", "write_file"]

#: Name of the file that records what produced an output folder; written last.
MANIFEST = "manifest.json"
#: Resolution of the PNG figures, dots per inch.
FIGURE_DPI = 110
_STAGING = ".ilcdob-staging-"
_RENAME_EXCHANGE = 2


class OutputError(IlcdobError, ValueError):
    """An output location cannot be written (not a folder, not writable, not ours to replace)."""


def version() -> str:
    """The installed ilcdob version (``"unknown"`` when run from a source tree that is not installed)."""
    try:
        return metadata.version("ilcdob")
    except metadata.PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class Provenance:
    """What produced an output: recorded in ``manifest.json`` (folders) or beside the data (files).

    Attributes
    ----------
    command : str
        The ``ilcdob`` subcommand (``"reproduce"``, ``"design"``, ...).
    arguments : list of str
        The command line after ``ilcdob``.
    fleet_sha256 : str or None
        SHA-256 of the fleet file's text as the command read it (None: no fleet involved).
    law : str or None
        Learning law of the run (:mod:`ilcdob.design.laws`), when the command has one.
    version : str
        ilcdob version.
    run_id : str
        Random identifier of the run; every file of one output carries the same.
    created_utc : str
        ISO 8601 time stamp of the run's start.
    """

    command: str
    arguments: list[str] = field(default_factory=list)
    fleet_sha256: str | None = None
    law: str | None = None
    version: str = field(default_factory=version)
    run_id: str = field(default_factory=lambda: uuid.uuid4().hex)
    created_utc: str = field(default_factory=lambda: datetime.now(timezone.utc).isoformat(timespec="seconds"))

    def to_dict(self) -> dict[str, Any]:
        """The provenance as a JSON object."""
        return asdict(self)


def _nonfinite(data: Any, where: str = "") -> str | None:
    """Location of the first non-finite float in a JSON-like document, or None."""
    if isinstance(data, float):
        return None if math.isfinite(data) else f"{where or '(top level)'} = {data!r}"
    if isinstance(data, Mapping):
        items: Iterable[tuple[str, Any]] = ((f"{where}.{k}" if where else str(k), v) for k, v in data.items())
    elif isinstance(data, (list, tuple)):
        items = ((f"{where}[{i}]", v) for i, v in enumerate(data))
    else:
        return None
    for loc, value in items:
        bad = _nonfinite(value, loc)
        if bad is not None:
            return bad
    return None


def json_text(data: Any, name: str) -> str:
    """``data`` as indented standard JSON text.

    Parameters
    ----------
    data : JSON-like
        Dicts, lists, strings, finite numbers, booleans and None.
    name : str
        File name, for the error message.

    Raises
    ------
    ilcdob.errors.NumericalError
        ``data`` holds NaN or an infinity (standard JSON has neither); the message names
        where.
    """
    from ilcdob.errors import NumericalError

    bad = _nonfinite(data)
    if bad is not None:
        raise NumericalError(f"{name}: non-finite number at {bad}; standard JSON cannot hold it and a result "
                             "that is not a number is not a result (a diverging simulation or an overflowing "
                             "input); nothing written")
    return json.dumps(data, indent=2) + "\n"


def _write(path: Path, name: str, content: Any) -> None:
    """Write one content item to ``path`` (a fresh file in a staging folder, or an atomic temporary)."""
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    elif isinstance(content, (bytes, bytearray)):
        path.write_bytes(bytes(content))
    elif isinstance(content, (dict, list)):
        path.write_text(json_text(content, name), encoding="utf-8")
    elif hasattr(content, "savefig"):
        fmt = Path(name).suffix.lstrip(".") or "png"
        content.savefig(path, format=fmt, dpi=FIGURE_DPI)
    elif callable(content):
        content(path)
        if not path.exists():
            raise OutputError(f"{name}: its writer created no file")
    else:
        raise TypeError(f"{name}: cannot write content of type {type(content).__name__}")


def _check_name(name: str) -> None:
    p = Path(name)
    if p.is_absolute() or ".." in p.parts or not p.parts or name == MANIFEST:
        raise ValueError(f"output file name {name!r}: expected a relative path inside the folder, not {MANIFEST}")


def file_sha256(path: Path) -> str:
    """SHA-256 of a file's bytes, hex (what ``manifest.json`` records).

    Parameters
    ----------
    path : Path
        The file.
    """
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_manifest(folder: str | Path) -> dict[str, Any] | None:
    """The ``manifest.json`` of an output folder, or None when it has none (or it is not ilcdob's).

    Parameters
    ----------
    folder : str or Path
        An output folder.
    """
    path = Path(folder) / MANIFEST
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return data if isinstance(data, dict) and data.get("writer") == "ilcdob" else None


def check_output_path(out: str | Path, *, folder: bool, overwrite: bool = False,
                      resumable: Iterable[str] = ()) -> Path:
    """Check, before any computation, that ``out`` can be written; returns it as a Path.

    Parameters
    ----------
    out : str or Path
        The ``--out`` of a command.
    folder : bool
        True: ``out`` is a folder written as a unit; False: a single file.
    overwrite : bool
        Allow replacing a non-empty folder that ilcdob did not write.
    resumable : iterable of str
        File names that mark an unfinished run of the same command (a campaign's sample
        store): a folder holding only those (and ilcdob's) files is ilcdob's to replace.

    Raises
    ------
    OutputError
        ``out`` is a file where a folder is expected (or the reverse), its parent folder
        cannot be created or written, or a foreign non-empty folder would be replaced.
    """
    out = Path(out)
    what = "--out"
    if folder and out.exists() and not out.is_dir():
        raise OutputError(f"`{what}` ({out}): is a file; expected a folder (a new or an earlier output folder)")
    if not folder and out.is_dir():
        raise OutputError(f"`{what}` ({out}): is a folder; expected a file name")
    parent = out.absolute().parent
    existing = parent
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"`{what}` ({out}): {existing} is a file, so the folder {parent} cannot be created")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"`{what}` ({out}): the folder {existing} is not writable; choose another location")
    if folder and out.is_dir() and not overwrite and read_manifest(out) is None:
        keep = set(resumable)
        foreign = sorted(p.name for p in out.iterdir() if p.name not in keep and not p.name.startswith("."))
        if foreign:
            raise OutputError(f"`{what}` ({out}): holds files that ilcdob did not write (e.g. {foreign[0]!r}) and "
                              "would be replaced as a whole; choose a new or empty folder, or add --overwrite")
    return out


def _staging_prefix(out: Path) -> str:
    return f".{out.name}{_STAGING}"


def _remove_stale_staging(out: Path) -> None:
    """Remove staging folders of killed runs into ``out`` (their process no longer exists)."""
    parent = out.absolute().parent
    if parent.is_dir():
        for p in stale_entries(parent, _staging_prefix(out)):
            shutil.rmtree(p, ignore_errors=True)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux renameat2 RENAME_EXCHANGE); False where unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    res = fn(at_fdcwd, os.fsencode(str(a)), at_fdcwd, os.fsencode(str(b)), _RENAME_EXCHANGE)
    if res == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL / ENOSYS / EOPNOTSUPP: the file system cannot exchange
        return False
    raise OSError(err, os.strerror(err), str(b))


class OutputFolder:
    """A folder written as a unit (see the module docstring); use as a context manager.

    Parameters
    ----------
    out : str or Path
        Target folder.
    provenance : Provenance
        What produces the folder; written to ``manifest.json``.
    overwrite : bool
        Replace a non-empty folder that ilcdob did not write.
    keep : iterable of str
        Files of the existing folder carried into the new one (a campaign's sample store,
        which the run keeps appending to in place).

    Examples
    --------
    >>> with OutputFolder("out", Provenance("reproduce")) as folder:  # doctest: +SKIP
    ...     folder.add_all({"results.json": {"rmse": 0.01}, "README.md": "# Results\\n"})
    """

    def __init__(self, out: str | Path, provenance: Provenance, *, overwrite: bool = False,
                 keep: Iterable[str] = ()) -> None:
        self.out = check_output_path(out, folder=True, overwrite=overwrite, resumable=keep)
        if self.out.is_symlink():  # replace the folder it points to, keep the link
            self.out = self.out.resolve()
        self.provenance = provenance
        self.keep = tuple(keep)
        self.files: list[str] = []
        self.staging: Path | None = None

    def __enter__(self) -> OutputFolder:
        parent = self.out.absolute().parent
        parent.mkdir(parents=True, exist_ok=True)
        _remove_stale_staging(self.out)
        self.staging = Path(tempfile.mkdtemp(prefix=f"{_staging_prefix(self.out)}{os.getpid()}-", dir=parent))
        return self

    def _staged(self) -> Path:
        if self.staging is None:
            raise RuntimeError("OutputFolder: use it as a context manager (`with OutputFolder(...) as folder:`)")
        return self.staging

    def path(self, name: str) -> Path:
        """Path of ``name`` inside the staging folder, for writers that need a path.

        Parameters
        ----------
        name : str
            Relative file name.
        """
        _check_name(name)
        p = self._staged() / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if name not in self.files:
            self.files.append(name)
        return p

    def add(self, name: str, content: Any) -> Path:
        """Write one file (content types: see the module docstring); returns its final path.

        Parameters
        ----------
        name : str
            Relative file name.
        content : str, bytes, dict, list, Figure or callable
            What to write.
        """
        _write(self.path(name), name, content)
        return self.out / name

    def add_all(self, files: Mapping[str, Any]) -> list[Path]:
        """Write every item of a content map; returns the final paths.

        Parameters
        ----------
        files : mapping of str to content
            File name -> content.
        """
        return [self.add(name, content) for name, content in files.items()]

    def _carry(self) -> None:
        for name in self.keep:
            src = self.out / name
            if src.is_file() and name not in self.files:
                dst = self.path(name)
                try:
                    os.link(src, dst)
                except OSError:
                    shutil.copy2(src, dst)

    def commit(self) -> None:
        """Write ``manifest.json`` and put the staged folder in place of the target."""
        staging = self._staged()
        self._carry()
        manifest = {"writer": "ilcdob", **self.provenance.to_dict(),
                    "files": {n: file_sha256(staging / n) for n in self.files}}
        (staging / MANIFEST).write_text(json_text(manifest, MANIFEST), encoding="utf-8")
        os.chmod(staging, 0o777 & ~current_umask())
        out = self.out
        if not out.exists():
            os.rename(staging, out)
        elif _exchange(staging, out):
            shutil.rmtree(staging, ignore_errors=True)
        else:
            old = Path(tempfile.mkdtemp(prefix=f"{_staging_prefix(out)}{os.getpid()}-old-", dir=out.absolute().parent))
            os.rmdir(old)
            os.rename(out, old)
            os.rename(staging, out)
            shutil.rmtree(old, ignore_errors=True)
        self.staging = None

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        elif self.staging is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging = None


def write_file(path: str | Path, content: Any) -> Path:
    """Write one file atomically (content types: see the module docstring); returns its path.

    Parameters
    ----------
    path : str or Path
        Destination file.
    content : str, bytes, dict, list, Figure or callable
        What to write.
    """
    path = check_output_path(path, folder=False)
    if isinstance(content, (dict, list)):
        content = json_text(content, path.name)  # refused before a temporary file exists
    with atomic_path(path) as tmp:
        _write(tmp, path.name, content)
    return path
