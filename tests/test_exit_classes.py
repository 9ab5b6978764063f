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


@pytest.mark.parametrize("value", ["1e300", "1e-300"])
def test_fleet_q_time_constant_beyond_double_range(tmp_path, capsys, value):
    """Q's matrices and M's gain overflowed (OverflowError: an internal error, exit 3)."""
    fleet = _fleet(tmp_path, "q_time_constant = 0.15", f"q_time_constant = {value}")
    line = _error(capsys, ["check", "--fleet", fleet])
    assert "system 'UAV1'" in line and "`dob.q_time_constant`: got" in line and "2e-08 to 20000 s" in line


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


@pytest.mark.parametrize("value", ["nan", "101", "inf", "-inf"])
def test_identify_min_fit_nan_is_bad_input_not_a_failed_check(tmp_path, capsys, value):
    # a fit in % is at most 100: a --min-fit above it could never hold, refused before the fit runs
    line = _error(capsys, ["identify", str(tmp_path / "f.csv"), "--input", "u", "--output", "y", "--poles", "2",
                           f"--min-fit={value}", "--out", str(tmp_path / "m.json")])
    assert "--min-fit" in line and repr(value) in line and "a finite number <= 100" in line


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
    (["--method", "norm-optimal", "--c-float"], ["`--c-float`", "L1/L2 filters"]),
    (["--method", "robust", "--c-prefix", "abc_"], ["`--c-prefix` 'abc_'", "C code"]),
    (["--method", "robust-set", "--c-float"], ["`--c-float`", "L1/L2 filters to give in float"]),
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


@pytest.mark.slow  # > 15 s on 2 cores: the default suite stays under 10 minutes
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


# ---------------------------------------------------------------- fault probe: signals, tampered inputs, options

def test_ctrl_c_while_the_interface_loads_is_one_line(monkeypatch, capsys):
    """The command's entry point imports the interface inside its own handler: a Ctrl-C there (about a
    second of imports) ends with exit 130 and one line, not a traceback."""
    import importlib.abc

    import ilcdob.__main__ as entry

    class _Interrupting(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name == "ilcdob.app.cli":
                raise KeyboardInterrupt
            return None

    monkeypatch.delitem(sys.modules, "ilcdob.app.cli")
    monkeypatch.setattr(sys, "meta_path", [_Interrupting(), *sys.meta_path])
    assert entry.main() == 130
    err = capsys.readouterr().err
    assert err.startswith("ilcdob: error: interrupted") and err.count("\n") == 1


def test_sigterm_while_writing_leaves_no_staging_folder(tmp_path, capsys, monkeypatch):
    """SIGTERM mid-write runs the output's cleanup (as Ctrl-C does): exit 143, one line, no staging
    folder and no output; the previous default handler ended the process with the folder left behind."""
    import os
    import signal

    from ilcdob.app import output

    real, calls = output._write, []

    def write_then_terminate(*args, **kwargs):
        calls.append(args)
        real(*args, **kwargs)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(output, "_write", write_then_terminate)
    before = signal.getsignal(signal.SIGTERM)
    out = tmp_path / "out"
    line = _error(capsys, [*DESIGN, "--out", str(out)], code=143)
    assert "terminated" in line and len(calls) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == []   # no folder, no staging folder
    assert signal.getsignal(signal.SIGTERM) is before        # the handler is put back


def test_a_swallowed_ctrl_c_inside_ipopt_is_raised_again():
    """CasADi catches the KeyboardInterrupt of a Ctrl-C during an IPOPT solve and returns as from a
    failed solve (``NonIpopt_Exception_Thrown``); :func:`honour_interrupts` raises it again."""
    import os
    import signal
    import threading

    import casadi as cs

    from ilcdob.interrupts import honour_interrupts

    # a chained Rosenbrock function with a limited-memory Hessian and no early acceptance: minutes of
    # iterations (a problem that IPOPT ends in 0.5 s let the signal arrive after the solve on a fast run),
    # capped at 60 s of CPU so that a lost signal fails the test instead of hanging it
    n = 20000
    x = cs.MX.sym("x", n)
    solver = cs.nlpsol("long", "ipopt", {"x": x, "f": 100 * cs.sumsqr(x[1:] - x[:-1] ** 2) + cs.sumsqr(1 - x[:-1])},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": 10 ** 6,
                        "ipopt.tol": 1e-30, "ipopt.acceptable_iter": 0, "ipopt.max_cpu_time": 60.0,
                        "ipopt.hessian_approximation": "limited-memory"})
    timer = threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT))
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # Python's own Ctrl-C, whatever ran before
    try:
        with pytest.raises(KeyboardInterrupt):
            with honour_interrupts():
                timer.start()
                solver(x0=-1.2 * np.ones(n))
    finally:
        timer.join()
        signal.signal(signal.SIGINT, previous)
    assert solver.stats()["return_status"] == "NonIpopt_Exception_Thrown"  # what CasADi made of the Ctrl-C


