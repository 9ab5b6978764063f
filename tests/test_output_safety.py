"""Outputs go only where a user meant them, inputs are read within stated bounds, concurrent
fleet edits are not lost, and a failed run leaves the previous state exactly.

Special files (devices, FIFOs, sockets) and mount points are never outputs; an output is never
one of the command's inputs; ``--overwrite`` never replaces a work tree or Python sources;
every input is a regular file of a stated size with bounded numbers and nesting; a failure
(a full disk simulated by an ``OSError(ENOSPC)``) leaves no staging folder, no campaign folder
and no figures of a failed fit.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import socket
import subprocess
import sys
import tomllib
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

import ilcdob
from ilcdob import FleetError, ModelFileError
from ilcdob.app import commands, output
from ilcdob.app.cli import main
from ilcdob.app.output import MANIFEST, OutputError, OutputFolder, Provenance, check_output_path, write_file
from ilcdob.errors import SignalError
from ilcdob.fleet import DEFAULT_FLEET_PATH
from ilcdob.identification.loaders import load_flight
from ilcdob.identification.oe import simulate_zoh
from ilcdob.inputs import MAX_DOCUMENT_BYTES, MAX_LOG_BYTES, MAX_NESTING, InputFileError, read_json, read_toml
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure
from probe_faults import MODEL  # a model.json as `ilcdob identify` writes it

FLEET = DEFAULT_FLEET_PATH.read_text(encoding="utf-8")
IDENTIFY = ["--input", "u", "--output", "y", "--poles", "2"]


def _error(capsys, argv: list[str]) -> str:
    """Run ``ilcdob --quiet ARGV``; it must end with exit 2 and one error line, which is returned."""
    rc = main(["--quiet", *argv])
    err = capsys.readouterr().err
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: "), err
    return lines[0]


@contextmanager
def _no_hang(seconds: int = 10):
    """Fail instead of hanging (a FIFO opened for reading blocks until a writer comes)."""
    def _alarm(signum, frame):
        raise TimeoutError(f"blocked for {seconds} s")

    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _flight(path: Path, seconds: float = 40.0) -> Path:
    ts = 0.02
    rng = np.random.default_rng(0)
    n = int(round(seconds / ts))
    u = np.repeat(rng.standard_normal(n // 25), 25)
    y = simulate_zoh(ModelStructure(2), np.array([3.0, 2.0, 2.0]), u, ts) + 0.01 * rng.standard_normal(n)
    FlightData(np.arange(n) * ts, {"u": u, "y": y}, {"u": "m/s^2", "y": "m"}, source="test").to_csv(path)
    return path


def _snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every entry under ``folder`` (relative path -> bytes; None for folders)."""
    return {p.relative_to(folder).as_posix(): (None if p.is_dir() else p.read_bytes())
            for p in sorted(folder.rglob("*"))}


# ------------------------------------------------------------------ where outputs may go

def test_special_files_and_mount_points_are_never_outputs(tmp_path, capsys):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    sock_path = tmp_path / "sock"
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(sock_path))
    try:
        for special, kind in ((fifo, "FIFO"), (sock_path, "socket"), (Path("/dev/null"), "character device")):
            with pytest.raises(OutputError, match=kind):
                check_output_path(special, folder=False)
        with pytest.raises(OutputError, match="mount point"):
            check_output_path("/", folder=True, overwrite=True)
        # through the command line: refused before any work, the FIFO stays a FIFO
        line = _error(capsys, ["check", "--out", str(fifo)])
        assert str(fifo) in line and "FIFO" in line
        assert fifo.is_fifo() and sorted(p.name for p in tmp_path.iterdir()) == ["pipe", "sock"]
    finally:
        sock.close()


def test_a_symlinked_out_writes_the_file_it_points_to(tmp_path):
    real, link = tmp_path / "real.json", tmp_path / "link.json"
    real.write_text("{}")
    link.symlink_to(real)
    assert write_file(link, {"a": 1}) == real
    assert link.is_symlink() and json.loads(real.read_text()) == {"a": 1}
    os.mkfifo(tmp_path / "pipe")
    (tmp_path / "to_pipe").symlink_to(tmp_path / "pipe")
    with pytest.raises(OutputError, match="FIFO"):  # the target is checked, not the link
        write_file(tmp_path / "to_pipe", {"a": 1})


