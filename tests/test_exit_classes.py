"""Exit classes, bounded work and a quiet console: one test per case of a security probe.

Everything a user can cause ends in exit 2 and one ``ilcdob: error:`` line, refused where the
value is read (not as an "internal error", exit 3); damaged flight logs end in bounded time;
options a method does not use are refused, not ignored; and ``--quiet`` leaves the error line
alone on stderr (no parser chatter, no raw SciPy warning, no Dask worker traceback).
"""

from __future__ import annotations

import io
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from ilcdob.app import commands
from ilcdob.app.cli import main
from ilcdob.errors import SpecError
from ilcdob.fleet import DEFAULT_FLEET_PATH

DATA = Path(__file__).resolve().parent / "data"
FLEET = DEFAULT_FLEET_PATH.read_text(encoding="utf-8")
DESIGN = ["design", "--from", "UAV1", "--to", "UAV2"]


def _error(capsys, argv: list[str], code: int = 2) -> str:
    """Run ``ilcdob --quiet ARGV``; check the exit code, that stderr is one error line and stdout empty."""
    rc = main(["--quiet", *argv])
    out, err = capsys.readouterr()
    assert rc == code, err[-3000:]
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: "), err[-3000:]
    assert out == ""
    return lines[0]


def _no_work(monkeypatch) -> None:
    """A refusal must come before the fleet is loaded (else the old code ran the whole command)."""
    def no_work(*args, **kwargs):
        raise AssertionError("the fleet was loaded: the option was not checked up front")

    monkeypatch.setattr(commands, "fleet_and_hash", no_work)


def _fleet(tmp_path: Path, old: str, new: str) -> str:
    assert old in FLEET
    path = tmp_path / "fleet.toml"
    path.write_text(FLEET.replace(old, new, 1), encoding="utf-8")
    return str(path)


# ---------------------------------------------------------------- bounded work: damaged flight logs

def _damaged(tmp_path: Path, source: str, keep: int, tail: bytes) -> Path:
    path = tmp_path / f"damaged{Path(source).suffix.lower()}"
    path.write_bytes((DATA / source).read_bytes()[:keep] + tail)
    return path


def test_ulog_with_a_damaged_tail_ends_in_bounded_time(tmp_path):
    # a valid header, then 1 MiB that announces 64 KiB messages at every byte: pyulog resynchronises byte by
    # byte, reading 64 KiB each time (64 GiB in all, hours); the read budget stops it. In a child process so
    # that a regression fails on the guard below instead of hanging the suite
    path = _damaged(tmp_path, "px4_sample_log_small_filtered.ulg", 16, b"\xff" * 2**20)
    run = subprocess.run([sys.executable, "-m", "ilcdob", "--quiet", "identify", str(path), "--input",
                          "vehicle_local_position.ax", "--output", "vehicle_local_position.x", "--poles", "2",
                          "--out", str(tmp_path / "model.json")], capture_output=True, text=True, timeout=300)
    assert run.returncode == 2, run.stderr[-2000:]
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: "), run.stderr[-2000:]
    assert str(path) in lines[0] and "damaged" in lines[0] and "MiB" in lines[0]
    assert not (tmp_path / "model.json").exists()


def test_ulog_parser_chatter_stays_off_stdout(tmp_path, capsys):
    # random bytes after the header: pyulog prints "Warning: no subscription found ..." on stdout
    tail = np.random.default_rng(0).integers(0, 256, 2**20, dtype=np.uint8).tobytes()
    path = _damaged(tmp_path, "px4_sample_log_small_filtered.ulg", 16, tail)
    line = _error(capsys, ["identify", str(path), "--input", "vehicle_local_position.ax", "--output",
                           "vehicle_local_position.x", "--poles", "2", "--out", str(tmp_path / "m.json")])
    assert str(path) in line


def test_dataflash_with_a_damaged_tail_prints_one_line(tmp_path, capfd):
    # pymavlink's compiled indexer writes "bad header" to file descriptor 2 for every damaged byte (a million)
    path = _damaged(tmp_path, "ardupilot_pymavlink_test.BIN", 8000, b"\xff" * 2**20)
    rc = main(["--quiet", "identify", str(path), "--input", "ATT.Roll", "--output", "ATT.Pitch", "--poles", "1",
               "--out", str(tmp_path / "m.json")])
    out, err = capfd.readouterr()
    assert rc == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("ilcdob: error: ") and "bad header" not in err, err[:2000]