def test_campaign_store_that_is_a_fifo_or_holds_nan_is_refused(tmp_path):
    """Resuming reads the sample store through the input checks: a FIFO is refused before it is
    opened (it blocked forever), and a record with NaN (never written: records are standard JSON)."""
    import os

    from ilcdob.validation.campaign.options import CampaignError
    from ilcdob.validation.campaign.store import SAMPLES_FILE, SampleStore, campaign_lock

    fifo = tmp_path / "fifo"
    fifo.mkdir()
    os.mkfifo(fifo / SAMPLES_FILE)
    with pytest.raises(CampaignError, match="FIFO"):
        SampleStore(fifo / SAMPLES_FILE, "abc").load()
    with pytest.raises(CampaignError, match="FIFO"):
        with campaign_lock(fifo):
            pass
    store = tmp_path / SAMPLES_FILE
    store.write_text('{"sample": 0, "settings": "abc", "ratio": 0.5}\n'
                     '{"sample": 1, "settings": "abc", "ratio": NaN}\n', encoding="utf-8")
    with pytest.raises(CampaignError, match="line 2"):
        SampleStore(store, "abc").load()


@pytest.fixture(scope="module")
def design_and_trial(tmp_path_factory):
    """A closed-form design folder (UAV1 -> UAV2) and a 500-sample trial of UAV1 (error 0.01 sin t m)."""
    base = tmp_path_factory.mktemp("learn")
    assert main(["--quiet", *DESIGN, "--out", str(base / "design")]) == 0
    t = np.arange(500) * 0.02
    rows = "".join(f"{t[k]:.10g},{0.01 * np.sin(t[k]):.10g}\n" for k in range(t.size))
    (base / "trial.csv").write_text("# units: time=s, error=m\ntime,error\n" + rows, encoding="utf-8")
    return base


