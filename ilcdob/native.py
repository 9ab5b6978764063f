"""CasADi functions compiled to native code by the machine's C compiler, kept on disk.

CasADi evaluates an SX function in its virtual machine: one interpreted instruction per
operation. The same function written out as C by CasADi's code generator
(:class:`casadi.CodeGenerator`) and compiled runs the same operations in the same order, and
CasADi loads the library as a :class:`casadi.Function` again (:func:`casadi.external`), so
callers keep its interface (``buffer``, ``mapaccum``). For the norm-optimal recursions that is
about 8 times as fast as the virtual machine (docs/performance.md, "Norm-optimal ILC", "Native code").

The results are those of the virtual machine bit for bit. Every operation is one IEEE double
operation in both, evaluated in the order of the expression graph, provided the compiler neither
reassociates (no ``-ffast-math``) nor fuses a product and a sum into one rounding: GCC and Clang
fuse by default where the target has fused multiply-add (aarch64 always), so the library is built
with ``-ffp-contract=off`` (:data:`FLAGS`). tests/test_native.py compares both on varied systems.

Where it applies, set by environment variables (read at every call):

``ILCDOB_NATIVE``
    ``auto`` (default): use a library already built for the function; build one when the caller
    asks (:meth:`NativeFunction.get` with ``build=True``) and a compiler is found; otherwise, or
    when the build fails (one warning per process and compiler), the virtual machine.
    ``off``: always the virtual machine. ``required``: always native; a missing compiler or a
    failed build is an error (:class:`~ilcdob.errors.NativeBuildError`).
``ILCDOB_CC``
    The compiler command (split like a shell would, so ``"ccache gcc"`` works); default ``$CC``,
    else ``cc``.
``ILCDOB_CACHE_DIR``
    Where the libraries are kept; default ``$XDG_CACHE_HOME/ilcdob/native``, else
    ``~/.cache/ilcdob/native``; with no home folder, ``$XDG_RUNTIME_DIR/ilcdob/native``, else a
    private folder of the process (below). A library's name carries a hash of its C source, the
    compiler's version line, the flags, the CasADi version and the platform, so a change of any of
    them builds a new one and a stale one is never loaded. Deleting the folder is always safe.

Loading a library runs its code, so a library is loaded only from a place that no one but this user
(and the administrator) can write:

* the folder: a real folder (a symbolic link is followed to it) owned by this user and writable by no
  group or other user; every folder above it owned by this user or root, and writable by others only
  with the sticky bit (as ``/tmp`` is). Folders ilcdob creates for the cache are made with mode 0700;
* the library: a regular file (not a link, FIFO or device: a FIFO would block the load for ever)
  owned by this user and writable by no group or other user. ilcdob writes its libraries 0644 less
  the umask.

Otherwise the path is not used: one warning (per path and process) names it and says why, and the
process keeps its libraries in a private folder (:func:`tempfile.mkdtemp`, mode 0700, removed when
the process ends) instead, building them there where it would build (so ``required`` still gets
native code) and running in the virtual machine where it would not. A checksum kept beside a library
would add nothing: whoever can replace the library can replace the checksum in the same folder, and
whoever cannot is kept out by the checks above.

A library is written atomically (:func:`~ilcdob.atomic.atomic_path`), so processes building the
same one at once (a campaign's workers) each replace it with a complete file. The checks are POSIX
ones (owner and mode); on Windows, where files carry access lists instead, they are not made.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import platform
import shlex
import shutil
import stat
import subprocess
import sys
import tempfile
import warnings
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Any

from .atomic import atomic_path, current_umask
from .errors import NativeBuildError, SpecError
from .inputs import file_kind

__all__ = ["MODES", "FLAGS", "native_mode", "compiler_command", "cache_dir", "private_dir", "library_folder",
           "untrusted_folder", "untrusted_library", "NativeFunction"]

#: Values of ``ILCDOB_NATIVE``.
MODES = ("auto", "off", "required")

#: Compiler flags of every library: optimised, position independent, a shared library, and no fused
#: multiply-add (the results must be the virtual machine's bit for bit; module docstring).
FLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off")

#: Seconds a build may take before it is abandoned (measured: 0.1 to 3.4 s per function, 11 to 109 states).
BUILD_TIMEOUT_S = 120.0

#: Compilers whose build failed in this process (``auto`` does not retry them).
_FAILED: set[tuple[str, ...]] = set()

#: The private library folder of each process that made one (pid -> folder; a forked child makes its own).
_PRIVATE: dict[int, Path] = {}

#: Paths refused in this process and why (each warned about once).
_WARNED: set[tuple[str, str]] = set()


def native_mode() -> str:
    """The mode set by ``ILCDOB_NATIVE`` (``auto`` when unset or empty).

    Raises
    ------
    SpecError
        The variable holds another value.
    """
    value = os.environ.get("ILCDOB_NATIVE", "").strip().lower() or "auto"
    if value not in MODES:
        raise SpecError(f"ILCDOB_NATIVE = {os.environ['ILCDOB_NATIVE']!r} is not a mode; valid: "
                        f"{', '.join(MODES)} (unset means auto)")
    return value


def compiler_command() -> list[str]:
    """The compiler command: ``ILCDOB_CC``, else ``CC``, else ``cc``, split into words.

    Raises
    ------
    SpecError
        The variable cannot be split as a shell would (an unterminated quote, a lone escape).
    """
    for name in ("ILCDOB_CC", "CC"):
        value = os.environ.get(name, "")
        try:
            words = shlex.split(value)
        except ValueError as err:
            raise SpecError(f"{name} = {value!r}: cannot be split into words as a shell would ({err}); give the "
                            f"compiler command with balanced quotes, e.g. {name}='gcc' or {name}='ccache gcc'"
                            ) from None
        if words:
            return words
    return ["cc"]


def cache_dir() -> Path:
    """The folder of the built libraries as configured (``ILCDOB_CACHE_DIR``, module docstring).

    With no home folder and no ``XDG_RUNTIME_DIR``, the private folder of this process (created,
    mode 0700). Whether the folder may be used is checked where a library is loaded
    (:meth:`NativeFunction.get`).

    Raises
    ------
    SpecError
        ``ILCDOB_CACHE_DIR`` starts with ``~user`` of an unknown user (or ``~`` with no home folder).
    """
    given = os.environ.get("ILCDOB_CACHE_DIR")
    if given:
        try:
            return Path(given).expanduser()
        except RuntimeError as err:  # ~nosuchuser, or ~ where no home folder is known
            raise SpecError(f"ILCDOB_CACHE_DIR = {given!r}: {err.args[0] if err.args else err} (its leading ~ "
                            "names no known home folder); give an absolute path, e.g. ILCDOB_CACHE_DIR=/path/to/cache"
                            ) from None
    base = os.environ.get("XDG_CACHE_HOME")
    if base and os.path.isabs(base):  # a relative one is to be ignored (XDG base directory specification)
        return Path(base) / "ilcdob" / "native"
    try:
        return Path.home() / ".cache" / "ilcdob" / "native"
    except RuntimeError:  # no home folder known (no HOME, no password entry): never a predictable shared path
        runtime = os.environ.get("XDG_RUNTIME_DIR")
        return Path(runtime) / "ilcdob" / "native" if runtime and os.path.isabs(runtime) else private_dir()


def private_dir() -> Path:
    """This process's private library folder: made by :func:`tempfile.mkdtemp` (mode 0700, a name no
    one can predict) at the first call, removed when the process ends."""
    pid = os.getpid()
    if pid not in _PRIVATE:
        _PRIVATE[pid] = Path(tempfile.mkdtemp(prefix="ilcdob-native-"))
        atexit.register(_remove_private, pid)
    return _PRIVATE[pid]


def _remove_private(pid: int) -> None:
    folder = _PRIVATE.pop(pid, None) if os.getpid() == pid else None  # not in a forked child: not its folder
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


def _writers(st: os.stat_result) -> str | None:
    """Who other than the owner may write a file of ``st`` ("its group", "every user" or both), None: no one."""
    who = [name for bit, name in ((stat.S_IWGRP, "its group"), (stat.S_IWOTH, "every user")) if st.st_mode & bit]
    return " and ".join(who) or None


def untrusted_folder(folder: Path) -> str | None:
    """Why ``folder`` may not hold libraries to load (module docstring), None when it may.

    The folder itself must belong to this user and be writable by no one else; the folders above
    it must belong to this user or root and be writable by others only with the sticky bit. Missing
    folders are fine (ilcdob creates them 0700 and checks again).

    Parameters
    ----------
    folder : Path
        The library folder.

    Returns
    -------
    str or None
        The reason, naming the offending folder, its owner or its mode.
    """
    if not hasattr(os, "geteuid"):
        return None
    uid = os.geteuid()
    try:
        real = Path(os.path.realpath(folder))
    except (OSError, RuntimeError) as err:
        return f"the path does not resolve ({err})"
    for p in [real, *real.parents]:
        try:
            st = os.stat(p)
        except FileNotFoundError:
            continue
        except OSError as err:
            return f"{p} cannot be examined ({err.strerror or err})"
        if not stat.S_ISDIR(st.st_mode):
            return f"{p} is {file_kind(st.st_mode)}, not a folder"
        writers = _writers(st)
        if p == real:
            if st.st_uid != uid:
                return f"the folder {p} belongs to user id {st.st_uid}, not to this user ({uid})"
            if writers:
                return f"the folder {p} can be written by {writers} (mode {stat.S_IMODE(st.st_mode):04o})"
        else:
            if st.st_uid not in (uid, 0):
                return f"the folder {p} above it belongs to user id {st.st_uid}, who could replace what is below"
            if writers and not st.st_mode & stat.S_ISVTX:
                return (f"the folder {p} above it can be written by {writers} without the sticky bit (mode "
                        f"{stat.S_IMODE(st.st_mode):04o}), who could replace what is below")
    return None


def untrusted_library(path: Path) -> str | None:
    """Why the file ``path`` may not be loaded (module docstring), None when it may or is missing.

    Parameters
    ----------
    path : Path
        A library's path in a folder that passed :func:`untrusted_folder`.

    Returns
    -------
    str or None
        The reason: what the file is, whom it belongs to or who can write it.
    """
    try:
        st = os.lstat(path)  # never opened or followed: a FIFO or a link is judged by what it is
    except FileNotFoundError:
        return None
    except OSError as err:
        return f"it cannot be examined ({err.strerror or err})"
    if not stat.S_ISREG(st.st_mode):
        return f"it is {file_kind(st.st_mode)}, not a regular file"
    if not hasattr(os, "geteuid"):
        return None
    if st.st_uid != os.geteuid():
        return f"it belongs to user id {st.st_uid}, not to this user ({os.geteuid()})"
    writers = _writers(st)
    if writers:
        return f"it can be written by {writers} (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def _refuse(path: Path, reason: str, what: str) -> None:
    """Warn once per path and reason that ``path`` is not used (module docstring)."""
    if (str(path), reason) in _WARNED:
        return
    _WARNED.add((str(path), reason))
    warnings.warn(f"native code: {what} {path.absolute()} is not used: {reason}. ilcdob loads only libraries from a "
                  f"place no other user can write; this process keeps its libraries in {private_dir()} instead. Fix "
                  "the owner or mode, delete the path, or set ILCDOB_CACHE_DIR to a folder of your own",
                  RuntimeWarning, stacklevel=4)


def library_folder(create: bool) -> Path:
    """The folder to load and build libraries in: :func:`cache_dir` when it passes
    :func:`untrusted_folder`, else (with one warning) :func:`private_dir`.

    Parameters
    ----------
    create : bool
        Create a missing :func:`cache_dir` (each new level mode 0700) and check it again.
    """
    folder = cache_dir()
    if folder in _PRIVATE.values():
        return folder
    reason = untrusted_folder(folder)
    if reason is None and create and not folder.is_dir():
        try:
            _make_private_folders(folder)
        except OSError as err:
            reason = f"it cannot be created ({err.strerror or err})"
        else:
            reason = untrusted_folder(folder)  # again: another user may have raced us in a shared parent
    if reason is None:
        return folder
    _refuse(folder, reason, "the library folder")
    return private_dir()


def _make_private_folders(folder: Path) -> None:
    missing = []
    p = folder.absolute()
    while not os.path.lexists(p) and p.parent != p:
        missing.append(p)
        p = p.parent
    for p in reversed(missing):
        try:
            p.mkdir(mode=0o700)
        except FileExistsError:
            pass  # made by another process meanwhile: checked by the caller


@lru_cache(maxsize=8)
def _compiler_identity(command: tuple[str, ...]) -> str | None:
    """First line of ``command --version`` (part of a library's hash); None when it does not run."""
    if shutil.which(command[0]) is None:
        return None
    try:
        done = subprocess.run([*command, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    lines = done.stdout.strip().splitlines()
    return lines[0] if done.returncode == 0 and lines else None


@dataclass
class NativeFunction:
    """A CasADi SX function and its native build.

    Parameters
    ----------
    function : casadi.Function
        The function, evaluated by CasADi's virtual machine.

    Attributes
    ----------
    loaded : casadi.Function or None
        The native build once loaded (same name, inputs and outputs), else None.
    """

    function: Any
    loaded: Any = field(default=None, init=False, repr=False)
    _digests: dict[str, str] = field(default_factory=dict, init=False, repr=False)

    @cached_property
    def source(self) -> str:
        """The function's C code (:class:`casadi.CodeGenerator`)."""
        import casadi as cs

        generator = cs.CodeGenerator(f"{self.function.name()}.c", {"with_header": False})
        generator.add(self.function)
        return generator.dump()

    def library(self, command: list[str]) -> Path | None:
        """Path of the library ``command`` builds.

        Parameters
        ----------
        command : list of str
            The compiler command (:func:`compiler_command`).

        Returns
        -------
        Path or None
            In :func:`cache_dir` (where :meth:`get` looks first), named by the function and a hash
            of what the build depends on (module docstring); None when the compiler does not run.
        """
        import casadi as cs

        identity = _compiler_identity(tuple(command))
        if identity is None:
            return None
        if identity not in self._digests:  # once per compiler: the source is tens to hundreds of kB
            key = "\0".join([self.source, identity, " ".join(FLAGS), cs.__version__, sys.platform,
                             platform.machine()])
            self._digests[identity] = hashlib.sha256(key.encode()).hexdigest()[:20]
        digest = self._digests[identity]
        suffix = ".dll" if os.name == "nt" else ".so"
        return cache_dir() / f"{self.function.name()}-{digest}{suffix}"

    def get(self, build: bool = True) -> Any:
        """The native function if there is (or, with ``build``, can be) one, else the virtual machine's.

        A folder or library that fails the checks of the module docstring is not used (one
        warning): the library is built in, or looked for in, :func:`private_dir` instead.

        Parameters
        ----------
        build : bool
            Build the library when none is on disk (mode ``auto``; ``required`` always builds).

        Returns
        -------
        casadi.Function
            :attr:`loaded`, or :attr:`function`.

        Raises
        ------
        NativeBuildError
            Mode ``required`` and no library could be built or loaded.
        SpecError
            A bad ``ILCDOB_NATIVE``, ``ILCDOB_CC`` or ``ILCDOB_CACHE_DIR``.
        """
        mode = native_mode()
        if mode == "off":
            return self.function
        if self.loaded is not None:
            return self.loaded
        command = compiler_command()
        path = self.library(command)
        if path is None:
            if mode == "required":
                raise NativeBuildError(f"ILCDOB_NATIVE=required, but the C compiler {shlex.join(command)!r} "
                                       f"(ILCDOB_CC, else CC, else cc) does not run; install one, set ILCDOB_CC, "
                                       f"or unset ILCDOB_NATIVE to run in CasADi's virtual machine")
            return self.function
        builds = mode == "required" or (build and tuple(command) not in _FAILED)
        path = library_folder(create=builds) / path.name
        reason = untrusted_library(path)
        if reason is not None:
            _refuse(path, reason, "the library")
            path = private_dir() / path.name
        missing = not os.path.lexists(path)
        if missing and not builds:
            return self.function
        try:
            if missing:
                self._build(command, path)
            self.loaded = self._load(path)
        except NativeBuildError as err:
            if mode == "required":
                raise
            _FAILED.add(tuple(command))
            warnings.warn(f"{err}; running in CasADi's virtual machine instead (the same results, slower). "
                          f"Set ILCDOB_CC to a working C compiler, or ILCDOB_NATIVE=off to stop trying.",
                          RuntimeWarning, stacklevel=2)
            return self.function
        return self.loaded

    def _load(self, path: Path) -> Any:
        """The library at ``path`` as a CasADi function."""
        import casadi as cs

        try:
            return cs.external(self.function.name(), str(path))
        except RuntimeError as err:
            first = str(err).strip().splitlines()
            raise NativeBuildError(f"loading {path} failed ({first[-1] if first else err}); delete the file "
                                   "to build it again") from err

    def _build(self, command: list[str], path: Path) -> None:
        """Write the C source and compile it into ``path`` (atomically, mode 0644 less the umask)."""
        name = self.function.name()
        try:
            with (tempfile.TemporaryDirectory(prefix="ilcdob-native-") as work,
                  atomic_path(path, mode=0o644 & ~current_umask()) as tmp):
                source = Path(work) / f"{name}.c"
                source.write_text(self.source, encoding="utf-8")
                done = subprocess.run([*command, *FLAGS, str(source), "-o", str(tmp)], capture_output=True,
                                      text=True, timeout=BUILD_TIMEOUT_S)
                if done.returncode != 0:
                    detail = (done.stderr or done.stdout).strip().splitlines()
                    raise NativeBuildError(f"compiling {name} with {shlex.join(command)!r} failed with status "
                                           f"{done.returncode}: {detail[0] if detail else 'no message'}")
        except subprocess.TimeoutExpired as err:
            raise NativeBuildError(f"compiling {name} with {shlex.join(command)!r} took more than "
                                   f"{BUILD_TIMEOUT_S:g} s") from err
        except OSError as err:
            raise NativeBuildError(f"compiling {name} into {path.parent} failed: {err}") from err