# ---------------------------------------------------------------- bounded work: counts with stated limits

def test_reproduce_iterations_have_a_limit_with_the_time_they_would_take(capsys, monkeypatch):
    _no_work(monkeypatch)
    line = _error(capsys, ["reproduce", "--iterations", "10000", "--scenarios", "1,2", "--out", "r"])
    assert "`--iterations`: got 10000" in line and "1 to 100" in line and "would take about" in line
    assert "0.1 s per scenario" in line and "2 scenario(s)" in line


@pytest.mark.parametrize("option, value, words", [
    ("--max-iter", "100000", ["1 to 10000", "--time-limit"]),
    ("--starts", "1000", ["1 to 20", "Levenberg-Marquardt"]),
])
def test_identify_counts_have_limits(tmp_path, capsys, option, value, words):
    line = _error(capsys, ["identify", str(tmp_path / "none.csv"), "--input", "u", "--output", "y", "--poles", "2",
                           option, value, "--out", str(tmp_path / "m.json")])
    assert option in line and repr(value) in line and all(w in line for w in words), line


def test_campaign_workers_beyond_the_cores_are_refused(tmp_path, capsys, monkeypatch):
    import distributed

    def no_cluster(*args, **kwargs):
        raise AssertionError("a local cluster was started")

    monkeypatch.setattr(distributed, "LocalCluster", no_cluster)
    line = _error(capsys, ["campaign", "--samples", "2", "--workers", "1000", "--out", str(tmp_path / "c")])
    assert "`workers`: got 1000" in line and "per usable core" in line


def test_campaign_robust_models_beyond_the_delta_set_limit(tmp_path, capsys):
    # used to fail on the worker, its traceback on stderr before the error line
    line = _error(capsys, ["campaign", "--samples", "2", "--methods", "robust", "--robust-models", "1000000",
                           "--workers", "1", "--scenarios", "1", "--duration", "5", "--out", str(tmp_path / "c")])
    assert "`robust_models`: got 1000000" in line and "0 to 200" in line
    assert not (tmp_path / "c").exists()


# ---------------------------------------------------------------- exit 2, not 3: values read and refused

def test_fleet_delay_of_a_million_seconds(tmp_path, capsys):
    fleet = _fleet(tmp_path, "delay = 0\n", "delay = 1e6\n")
    line = _error(capsys, ["check", "--fleet", fleet])
    assert "UAV1" in line and "`delay`: got 1e+06 s" in line and "at most 1000 samples" in line


def test_fleet_q_order_of_a_million(tmp_path, capsys):
    fleet = _fleet(tmp_path, "q_order = 3", "q_order = 1000000")
    line = _error(capsys, ["check", "--fleet", fleet])
    assert "UAV1" in line and "`dob.q_order`: got 1000000" in line and "1 to 20" in line


@pytest.mark.parametrize("argv, words", [
    (["compare", "--scenario", "1", "--duration", "2", "--methods", "closed-form", "--seed", "-1"],
     ["argument --seed", "'-1'", "integer >= 0"]),
    (["reproduce", "--scenarios", "1", "--iterations", "1", "--sensor-noise", "0.001", "--seed", "-1", "--out", "r"],
     ["`seed`: got -1", "integer >= 0"]),
])
def test_negative_seed(capsys, argv, words):
    line = _error(capsys, argv)
    assert all(w in line for w in words), line


@pytest.mark.parametrize("scale", ["nan", "inf", "-1", "0"])
def test_check_scale_must_be_a_positive_factor(capsys, scale):
    line = _error(capsys, ["check", "--scale", scale])
    assert "`scale`: got" in line and "factor > 0" in line


def test_check_scale_with_a_bound_is_refused(capsys):
    line = _error(capsys, ["check", "--scale", "2", "--bound", "0.2"])
    assert "`scale`: got 2.0 with `bound` 0.2" in line and "give one of them" in line


def test_identify_min_fit_nan_is_bad_input_not_a_failed_check(tmp_path, capsys):
    line = _error(capsys, ["identify", str(tmp_path / "f.csv"), "--input", "u", "--output", "y", "--poles", "2",
                           "--min-fit", "nan", "--out", str(tmp_path / "m.json")])
    assert "--min-fit" in line and "'nan'" in line and "<= 100" in line