def test_an_output_is_never_one_of_the_inputs(tmp_path, capsys, monkeypatch):
    csv = _flight(tmp_path / "flight.csv")
    before = csv.read_bytes()
    line = _error(capsys, ["identify", str(csv), *IDENTIFY, "--out", str(csv)])
    assert "is the input flight file" in line and csv.read_bytes() == before
    os.link(csv, tmp_path / "hard.csv")  # the same file under another name
    line = _error(capsys, ["identify", str(csv), *IDENTIFY, "--out", str(tmp_path / "hard.csv")])
    assert "is the input flight file" in line
    line = _error(capsys, ["identify", str(csv), *IDENTIFY, "--out", str(tmp_path / "plots" / "m.json"),
                           "--plot", str(tmp_path / "plots")])
    assert "inside `--plot`" in line
    # a folder output holding an input: the fleet file would go with the folder
    work = tmp_path / "work"
    work.mkdir()
    (work / "fleet.toml").write_text(FLEET, encoding="utf-8")
    line = _error(capsys, ["design", "--from", "UAV1", "--to", "UAV2", "--fleet", str(work / "fleet.toml"),
                           "--out", str(work), "--overwrite"])
    assert "holds the input --fleet" in line and (work / "fleet.toml").read_text(encoding="utf-8") == FLEET
    # the report into one of its own input folders
    line = _error(capsys, ["report", str(work), "--out", str(work / "report.html")])
    assert "inside the input folder" in line
    # fleet add: the model file is not the fleet file
    with pytest.raises(OutputError, match="is the input --model"):
        commands.add_to_fleet(work / "fleet.toml", "X", work / "fleet.toml", ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.05),
                              ilcdob.DOBSpec(3, 0.15))


def test_out_dot_is_refused_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    line = _error(capsys, ["design", "--from", "UAV1", "--to", "UAV2", "--out", "."])
    assert "working folder" in line
    assert [p.name for p in tmp_path.iterdir()] == ["work"] and not any(work.iterdir())


def test_overwrite_never_replaces_a_work_tree_or_python_sources(tmp_path, capsys, monkeypatch):
    repo = tmp_path / "repo"
    (repo / "design").mkdir(parents=True)
    (repo / "design" / "__init__.py").write_text("# the package\n")
    monkeypatch.chdir(repo)
    line = _error(capsys, ["design", "--from", "UAV1", "--to", "UAV2", "--out", "design/", "--overwrite"])
    assert "'__init__.py'" in line and "Python source" in line
    assert (repo / "design" / "__init__.py").read_text() == "# the package\n"
    (tmp_path / "results" / ".git").mkdir(parents=True)
    (tmp_path / "results" / "deep" / "er").mkdir(parents=True)
    (tmp_path / "results" / "deep" / "er" / "tool.py").write_text("")
    with pytest.raises(OutputError, match=r"'\.git'.*work tree"):
        OutputFolder(tmp_path / "results", Provenance("test"), overwrite=True)
    (tmp_path / "results" / ".git").rmdir()
    with pytest.raises(OutputError, match="'deep/er/tool.py'"):
        OutputFolder(tmp_path / "results", Provenance("test"), overwrite=True)
    assert (tmp_path / "results" / "deep" / "er" / "tool.py").exists()
    monkeypatch.setenv("HOME", str(tmp_path / "results" / "deep"))
    with pytest.raises(OutputError, match="home folder"):  # holds the home folder
        OutputFolder(tmp_path / "results", Provenance("test"), overwrite=True)


def test_files_that_ilcdob_did_not_write_are_kept_without_overwrite(tmp_path, monkeypatch):
    out = tmp_path / "out"
    with OutputFolder(out, Provenance("test")) as folder:
        folder.add("a.txt", "a")
    (out / "notes.txt").write_text("mine")  # added by the user to an ilcdob folder
    with pytest.raises(OutputError, match="'notes.txt'.*not listed in its manifest.json.*--overwrite"):
        OutputFolder(out, Provenance("test"))
    with OutputFolder(out, Provenance("test"), overwrite=True) as folder:
        folder.add("b.txt", "b")
    assert sorted(p.name for p in out.iterdir()) == ["b.txt", MANIFEST]
    monkeypatch.setattr(output, "MAX_REPLACED_ENTRIES", 3)
    for i in range(4):
        (out / f"f{i}").write_text("")
    with pytest.raises(OutputError, match="more than 3 files"):
        OutputFolder(out, Provenance("test"), overwrite=True)


# ------------------------------------------------------------------ reading inputs

def test_fifos_and_devices_are_never_read(tmp_path):
    fifo = tmp_path / "fleet.toml"
    os.mkfifo(fifo)
    with _no_hang():
        with pytest.raises(FleetError, match=r"fleet\.toml: cannot read fleet file: it is a FIFO"):
            ilcdob.load_fleet(fifo)
        with pytest.raises(ModelFileError, match="FIFO"):
            ilcdob.load_model(fifo)
        log = tmp_path / "log.csv"
        os.mkfifo(log)
        with pytest.raises(SignalError, match="FIFO"):
            load_flight(log, ["u"])
    with pytest.raises(FleetError, match="character device"):
        ilcdob.load_fleet("/dev/null")
    with pytest.raises(ModelFileError, match="character device"):
        ilcdob.load_model("/dev/null")


