"""Names are data, never code or paths; the report trusts nothing it reads.

Hostile system names (comment terminators, line splices, ``<script>``, quotes, path
separators, ``..``, NUL, very long and non-ASCII names) are refused where fleets are read,
naming the file, the name and the rule; every emitter escapes for its target anyway (C code
that compiles with no injected macro, HTML without a raw ``<script>``, file names, CSV
fields). ``ilcdob report`` refuses a folder holding a file its manifest does not list or
lists with another hash, and a JSON input whose fields have the wrong type or that is not
standard JSON, each with exit status 2 and a message naming the file and the key.
"""

from __future__ import annotations

import csv
import hashlib
import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from ilcdob.app.cli import main
from ilcdob.app.commands import reproduce_to_folder
from ilcdob.app.html import ReportError, build_report
from ilcdob.design.export.c_export import c_code
from ilcdob.design.pair import design_pair
from ilcdob.errors import FleetError
from ilcdob.fleet import load_fleet
from ilcdob.fleet_io import toml_value
from ilcdob.names import NAME_MAX_LENGTH, c_comment, c_identifier, check_name, csv_field, file_name, html_text

INJECTED = "#define ILCDOB_INJECTED_MACRO 42"
HOSTILE = {
    "comment terminator": "UAV*/x",
    "comment opener": "UAV/*x",
    "backslash-newline splice": f"x*\\\n/\n{INJECTED}\n/*",
    "trigraph splice": f"x*??/\n/\n{INJECTED}\n/*",
    "script": "<script>alert(1)</script>",
    "double quote": 'UAV"1',
    "single quote": "UAV'1",
    "slash": "a/b",
    "backslash": "a\\b",
    "dot dot": "..",
    "parent path": "../evil",
    "NUL": "UAV\x001",
    "newline": "UAV\n1",
    "very long": "U" * 10_000,
    "non-ASCII": "Drohne-\u00dc",
    "right-to-left override": "UAV\u202e1",
    "leading space": " UAV1",
    "trailing dot": "UAV1.",
    "empty": "",
}
#: Names of the built-in fleet, the README, the examples and the tests: all follow the rule.
IN_USE = ["UAV1", "UAV2", "UAV3", "UAV4", "UAV5", "A", "B1", "crazyflie", "px4", "hummingbird", "tf_direct",
          "UAV 1", "Tarot-650", "heavy", "x.y+z_1", "N" * NAME_MAX_LENGTH]

SYSTEM = ("plant = { num = [1.0], den = [0.05, 1.0, 0.0, 0.0] }\n"
          "controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }\n"
          "dob = { q_order = 3, q_time_constant = 0.15 }\n")


def _fleet_text(*names: str) -> str:
    return "sample_time = 0.02\n" + "".join(f"[[system]]\nname = {toml_value(n)}\n{SYSTEM}" for n in names)


# ------------------------------------------------------------------------------ the name rule

@pytest.mark.parametrize("label", list(HOSTILE))
def test_a_fleet_file_with_a_hostile_name_is_refused_naming_file_name_and_rule(tmp_path, label):
    name = HOSTILE[label]
    path = tmp_path / "fleet.toml"
    path.write_text(_fleet_text("UAV1", name), encoding="utf-8")
    with pytest.raises(FleetError) as err:
        load_fleet(path)
    msg = str(err.value)
    assert str(path) in msg and "system #2" in msg and "a system name is 1 to 64 characters" in msg, msg
    assert repr(name[:60]) in msg and len(msg) < 800, msg  # the value, shortened when long
    assert "\n" not in msg and "\x00" not in msg  # control characters shown escaped


def test_names_in_use_follow_the_rule_and_pass_every_escape_unchanged(tmp_path):
    path = tmp_path / "fleet.toml"
    path.write_text(_fleet_text(*IN_USE), encoding="utf-8")
    assert load_fleet(path).names == IN_USE
    for name in IN_USE:
        assert check_name(name) == name
        assert file_name(name) == name and csv_field(name) == name and c_comment(name) == name
        assert html_text(name) == name
    with pytest.raises(FleetError, match=r"got 'N{60}'\.\.\. \(65 characters\): it has 65 characters"):
        path.write_text(_fleet_text("N" * 65), encoding="utf-8")
        load_fleet(path)


