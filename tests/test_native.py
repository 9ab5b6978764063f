"""Native builds of the compiled recursions (ilcdob/native.py, design/methods/norm_optimal.py).

The native library must give CasADi's virtual machine's numbers bit for bit (the same IEEE
operations in the same order, no fused multiply-add): checked on the built-in fleet and on
systems unlike it, a relative-degree-2 plant (its sampling zero near -1) with a DOB of order 8 at
1 ms and a plant with a fractional input delay at 50 ms, over trial lengths that use every block
size. The accuracy of the recursion itself (against 80-bit arithmetic) is tests/test_norm_optimal.py's.
Then what a user meets: where the libraries go, when they are built, reuse, and a compiler that is
missing or fails.
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

from ilcdob import native
from ilcdob.design.methods import norm_optimal as no
from ilcdob.design.methods.norm_optimal import NormOptimalDesigner, NormOptimalOptions
from ilcdob.errors import NativeBuildError, SpecError
from ilcdob.fleet import fleet_from_dict

sys.path.insert(0, str(Path(__file__).parent))
from test_conditioning import _system  # noqa: E402  (the stress systems, described there)


@pytest.fixture
def library_folder(tmp_path, monkeypatch):
    """An empty library folder, fresh in-process caches and no remembered failures."""
    folder = tmp_path / "native"
    monkeypatch.setenv("ILCDOB_CACHE_DIR", str(folder))
    monkeypatch.setattr(native, "_FAILED", set())
    for cached in (no._base, no._native, no._block):
        cached.cache_clear()
    yield folder
    for cached in (no._native, no._block):  # their libraries lie in a folder about to be removed
        cached.cache_clear()


def _fake_compiler(folder: Path, version: str, status: int, message: str = "") -> str:
    """A compiler command that prints ``version`` for ``--version`` and otherwise exits with ``status``."""
    path = folder / f"fakecc-{status}"
    path.write_text(f'#!/bin/sh\nif [ "$1" = --version ]; then echo "{version}"; exit 0; fi\n'
                    f'echo "{message}" >&2\nexit {status}\n')
    path.chmod(0o755)
    return str(path)


def _design(target, source, n, mode, monkeypatch):
    """Gains, one solve and (with a ``source``) the compact law of ``target`` learning from it, in ``mode``."""
    monkeypatch.setenv("ILCDOB_NATIVE", mode)
    t = np.arange(n) * 0.01
    e0, df = 0.01 * np.sin(0.9 * t) + 1e-3 * np.cos(7.0 * t), 0.1 * np.sin(1.3 * t)
    des = NormOptimalDesigner(target, n, NormOptimalOptions(1e-6, 1e-5))
    out = [des.gains, des.pivots, des.solve(e0)]
    return out + [des.law(source, 1e-8).apply(e0, df)] if source is not None else out


def _stress_fleet(ts):
    return fleet_from_dict({"sample_time": ts, "system": [_system("a", 8), _system("b", 8)]})


#: The stress cases: sample time, system (0: ``a8``, relative degree 2; 1: ``b8``, a fractional delay).
STRESS = {"1 ms, order 8, relative degree 2": (0.001, 0), "50 ms, order 8, fractional delay": (0.05, 1)}


@pytest.mark.parametrize("case", ["built-in", *STRESS])
def test_native_recursions_equal_the_virtual_machine_bit_for_bit(case, fleet, library_folder, monkeypatch, cc):
    # the built-in pair: the design and the law (the inverse's recursions, simulation); the stress systems
    # (a8: 22 states, b8: 23 at 50 ms): the design's recursions (each build takes 1.3 to 2 s of compiler)
    if case == "built-in":
        source, target = fleet.loops[0], fleet.loops[1]
    else:
        ts, system = STRESS[case]
        source, target = None, _stress_fleet(ts).loops[system]
    n = 2999  # 750 calls of 4 samples (512 + 3 x 64 + 5 x 8 + 6 x 1), 188 of 16: every block size
    vm = _design(target, source, n, "off", monkeypatch)
    compiled = _design(target, source, n, "required", monkeypatch)
    for name, a, b in zip(("gains", "pivots", "solve", "law"), vm, compiled):
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert np.max(np.abs(vm[-1])) > 0
    # the native libraries were used: one per recursion and system built into the folder
    built = sorted(p.name.split("-")[0] for p in library_folder.iterdir())
    assert {"norm_optimal_gains", "norm_optimal_backward", "norm_optimal_forward"} <= {
        name.rsplit("_", 1)[0] for name in built}
    assert all(p.suffix == ".so" for p in library_folder.iterdir())


def test_libraries_are_built_for_long_trials_and_reused(fleet, library_folder, monkeypatch, cc):
    target = fleet.loops[1]
    monkeypatch.setattr(no, "_NATIVE_MIN_SAMPLES", 500)
    NormOptimalDesigner(target, 499).solve(np.ones(499))  # shorter: the virtual machine, nothing built
    assert not library_folder.exists() or not any(library_folder.iterdir())
    NormOptimalDesigner(target, 500).solve(np.ones(500))  # long enough: the gains and both passes built
    libraries = sorted(library_folder.iterdir())
    assert len(libraries) == 3
    pattern = no._pattern(no._state_space(target.nominal.G_f))
    kinds = ("gains", "backward", "forward")
    assert all(no._native(kind, pattern, no._UNROLL[kind]).loaded is not None for kind in kinds)
    # a new process (fresh caches) loads them, even for a short trial, and builds nothing
    for cached in (no._native, no._block):
        cached.cache_clear()

    def no_build(self, command, path):
        raise AssertionError(f"{path.name} built again")

    monkeypatch.setattr(native.NativeFunction, "_build", no_build)
    NormOptimalDesigner(target, 100).solve(np.ones(100))
    assert sorted(library_folder.iterdir()) == libraries
    assert all(no._native(kind, pattern, no._UNROLL[kind]).loaded is not None for kind in kinds)


def test_library_names_change_with_the_compiler(fleet, library_folder, tmp_path):
    f = native.NativeFunction(no._base("simulate", no._pattern(no._state_space(fleet.loops[0].nominal.G_f)), 16))
    one = f.library([_fake_compiler(tmp_path, "cc 1.0", 0)])
    (tmp_path / "v2").mkdir()
    two = f.library([_fake_compiler(tmp_path / "v2", "cc 2.0", 0)])
    assert one.parent == two.parent == library_folder
    assert one.name.startswith("norm_optimal_simulate_11-") and one != two


def test_missing_compiler(fleet, library_folder, monkeypatch):
    target, n = fleet.loops[1], 300
    expected = _design(target, fleet.loops[0], n, "off", monkeypatch)
    monkeypatch.setenv("ILCDOB_CC", "/nonexistent/cc")
    monkeypatch.setattr(no, "_NATIVE_MIN_SAMPLES", 1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # auto: the virtual machine, as documented, without a warning
        got = _design(target, fleet.loops[0], n, "auto", monkeypatch)
    for a, b in zip(expected, got):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(NativeBuildError, match=r"ILCDOB_NATIVE=required.*'/nonexistent/cc'.*ILCDOB_CC"):
        _design(target, fleet.loops[0], n, "required", monkeypatch)


@pytest.mark.skipif(os.name == "nt", reason="the fake compiler is a shell script")
def test_failing_compiler(fleet, library_folder, monkeypatch, tmp_path):
    target, n = fleet.loops[1], 300
    expected = NormOptimalDesigner(target, n).solve(np.ones(n))
    monkeypatch.setenv("ILCDOB_CC", _fake_compiler(tmp_path, "fakecc 9", 1, "error: no room"))
    monkeypatch.setattr(no, "_NATIVE_MIN_SAMPLES", 1)
    with pytest.warns(RuntimeWarning, match=r"compiling norm_optimal_gains_11 with '.*fakecc-1' failed with "
                                            r"status 1: error: no room; running in CasADi's virtual machine") as seen:
        got = NormOptimalDesigner(target, n).solve(np.ones(n))
    assert len(seen) == 1  # once per process and compiler, not once per recursion
    np.testing.assert_array_equal(got, expected)
    assert not library_folder.exists() or not any(library_folder.iterdir())  # nothing half-written
    monkeypatch.setenv("ILCDOB_NATIVE", "required")
    with pytest.raises(NativeBuildError, match="failed with status 1: error: no room"):
        NormOptimalDesigner(target, n)


def test_bad_mode(fleet, monkeypatch):
    monkeypatch.setenv("ILCDOB_NATIVE", "fast")
    with pytest.raises(SpecError, match=r"ILCDOB_NATIVE = 'fast' is not a mode; valid: auto, off, required"):
        NormOptimalDesigner(fleet.loops[1], 100)


def test_unloadable_library(fleet, library_folder, monkeypatch, cc):
    f = native.NativeFunction(no._base("simulate", no._pattern(no._state_space(fleet.loops[0].nominal.G_f)), 16))
    path = f.library(native.compiler_command())
    path.parent.mkdir(parents=True)
    path.write_bytes(b"not a library")  # e.g. a disk that filled up under another tool's copy
    with pytest.warns(RuntimeWarning, match=r"loading .* failed .*delete the file to build it again; running in "
                                            r"CasADi's virtual machine"):
        assert f.get() is f.function
    monkeypatch.setenv("ILCDOB_NATIVE", "required")
    with pytest.raises(NativeBuildError, match="delete the file"):
        native.NativeFunction(f.function).get()


def test_library_folder_defaults(monkeypatch, tmp_path):
    monkeypatch.delenv("ILCDOB_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert native.cache_dir() == tmp_path / "xdg" / "ilcdob" / "native"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/cache")  # ignored, as the XDG specification says
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert native.cache_dir() == tmp_path / "home" / ".cache" / "ilcdob" / "native"

    def no_home():
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.setattr(Path, "home", staticmethod(no_home))
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path / "run"))
    assert native.cache_dir() == tmp_path / "run" / "ilcdob" / "native"
    # no home, no runtime folder: never a predictable path in the shared temporary folder, but a
    # private folder of this process (mkdtemp: mode 0700, a random name)
    monkeypatch.delenv("XDG_RUNTIME_DIR")
    monkeypatch.setattr(native, "_PRIVATE", {})
    folder = native.cache_dir()
    assert folder == native.private_dir() == native.cache_dir()
    assert folder.is_relative_to(Path(tempfile.gettempdir())) and folder.name.startswith("ilcdob-native-")
    if os.name != "nt":
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    native._remove_private(os.getpid())
    assert not folder.exists()


def test_bad_environment_variables_name_themselves(fleet, monkeypatch):
    monkeypatch.setenv("ILCDOB_CC", "gcc 'unterminated")
    with pytest.raises(SpecError, match=r"ILCDOB_CC = \"gcc 'unterminated\": cannot be split .*No closing quotation"):
        native.compiler_command()
    monkeypatch.delenv("ILCDOB_CC")
    monkeypatch.setenv("ILCDOB_CACHE_DIR", "~nosuchuser-ilcdob/x")
    with pytest.raises(SpecError, match=r"ILCDOB_CACHE_DIR = '~nosuchuser-ilcdob/x': .*absolute path"):
        native.cache_dir()


# --- what another local user may have planted: nothing of it is loaded, nothing hangs -------------------------

POSIX = pytest.mark.skipif(not hasattr(os, "geteuid"), reason="owner and mode checks are POSIX ones")

#: A shared library whose constructor runs when it is loaded: it writes the marker file named at build time.
PLANTED_C = """
#include <stdio.h>
__attribute__((constructor)) static void planted(void) {
    FILE *f = fopen(MARKER, "w");
    if (f) { fputs("planted code ran", f); fclose(f); }
}
"""

OTHER_UID = 54321  # a user id that is not this process's (files are given to it with chown, as root only)


def _plant(cc: str, path: Path, marker: Path) -> None:
    """Compile the planted library to ``path``; loading it writes ``marker``."""
    source = path.parent / "planted.c" if path.parent.is_dir() else Path(tempfile.mkdtemp()) / "planted.c"
    source.write_text(PLANTED_C)
    subprocess.run([cc, "-shared", "-fPIC", f'-DMARKER="{marker}"', str(source), "-o", str(path)], check=True)
    source.unlink()


def _function(fleet):
    return no._base("simulate", no._pattern(no._state_space(fleet.loops[0].nominal.G_f)), 16)


def _fresh(monkeypatch):
    monkeypatch.setattr(native, "_WARNED", set())
    monkeypatch.setattr(native, "_PRIVATE", {})
    monkeypatch.setattr(native, "_FAILED", set())


def _get_refused(f, build, reason):
    """``f.get(build)`` with exactly one warning matching ``reason``; a second call warns no more."""
    with pytest.warns(RuntimeWarning, match=reason) as seen:
        got = f.get(build=build)
    assert len(seen) == 1, [str(w.message) for w in seen]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        native.NativeFunction(f.function).get(build=build)  # the same path again: said once per process
    return got


def _private_libraries():
    return [p for folder in native._PRIVATE.values() for p in folder.iterdir()]


def _root_only():
    if os.geteuid() != 0:
        pytest.skip("giving a file to another user needs root (chown)")


def _planted_case(name, tmp_path, fleet, cc, monkeypatch):
    """A cache folder and a planted library at the name ilcdob expects, prepared for ``name``."""
    _fresh(monkeypatch)
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o700)
    cache.chmod(0o700)
    monkeypatch.setenv("ILCDOB_CACHE_DIR", str(cache))
    f = native.NativeFunction(_function(fleet))
    path = f.library(native.compiler_command())
    marker = tmp_path / "marker"
    if name == "fifo":
        os.mkfifo(path)
    else:
        _plant(cc, path, marker)
    if name == "0666 library":
        path.chmod(0o666)
    elif name == "another user's library":
        _root_only()
        os.chown(path, OTHER_UID, OTHER_UID)
    elif name == "world-writable folder":
        cache.chmod(0o777)
    elif name == "another user's folder":
        _root_only()
        os.chown(cache, OTHER_UID, OTHER_UID)
    elif name == "symlink to another user's folder":
        _root_only()
        os.chown(cache, OTHER_UID, OTHER_UID)
        (tmp_path / "link").symlink_to(cache)
        monkeypatch.setenv("ILCDOB_CACHE_DIR", str(tmp_path / "link"))
    elif name == "folder above writable by all":
        inner = cache / "inner"
        inner.mkdir(mode=0o700)
        os.replace(path, inner / path.name)
        path = inner / path.name
        cache.chmod(0o777)  # others may rename `inner` away and put their own in its place
        monkeypatch.setenv("ILCDOB_CACHE_DIR", str(inner))
    return f, path, marker


PLANTED = {  # case -> what the warning must say
    "0666 library": r"the library .* is not used: it can be written by its group and every user \(mode 0666\)",
    "another user's library": rf"the library .* is not used: it belongs to user id {OTHER_UID}, not to this user",
    "fifo": r"the library .* is not used: it is a FIFO \(named pipe\), not a regular file",
    "world-writable folder": r"the library folder .* is not used: the folder .* can be written by its group and every "
                             r"user \(mode 0777\)",
    "another user's folder": rf"the library folder .* is not used: the folder .* belongs to user id {OTHER_UID}",
    "symlink to another user's folder": rf"the library folder .*link is not used: the folder .*cache belongs to user "
                                        rf"id {OTHER_UID}",
    "folder above writable by all": r"the library folder .*inner is not used: the folder .*cache above it can be "
                                    r"written by its group and every user without the sticky bit",
}


@POSIX
@pytest.mark.parametrize("name", list(PLANTED))
def test_a_planted_library_is_never_loaded(name, tmp_path, fleet, cc, monkeypatch):
    f, path, marker = _planted_case(name, tmp_path, fleet, cc, monkeypatch)
    monkeypatch.setenv("ILCDOB_NATIVE", "auto")
    # a short trial (no build): the virtual machine, the planted file untouched and not run
    assert _get_refused(f, False, PLANTED[name]) is f.function
    assert not marker.exists() and os.path.lexists(path)
    # a long one: built afresh in this process's private folder, and loaded from there
    monkeypatch.setattr(native, "_WARNED", set())
    got = _get_refused(native.NativeFunction(f.function), True, PLANTED[name])
    assert got is not f.function and not marker.exists()
    assert [p.name for p in _private_libraries()] == [path.name]
    x = np.linspace(-1.0, 1.0, f.function.sparsity_in(0).numel())
    np.testing.assert_array_equal(np.asarray(got(x, *[0.0] * (f.function.n_in() - 1))[0]),
                                  np.asarray(f.function(x, *[0.0] * (f.function.n_in() - 1))[0]))
    native._remove_private(os.getpid())


@POSIX
def test_a_planted_fifo_does_not_block_a_command(tmp_path, fleet, cc):
    # in a child process with a timeout, so that a regression fails instead of hanging the suite
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o700)
    env = {**os.environ, "ILCDOB_CACHE_DIR": str(cache), "ILCDOB_NATIVE": "required"}
    f = native.NativeFunction(_function(fleet))
    os.mkfifo(cache / f.library(native.compiler_command()).name)
    script = ("import warnings, ilcdob\n"
              "from ilcdob.design.methods import norm_optimal as no\n"
              "lp = ilcdob.default_fleet().loops[0]\n"
              "f = no._native('simulate', no._pattern(no._state_space(lp.nominal.G_f)), 16)\n"
              "with warnings.catch_warnings(record=True) as seen:\n"
              "    warnings.simplefilter('always')\n"
              "    got = f.get()\n"
              "print(got is not f.function, len(seen), seen[0].message if seen else '')\n")
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120,
                          cwd=Path(__file__).parents[1])
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("True 1 native code: the library ") and "FIFO" in done.stdout


@POSIX
def test_a_planted_predictable_temporary_folder_is_not_used(tmp_path, fleet, cc, monkeypatch):
    # no home folder: where an earlier version looked ($TMPDIR/ilcdob-cache-<uid>/ilcdob/native), another
    # user plants a folder open to all with a library in it; this version never looks there
    _fresh(monkeypatch)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)
    monkeypatch.delenv("ILCDOB_CACHE_DIR")
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    monkeypatch.setattr(Path, "home", staticmethod(lambda: (_ for _ in ()).throw(RuntimeError("no home"))))
    planted = tmp_path / f"ilcdob-cache-{os.getuid()}" / "ilcdob" / "native"
    planted.mkdir(parents=True)
    for p in (planted, planted.parent, planted.parent.parent):
        p.chmod(0o777)
    f = native.NativeFunction(_function(fleet))
    _plant(cc, planted / f.library([cc]).name, tmp_path / "marker")
    monkeypatch.setenv("ILCDOB_CC", cc)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = f.get(build=True)
    assert got is not f.function and not (tmp_path / "marker").exists()
    assert [p.parent for p in _private_libraries()] == [native.private_dir()]
    assert native.private_dir().parent == tmp_path and stat.S_IMODE(native.private_dir().stat().st_mode) == 0o700
    native._remove_private(os.getpid())


@POSIX
def test_built_libraries_and_folders_are_private(tmp_path, fleet, cc, monkeypatch):
    # even under a permissive umask: folders 0700, libraries 0644 (never writable by others, so loaded next time)
    _fresh(monkeypatch)
    monkeypatch.setenv("ILCDOB_CACHE_DIR", str(tmp_path / "a" / "b"))
    previous = os.umask(0)
    try:
        f = native.NativeFunction(_function(fleet))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert f.get() is not f.function
    finally:
        os.umask(previous)
    assert [stat.S_IMODE(p.stat().st_mode) for p in (tmp_path / "a", tmp_path / "a" / "b")] == [0o700, 0o700]
    (library,) = (tmp_path / "a" / "b").iterdir()
    assert stat.S_IMODE(library.stat().st_mode) == 0o644 and native.untrusted_library(library) is None
    assert native.untrusted_folder(tmp_path / "a" / "b") is None


@POSIX
def test_an_unprivileged_user_does_not_run_another_users_library(tmp_path, fleet, cc):
    # the attack as it happens: user A (OTHER_UID) owns the folder ILCDOB_CACHE_DIR names and has put a
    # library in it; user B (nobody) runs ilcdob. Only root can play both users here.
    if os.geteuid() != 0:
        pytest.skip("running as two users needs root")
    nobody = 65534
    shared = Path(tempfile.mkdtemp(prefix="ilcdob-test-"))
    try:
        shared.chmod(0o777 | stat.S_ISVTX)  # like /tmp: nobody makes its private folder here
        cache, marker_dir = shared / "cache", shared / "markers"
        cache.mkdir()
        marker_dir.mkdir()
        marker_dir.chmod(0o777)
        f = native.NativeFunction(_function(fleet))
        path = cache / f.library([cc]).name
        _plant(cc, path, marker_dir / "ran")
        for p in (cache, path):
            os.chown(p, OTHER_UID, OTHER_UID)
        # the child imports as root (the interpreter may lie in root's home), then drops to nobody for good
        # before it looks for the library
        script = ("import os, warnings, ilcdob\n"
                  "from ilcdob.design.methods import norm_optimal as no\n"
                  "lp = ilcdob.default_fleet().loops[0]\n"
                  "f = no._native('simulate', no._pattern(no._state_space(lp.nominal.G_f)), 16)\n"
                  "f.source\n"
                  f"os.setgroups([]); os.setgid({nobody}); os.setuid({nobody})\n"
                  "assert os.geteuid() == os.getuid() == " + str(nobody) + "\n"
                  "with warnings.catch_warnings(record=True) as seen:\n"
                  "    warnings.simplefilter('always')\n"
                  "    got = f.get(build=True)\n"
                  "print(got is not f.function, len(seen), seen[0].message if seen else '')\n")
        env = {**os.environ, "ILCDOB_CACHE_DIR": str(cache), "ILCDOB_CC": cc, "HOME": str(shared),
               "TMPDIR": str(shared)}
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                              timeout=120, cwd=Path(__file__).parents[1])
        assert done.returncode == 0, done.stderr
        # refused, built afresh in the private folder as nobody, and that build loaded
        assert done.stdout.startswith("True 1 native code: the library folder "), done.stdout
        assert f"belongs to user id {OTHER_UID}, not to this user ({nobody})" in done.stdout
        assert not (marker_dir / "ran").exists()
    finally:
        shutil.rmtree(shared, ignore_errors=True)
