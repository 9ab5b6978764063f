"""Every failure a user can cause ends in one ``ilcdob: error:`` line with the right exit code.

One test per case of a user probe of the previous release: the message names the input and
the value, no Python traceback reaches the user, and nothing is written.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from ilcdob.app import commands
from ilcdob.app.cli import main
from ilcdob.fleet import DEFAULT_FLEET_PATH
from ilcdob.identification.oe import simulate_zoh
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure

FLEET = DEFAULT_FLEET_PATH.read_text(encoding="utf-8")
COV_UAV1 = "covariance = [[0.001221506944, 0.001173509429], [0.001173509428, 0.001182357421]]"
IDENTIFY = ["--input", "u", "--output", "y", "--poles", "3", "--integrators", "2"]


def _error(capsys, argv: list[str], code: int) -> str:
    """Run ``ilcdob --quiet ARGV``; check the exit code and the single error line, and return it."""
    rc = main(["--quiet", *argv])
    err = capsys.readouterr().err
    assert rc == code, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: "), err
    return lines[0]


def _fleet(tmp_path, old: str, new: str, name: str = "fleet.toml") -> str:
    assert old in FLEET
    path = tmp_path / name
    path.write_text(FLEET.replace(old, new, 1), encoding="utf-8")
    return str(path)


def _flight(path, y_scale: float = 1.0, seconds: float = 60.0) -> None:
    """A 60 s flight of 1/(s^2 (s/7 + 1)) with a 0.04 s delay, columns time, u (m/s^2), y (m)."""
    ts = 0.02
    t = np.arange(int(round(seconds / ts))) * ts
    rng = np.random.default_rng(0)
    u = np.sin(2 * np.pi * 0.5 * t) + 0.3 * rng.standard_normal(t.size)
    structure = ModelStructure(3, 0, 2)
    y = simulate_zoh(structure, structure.join([7.0], [1.0, 7.0, 0.0, 0.0]), u, ts, delay=0.04)
    FlightData(t, {"u": u, "y": y_scale * y}, {"u": "m/s^2", "y": "m"}).to_csv(path)


# 1
def test_binary_fleet_file(tmp_path, capsys):
    path = tmp_path / "fleet.toml"
    path.write_bytes(bytes(range(256)) * 4)
    line = _error(capsys, ["check", "--fleet", str(path)], 2)
    assert str(path) in line and "UTF-8" in line and "0x80" in line


# 2
def test_fleet_gain_that_is_text(tmp_path, capsys):
    fleet = _fleet(tmp_path, "kp = 3,", 'kp = "abc",')
    line = _error(capsys, ["check", "--fleet", fleet], 2)
    assert "UAV1" in line and "kp" in line and "'abc'" in line and "expected a number" in line


# 3
@pytest.mark.parametrize("old, new, value", [
    ("den = [1, 10.32326473, 0, 0]", "den = [1e-300, 1, 0, 0]", "1e-300"),
    ("num = [10.37568301]", "num = [1e300]", "1e+300"),
])
def test_plant_coefficients_out_of_double_range(tmp_path, capsys, old, new, value):
    line = _error(capsys, ["check", "--fleet", _fleet(tmp_path, old, new)], 2)
    assert "UAV1" in line and "`plant`" in line and value in line and "orders of magnitude" in line


# 4
def test_identify_fleet_needs_the_table_i_vehicles(tmp_path, capsys):
    text = FLEET.replace('"UAV1"', '"A"').replace('"UAV2"', '"B"').replace('"UAV3"', '"C"')
    fleet = tmp_path / "renamed.toml"
    fleet.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    line = _error(capsys, ["identify-fleet", "--fleet", str(fleet), "--out", str(out)], 2)
    assert "'A'" in line and "UAV1, UAV2, UAV3 only" in line
    assert not out.exists()


# 5
def test_too_many_poles(tmp_path, capsys):
    _flight(tmp_path / "f.csv")
    line = _error(capsys, ["identify", str(tmp_path / "f.csv"), "--input", "u", "--output", "y", "--poles", "30",
                           "--out", str(tmp_path / "m.json")], 2)
    assert "poles" in line and "30" in line and "1 to 12" in line
    assert not (tmp_path / "m.json").exists()


# 6
@pytest.mark.parametrize("duration", ["0.01", "0.02"])
def test_compare_duration_below_two_samples(tmp_path, capsys, duration):
    out = tmp_path / "cmp"
    line = _error(capsys, ["compare", "--scenario", "1", "--duration", duration, "--out", str(out)], 2)
    assert "`duration`" in line and f"got {duration} s" in line and "at least 2 samples" in line
    assert not out.exists()


# 7
@pytest.mark.parametrize("extra, words", [
    (["--method", "norm-optimal", "--lifted", "--n", "50000"], ["`--n`", "50000", "160 GB", "10000", "--lifted"]),
    (["--method", "fir", "--samples", "10000"], ["`--samples`", "10000", "1 to 200"]),
    (["--method", "robust", "--samples", "10000"], ["`--samples`", "10000", "1 to 200"]),
])
def test_design_sizes_refused_up_front(tmp_path, capsys, monkeypatch, extra, words):
    def no_work(*args, **kwargs):
        raise AssertionError("the fleet was loaded: the size was not checked up front")

    monkeypatch.setattr(commands, "fleet_and_hash", no_work)
    out = tmp_path / "design"
    line = _error(capsys, ["design", "--from", "UAV1", "--to", "UAV2", *extra, "--out", str(out)], 2)
    assert all(w in line for w in words), line
    assert not out.exists()


def test_compare_delta_samples_limit(tmp_path, capsys):
    line = _error(capsys, ["compare", "--scenario", "1", "--samples", "10000", "--duration", "1"], 2)
    assert "10000" in line and "1 to 200" in line


# 8
def test_max_delay_beyond_half_the_flight(tmp_path, capsys):
    _flight(tmp_path / "f.csv")
    line = _error(capsys, ["identify", str(tmp_path / "f.csv"), *IDENTIFY, "--delay", "auto", "--max-delay", "1000",
                           "--out", str(tmp_path / "m.json")], 2)
    assert "max_delay" in line and "1000" in line and "30 s" in line
    assert not (tmp_path / "m.json").exists()


def test_max_delay_within_half_the_flight_runs(tmp_path, capsys):
    _flight(tmp_path / "f.csv")
    rc = main(["--quiet", "identify", str(tmp_path / "f.csv"), *IDENTIFY, "--delay", "auto", "--max-delay", "5",
               "--out", str(tmp_path / "m.json")])
    assert rc == 0, capsys.readouterr().err
    assert abs(json.loads((tmp_path / "m.json").read_text())["delay"] - 0.04) < 0.01


# 9
def test_noise_amplitude_out_of_range(tmp_path, capsys):
    line = _error(capsys, ["check", "--fleet", _fleet(tmp_path, "amplitude = 0.03", "amplitude = 1e300")], 2)
    assert "UAV1" in line and "noise.amplitude" in line and "1e+300" in line and "0 to 1000 m/s^2" in line


# 10
@pytest.mark.parametrize("cov, what", [
    ("[[-1.0, 0.0], [0.0, -1.0]]", "negative eigenvalue"),
    ("[[1e-3, 5.0], [0.0, 1e-3]]", "not symmetric"),
])
def test_covariance_must_be_symmetric_positive_semidefinite(tmp_path, capsys, cov, what):
    fleet = _fleet(tmp_path, COV_UAV1, f"covariance = {cov}")
    line = _error(capsys, ["check", "--fleet", fleet], 2)
    assert "UAV1" in line and "identification.covariance" in line and what in line
    assert "symmetric positive semi-definite" in line


def test_model_file_covariance_must_be_positive_semidefinite(tmp_path, capsys):
    model = {"num": [10.37568301], "den": [1, 10.32326473, 0, 0], "delay": 0.0,
             "structure": {"poles": 3, "zeros": 0, "integrators": 2}, "parameters": [10.32326473, 10.37568301],
             "covariance": [[1e-3, 0.0], [0.0, -2e-3]], "delay_estimated": False, "sample_time": 0.02}
    (tmp_path / "uav.json").write_text(json.dumps(model), encoding="utf-8")
    fleet = FLEET.split("[[system]]")[0] + (
        '[[system]]\nname = "UAV4"\nplant = { model = "uav.json" }\n'
        "controller = { kp = 3, ki = 0.3, kd = 2.42, derivative_filter = 0.05 }\n"
        "dob = { q_order = 3, q_time_constant = 0.15 }\n")
    (tmp_path / "fleet.toml").write_text(fleet, encoding="utf-8")
    line = _error(capsys, ["check", "--fleet", str(tmp_path / "fleet.toml")], 2)
    assert "uav.json" in line and "`covariance`" in line and "negative eigenvalue -0.002" in line


# 11
@pytest.mark.parametrize("content, words", [
    (bytes(range(128, 256)), ["UTF-8", "regenerate"]),
    (b"[1, 2, 3]", ["expected a JSON object", "list"]),
])
def test_report_on_a_broken_results_json(tmp_path, capsys, content, words):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "results.json").write_bytes(content)
    line = _error(capsys, ["report", str(folder), "--out", str(tmp_path / "r.html")], 2)
    assert "results.json" in line and all(w in line for w in words), line
    assert not (tmp_path / "r.html").exists()


# 12
def test_constant_output_log(tmp_path, capsys):
    _flight(tmp_path / "zero.csv", y_scale=0.0)
    line = _error(capsys, ["identify", str(tmp_path / "zero.csv"), *IDENTIFY, "--out", str(tmp_path / "m.json")], 2)
    assert "zero.csv" in line and "`y`" in line and "constant" in line


def test_output_without_response_and_input_without_excitation(tmp_path, capsys):
    t = np.arange(3000) * 0.02
    rng = np.random.default_rng(4)
    FlightData(t, {"u": rng.standard_normal(t.size), "y": 1e-3 * rng.standard_normal(t.size)}).to_csv(
        tmp_path / "noise.csv")  # the output is sensor noise, independent of the input
    line = _error(capsys, ["identify", str(tmp_path / "noise.csv"), "--input", "u", "--output", "y", "--poles", "1",
                           "--out", str(tmp_path / "m.json")], 2)
    assert "shows no response to input `u`" in line and "below 1 %" in line
    FlightData(t, {"u": np.full(t.size, 0.5), "y": rng.standard_normal(t.size)}).to_csv(tmp_path / "still.csv")
    line = _error(capsys, ["identify", str(tmp_path / "still.csv"), "--input", "u", "--output", "y", "--poles", "1",
                           "--out", str(tmp_path / "m.json")], 2)
    assert "input `u` is constant" in line
    assert not (tmp_path / "m.json").exists()


def test_large_csv_reads_fast_path_and_slow_path_alike(tmp_path):
    """The pyarrow fast path and the line-by-line parser give the same flight (a comment inside
    the data sends the file to the slow path)."""
    from ilcdob.identification.loaders import load_csv

    _flight(tmp_path / "f.csv")
    text = (tmp_path / "f.csv").read_text()
    lines = text.splitlines()
    (tmp_path / "slow.csv").write_text("\n".join(lines[:5] + ["# a note in the middle"] + lines[5:]) + "\n")
    fast, slow = (load_csv(tmp_path / n, {"u": "u", "y": "y"}) for n in ("f.csv", "slow.csv"))
    np.testing.assert_array_equal(fast.t, slow.t)
    np.testing.assert_array_equal(fast["y"], slow["y"])
    assert fast.units == slow.units == {"u": "m/s^2", "y": "m"}


def test_design_n_must_match_the_trial(tmp_path, capsys):
    t = np.arange(500) * 0.02
    FlightData(t, {"error": 0.01 * np.sin(t), "learning": np.zeros(t.size)}, {"error": "m", "learning": "m/s^2"}
               ).to_csv(tmp_path / "trial.csv")
    line = _error(capsys, ["design", "--from", "UAV1", "--to", "UAV2", "--method", "norm-optimal", "--trial",
                           str(tmp_path / "trial.csv"), "--n", "300", "--out", str(tmp_path / "d")], 2)
    assert "`--n`: got 300" in line and "500 samples" in line and "--n 500" in line
    assert not (tmp_path / "d").exists()


# 13
@pytest.mark.parametrize("cut", ["{t},4.", "{t},{u}", "{t},{u},1.2e"])
def test_csv_cut_in_its_last_row(tmp_path, capsys, cut):
    _flight(tmp_path / "f.csv")
    lines = (tmp_path / "f.csv").read_text().rstrip("\n").splitlines()
    t, u, _ = lines[-1].split(",")
    (tmp_path / "f.csv").write_text("\n".join(lines[:-1] + [cut.format(t=t, u=u)]) + "\n")
    line = _error(capsys, ["identify", str(tmp_path / "f.csv"), *IDENTIFY, "--out", str(tmp_path / "m.json")], 2)
    assert "f.csv" in line and f"line {len(lines)}" in line, line


# 14
@pytest.mark.parametrize("command", [["reproduce"], ["design", "--from", "UAV1", "--to", "UAV2"],
                                     ["compare", "--scenario", "1"], ["extensions"], ["identify-fleet"]])
def test_out_that_is_a_file(tmp_path, capsys, monkeypatch, command):
    def no_work(*args, **kwargs):
        raise AssertionError("the computation started before --out was checked")

    monkeypatch.setattr(commands, "fleet_and_hash", no_work)
    out = tmp_path / "taken"
    out.write_text("mine", encoding="utf-8")
    line = _error(capsys, [*command, "--out", str(out)], 2)
    assert "`--out`" in line and str(out) in line and "is a file" in line
    assert out.read_text(encoding="utf-8") == "mine" and sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


# 15
@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_parent_of_out(tmp_path, capsys):
    parent = tmp_path / "ro"
    parent.mkdir()
    parent.chmod(0o555)
    try:
        line = _error(capsys, ["design", "--from", "UAV1", "--to", "UAV2", "--out", str(parent / "out")], 2)
    finally:
        parent.chmod(0o755)
    assert str(parent) in line
    assert not (parent / "out").exists()


# 16
def test_unexpected_exception_is_one_line_exit_3(capsys, monkeypatch):
    def bug(*args, **kwargs):
        return 1 / 0

    monkeypatch.setattr(commands, "check_to_json", bug)
    line = _error(capsys, ["check"], 3)
    assert line == ("ilcdob: error: internal error: ZeroDivisionError: division by zero (run with --debug for the "
                    "traceback; please report it)")
    assert main(["--quiet", "--debug", "check"]) == 3
    assert "Traceback" in capsys.readouterr().err


def test_design_rerun_with_another_method_leaves_no_stale_file(tmp_path, capsys):
    out = tmp_path / "d"
    assert main(["--quiet", "design", "--from", "UAV1", "--to", "UAV2", "--out", str(out)]) == 0
    assert (out / "filters.h").exists()
    assert main(["--quiet", "design", "--from", "UAV1", "--to", "UAV2", "--method", "norm-optimal", "--n", "40",
                 "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["README.md", "bode.png", "filters.json", "lifted.npz",
                                                    "manifest.json"]
    assert json.loads((out / "filters.json").read_text())["method"] == "norm-optimal"


@pytest.mark.parametrize("command", [["check"], ["design", "--from", "UAV1", "--to", "UAV2", "--method", "fir"]])
@pytest.mark.parametrize("value", ["2", "0", "-0.1", "nan"])
def test_a_bound_outside_0_1_is_named_as_the_option(tmp_path, capsys, command, value):
    """The command line's error names the option the user typed (``--bound``), not the library's parameter."""
    assert main([command[0], "--bound", value, *command[1:], "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"argument --bound: got '{value}', expected a relative error in (0, 1)" in err, err
    assert "`bound`" not in err and not (tmp_path / "out").exists()