def _model_json(path: Path) -> Path:
    """A model.json as `ilcdob identify` writes it: 7.4 / (s^2 (s + 7.2))."""
    cov = [[4e-4, 3.5e-4], [3.5e-4, 3.8e-4]]
    path.write_text(json.dumps({
        "num": [7.4], "den": [1.0, 7.2, 0.0, 0.0], "delay": 0.0,
        "structure": {"poles": 3, "zeros": 0, "integrators": 2},
        "parameters": [7.2, 7.4], "std": [0.02, 0.0195], "delay_estimated": False,
        "fit_percent": {"estimation": 98.5, "validation": 97.25}, "covariance": cov, "noise_variance": 1e-6,
        "sample_time": 0.02, "residuals": {"whiteness_inside_99": 1.0, "input_correlation_inside_99": 1.0},
        "signals": {"input": "acc_cmd", "output": "x"}, "solver": {"status": "converged"},
        "files": {"estimation": ["chirp.csv"], "validation": []}}), encoding="utf-8")
    return path


@pytest.mark.parametrize("label", ["backslash-newline splice", "script", "parent path", "NUL", "non-ASCII"])
def test_fleet_add_refuses_a_hostile_name_and_writes_nothing(tmp_path, capsys, label):
    model = _model_json(tmp_path / "uav4.json")
    fleet = tmp_path / "fleet.toml"
    args = ["--model", str(model), "--kp", "1.2", "--ki", "0.12", "--kd", "1.53", "--q-order", "3",
            "--q-time-constant", "0.15"]
    assert main(["fleet", "add", str(fleet), "--name", HOSTILE[label], *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ilcdob: error: ") and err.count("\n") == 1, err
    assert str(fleet) in err and "a system name is" in err and repr(HOSTILE[label]) in err, err
    assert not fleet.exists()
    assert main(["fleet", "add", str(fleet), "--name", "UAV 4", *args]) == 0  # a valid name is added
    assert load_fleet(fleet).names == ["UAV 4"]


# ------------------------------------------------------------------------------ every emitter escapes

def test_every_escape_neutralises_every_hostile_name():
    seen_files = set()
    for label, name in HOSTILE.items():
        comment = c_comment(name)
        assert all(" " <= ch <= "~" for ch in comment), label
        assert not any(s in comment for s in ("*/", "/*", "\\", "??")), (label, comment)
        assert re.fullmatch(r"[A-Za-z0-9_]*", c_identifier(name)), label
        text = html_text(name)
        assert not any(ch in text for ch in "<>\"'\x00"), (label, text)
        assert html.unescape(text) == name.replace("\x00", "\ufffd"), label
        fname = file_name(name)
        assert fname not in ("", ".", "..") and not any(ch in fname for ch in "/\\\x00\n"), (label, fname)
        assert len(fname) <= NAME_MAX_LENGTH and (fname[0].isalnum() or fname[0] == "_"), (label, fname)
        seen_files.add(fname)
        field = csv_field(name)
        rows = list(csv.reader([f"time,{field},x"]))
        assert "\n" not in field and "\r" not in field and len(rows) == 1 and len(rows[0]) == 3, (label, field)
    assert len(seen_files) == len(HOSTILE)  # two different names never share a file


@pytest.mark.parametrize("label", ["backslash-newline splice", "trigraph splice", "comment opener",
                                   "right-to-left override"])
def test_c_code_of_a_hostile_name_compiles_and_defines_nothing_injected(cc, fleet, tmp_path, label):
    filters = design_pair(fleet, "UAV1", "UAV2").filters
    # as if filters.json had been edited: the name rule never saw these
    code = c_code({**filters, "from": HOSTILE[label], "to": f"UAV2 {HOSTILE[label]}", "method": HOSTILE[label]})
    assert re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", code.prefix)
    for text in (code.header, code.source):
        assert not any(line.lstrip().startswith(INJECTED) for line in text.splitlines())
    (tmp_path / "filters.h").write_text(code.header, encoding="utf-8")
    (tmp_path / "filters.c").write_text(code.source, encoding="utf-8")
    (tmp_path / "probe.c").write_text('#include "filters.h"\n#ifdef ILCDOB_INJECTED_MACRO\n#error injected\n#endif\n'
                                      "int probe(void);\n", encoding="utf-8")
    for source in ("filters.c", "probe.c"):  # -std=c99 reads trigraphs
        run = subprocess.run([cc, "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-fsyntax-only",
                              f"-I{tmp_path}", str(tmp_path / source)], capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, (source, run.stderr[-2000:])


# ------------------------------------------------------------------------------ the report trusts nothing

@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A small `ilcdob reproduce` folder (scenario 4, one iteration, no figures)."""
    out = tmp_path_factory.mktemp("run") / "run"
    reproduce_to_folder(out, fleet=None, scenarios=[4], iterations=1, figures=False)
    return out


def _copy(run_dir: Path, tmp_path: Path) -> Path:
    folder = tmp_path / "run"
    shutil.copytree(run_dir, folder)
    return folder


def _edit(folder: Path, name: str, change) -> None:
    """Edit the JSON file ``name`` with ``change(data)`` and rehash it in the manifest, as a forger would."""
    path = folder / name
    data = json.loads(path.read_text(encoding="utf-8"))
    change(data)
    _replace(folder, name, json.dumps(data).encode())


def _replace(folder: Path, name: str, content: bytes, *, listed: bool = True) -> None:
    (folder / name).parent.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(content)
    manifest = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    if listed:
        manifest["files"][name] = hashlib.sha256(content).hexdigest()
    else:
        manifest["files"].pop(name, None)
    (folder / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")


def _report_error(capsys, folder: Path, tmp_path: Path) -> str:
    out = tmp_path / "report.html"
    assert main(["report", str(folder), "--out", str(out)]) == 2
    assert not out.exists()
    lines = capsys.readouterr().err.splitlines()
    # the sections rendered before the failing one are progress lines; the error is one line, no traceback
    assert lines and lines[-1].startswith("ilcdob: error: ") and all(ln.startswith("[") for ln in lines[:-1]), lines
    return lines[-1] + "\n"


def test_every_value_of_the_report_is_escaped(run_dir, tmp_path, capsys):
    folder = _copy(run_dir, tmp_path)
    script = "<script>alert(1)</script>"

    def theorem(data):
        data["orders"][0]["order"][0] = script
        data["orders"][0]["table"] = script
        data["orders"][0]["pairs"][0].update(source=script, statement=script)

    _edit(folder, "theorem.json", theorem)
    _edit(folder, "results.json", lambda d: d["scenarios"][0].update(title=script))
    _edit(folder, "fleet.json", lambda d: d.update(source=script, header=[script] + d["header"][1:]))
    other = tmp_path / "compare"
    other.mkdir()
    (other / "compare.json").write_text(json.dumps({script: script, "methods": {script: {script: 1.0, "x": script}}}))
    page = build_report([folder, other]).lower()
    assert "<script" not in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    # a number field holding markup is refused, not rendered
    _edit(folder, "theorem.json", lambda d: d.update(samples=script))
    err = _report_error(capsys, folder, tmp_path)
    assert "theorem.json" in err and 'key "samples"' in err and "expected an integer >= 1" in err, err


def test_a_file_the_manifest_does_not_list_is_refused_naming_it(run_dir, tmp_path, capsys):
    folder = _copy(run_dir, tmp_path)
    # forged numbers in results.json, dropped from the manifest so that no hash can disagree
    data = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    data["scenarios"][0]["systems"]["UAV1"]["rmse_dob"] = 1e-9
    _replace(folder, "results.json", json.dumps(data).encode(), listed=False)
    err = _report_error(capsys, folder, tmp_path)
    assert "results.json" in err and "is not listed in manifest.json" in err and "ilcdob reproduce" in err, err
    # a file added beside the run's files, also in a subfolder
    for extra in ("notes.txt", "sub/rmse_bars.png"):
        folder = _copy(run_dir, tmp_path / extra.replace("/", "_"))
        (folder / extra).parent.mkdir(parents=True, exist_ok=True)
        (folder / extra).write_text("x")
        with pytest.raises(ReportError, match=rf"{re.escape(extra)} is not listed in manifest\.json"):
            build_report([folder])


@pytest.mark.parametrize("change, words", [
    (lambda m: m.update(files=[]), ['key "files"', "expected an object"]),
    (lambda m: m.update(arguments=5), ['key "arguments"', "expected a list of texts"]),
    (lambda m: m["files"].update({"../outside.json": "0" * 64}), ["'../outside.json'", "not a relative path"]),
    (lambda m: m["files"].update({"results.json": "not a hash"}), ['files.results.json', "SHA-256"]),
    (lambda m: m.update(writer="someone"), ['key "writer"', "expected 'ilcdob'"]),
], ids=["files", "arguments", "outside", "hash", "writer"])
def test_a_malformed_manifest_is_refused(run_dir, tmp_path, capsys, change, words):
    folder = _copy(run_dir, tmp_path)
    manifest = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    change(manifest)
    (folder / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    err = _report_error(capsys, folder, tmp_path)
    assert "manifest.json" in err and all(w in err for w in words), err


def _set_rmse(d):
    d["scenarios"][0]["systems"]["UAV1"]["rmse_dob"] = "0.0001"


def _set_band(d):
    d["orders"][0]["pairs"][0]["failing_band"] = ["low", "high"]


@pytest.mark.parametrize("name, change, key", [
    ("results.json", _set_rmse, "scenarios[0].systems.UAV1.rmse_dob"),
    ("results.json", lambda d: d.update(iterations=7), "iterations"),
    ("results.json", lambda d: d["scenarios"][0].update(id="../../secret"), "scenarios[0].id"),
    ("results.json", lambda d: d["scenarios"][0].update(order=["UAV1", 2]), "scenarios[0].order"),
    ("fleet.json", lambda d: d.update(sample_time="fast"), "sample_time"),
    ("fleet.json", lambda d: d["rows"].__setitem__(0, 5), "rows[0]"),
    ("theorem.json", _set_band, "orders[0].pairs[0].failing_band"),
    ("theorem.json", lambda d: d["orders"][0]["pairs"][0].update(holds_everywhere="yes"),
     "orders[0].pairs[0].holds_everywhere"),
])
def test_a_field_of_the_wrong_type_is_refused_naming_file_and_key(run_dir, tmp_path, capsys, name, change, key):
    folder = _copy(run_dir, tmp_path)
    _edit(folder, name, change)
    err = _report_error(capsys, folder, tmp_path)
    assert f"{name}: key \"{key}\": got" in err and "regenerate it with" in err, err


@pytest.mark.parametrize("text, words", [
    (b'{"plant": "linear", "sample_time": NaN, "scenarios": []}', ["not valid JSON", "NaN"]),
    (b'{"plant": "linear", "sample_time": 1e999, "scenarios": []}', ["not valid JSON", "out of range"]),
    (b'{"plant": "linear", "iterations": ' + b"1" * 5000 + b', "scenarios": []}', ["not valid JSON"]),
    (b'{"plant": "linear", "scenarios": [], "x": ' + b"[" * 5000 + b"]" * 5000 + b"}", ["results.json"]),
], ids=["NaN", "overflow", "huge integer", "deep nesting"])
def test_results_json_that_is_not_standard_json_is_refused(run_dir, tmp_path, capsys, text, words):
    folder = _copy(run_dir, tmp_path)
    _replace(folder, "results.json", text)
    err = _report_error(capsys, folder, tmp_path)
    assert "results.json" in err and all(w in err for w in words), err


def test_a_figure_that_does_not_decode_is_refused_naming_it(run_dir, tmp_path, capsys):
    folder = _copy(run_dir, tmp_path)
    _replace(folder, "rmse_bars.png", b"\x89PNG\r\n\x1a\n" + b"\x00" * 64)
    err = _report_error(capsys, folder, tmp_path)
    assert "rmse_bars.png: not a readable PNG figure" in err and "regenerate" in err, err