def test_reproduce_bandwidth_too_low_to_pad(tmp_path, capsys):
    # 1e-300 rad/s made a singular filter (exit 3); above it, down to 1e-6, a padding of up to 10^9 samples
    # ran out of memory
    line = _error(capsys, ["reproduce", "--scenarios", "1", "--iterations", "1", "--no-figures", "--bandwidth",
                           "1e-300", "--out", str(tmp_path / "r")])
    assert "`--bandwidth`" in line and "at least 0.001885 rad/s" in line
    assert not (tmp_path / "r").exists()


def test_usage_errors_are_one_line(capsys):
    line = _error(capsys, ["reproduce", "--iterations", "0", "--out", "r"])
    assert "`reproduce`: argument --iterations: got '0'" in line and "ilcdob reproduce --help" in line


def test_a_console_that_cannot_encode_a_character_gets_its_escape(tmp_path, monkeypatch):
    out, err = io.BytesIO(), io.BytesIO()
    monkeypatch.setattr(sys, "stdout", io.TextIOWrapper(out, encoding="ascii", errors="strict"))
    monkeypatch.setattr(sys, "stderr", io.TextIOWrapper(err, encoding="ascii", errors="strict"))
    assert main(["check", "--fleet", str(tmp_path / "flotte-é.toml")]) == 2
    assert main([*DESIGN, "--out", str(tmp_path / "sortie-é")]) == 0  # its notes name the folder
    sys.stderr.flush()
    text = err.getvalue().decode("ascii")
    assert "ilcdob: error: " in text and "flotte-\\xe9.toml" in text and "wrote " in text and "sortie-\\xe9" in text


# ---------------------------------------------------------------- silent acceptance: refused, not ignored

@pytest.mark.parametrize("extra, words", [
    (["--method", "robust-set", "--rho", "1.5"], ["`--rho`: got 1.5", "(0, 1]"]),
    (["--rho", "0.5"], ["`--rho` 0.5", "closed-form does not use it", "robust and robust-set"]),
    (["--method", "fir", "--rho", "0.5"], ["`--rho` 0.5", "fir does not use it"]),
    (["--method", "robust-set", "--samples", "3"], ["`--samples` 3", "only fir and robust"]),
    (["--bound", "0.2"], ["`--bound` 0.2", "closed-form does not use it"]),
    (["--method", "norm-optimal", "--bound", "0.2"], ["`--bound` 0.2", "norm-optimal does not use it"]),
    (["--method", "fir", "--n", "300"], ["`--n` 300", "only norm-optimal does"]),
    (["--method", "norm-optimal", "--c-float"], ["`--c-float`", "C code"]),
    (["--method", "robust-set", "--c-prefix", "abc_"], ["`--c-prefix` 'abc_'", "C code"]),
])
def test_design_options_the_method_does_not_use_are_refused(tmp_path, capsys, monkeypatch, extra, words):
    _no_work(monkeypatch)
    line = _error(capsys, [*DESIGN, *extra, "--out", str(tmp_path / "d")])
    assert all(w in line for w in words), line
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("argv, words", [
    (["compare", "--scenario", "1", "--methods", "closed-form,fir", "--rho", "0.5"], ["`--rho` 0.5", "--methods"]),
    (["compare", "--scenario", "1", "--methods", "robust-set", "--rho", "1.5"], ["`--rho`: got 1.5", "(0, 1]"]),
    (["compare", "--scenario", "1", "--duration", "1e9"], ["`--duration`: got 1e+09 s", "lasts 60 s"]),
    (["campaign", "--samples", "2", "--methods", "closed-form", "--rho", "0.5"], ["`--rho` 0.5"]),
    (["campaign", "--samples", "2", "--methods", "fir", "--robust-models", "2"], ["`--robust-models` 2"]),
    (["campaign", "--samples", "2", "--delta-set", "disc"], ["`--delta-set` 'disc'", "robust-set"]),
    (["campaign", "--samples", "2", "--methods", "robust-set", "--rho", "1.5"], ["`rho`: got 1.5", "(0, 1]"]),
])
def test_compare_and_campaign_options_no_method_uses_are_refused(tmp_path, capsys, monkeypatch, argv, words):
    def no_work(*args, **kwargs):
        raise AssertionError("the command ran: the option was not checked up front")

    monkeypatch.setattr(commands, "compare_to_folder", no_work)
    monkeypatch.setattr(commands, "campaign_to_folder", no_work)
    line = _error(capsys, [*argv, "--out", str(tmp_path / "o")])
    assert all(w in line for w in words), line