def test_inputs_larger_than_the_stated_limit_are_refused(tmp_path):
    big = tmp_path / "fleet.toml"
    with open(big, "wb") as fh:  # sparse: no disk used
        fh.truncate(MAX_DOCUMENT_BYTES + 1)
    with pytest.raises(FleetError, match=r"more than the 8 MiB read at most for a fleet file"):
        ilcdob.load_fleet(big)
    log = tmp_path / "log.csv"
    with open(log, "wb") as fh:
        fh.truncate(MAX_LOG_BYTES + 1)
    with pytest.raises(SignalError, match=r"more than the 512 MiB read at most for a flight log"):
        load_flight(log, ["u"])


def test_numbers_beyond_float_range_are_refused_with_their_place(tmp_path, capsys):
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(FLEET.replace("kp = 3,", "kp = 1" + "0" * 400 + ",", 1), encoding="utf-8")
    line = _error(capsys, ["check", "--fleet", str(fleet)])
    assert str(fleet) in line and "system[0].controller.kp" in line and "beyond the range of a float" in line
    fleet.write_text(FLEET.replace("kp = 3,", "kp = 1" + "0" * 5000 + ",", 1), encoding="utf-8")
    assert "beyond the range of a float" in _error(capsys, ["check", "--fleet", str(fleet)])
    model = tmp_path / "model.json"
    model.write_text(json.dumps(MODEL).replace('"sample_time": 0.02', '"sample_time": ' + "9" * 400))
    with pytest.raises(ModelFileError, match=r"sample_time = 999.*\(400 digits\) is beyond the range of a float"):
        ilcdob.load_model(model)
    model.write_text(json.dumps(MODEL).replace('"delay": 0.03', '"delay": 1e400'))
    with pytest.raises(ModelFileError, match=r"delay = 1e400"):
        ilcdob.load_model(model)


@pytest.mark.parametrize("depth", [MAX_NESTING + 1, 3000, 100_000])
def test_deep_nesting_is_refused(tmp_path, capsys, depth):
    model = tmp_path / "model.json"
    model.write_text('{"files": ' + "[" * depth + "]" * depth + "}")
    with pytest.raises(ModelFileError, match=f"nested deeper than {MAX_NESTING} levels"):
        ilcdob.load_model(model)
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(f"sample_time = 0.02\nx = {'[' * depth}{']' * depth}\n")
    line = _error(capsys, ["check", "--fleet", str(fleet)])
    assert str(fleet) in line and f"nested deeper than {MAX_NESTING} levels" in line


def test_documents_within_the_limits_read_as_before(tmp_path):
    path = tmp_path / "doc.json"
    path.write_text(json.dumps({"a": [[[1, 2.5]]], "big": 10 ** 300, "n": None, "s": "x"}))
    assert read_json(path, "test") == {"a": [[[1, 2.5]]], "big": 10 ** 300, "n": None, "s": "x"}
    toml = tmp_path / "doc.toml"
    toml.write_text("a = inf\nb = -inf\nc = 1.5\nd = 12\n" + "e." * (MAX_NESTING - 1) + "f = 1\n")
    data = read_toml(toml, "test")
    assert data["a"] == float("inf") and data["b"] == -float("inf") and data["d"] == 12
    toml.write_text("e." * MAX_NESTING + "f = 1\n")  # dotted keys nest tables without recursion
    with pytest.raises(InputFileError, match="nested deeper"):
        read_toml(toml, "test")
    assert tomllib.loads(toml.read_text())  # valid TOML: only the limit refuses it


# ------------------------------------------------------------------ concurrent fleet edits

_ADD = """
import sys, time
from pathlib import Path
import ilcdob
fleet, name, model, go = sys.argv[1:]
while not Path(go).exists():
    time.sleep(0.005)
ilcdob.add_system(fleet, name, model, ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.05), ilcdob.DOBSpec(3, 0.15))
"""


def _adds_at_once(tmp_path: Path, fleet: Path, model: Path, names: list[str]) -> None:
    go = tmp_path / f"go-{names[0]}"
    procs = [subprocess.Popen([sys.executable, "-c", _ADD, str(fleet), name, str(model), str(go)],
                              stderr=subprocess.PIPE, text=True) for name in names]
    go.touch()
    for p in procs:
        assert p.wait(timeout=120) == 0, p.stderr.read()
        p.stderr.close()


