"""A learning signal whose trial ends rise above its interior is announced (design --trial, learn).

The source is the 2 ms vehicle with a mode at 12 rad/s damped 0.05 of ``tests/test_band_exact.py``, its hover trial
in the paper's disturbance flown without noise; the Theorem's filters unfiltered (``--bandwidth off``) end the
learning signal at 2.05 times its interior peak, the default band does not.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.design.filters.trial_edges import END_PEAK_FACTOR, end_peaks
from ilcdob.validation.simulate import simulate_flight
from test_band_exact import TWO_MS, _fleet


def _fleet_toml(path):
    rows = ["sample_time = 0.002"]
    for s in TWO_MS:
        rows.append("[[system]]\n" + "\n".join(f"{k} = {_toml(v)}" for k, v in {**s, "uncertainty": {"bound": 0.3}}
                                                .items()))
    path.write_text("\n\n".join(rows) + "\n")
    return path


def _toml(v):
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    return json.dumps(v)


@pytest.fixture
def trial(tmp_path):
    flt = _fleet(0.002, 0.3, TWO_MS)
    n = 15000
    t = np.arange(n) * 0.002
    d = 0.3 + 0.5 * np.sin(0.94 * t) + 0.2 * np.sin(1.41 * t + 0.5)
    e = simulate_flight(flt.loop("damped"), np.zeros(n), d).e
    path = tmp_path / "trial.csv"
    np.savetxt(path, np.c_[t, e, np.zeros(n)], delimiter=",", header="time,error,learning", comments="")
    return path


def test_an_end_above_twice_the_interior_is_named_with_its_cause(tmp_path, trial, capsys):
    """``--bandwidth off``: the warning names the end, its peak, the ratio and the band as the cause; ``learn``'s
    ``learning.json`` and ``design``'s ``filters.json`` record the ends, the last one flagged, and the figures are
    the signal's own (recomputed here from learning_signal.csv)."""
    fleet = _fleet_toml(tmp_path / "fleet.toml")
    design, learned = tmp_path / "design", tmp_path / "learned"
    # exit 1 with the folder written: without a band the law is not "never worse" on whole trials (the sinusoid near
    # Nyquist under an all-pass error reaches 5.2), which `design` says
    assert main(["design", "--fleet", str(fleet), "--from", "damped", "--to", "fast", "--bandwidth", "off",
                 "--trial", str(trial), "--out", str(design), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "learning signal: its end" in err and "not guaranteed: whole trials of 60 s" in err, err
    assert main(["learn", str(trial), "--design", str(design), "--error", "error", "--learning", "learning",
                 "--out", str(learned), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "learning signal: its end (0.25 s)" in err and "without a learning band" in err, err
    ends = json.loads((learned / "learning.json").read_text())["learning_signal"]["ends"]
    assert ends["flagged"] == ["end"] and ends["end_peak"] > END_PEAK_FACTOR * ends["interior_peak"]
    u = np.loadtxt(learned / "learning_signal.csv", delimiter=",", skiprows=2)[:, 1]
    m = 125  # 0.25 s at 2 ms; the CSV keeps 10 significant digits
    assert ends["end_peak"] == pytest.approx(np.max(np.abs(u[-m:])), rel=1e-9)
    assert ends["interior_peak"] == pytest.approx(np.max(np.abs(u[m:-m])), rel=1e-9)
    recorded = json.loads((design / "filters.json").read_text())["trial"]["learning_signal"]["ends"]
    assert recorded["flagged"] == ["end"]


def test_the_default_band_leaves_no_end_to_announce(tmp_path, trial, capsys):
    """The same trial with the band ``design`` chooses: no end flagged, no warning."""
    fleet = _fleet_toml(tmp_path / "fleet.toml")
    design, learned = tmp_path / "design", tmp_path / "learned"
    assert main(["design", "--fleet", str(fleet), "--from", "damped", "--to", "fast", "--trial", str(trial),
                 "--out", str(design), "--quiet"]) == 0
    assert main(["learn", str(trial), "--design", str(design), "--error", "error", "--learning", "learning",
                 "--out", str(learned), "--quiet"]) == 0
    assert "learning signal: its" not in capsys.readouterr().err
    assert json.loads((learned / "learning.json").read_text())["learning_signal"]["ends"]["flagged"] == []
    u = np.loadtxt(learned / "learning_signal.csv", delimiter=",", skiprows=2)[:, 1]
    assert end_peaks(u, 0.002).flagged == []
