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

Where an output may go is checked before any computation (:func:`check_output_path`): a
regular file or a folder only (never a device node, FIFO, socket or mount point), never one of
the command's inputs (nor a folder holding one), and a symbolic link is followed explicitly (the
output replaces what the link points to; the link stays). A folder with files that ilcdob did not
write (not listed in its ``manifest.json``; every file when it has none) is replaced only with
``overwrite=True`` (``--overwrite``), and a folder holding a version-control work tree or Python
sources is never replaced, so a mistyped ``--out`` never deletes a user's files. A failure at any
point, a full disk included, leaves no staging folder and no folder created for the output.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import hashlib
import json
import math
import os
import shutil
import stat
import sys
import tempfile
import uuid
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any

from ilcdob.atomic import atomic_path, current_umask, make_folders, remove_folders, stale_entries
from ilcdob.errors import IlcdobError, OutputError
from ilcdob.inputs import file_kind, read_json, read_text

__all__ = ["FIGURE_DPI", "MANIFEST", "OutputError", "OutputFolder", "Provenance", "check_output_path",
           "file_sha256", "json_text", "read_manifest", "version", "write_file",
           "ManifestError", "verify_manifest"]

#: Name of the file that records what produced an output folder; written last.
MANIFEST = "manifest.json"
#: Resolution of the PNG figures, dots per inch.
FIGURE_DPI = 110
_STAGING = ".ilcdob-staging-"
_RENAME_EXCHANGE = 2


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
        Learning law of the run (:mod:`ilcdob.design.law.laws`), when the command has one.
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

    Raises
    ------
    OutputError
        ``path`` is not a regular file (a FIFO or a device is opened without blocking and
        never read).
    """
    h = hashlib.sha256()
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    with os.fdopen(fd, "rb") as fh:
        mode = os.fstat(fh.fileno()).st_mode
        if not stat.S_ISREG(mode):  # a FIFO or a device in a result folder: never read (it could block)
            raise OutputError(f"{path}: is {file_kind(mode)}, not a regular file; an output folder holds regular "
                              "files only")
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_manifest(folder: str | Path) -> dict[str, Any] | None:
    """The ``manifest.json`` of an output folder, or None when it has none (or it is not ilcdob's).

    Nothing is checked beyond the ``writer`` key; :func:`verify_manifest` checks a folder
    against its manifest.

    Parameters
    ----------
    folder : str or Path
        An output folder.
    """
    path = Path(folder) / MANIFEST
    try:  # a regular file of bounded size only: a FIFO named manifest.json must not hang the command
        data = read_json(path, "manifest")
    except (OSError, IlcdobError):
        return None
    return data if isinstance(data, dict) and data.get("writer") == "ilcdob" else None


class ManifestError(IlcdobError, ValueError):
    """An output folder does not hold what its ``manifest.json`` records: a listed file is missing or
    changed, a file is not listed, or the manifest itself is not one that ilcdob writes."""


#: Text fields of ``manifest.json`` that :func:`verify_manifest` returns checked (``arguments``: a list of them).
_MANIFEST_TEXT = ("command", "version", "run_id", "created_utc")


def _shown(name: str) -> str:
    """A file name for a message: as it is when printable, else its ``repr``."""
    return name if name.isprintable() else repr(name)


def _listed_name(name: str) -> bool:
    """Whether a manifest key is a file name OutputFolder writes: relative, ``/``-separated, inside."""
    parts = name.split("/")
    return (bool(name) and name.isprintable() and "\\" not in name and name != MANIFEST
            and all(p not in ("", ".", "..") for p in parts))


def _folder_entries(folder: Path) -> list[str]:
    """Every file of ``folder`` and below, ``/``-separated (a symbolic link to a folder counts as a file)."""
    found = []
    for dirpath, dirnames, filenames in os.walk(folder, followlinks=False):
        rel = Path(dirpath).relative_to(folder)
        found += [(rel / d).as_posix() for d in dirnames if (Path(dirpath) / d).is_symlink()]
        found += [(rel / f).as_posix() for f in filenames]
    return found


def _rerun(manifest: dict[str, Any]) -> str:
    """The command line that wrote a (checked) manifest's folder, for messages."""
    import shlex

    line = shlex.join(["ilcdob", manifest.get("command", "<command>"), *manifest.get("arguments", [])])
    return line if line.isprintable() else repr(line)


def _check_manifest(path: Path, data: Any) -> dict[str, Any]:
    """``data`` if it is a manifest of the form :class:`OutputFolder` writes, else :class:`ManifestError`."""
    fix = "it is not a manifest written by ilcdob (edited, or from elsewhere); regenerate the folder"
    if not isinstance(data, dict):
        raise ManifestError(f"{path}: got a JSON {type(data).__name__}, expected an object; {fix}")
    if data.get("writer") != "ilcdob":
        raise ManifestError(f"{path}: key \"writer\": got {data.get('writer')!r:.80}, expected 'ilcdob'; {fix}")
    for key in _MANIFEST_TEXT:
        if key in data and not isinstance(data[key], str):
            raise ManifestError(f"{path}: key \"{key}\": got {data[key]!r:.80}, expected a text; {fix}")
    args = data.get("arguments", [])
    if not isinstance(args, list) or not all(isinstance(a, str) for a in args):
        raise ManifestError(f"{path}: key \"arguments\": got {args!r:.80}, expected a list of texts; {fix}")
    files = data.get("files")
    if not isinstance(files, dict):
        raise ManifestError(f"{path}: key \"files\": got {files!r:.80}, expected an object of file name -> "
                            f"SHA-256; {fix}")
    for name, digest in files.items():
        if not _listed_name(name):
            raise ManifestError(f"{path}: key \"files\": file name {name!r:.80} is not a relative path inside the "
                                f"folder; {fix}")
        if not (isinstance(digest, str) and len(digest) == 64 and all(c in "0123456789abcdef" for c in digest)):
            raise ManifestError(f"{path}: key \"files.{_shown(name)}\": got {digest!r:.80}, expected a SHA-256 "
                                f"(64 lower-case hex digits); {fix}")
    return data


def verify_manifest(folder: str | Path) -> dict[str, Any] | None:
    """Check that an output folder holds exactly the files of its ``manifest.json``, each as its run wrote it.

    Every file the manifest lists must exist with the SHA-256 it records, and every file of the
    folder (subfolders included) except ``manifest.json`` must be listed: :class:`OutputFolder`
    lists everything it writes, so a file it does not list was added, renamed or dropped from
    the list since.

    Parameters
    ----------
    folder : str or Path
        An output folder.

    Returns
    -------
    dict or None
        The checked manifest (``writer``, ``files``, ``arguments`` and the texts ``command``,
        ``version``, ``run_id``, ``created_utc`` where present); None when the folder has no
        ``manifest.json`` at all (written before manifests existed: nothing to check against).

    Raises
    ------
    ManifestError
        ``manifest.json`` is unreadable, not JSON or not of the form ilcdob writes; a listed file
        is missing or differs from what its run wrote; or a file is not listed. The message names
        the folder and the file and gives the command that regenerates the folder.
    """
    folder = Path(folder)
    path = folder / MANIFEST
    if not os.path.lexists(path):
        return None
    text = read_text(path, "manifest", error=ManifestError, hint="regenerate the folder")  # regular file, size cap
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise ManifestError(f"{path}: not a manifest written by ilcdob (not JSON text: {str(exc)[:120]}); "
                            "regenerate the folder") from exc
    manifest = _check_manifest(path, data)
    files = manifest["files"]
    for name, digest in files.items():
        target = folder / name
        if not target.is_file():
            raise ManifestError(f"{folder}: {_shown(name)} is listed in {MANIFEST} but missing; the folder is "
                                f"incomplete. Regenerate it: {_rerun(manifest)}")
        if file_sha256(target) != digest:
            raise ManifestError(f"{folder}: {_shown(name)} differs from the file its run wrote ({MANIFEST}); the "
                                f"folder mixes files of different runs or was edited. Regenerate it: "
                                f"{_rerun(manifest)}")
    unlisted = sorted(n for n in _folder_entries(folder) if n != MANIFEST and n not in files)
    if unlisted:
        more = f" (and {len(unlisted) - 1} more)" if len(unlisted) > 1 else ""
        raise ManifestError(f"{folder}: {_shown(unlisted[0])}{more} is not listed in {MANIFEST}: its run did not "
                            "write it (added, renamed or dropped from the list since), so the folder is not what "
                            f"the run wrote. Remove it, or regenerate the folder: {_rerun(manifest)}")
    return manifest


#: Entries that make a folder never ours to replace, even with ``overwrite``: version-control
#: work trees and Python sources (ilcdob writes neither).
PROTECTED_NAMES = frozenset({".git", ".hg", ".svn", ".bzr", "pyproject.toml", "setup.py", "setup.cfg"})
#: Suffixes of Python sources (see :data:`PROTECTED_NAMES`).
PROTECTED_SUFFIXES = frozenset({".py", ".pyi", ".pyx", ".pxd", ".ipynb"})
#: Most entries (files and folders, at any depth) of a folder that an output replaces: ilcdob's
#: output folders hold a few hundred at most; a larger tree is not a results folder.
MAX_REPLACED_ENTRIES = 10_000

def _target(out: Path, option: str) -> Path:
    """The path written: a symbolic link's target (resolved explicitly), ``.``/``..`` made absolute."""
    if out.is_symlink() or out.name in ("", ".", ".."):
        try:
            return out.resolve()
        except (OSError, RuntimeError) as exc:  # a loop of links
            raise OutputError(f"`{option}` ({out}): a symbolic link that does not resolve ({exc}); give a plain "
                              "path") from None
    return out


def _inside(child: Path, parent: Path) -> bool:
    return child == parent or parent in child.parents


def _check_inputs(out: Path, option: str, folder: bool, inputs: Mapping[str, Any] | None) -> None:
    """Refuse an output that is one of the command's inputs, holds one, or lies inside an input folder."""
    real = Path(os.path.realpath(out))
    for name, given in (inputs or {}).items():
        if given is None:
            continue
        for p in ([given] if isinstance(given, (str, os.PathLike)) else list(given)):
            rp = Path(os.path.realpath(p))
            same = rp == real
            if not same and os.path.exists(p) and os.path.exists(out):
                same = os.path.samefile(p, out)  # a hard link
            if same:
                raise OutputError(f"`{option}` ({out}): is the input {name} ({p}); writing it would replace that "
                                  f"input. Give another `{option}`")
            if folder and _inside(rp, real):
                raise OutputError(f"`{option}` ({out}): holds the input {name} ({p}), and the folder is replaced as a "
                                  f"whole, so that input would be lost. Give another `{option}` folder (or move the "
                                  "input out of it)")
            if rp.is_dir() and _inside(real, rp):
                raise OutputError(f"`{option}` ({out}): lies inside the input {name} ({p}); writing there would change "
                                  f"that input. Give a `{option}` outside it")


def _check_replaceable(out: Path, option: str, overwrite: bool, resumable: Iterable[str]) -> None:
    """Refuse to replace a folder that is not ilcdob's: protected content always, foreign files
    without ``overwrite`` (see :func:`check_output_path`)."""
    count = 0
    for root, dirs, files in os.walk(out, onerror=None, followlinks=False):
        for name in sorted(dirs) + sorted(files):
            count += 1
            entry = Path(root) / name
            rel = entry.relative_to(out).as_posix()
            if name in PROTECTED_NAMES or Path(name).suffix.lower() in PROTECTED_SUFFIXES:
                what = "a version-control work tree" if name.startswith(".") else "a Python source"
                raise OutputError(f"`{option}` ({out}): holds {rel!r}, {what}; an output folder is replaced as a "
                                  "whole, and ilcdob never replaces a folder holding a work tree or Python sources, "
                                  f"even with --overwrite. Give a new folder for the results, e.g. `{option} "
                                  "results`")
            if name in dirs and os.path.ismount(entry):
                raise OutputError(f"`{option}` ({out}): holds the mount point {rel!r}; an output folder is replaced as "
                                  f"a whole, which would empty that file system. Give a new folder for the results")
            if count > MAX_REPLACED_ENTRIES:
                raise OutputError(f"`{option}` ({out}): holds more than {MAX_REPLACED_ENTRIES} files and folders; an "
                                  "output folder is replaced as a whole, and ilcdob's output folders hold a few "
                                  "hundred at most, so this is not one. Give a new folder for the results")
    if overwrite or count == 0:
        return
    listed = out / MANIFEST
    manifest = read_manifest(out) if listed.is_file() and not listed.is_symlink() else None  # never open a FIFO
    ours = {MANIFEST, *resumable}
    if manifest is not None and isinstance(manifest.get("files"), Mapping):
        ours |= {str(name).split("/", 1)[0] for name in manifest["files"]}
    foreign = sorted(p.name for p in out.iterdir() if p.name not in ours and not p.name.startswith("."))
    if foreign:
        wrote = "not listed in its manifest.json" if manifest is not None else "no manifest.json of ilcdob"
        raise OutputError(f"`{option}` ({out}): holds files that ilcdob did not write (e.g. {foreign[0]!r}; {wrote}) "
                          "and would be replaced as a whole; choose a new or empty folder, or add --overwrite")


def check_output_path(out: str | Path, *, folder: bool, overwrite: bool = False,
                      resumable: Iterable[str] = (), inputs: Mapping[str, Any] | None = None, option: str = "--out") -> Path:
    """Check, before any computation, that ``out`` can be written; returns the path to write.

    What is refused, and why:

    * a path that exists and is neither a regular file nor a folder (a character or block
      device such as ``/dev/null``, a FIFO, a socket): results go to a file or a folder, and
      replacing a device node with a file would break the system;
    * a mount point (the root of a file system): it cannot be replaced, and a staging folder
      would land in the file system above it;
    * for a folder: the working folder or a folder holding it (``--out .``), which the swap
      would pull from under the shell, and the home folder or a folder holding it;
    * one of the command's ``inputs`` (compared by resolved path and as the same file, so a
      hard link counts), a folder holding one (it would be lost with the folder), or a path
      inside an input folder;
    * an existing folder holding a version-control work tree (``.git``, ...), Python sources
      (:data:`PROTECTED_NAMES`, :data:`PROTECTED_SUFFIXES`), a mount point, or more than
      :data:`MAX_REPLACED_ENTRIES` entries: never replaced, even with ``overwrite``;
    * without ``overwrite``: an existing folder with files ilcdob did not write, i.e. files
      not listed in its ilcdob ``manifest.json`` (every file when it has none; names starting
      with ``.`` are not counted).

    A symbolic link ``out`` is resolved explicitly: the output goes to the file or folder the
    link points to (checked as above), and the link stays.

    Parameters
    ----------
    out : str or Path
        The ``--out`` of a command.
    folder : bool
        True: ``out`` is a folder written as a unit; False: a single file.
    overwrite : bool
        Allow replacing a non-empty folder with files that ilcdob did not write.
    resumable : iterable of str
        File names that mark an unfinished run of the same command (a campaign's sample
        store): a folder holding only those (and ilcdob's) files is ilcdob's to replace.
    inputs : mapping of str to path(s), optional
        The command's input files and folders by option name (``{"--fleet": path}``; a value
        may be a list of paths, or None).
    option : str
        The option ``out`` was given with, for messages.

    Returns
    -------
    Path
        ``out``, or the target of a symbolic link ``out`` (absolute), or ``.``/``..`` made
        absolute.

    Raises
    ------
    OutputError
        ``out`` is a file where a folder is expected (or the reverse, a file name ending in a
        slash included), a special file, a mount
        point, an input (or holds or lies in one), its parent folder cannot be created or
        written, or a folder would be replaced that is not ilcdob's to replace.
    """
    if not folder and isinstance(out, str) and out.endswith(("/", os.sep)):
        raise OutputError(f"`{option}` ({out}): ends in a slash, which names a folder; expected a file name, e.g. "
                          f"`{option} {out.rstrip('/' + os.sep) or 'result.json'}`")
    given = Path(out)
    out = _target(given, option)
    try:
        st: os.stat_result | None = os.lstat(out)
    except OSError:
        st = None  # missing (or a parent that is a file: reported below)
    if st is not None:
        _check_existing(out, given, st, option, folder)
    if folder:
        _check_not_cwd_or_home(out, given, option)
    _check_inputs(out, option, folder, inputs)
    _check_parent(out, given, option)
    if folder and st is not None:
        _check_replaceable(out, option, overwrite, resumable)
    return out


def _check_existing(out: Path, given: Path, st: os.stat_result, option: str, folder: bool) -> None:
    """Refuse an existing ``out`` of the wrong kind (a folder for a file and the reverse, a device, FIFO or
    socket) or a mount point (``given``: the path as given, for the message; ``st``: its lstat)."""
    if stat.S_ISDIR(st.st_mode) and not folder:
        raise OutputError(f"`{option}` ({given}): is a folder; expected a file name")
    if stat.S_ISREG(st.st_mode) and folder:
        raise OutputError(f"`{option}` ({given}): is a file; expected a folder (a new or an earlier output folder)")
    if not stat.S_ISDIR(st.st_mode) and not stat.S_ISREG(st.st_mode):
        raise OutputError(f"`{option}` ({given}): is {file_kind(st.st_mode)}; expected "
                          f"{'a folder' if folder else 'a regular file'}: results are written to regular files "
                          f"and folders only, never over a device, FIFO or socket. Give another `{option}`")
    if os.path.ismount(out):
        raise OutputError(f"`{option}` ({given}): is a mount point (the root of a file system), which an output "
                          f"cannot replace; give a {'folder' if folder else 'file'} inside it, e.g. "
                          f"`{option} {Path(given, 'results')}`")


def _check_not_cwd_or_home(out: Path, given: Path, option: str) -> None:
    """Refuse an output folder that is (or holds) the working folder or the home folder."""
    try:
        cwd = Path.cwd().resolve()
    except OSError:
        cwd = None
    if cwd is not None and _inside(cwd, out.resolve()):
        raise OutputError(f"`{option}` ({given}): is the working folder (or holds it); an output folder is "
                          "replaced as a whole, which would pull it from under the shell. Give a new folder, "
                          f"e.g. `{option} results`")
    try:
        home = Path.home().resolve()
    except (OSError, RuntimeError):
        home = None
    if home is not None and home != Path(home.anchor) and _inside(home, out.resolve()):
        raise OutputError(f"`{option}` ({given}): is the home folder (or holds it), which an output folder never "
                          f"replaces, even with --overwrite. Give a new folder, e.g. `{option} {home / 'results'}`")


def _check_parent(out: Path, given: Path, option: str) -> None:
    """Refuse an output whose parent folder cannot be created (a file on the way) or written."""
    parent = out.absolute().parent
    existing = parent
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"`{option}` ({given}): {existing} is a file, so the folder {parent} cannot be created")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"`{option}` ({given}): the folder {existing} is not writable; choose another location")


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
    option : str
        The option the folder was given with, for messages (``--out``, ``--plot``).

    Examples
    --------
    >>> with OutputFolder("out", Provenance("reproduce")) as folder:  # doctest: +SKIP
    ...     folder.add_all({"results.json": {"rmse": 0.01}, "README.md": "# Results\\n"})
    """

    def __init__(self, out: str | Path, provenance: Provenance, *, overwrite: bool = False,
                 keep: Iterable[str] = (), option: str = "--out") -> None:
        # a symbolic link is resolved by the check: the folder it points to is replaced, the link stays
        self.out = check_output_path(out, folder=True, overwrite=overwrite, resumable=keep, option=option)
        self.provenance = provenance
        self.keep = tuple(keep)
        self.files: list[str] = []
        self.staging: Path | None = None
        self._sealed = False
        self._created: list[Path] = []

    def __enter__(self) -> OutputFolder:
        parent = self.out.absolute().parent
        self._created = make_folders(parent)
        try:
            _remove_stale_staging(self.out)
            self.staging = Path(tempfile.mkdtemp(prefix=f"{_staging_prefix(self.out)}{os.getpid()}-", dir=parent))
        except BaseException:
            remove_folders(self._created)
            raise
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

    def seal(self) -> None:
        """Write the last bytes of the folder (carried files, ``manifest.json``): after it, only the
        swap of :meth:`commit` (renames) remains.

        For a command with a second output: seal the folder, write the other output, and let
        the ``with`` block end; when the other output fails, the folder is discarded, and a
        full disk cannot leave one output written without the other.
        """
        staging = self._staged()
        if self._sealed:
            return
        self._carry()
        manifest = {"writer": "ilcdob", **self.provenance.to_dict(),
                    "files": {n: file_sha256(staging / n) for n in self.files}}
        (staging / MANIFEST).write_text(json_text(manifest, MANIFEST), encoding="utf-8")
        os.chmod(staging, 0o777 & ~current_umask())
        self._sealed = True

    def commit(self) -> None:
        """Write ``manifest.json`` (:meth:`seal`) and put the staged folder in place of the target.

        Any failure removes the staging folder (and folders created for it) and leaves the
        previous folder in place.
        """
        staging = self._staged()
        try:
            self.seal()
            out = self.out
            if not os.path.lexists(out):
                os.rename(staging, out)
                old = None
            elif _exchange(staging, out):
                old = staging  # the previous folder, now under the staging name
            else:
                old = Path(tempfile.mkdtemp(prefix=f"{_staging_prefix(out)}{os.getpid()}-old-",
                                            dir=out.absolute().parent))
                os.rmdir(old)
                os.rename(out, old)
                try:
                    os.rename(staging, out)
                except BaseException:
                    os.rename(old, out)
                    raise
        except BaseException:
            self._discard()
            raise
        self.staging = None
        self._created = []
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def _discard(self) -> None:
        """Remove the staging folder and the folders made for it: the previous state stays."""
        if self.staging is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging = None
        remove_folders(self._created)
        self._created = []

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self._discard()


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