def test_fleet_adds_at_once_all_land(tmp_path):
    model = tmp_path / "model.json"
    model.write_text(json.dumps(MODEL))
    new = tmp_path / "fleets" / "fleet.toml"
    _adds_at_once(tmp_path, new, model, ["A", "B"])  # both create the file
    assert sorted(ilcdob.load_fleet(new).names) == ["A", "B"]
    assert sorted(p.name for p in new.parent.iterdir()) == ["fleet.toml"]  # no lock file, no temporary
    three = tmp_path / "three.toml"
    three.write_text(FLEET, encoding="utf-8")
    _adds_at_once(tmp_path, three, model, ["C", "D", "E"])  # all append to a fleet of three
    names = ilcdob.load_fleet(three).names
    assert names[:3] == ["UAV1", "UAV2", "UAV3"] and sorted(names[3:]) == ["C", "D", "E"]
    # a refused add leaves no folder, although the folder is made first (the lock is on it)
    with pytest.raises(FleetError, match="sample_time"):
        ilcdob.add_system(tmp_path / "new" / "deeper" / "fleet.toml", "A", model,
                          ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.05), ilcdob.DOBSpec(3, 0.15), sample_time=-1.0)
    assert not (tmp_path / "new").exists()


def test_fleet_add_through_a_symlink_edits_the_file_it_points_to(tmp_path):
    model = tmp_path / "model.json"
    model.write_text(json.dumps(MODEL))
    (tmp_path / "shared").mkdir()
    real, link = tmp_path / "shared" / "fleet.toml", tmp_path / "fleet.toml"
    real.write_text(FLEET, encoding="utf-8")
    link.symlink_to(real)
    commands.add_to_fleet(link, "A", model, ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.05), ilcdob.DOBSpec(3, 0.15))
    assert link.is_symlink() and ilcdob.load_fleet(real).names == ["UAV1", "UAV2", "UAV3", "A"]
    assert tomllib.loads(real.read_text())["system"][-1]["plant"] == {"model": "../model.json"}


# ------------------------------------------------------------------ a failed run leaves the previous state

def _disk_full(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_full_disk_at_the_manifest_leaves_no_staging_and_no_new_folders(tmp_path, monkeypatch):
    out = tmp_path / "out"
    with OutputFolder(out, Provenance("test", ["first"])) as folder:
        folder.add("a.txt", "first")
    before = _snapshot(tmp_path)
    real = output.json_text
    monkeypatch.setattr(output, "json_text", lambda data, name: _disk_full() if name == MANIFEST else real(data, name))
    for target in (out, tmp_path / "new" / "deeper" / "out"):
        with pytest.raises(OSError, match="No space left"):
            with OutputFolder(target, Provenance("test", ["second"])) as folder:
                folder.add("a.txt", "second")
        assert _snapshot(tmp_path) == before


def test_identify_plots_only_a_run_that_succeeded(tmp_path, monkeypatch):
    csv = _flight(tmp_path / "flight.csv")
    plots, model = tmp_path / "plots", tmp_path / "model.json"
    structure = ModelStructure(2)
    from ilcdob.identification.tfest import FitOptions

    monkeypatch.setattr(commands, "write_file", _disk_full)  # the model file cannot be written
    with pytest.raises(OSError, match="No space left"):
        commands.identify_to_json([csv], commands.IdentifyInputs(input="u", output="y"), structure, FitOptions(),
                                  model, plot=plots)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.csv"]


def test_a_failed_campaign_leaves_no_folder(tmp_path, monkeypatch):
    import ilcdob.validation.campaign as campaign
    from ilcdob.validation.campaign import CampaignError, CampaignOptions

    def unreachable(fleet, options, out, **kwargs):  # what run_campaign has done when the scheduler fails
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / campaign.SAMPLES_FILE).touch()
        (out / campaign.SETTINGS_FILE).write_text("{}")
        raise CampaignError("cannot reach the Dask scheduler tcp://127.0.0.1:9")

    monkeypatch.setattr(campaign, "run_campaign", unreachable)
    for out in (tmp_path / "c", tmp_path / "new" / "c"):
        with pytest.raises(CampaignError):
            commands.campaign_to_folder(out, CampaignOptions(samples=2))
        assert sorted(p.name for p in tmp_path.iterdir()) == []
    (tmp_path / "mine").mkdir()  # an empty folder stays an empty folder
    with pytest.raises(CampaignError):
        commands.campaign_to_folder(tmp_path / "mine", CampaignOptions(samples=2))
    assert [p.name for p in tmp_path.iterdir()] == ["mine"] and not any((tmp_path / "mine").iterdir())

    def flown_one(fleet, options, out, **kwargs):  # a sample stored, then the disk is full
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / campaign.SAMPLES_FILE).write_text('{"sample": 0}\n')
        _disk_full()

    monkeypatch.setattr(campaign, "run_campaign", flown_one)
    with pytest.raises(OSError):
        commands.campaign_to_folder(tmp_path / "kept", CampaignOptions(samples=2))
    assert (tmp_path / "kept" / campaign.SAMPLES_FILE).read_text() == '{"sample": 0}\n'  # kept for the resume
