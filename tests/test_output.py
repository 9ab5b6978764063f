"""The one results writer (ilcdob.app.output): folders written as a unit, standard JSON, provenance."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from matplotlib.figure import Figure

from ilcdob.app.output import (MANIFEST, OutputError, OutputFolder, Provenance, check_output_path, read_manifest,
                               write_file)
from ilcdob.errors import NumericalError


def _write(out: Path, tag: str, names: list[str]) -> None:
    with OutputFolder(out, Provenance("test", [tag])) as folder:
        folder.add_all({n: f"{tag} {n}\n" for n in names})


def test_a_folder_is_replaced_as_a_whole_and_stale_files_go(tmp_path):
    out = tmp_path / "out"
    _write(out, "first", ["a.txt", "b.txt"])
    _write(out, "second", ["a.txt"])
    assert sorted(p.name for p in out.iterdir()) == ["a.txt", MANIFEST]
    assert (out / "a.txt").read_text() == "second a.txt\n"
    manifest = read_manifest(out)
    assert manifest["arguments"] == ["second"] and set(manifest["files"]) == {"a.txt"}
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no staging folder left


def test_a_failure_leaves_the_previous_folder(tmp_path):
    out = tmp_path / "out"
    _write(out, "first", ["a.txt"])
    with pytest.raises(RuntimeError):
        with OutputFolder(out, Provenance("test")) as folder:
            folder.add("a.txt", "new")
            raise RuntimeError("the command failed")
    assert (out / "a.txt").read_text() == "first a.txt\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_content_types_and_figures(tmp_path):
    fig = Figure(figsize=(2, 2))
    fig.subplots().plot([0, 1], [1, 0])
    with OutputFolder(tmp_path / "out", Provenance("test")) as folder:
        folder.add_all({"x.json": {"a": [1, 2.5, None]}, "f.png": fig, "b.bin": b"\x00\x01",
                        "sub/c.txt": "c", "w.txt": lambda path: path.write_text("w")})
    out = tmp_path / "out"
    assert json.loads((out / "x.json").read_text()) == {"a": [1, 2.5, None]}
    assert (out / "f.png").read_bytes().startswith(b"\x89PNG")
    assert (out / "b.bin").read_bytes() == b"\x00\x01" and (out / "sub/c.txt").read_text() == "c"
    assert (out / "w.txt").read_text() == "w"


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_non_finite_json_is_refused_with_its_location(tmp_path, bad):
    with pytest.raises(NumericalError, match=r"scenarios\[1\]\.rmse"):
        write_file(tmp_path / "r.json", {"scenarios": [{"rmse": 1.0}, {"rmse": bad}]})
    assert not any(tmp_path.iterdir())


def test_foreign_folders_are_not_replaced_without_overwrite(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("months of work")
    with pytest.raises(OutputError, match="thesis.tex.*--overwrite"):
        OutputFolder(out, Provenance("test"))
    assert (out / "thesis.tex").exists()
    with OutputFolder(out, Provenance("test"), overwrite=True) as folder:
        folder.add("a.txt", "a")
    assert sorted(p.name for p in out.iterdir()) == ["a.txt", MANIFEST]


def test_output_locations_are_checked_before_any_work(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="is a file; expected a folder"):
        check_output_path(tmp_path / "file", folder=True)
    with pytest.raises(OutputError, match="is a folder; expected a file name"):
        check_output_path(tmp_path, folder=False)
    with pytest.raises(OutputError, match="cannot be created"):
        check_output_path(tmp_path / "file" / "sub" / "out", folder=True)
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        with pytest.raises(OutputError, match="not writable"):
            check_output_path(ro / "out", folder=True)


def test_a_symlinked_output_folder_keeps_its_link(tmp_path):
    real, link = tmp_path / "real", tmp_path / "link"
    _write(real, "first", ["a.txt"])
    link.symlink_to(real, target_is_directory=True)
    _write(link, "second", ["b.txt"])
    assert link.is_symlink() and (link / "b.txt").read_text() == "second b.txt\n"
    assert sorted(p.name for p in real.iterdir()) == ["b.txt", MANIFEST]


def test_kept_files_are_carried_into_the_new_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "samples.jsonl").write_text("{}\n")  # an unfinished run's store: ours, not foreign
    with OutputFolder(out, Provenance("test"), keep=["samples.jsonl"]) as folder:
        folder.add("summary.json", {"n": 1})
    assert (out / "samples.jsonl").read_text() == "{}\n"
    assert set(read_manifest(out)["files"]) == {"summary.json", "samples.jsonl"}


_SLOW_WRITER = """
import sys, time
from pathlib import Path
from ilcdob.app.output import OutputFolder, Provenance
out, tag = Path(sys.argv[1]), sys.argv[2]
with OutputFolder(out, Provenance("test", [tag])) as folder:
    for i in range(40):
        folder.add(f"f{i:02d}.txt", f"{tag} {i}\\n" * 2000)
        time.sleep(0.005)
"""


def _complete(out: Path) -> str:
    """The tag of the run whose complete output ``out`` holds (fails on a mix or a partial folder)."""
    manifest = read_manifest(out)
    assert manifest is not None, sorted(p.name for p in out.iterdir())
    tag = manifest["arguments"][0]
    names = sorted(p.name for p in out.iterdir() if p.name != MANIFEST)
    assert names == [f"f{i:02d}.txt" for i in range(40)]
    assert all((out / n).read_text().startswith(f"{tag} ") for n in names)
    return tag


@pytest.mark.parametrize("delay", [0.02, 0.08, 0.15, 0.25, 0.4])
def test_sigkill_at_any_point_leaves_one_complete_run(tmp_path, delay):
    out = tmp_path / "out"
    subprocess.run([sys.executable, "-c", _SLOW_WRITER, str(out), "old"], check=True)
    proc = subprocess.Popen([sys.executable, "-c", _SLOW_WRITER, str(out), "new"])
    time.sleep(delay)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert _complete(out) in ("old", "new")
    # the next run removes the killed run's staging folder
    subprocess.run([sys.executable, "-c", _SLOW_WRITER, str(out), "next"], check=True)
    assert _complete(out) == "next"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