# ---------------------------------------------------------------- --quiet means quiet

# in child processes: the warnings reach the console as they do for a user (pytest records them otherwise)
_SCIPY_WARNINGS = """
import sys
import numpy as np
import scipy.linalg
import scipy.signal
from ilcdob.app import commands
from ilcdob.app.cli import main
from ilcdob.errors import SpecError

def check_meeting_scipy_warnings(*args, **kwargs):
    scipy.linalg.solve(scipy.linalg.hilbert(14), np.ones(14))  # ill-conditioned: LinAlgWarning
    scipy.signal.normalize([1e-20, 1.0], [1.0, 1.0])  # a vanishing leading coefficient: BadCoefficients
    raise SpecError("`bound`: got 7.0, expected a relative error in (0, 1)")

commands.check_to_json = check_meeting_scipy_warnings
sys.exit(main(sys.argv[1:]))
"""


def _stderr_lines(argv: list[str], code: int = 2) -> list[str]:
    run = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=300)
    assert run.returncode == code, run.stderr[-3000:]
    assert run.stdout == ""
    return run.stderr.strip().splitlines()


def test_quiet_leaves_the_error_line_alone_after_scipy_warnings():
    lines = _stderr_lines(["-c", _SCIPY_WARNINGS, "--quiet", "check"])
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: `bound`: got 7.0"), lines


def test_without_quiet_each_warning_is_one_readable_line_and_the_error_comes_last():
    lines = _stderr_lines(["-c", _SCIPY_WARNINGS, "check"])
    assert len(lines) == 3 and lines[-1].startswith("ilcdob: error: `bound`"), lines
    assert lines[0].startswith("ilcdob: warning: An ill-conditioned matrix") and "(LinAlgWarning in " in lines[0]
    assert lines[1].startswith("ilcdob: warning: Badly conditioned filter") and "(BadCoefficients in " in lines[1]


def test_quiet_hides_a_numpy_overflow_warning_before_the_error(tmp_path, capsys):
    model = tmp_path / "model.json"
    assert main(["--quiet", "identify", _flight(tmp_path), "--input", "u", "--output", "y", "--poles", "1",
                 "--out", str(model)]) == 0
    lines = _stderr_lines(["-m", "ilcdob", "--quiet", "fleet", "add", str(tmp_path / "f.toml"), "--name", "A",
                           "--model", str(model), "--kp", "1e300", "--ki", "0.3", "--kd", "2.4", "--q-order", "3",
                           "--q-time-constant", "0.15"])
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: ") and "unstable" in lines[0], lines


def _flight(tmp_path: Path) -> str:
    t = np.arange(1000) * 0.02
    u = np.sign(np.sin(0.7 * t))
    y = np.zeros_like(u)
    for k in range(1, t.size):
        y[k] = 0.9 * y[k - 1] + 0.1 * u[k - 1]
    path = tmp_path / "flight.csv"
    np.savetxt(path, np.c_[t, u, y], delimiter=",", header="time,u,y", comments="")
    return str(path)


def test_campaign_worker_failure_is_one_line(tmp_path, capfd):
    # true plants 10^6 standard deviations out: every draw unstable, the sample fails on its worker; the
    # worker's "Compute Failed" log and traceback used to reach stderr ahead of the error line
    rc = main(["--quiet", "campaign", "--samples", "1", "--methods", "closed-form", "--scenarios", "1",
               "--duration", "5", "--workers", "1", "--scale", "1e6", "--out", str(tmp_path / "c")])
    out, err = capfd.readouterr()
    assert rc == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: a sample failed on a worker"), err[-3000:]
    assert "sampled plants gave unstable loops" in lines[0]


def test_campaign_duration_below_two_samples_is_refused_before_the_cluster(tmp_path, capsys):
    line = _error(capsys, ["campaign", "--samples", "2", "--methods", "closed-form", "--scenarios", "1",
                           "--duration", "1e-9", "--workers", "1", "--out", str(tmp_path / "c")])
    assert "`duration`: got 1e-09 s" in line and "at least 2 samples" in line
    assert not (tmp_path / "c").exists()