def _tampered_design(base: Path, tmp_path: Path, change, forge: bool) -> Path:
    """A copy of the design folder with ``change(filters)`` applied (and, with ``forge``, rehashed)."""
    import hashlib
    import json
    import shutil

    design = tmp_path / "design"
    shutil.copytree(base / "design", design)
    path = design / "filters.json"
    filters = json.loads(path.read_text(encoding="utf-8"))
    change(filters)
    path.write_text(json.dumps(filters), encoding="utf-8")
    if forge:
        manifest = json.loads((design / "manifest.json").read_text(encoding="utf-8"))
        manifest["files"]["filters.json"] = hashlib.sha256(path.read_bytes()).hexdigest()
        (design / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    return design


@pytest.mark.parametrize("change, forge, words", [
    (lambda f: f["L1"].__setitem__("advance", 3), False, "filters.json"),   # edited, manifest not updated
    (lambda f: f.update(sample_time="fast"), True, "`sample_time`: got 'fast'"),
    (lambda f: f.update(L1=3), True, "`L1`: got 3"),
    (lambda f: f["L1"].update(sos=[["a"] * 6]), True, "`L1.sos`"),
    (lambda f: f["L1"].update(advance=10**12), True, "at most 1000000"),
])
def test_learn_refuses_a_tampered_design_folder(design_and_trial, tmp_path, capsys, change, forge, words):
    """An edited ``filters.json`` fails the folder's manifest; a forged one (rehashed) is type-checked:
    each ended in exit 3 ("internal error") or was used."""
    design = _tampered_design(design_and_trial, tmp_path, change, forge)
    line = _error(capsys, ["learn", str(design_and_trial / "trial.csv"), "--design", str(design), "--error",
                           "error", "--out", str(tmp_path / "out")])
    assert words in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("change, words", [
    (lambda f: f["limit"].update(acceleration_m_s2="abc"), "`limit.acceleration_m_s2`: got 'abc'"),
    (lambda f: f["limit"].update(acceleration_m_s2=True), "`limit.acceleration_m_s2`: got True"),
    (lambda f: f["limit"].update(acceleration_m_s2=-1.0), "`limit.acceleration_m_s2`: got -1.0"),
    (lambda f: f.update(limit="abc"), "`limit`: got 'abc'"),
    (lambda f: f.update(c="abc"), "`c`: got 'abc'"),
    (lambda f: f["c"].update(prefix=5), "`c.prefix`: got 5"),
    (lambda f: f.update(axis="w"), "`axis`: got 'w'"),
    (lambda f: f.update(method=[1]), "`method`: got [1]"),
])
def test_learn_type_checks_a_design_folder_without_manifest(design_and_trial, tmp_path, capsys, change, words):
    """A folder without a manifest is used (provenance unknown), so every entry of its filters.json that
    learn uses is type-checked: a limit of "abc" ended in exit 3, True was taken as 1 m/s^2, an axis or
    prefix of any type was used, and a bad prefix was blamed on --c-prefix."""
    design = _tampered_design(design_and_trial, tmp_path, change, False)
    (design / "manifest.json").unlink()
    line = _error(capsys, ["learn", str(design_and_trial / "trial.csv"), "--design", str(design), "--error",
                           "error", "--out", str(tmp_path / "out")])
    assert str(design / "filters.json") in line and words in line, line
    assert not (tmp_path / "out").exists()


def test_learn_refuses_absurd_trial_values(design_and_trial, tmp_path, capsys):
    """An error of 1e300 m overflowed the limit check's RMS and ended in exit 3."""
    text = (design_and_trial / "trial.csv").read_text(encoding="utf-8").splitlines()
    text[12] = text[12].split(",")[0] + ",1e300"
    (tmp_path / "trial.csv").write_text("\n".join(text) + "\n", encoding="utf-8")
    line = _error(capsys, ["learn", str(tmp_path / "trial.csv"), "--design", str(design_and_trial / "design"),
                           "--error", "error", "--out", str(tmp_path / "out")])
    assert "1e+300 m at sample 10" in line


@pytest.mark.parametrize("column, words", [
    (1, "the error (column `error`) is 1e+300 m at sample 10"),
    (2, "the learning signal (column `learning`) is 1e+300 m/s^2 at sample 10"),
])
def test_design_trial_refuses_absurd_values(design_and_trial, tmp_path, capsys, column, words):
    """``design --trial`` read the file without learn's value check: the limit check's RMS overflowed (exit 3)."""
    rows = (design_and_trial / "trial.csv").read_text(encoding="utf-8").splitlines()[2:]
    cells = [row.split(",") + ["0"] for row in rows]
    cells[10][column] = "1e300"
    trial = tmp_path / "trial.csv"
    trial.write_text("time,error,learning\n" + "".join(",".join(c) + "\n" for c in cells), encoding="utf-8")
    line = _error(capsys, [*DESIGN, "--trial", str(trial), "--out", str(tmp_path / "out")])
    assert str(trial) in line and words in line, line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["design", "learn"])
def test_a_trial_too_short_for_the_auto_band_names_the_file(tmp_path, capsys, command):
    """``--bandwidth auto`` on a 3-sample trial was refused as "`e_prev`: got 3 samples" (no file named)."""
    trial = tmp_path / "short.csv"
    trial.write_text("time,error,learning\n0,0.01,0\n0.02,0.01,0\n0.04,0.01,0\n", encoding="utf-8")
    argv = ([*DESIGN, "--trial", str(trial)] if command == "design" else
            ["learn", str(trial), "--from", "UAV1", "--to", "UAV2", "--error", "error"])
    line = _error(capsys, [*argv, "--out", str(tmp_path / "out")])
    assert f"{trial}: 3 samples" in line and "at least 64" in line and "--bandwidth" in line, line


