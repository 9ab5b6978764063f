"""A light start: ``import ilcdob`` and the command line's parser load none of the numerical stack.

Time is not asserted (benchmarks/bench_startup.py measures it: ``--help`` and ``--version`` take
about 0.07 s of CPU, ``import ilcdob`` 0.04 s, against 1.3 s for every command's imports); what
makes it fast is: the public names of ``ilcdob`` are imported on first use, and the commands'
modules only once a command runs.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = ("numpy", "scipy", "control", "matplotlib", "casadi", "cvxpy")


def _loaded_after(code: str) -> list[str]:
    probe = f"{code}\nimport sys\nprint('loaded:' + ','.join(m for m in {HEAVY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True)
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("loaded:")][-1]
    return [m for m in line[len("loaded:"):].split(",") if m]


@pytest.mark.parametrize("code", [
    "import ilcdob",
    "from ilcdob.app.cli import build_parser; build_parser().format_help()",
    "from ilcdob.app.cli import main\ntry:\n    main(['--version'])\nexcept SystemExit:\n    pass",
])
def test_start_loads_no_numerical_library(code):
    assert _loaded_after(code) == []


def test_public_names_load_on_first_use():
    import ilcdob

    assert ilcdob.tfest.__module__ == "ilcdob.identification.tfest"
    assert ilcdob.design_pair.__module__ == "ilcdob.design.pair"
    assert set(ilcdob.__all__) <= set(dir(ilcdob))
    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        ilcdob.nothing_here  # noqa: B018 - the attribute access is the test


def test_identify_without_figures_loads_neither_python_control_nor_matplotlib(tmp_path):
    """A fit of a CSV log (no ``--plot``) draws nothing and builds no LTI object: python-control (0.6-1.1 s of
    CPU to import, matplotlib.pyplot with it) and matplotlib stay unloaded; a fleet, a figure or a
    ``to_control()`` loads them when asked."""
    import numpy as np

    t = np.arange(600) * 0.01
    u = np.sign(np.sin(2 * np.pi * 0.4 * t))
    y = np.convolve(u, 0.02 * np.exp(-0.02 * np.arange(600)))[:600]  # a first-order lag, pole 2 rad/s
    np.savetxt(tmp_path / "log.csv", np.column_stack([t, u, y]), delimiter=",", header="time,u,y", comments="")
    run = (f"from ilcdob.app.cli import main\nassert main(['--quiet', 'identify', {str(tmp_path / 'log.csv')!r}, "
           f"'--input', 'u', '--output', 'y', '--poles', '1', '--out', {str(tmp_path / 'model.json')!r}]) == 0")
    loaded = _loaded_after(run)
    assert "numpy" in loaded and "scipy" in loaded, loaded  # the probe ran the fit
    assert "control" not in loaded and "matplotlib" not in loaded, loaded
