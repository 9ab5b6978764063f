"""The scripts in examples/ run as a user runs them (a fresh process, in an empty folder) and do
what their docstrings say."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _run(script: str, cwd: Path, *args: str) -> str:
    run = subprocess.run([sys.executable, str(EXAMPLES / script), *args], cwd=cwd, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    return run.stdout


def test_every_example_is_tested():
    assert sorted(p.name for p in EXAMPLES.glob("*.py")) == ["design_for_your_fleet.py", "identify_a_channel.py",
                                                             "identify_a_log.py", "run_a_campaign.py"]


@pytest.mark.slow  # > 15 s on 2 cores: the default suite stays under 10 minutes
def test_identify_a_channel(tmp_path):
    """Short flights of one vehicle of one's own making: every channel and axis fits, static gains near the
    loop's (4 % at 12 s; the 30 s table of docs/closed_loop.md is within 1.6 %)."""
    pytest.importorskip("rotorpy")
    out = _run("identify_a_channel.py", tmp_path, "12", "lab-quad")
    rows = [line.split() for line in out.splitlines()[1:]]
    assert len(rows) == 6 and {r[1] for r in rows} == {"position", "acceleration"}
    for r in rows:
        assert float(r[5]) >= 90.0, r
        assert abs(float(r[6]) / float(r[8]) - 1) <= 0.04, r


def test_identify_a_log(tmp_path):
    out = _run("identify_a_log.py", tmp_path)
    model = json.loads((tmp_path / "identified_log" / "model.json").read_text())
    assert model["fit_percent"]["estimation"] > 95.0  # the real PX4 log: vz -> z is an integrator plus lag
    assert sorted(p.name for p in (tmp_path / "identified_log" / "figures").glob("*.png")) == [
        "bode.png", "compare.png", "residuals.png"]
    assert "logger dropout" in out


def test_design_for_your_fleet(tmp_path):
    out = _run("design_for_your_fleet.py", tmp_path)
    assert "heavy -> light" in out  # the Theorem table
    folder = tmp_path / "my_design"
    assert {"filters.json", "filters.h", "filters.c", "README.md", "manifest.json"} <= {p.name for p in folder.iterdir()}
    assert json.loads((folder / "filters.json").read_text())["from"] == "heavy"


@pytest.mark.slow  # > 15 s on 2 cores: the default suite stays under 10 minutes
@pytest.mark.parametrize("samples", [2])
def test_run_a_campaign_and_resume(tmp_path, samples):
    _run("run_a_campaign.py", tmp_path, str(samples))
    out = _run("run_a_campaign.py", tmp_path, str(samples + 1))  # resumes: one more sample flown
    lines = (tmp_path / "my_campaign" / "samples.jsonl").read_text().splitlines()
    assert len(lines) == samples + 1
    assert "closed-form" in out and "100.0%" in out
