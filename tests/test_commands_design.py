"""`ilcdob design`: filters.json, C code, lifted.npz and the learning signal of a trial."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.design import closed_form_filters
from ilcdob.design.export import apply_coefficients
from ilcdob.signals import FlightData
from ilcdob.identification.loaders import load_csv
from ilcdob.validation.simulate import rmse, simulate_flight


def _trial(fleet, path, n=1500):
    t = np.arange(n) * fleet.sample_time
    d = np.sin(0.9425 * t)
    fl = simulate_flight(fleet.loop("UAV1"), np.zeros(n), d, d_f=0.1 * np.sin(1.3 * t))
    FlightData(t, {"error": fl.e, "learning": fl.d_f}, {"error": "m", "learning": "m/s^2"}).to_csv(path)
    return d, fl


def test_closed_form_coefficients_reproduce_the_filters(fleet, tmp_path, capsys):
    trial = tmp_path / "trial.csv"
    d, fl = _trial(fleet, trial)
    out = tmp_path / "cf"
    assert main(["design", "--from", "UAV1", "--to", "UAV2", "--method", "closed-form", "--trial", str(trial),
                 "--out", str(out)]) == 0
    filters = json.loads((out / "filters.json").read_text())
    assert filters["method"] == "closed-form" and filters["from"] == "UAV1" and filters["sample_time"] == 0.02
    assert filters["L1"]["sos"] and filters["L1"]["advance"] > 0
    # applying the exported coefficients gives the closed-form learning signal
    ref = closed_form_filters(fleet.loop("UAV1"), fleet.loop("UAV2")).apply(fl.e, fl.d_f)
    from_json = apply_coefficients(filters["L1"], fl.e) + apply_coefficients(filters["L2"], fl.d_f)
    assert np.max(np.abs(from_json - ref)[:-30]) < 1e-6 * np.max(np.abs(ref))
    # the learning signal written for the next vehicle removes its error (Case I)
    ls = load_csv(out / "learning_signal.csv", {"d_f": "learning"})
    loaded = load_csv(trial, {"e": "error", "d_f": "learning"})  # 10 significant digits in the CSV
    ref_csv = closed_form_filters(fleet.loop("UAV1"), fleet.loop("UAV2")).apply(loaded["e"], loaded["d_f"])
    np.testing.assert_allclose(ls["d_f"], ref_csv, rtol=1e-8, atol=1e-9 * np.max(np.abs(ref_csv)))
    n = len(ls)
    base = simulate_flight(fleet.loop("UAV2"), np.zeros(n), d)
    learned = simulate_flight(fleet.loop("UAV2"), np.zeros(n), d, d_f=ls["d_f"])
    assert rmse(learned.e) < 1e-4 * rmse(base.e)
    header = (out / "filters.h").read_text()
    assert "ILCDOB_UAV1_UAV2_L1_ADVANCE" in header and "void ilcdob_uav1_uav2_l1_apply(" in header


def test_c_header_compiles(tmp_path):
    out = tmp_path / "cf"
    assert main(["design", "--from", "UAV2", "--to", "UAV3", "--out", str(out)]) == 0
    src = tmp_path / "use.c"
    src.write_text('#include "filters.h"\nint main(void){double u[3] = {0, 0, 0};\n'
                   'ilcdob_uav2_uav3_l1_apply(u, u, 3); return (int)u[2] + ILCDOB_UAV2_UAV3_L2_ADVANCE;}\n')
    res = subprocess.run(["gcc", "-Wall", "-Werror", f"-I{out}", str(src), str(out / "filters.c"), "-o",
                          str(tmp_path / "a.out")], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert subprocess.run([str(tmp_path / "a.out")]).returncode == 0


def test_norm_optimal_writes_lifted_matrices(fleet, tmp_path):
    trial = tmp_path / "trial.csv"
    d, fl = _trial(fleet, trial, n=400)
    out = tmp_path / "no"
    assert main(["design", "--from", "UAV1", "--to", "UAV2", "--method", "norm-optimal", "--trial", str(trial),
                 "--out", str(out)]) == 0
    lifted = np.load(out / "lifted.npz")
    assert lifted["L1"].shape == (400, 400) and lifted["L2"].shape == (400, 400)
    ls = load_csv(out / "learning_signal.csv", {"d_f": "learning"})
    via_matrices = lifted["L1"] @ fl.e + lifted["L2"] @ fl.d_f
    base = simulate_flight(fleet.loop("UAV2"), np.zeros(400), d)
    for df in (ls["d_f"], via_matrices):
        assert rmse(simulate_flight(fleet.loop("UAV2"), np.zeros(400), d, d_f=df).e) < 1e-3 * rmse(base.e)


def test_design_errors(tmp_path, capsys):
    assert main(["design", "--from", "UAV1", "--to", "UAV9", "--out", str(tmp_path / "x")]) == 2
    assert "UAV9" in capsys.readouterr().err
    assert main(["design", "--from", "UAV1", "--to", "UAV2", "--method", "magic", "--out", str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err
    assert "magic" in err and "closed-form" in err
    assert not (tmp_path / "y" / "filters.json").exists()


def test_fir_design_via_cli(fleet, tmp_path):
    trial = tmp_path / "trial.csv"
    d, fl = _trial(fleet, trial, n=3000)
    out = tmp_path / "fir"
    assert main(["design", "--from", "UAV1", "--to", "UAV2", "--method", "fir", "--trial", str(trial),
                 "--out", str(out)]) == 0
    filters = json.loads((out / "filters.json").read_text())
    assert filters["L1"]["den"] == [1.0] and filters["robustness"]["worst_te1"] < 0.9  # margin 0.1
    ls = load_csv(out / "learning_signal.csv", {"d_f": "learning"})
    base = simulate_flight(fleet.loop("UAV2"), np.zeros(3000), d)
    learned = simulate_flight(fleet.loop("UAV2"), np.zeros(3000), d, d_f=ls["d_f"])
    assert rmse(learned.e) < 0.1 * rmse(base.e)  # FIR: within 10 % of DOB-only (closed form: ~0)


def test_check_cli_reports_the_theorem_condition(tmp_path, capsys):
    out = tmp_path / "check.json"
    assert main(["check", "--order", "UAV1,UAV3,UAV2", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["order"] == ["UAV1", "UAV3", "UAV2"]
    assert all(p["holds_everywhere"] for p in data["pairs"])  # identified uncertainty is small
    assert main(["check", "--bound", "0.9"]) == 1  # a check that ran and does not hold
    captured = capsys.readouterr()
    assert "NO" in captured.out  # |Delta| = 0.9 > |1 + PC|/2 -> 0.5 at high frequency
    assert "ilcdob: check: the Theorem's condition does not hold" in captured.err
    assert main(["check", "--order", "UAV1,UAV7"]) == 2


def test_robust_design_via_cli(fleet, tmp_path, capsys):
    trial = tmp_path / "trial.csv"
    d, fl = _trial(fleet, trial, n=400)
    out = tmp_path / "robust"
    assert main(["design", "--from", "UAV1", "--to", "UAV2", "--method", "robust", "--out", str(out)]) == 2
    assert "--trial" in capsys.readouterr().err and not (out / "filters.json").exists()
    assert main(["design", "--from", "UAV1", "--to", "UAV2", "--method", "robust", "--trial", str(trial),
                 "--rho", "0.5", "--samples", "3", "--out", str(out)]) == 0
    filters = json.loads((out / "filters.json").read_text())
    assert filters["method"] == "robust" and filters["models"] == 4  # nominal + 3 samples
    assert len(filters["trial"]["ratios"]) == 4 and filters["trial"]["worst_ratio"] <= 0.5 + 1e-6
    arrays = np.load(out / "lifted.npz")
    ls = load_csv(out / "learning_signal.csv", {"d_f": "learning"})
    np.testing.assert_allclose(ls["d_f"], arrays["d_f"], rtol=1e-9, atol=1e-12)
    base = simulate_flight(fleet.loop("UAV2"), np.zeros(400), d)
    learned = simulate_flight(fleet.loop("UAV2"), np.zeros(400), d, d_f=ls["d_f"])
    # the nominal pair is model 0: its predicted ratio is what UAV2 flies (same disturbance, exact model)
    assert rmse(learned.e) / rmse(base.e) == pytest.approx(filters["trial"]["ratios"][0], rel=1e-3, abs=1e-4)
