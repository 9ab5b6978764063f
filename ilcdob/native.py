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
    ``~/.cache/ilcdob/native`` (with no home folder, one in the temporary folder). A library's
    name carries a hash of its C source, the compiler's version line, the flags, the CasADi
    version and the platform, so a change of any of them builds a new one and a stale one is
    never loaded. Deleting the folder is always safe.

A library is written atomically (:func:`~ilcdob.atomic.atomic_path`), so processes building the
same one at once (a campaign's workers) each replace it with a complete file.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import warnings
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Any

from .atomic import atomic_path
from .errors import NativeBuildError, SpecError

__all__ = ["MODES", "FLAGS", "native_mode", "compiler_command", "cache_dir", "NativeFunction"]

#: Values of ``ILCDOB_NATIVE``.
MODES = ("auto", "off", "required")

#: Compiler flags of every library: optimised, position independent, a shared library, and no fused
#: multiply-add (the results must be the virtual machine's bit for bit; module docstring).
FLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off")

#: Seconds a build may take before it is abandoned (measured: 0.1 to 3.4 s per function, 11 to 109 states).
BUILD_TIMEOUT_S = 120.0

#: Compilers whose build failed in this process (``auto`` does not retry them).
_FAILED: set[tuple[str, ...]] = set()


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
    """The compiler command: ``ILCDOB_CC``, else ``CC``, else ``cc``, split into words."""
    for name in ("ILCDOB_CC", "CC"):
        words = shlex.split(os.environ.get(name, ""))
        if words:
            return words
    return ["cc"]


def cache_dir() -> Path:
    """The folder of the built libraries (``ILCDOB_CACHE_DIR``, module docstring)."""
    if os.environ.get("ILCDOB_CACHE_DIR"):
        return Path(os.environ["ILCDOB_CACHE_DIR"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME")
    if not base:
        try:
            base = Path.home() / ".cache"
        except RuntimeError:  # no home folder known (no HOME, no password entry): the temporary folder
            base = Path(tempfile.gettempdir()) / f"ilcdob-cache-{os.getuid() if hasattr(os, 'getuid') else 0}"
    return Path(base) / "ilcdob" / "native"


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
            In :func:`cache_dir`, named by the function and a hash of what the build depends on
            (module docstring); None when the compiler does not run.
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
        missing = not path.exists()
        if missing and mode == "auto" and (not build or tuple(command) in _FAILED):
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
        """Write the C source and compile it into ``path`` (atomically)."""
        name = self.function.name()
        try:
            with tempfile.TemporaryDirectory(prefix="ilcdob-native-") as work, atomic_path(path) as tmp:
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
