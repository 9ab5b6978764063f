"""`ilcdob identify` on CSV files written with FlightData.to_csv."""

from __future__ import annotations

import json

import numpy as np

from ilcdob.cli import main
from ilcdob.identification.data import FlightData
from ilcdob.identification.model import ModelStructure, simulate_zoh

TS = 0.02
STRUCTURE = ModelStructure(3, 0, 2)
TRUE = STRUCTURE.join([7.0], [1.0, 7.0, 0.0, 0.0])  # 1/(s^2 (s/7 + 1)), 0.04 s delay


def _flight(path, seed, f1):
    rng = np.random.default_rng(seed)
    t = np.arange(2500) * TS
    phase = 2 * np.pi * (0.2 * t + (f1 - 0.2) * t**2 / (2 * t[-1]))
    u = 0.8 * np.cos(phase)
    y = simulate_zoh(STRUCTURE, TRUE, u, TS, delay=0.04)
    y = y + 0.002 * rng.standard_normal(t.size)
    FlightData(t, {"acc_cmd": u, "x": y}, {"acc_cmd": "m/s^2", "x": "m"}, source=str(path)).to_csv(path)


def test_identify_csv_writes_model_json_and_figures(tmp_path, capsys):
    est, val = tmp_path / "chirp.csv", tmp_path / "val.csv"
    _flight(est, 0, 4.0)
    _flight(val, 1, 3.0)
    out = tmp_path / "model.json"
    rc = main(["identify", str(est), "--input", "acc_cmd", "--output", "x", "--poles", "3",
               "--integrators", "2", "--delay", "auto", "--validate", str(val), "--out", str(out),
               "--plot", str(tmp_path / "plots")])
    assert rc == 0
    model = json.loads(out.read_text())
    # truth: num [7], den [1, 7, 0, 0], delay 0.04 s; 2 mm noise on 1-m-scale output
    np.testing.assert_allclose(model["num"], [7.0], rtol=0.02)
    np.testing.assert_allclose(model["den"], [1.0, 7.0, 0.0, 0.0], rtol=0.02, atol=1e-12)
    assert abs(model["delay"] - 0.04) < 0.004
    assert model["fit_percent"]["validation"] > 95.0
    assert np.asarray(model["covariance"]).shape == (3, 3)  # a0, b0 and the delay
    for name in ("compare.png", "residuals.png", "bode.png"):
        assert (tmp_path / "plots" / name).stat().st_size > 1000
    assert "fit:" in capsys.readouterr().out


def test_identify_reports_a_missing_column(tmp_path, capsys):
    est = tmp_path / "chirp.csv"
    _flight(est, 0, 4.0)
    rc = main(["identify", str(est), "--input", "thrust", "--output", "x", "--poles", "3",
               "--out", str(tmp_path / "m.json")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "thrust" in err and "chirp.csv" in err
    assert not (tmp_path / "m.json").exists()
