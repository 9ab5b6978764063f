"""Native builds of the compiled recursions (ilcdob/native.py, design/norm_optimal.py).

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
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

from ilcdob import native
from ilcdob.design import norm_optimal as no
from ilcdob.design.norm_optimal import NormOptimalDesigner, NormOptimalOptions
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
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert native.cache_dir() == tmp_path / "home" / ".cache" / "ilcdob" / "native"

    def no_home():
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.setattr(Path, "home", staticmethod(no_home))
    assert native.cache_dir().parts[-2:] == ("ilcdob", "native")
    assert native.cache_dir().is_relative_to(Path(tempfile.gettempdir()))
