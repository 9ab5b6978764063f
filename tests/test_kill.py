"""A SIGKILL at any point of reproduce, design and identify leaves the previous complete output or
the new complete output: never a mix, never a partial folder, no temporary file in it."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ilcdob.app.html import check_folder
from ilcdob.app.output import MANIFEST, read_manifest
from ilcdob.identification.oe import simulate_zoh
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure

KILL_AT = (0.3, 1.2, 2.5, 4.0)  # s after the start: imports, computation, writing


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "ilcdob", "--quiet", *args]


def _killed(cmd: list[str], delay: float) -> None:
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(delay)
    proc.send_signal(signal.SIGKILL)
    proc.wait()


def _complete_run(out: Path) -> str:
    """The run id whose complete output ``out`` holds; fails on a mix, a partial folder or stray files."""
    manifest = read_manifest(out)
    assert manifest is not None, sorted(p.name for p in out.iterdir())
    check_folder(out)  # every file is the one its run wrote
    extra = {p.name for p in out.iterdir()} - set(manifest["files"]) - {MANIFEST}
    assert not extra, extra
    return manifest["run_id"]


def _folder_command_survives_kills(tmp_path: Path, args: list[str]) -> None:
    out = tmp_path / "out"
    subprocess.run(_cli(*args, "--out", str(out)), check=True, capture_output=True)
    runs = {_complete_run(out)}
    for delay in KILL_AT:
        _killed(_cli(*args, "--out", str(out)), delay)
        runs.add(_complete_run(out))
    assert [p.name for p in tmp_path.iterdir()] == ["out"] or all(
        p.name.startswith(".out.ilcdob-staging-") for p in tmp_path.iterdir() if p.name != "out")
    # the next run cleans what the killed runs left beside the folder
    subprocess.run(_cli(*args, "--out", str(out)), check=True, capture_output=True)
    _complete_run(out)
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


@pytest.mark.slow  # 20 s; the design kill test covers the staging path by default, the fault probe every command
def test_reproduce_survives_sigkill(tmp_path):
    _folder_command_survives_kills(tmp_path, ["reproduce", "--scenarios", "1,4", "--iterations", "1"])


@pytest.mark.slow  # > 15 s on 2 cores: the default suite stays under 10 minutes
def test_design_survives_sigkill(tmp_path):
    _folder_command_survives_kills(tmp_path, ["design", "--from", "UAV1", "--to", "UAV2", "--method", "fir",
                                              "--samples", "2"])


@pytest.fixture()
def flight_csv(tmp_path) -> Path:
    rng = np.random.default_rng(0)
    ts, n = 0.02, 6000
    u = np.repeat(rng.standard_normal(n // 50), 50)
    y = simulate_zoh(ModelStructure(2), np.array([3.0, 2.0, 2.0]), u, ts) + 0.01 * rng.standard_normal(n)
    path = tmp_path / "flight.csv"
    FlightData(np.arange(n) * ts, {"u": u, "y": y}, {"u": "m/s^2", "y": "m"}, source="test").to_csv(path)
    return path


@pytest.mark.slow  # 12 s (-m slow); the design kill test covers the staging path by default
def test_identify_survives_sigkill(tmp_path, flight_csv):
    model, plots = tmp_path / "model.json", tmp_path / "plots"
    args = ["identify", str(flight_csv), "--input", "u", "--output", "y", "--poles", "2", "--delay", "auto",
            "--out", str(model), "--plot", str(plots)]
    subprocess.run(_cli(*args), check=True, capture_output=True)
    for delay in KILL_AT:
        _killed(_cli(*args), delay)
        data = json.loads(model.read_text())  # always a complete model file
        assert data["provenance"]["command"] == "identify"
        _complete_run(plots)
    subprocess.run(_cli(*args), check=True, capture_output=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.csv", "model.json", "plots"]