@pytest.mark.parametrize("contents, words", [
    ({"methods": [1, 2]}, 'key "methods": got [1, 2], expected an object'),
    ({"methods": {"fir": {"ratio_nominal": "big"}}}, "methods.fir.ratio_nominal"),
    ({"methods": {}, "scenarios": {"s1": {"methods": "all"}}}, "scenarios.s1.methods"),
    ({"samples": "abc", "methods": {}}, 'key "samples": got \'abc\', expected a number or null'),
    ({"wall_time_s": [1], "methods": {}}, 'key "wall_time_s": got [1]'),
    ({"rmse_without_learning": {"nominal": "abc"}, "methods": {}}, 'key "rmse_without_learning.nominal"'),
])
def test_report_type_checks_compare_and_campaign_tables(tmp_path, capsys, contents, words):
    """The method tables of compare.json and campaign.json were rendered whatever they held."""
    import json

    folder = tmp_path / "compare"
    folder.mkdir()
    (folder / "compare.json").write_text(json.dumps(contents), encoding="utf-8")
    line = _error(capsys, ["report", str(folder), "--out", str(tmp_path / "r.html")])
    assert words in line and not (tmp_path / "r.html").exists()


@pytest.mark.parametrize("argv, words", [
    (["compare", "--scenario", "1", "--methods", ","], "without empty entries"),
    (["campaign", "--samples", "1", "--methods", "closed-form,"], "without empty entries"),
])
def test_empty_method_lists_are_refused(tmp_path, capsys, monkeypatch, argv, words):
    """``--methods ,`` ran every default method."""
    _no_work(monkeypatch)
    assert words in _error(capsys, [*argv, "--out", str(tmp_path / "out")])


def _flight_csv(path: Path) -> str:
    rng = np.random.default_rng(0)
    u = np.repeat(rng.standard_normal(40), 25)
    y = np.convolve(u, 0.1 * 0.9 ** np.arange(50))[:u.size]
    path.write_text("time,u,y\n" + "".join(f"{0.01 * k:.4f},{u[k]:.6g},{y[k]:.6g}\n" for k in range(u.size)),
                    encoding="utf-8")
    return str(path)


@pytest.mark.parametrize("extra, out, words", [
    (["--max-delay", "0.1"], "m.json", "with a fixed delay"),
    (["--input", "y"], "m.json", "both name 'y'"),
    ([], "m.json/", "ends in a slash"),
])
def test_identify_options_that_contradict_are_refused(tmp_path, capsys, extra, out, words):
    """``--max-delay`` without ``--delay auto`` was ignored, a signal modelled from itself accepted, and
    ``--out m.json/`` wrote a file."""
    flight = _flight_csv(tmp_path / "flight.csv")
    line = _error(capsys, ["identify", flight, "--input", "u", "--output", "y", "--poles", "1", *extra,
                           "--out", f"{tmp_path}/{out}"])
    assert words in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.csv"]


def test_a_full_disk_names_what_was_being_written(tmp_path, capsys, monkeypatch):
    """ENOSPC carries no file name: the message names the output it was writing."""
    import errno

    from ilcdob.app import output

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(output, "_write", full)
    out = tmp_path / "out"
    line = _error(capsys, [*DESIGN, "--out", str(out)])
    assert f"No space left on device while writing {out}: free space" in line
    assert list(tmp_path.iterdir()) == []


def test_campaign_into_a_dangling_link_writes_where_it_points(tmp_path, capsys):
    """``--out`` a symbolic link to a folder not made yet: the campaign writes there, as every other
    command does (it ended in a bare "File exists")."""
    (tmp_path / "link").symlink_to(tmp_path / "target")
    rc = main(["--quiet", "campaign", "--samples", "1", "--scenarios", "1", "--methods", "closed-form",
               "--duration", "2", "--workers", "1", "--out", str(tmp_path / "link")])
    assert rc == 0, capsys.readouterr().err
    assert (tmp_path / "link").is_symlink() and (tmp_path / "target" / "campaign.json").is_file()
