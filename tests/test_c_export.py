"""C code of the learning filters: the same numbers as Python, sections canonical, CLI files."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.app.output import OutputFolder, Provenance
from ilcdob.design.c_export import c_code, check_c_prefix, default_c_prefix, design_files, reference_trial
from ilcdob.design.export import DIRECT_FORM_RTOL, apply_coefficients, direct_form_disagreement
from ilcdob.design.pair import design_pair
from ilcdob.errors import SpecError
from ilcdob.fleet import default_fleet, load_fleet

# Third-order plants differing in lag at Ts = 0.01 s; C has a 3-sample input delay.
LAGGED_FLEET = """\
sample_time = 0.01
[[system]]
name = "A"
plant = { num = [1.0], den = [0.05, 1.0, 0.0, 0.0] }
controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }

[[system]]
name = "B"
plant = { num = [1.0], den = [0.2, 1.0, 0.0, 0.0] }
controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }

[[system]]
name = "C"
plant = { num = [1.0], den = [0.12, 1.0, 0.0, 0.0] }
delay = 0.03
controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }
"""

CFLAGS = ["-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror", "-ffp-contract=off"]


@pytest.fixture(scope="module")
def cc() -> str:
    path = shutil.which("cc")
    if path is None:
        pytest.skip("no C compiler: `cc` is not on PATH, the emitted C code cannot be compiled")
    return path


@pytest.fixture(scope="module")
def lagged_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("fleet") / "lagged.toml"
    path.write_text(LAGGED_FLEET, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def lagged(lagged_file):
    return load_fleet(lagged_file)


@pytest.fixture(scope="module")
def delayed_design(lagged):
    """L1 of C -> A inverts C's delayed loop: the largest advance of the lagged fleet."""
    return design_pair(lagged, "C", "A").filters


def _driver(prefix: str, with_float: bool) -> str:
    """Read samples from stdin; print L1, L2 (double), L1 in place, and L1, L2 in float."""
    floats = ""
    if with_float:
        floats = (f"    for (k = 0; k < n; ++k) uf[k] = (float)u[k];\n"
                  f"    {prefix}l1_apply_f(uf, f1, n);\n    {prefix}l2_apply_f(uf, f2, n);\n")
    out_f = ', (double)f1[k], (double)f2[k]' if with_float else ", 0.0, 0.0"
    return f"""#include <stdio.h>
#include "filters.h"
#define NMAX 4096
static double u[NMAX], y1[NMAX], y2[NMAX], w[NMAX];
static float uf[NMAX], f1[NMAX], f2[NMAX];
int main(void)
{{
    size_t n = 0, k;
    double v;
    while (n < NMAX && scanf("%lf", &v) == 1)
        u[n++] = v;
    {prefix}l1_apply(u, y1, n);
    {prefix}l2_apply(u, y2, n);
    for (k = 0; k < n; ++k)
        w[k] = u[k];
    {prefix}l1_apply(w, w, n);
{floats}    for (k = 0; k < n; ++k)
        printf("%.17g %.17g %.17g %.9g %.9g\\n", y1[k], y2[k], w[k]{out_f});
    (void)uf; (void)f1; (void)f2;
    return 0;
}}
"""


def _build(cc: str, folder: Path, with_float: bool, prefix: str) -> Path:
    (folder / "driver.c").write_text(_driver(prefix, with_float))
    exe = folder / "driver"
    res = subprocess.run([cc, *CFLAGS, f"-I{folder}", str(folder / "driver.c"), str(folder / "filters.c"), "-o",
                          str(exe)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return exe


def _run(exe: Path, x: np.ndarray) -> np.ndarray:
    res = subprocess.run([str(exe)], input="\n".join(f"{v:.17g}" for v in x), capture_output=True, text=True,
                         check=True)
    return np.loadtxt(res.stdout.splitlines(), ndmin=2)


def write_design_folder(out, filters, float_variant=False):
    """Write a design folder as ``ilcdob design`` does; returns the filters.json content."""
    files, data = design_files(filters, float_variant=float_variant)
    with OutputFolder(out, Provenance("design"), overwrite=True) as folder:
        folder.add_all(files)
    return data


def _rel(y: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(y - ref)) / np.max(np.abs(ref)))


def test_c_filters_match_python_on_a_delayed_plant(cc, delayed_design, tmp_path):
    filters = delayed_design
    assert filters["L1"]["advance"] >= 20 and "num" not in filters["L1"]
    data = write_design_folder(tmp_path, filters, float_variant=True)
    stated = data["c"]["float"]["max_relative_error"]
    exe = _build(cc, tmp_path, True, data["c"]["prefix"])
    rng = np.random.default_rng(3)
    signals = {"reference": reference_trial(filters["sample_time"]),
               "random walk": np.cumsum(rng.standard_normal(1500)) * 0.01,
               "one sample": np.array([0.3]), "shorter than the fit": rng.standard_normal(5),
               "shorter than the advance": rng.standard_normal(11)}
    for label, x in signals.items():
        out = _run(exe, x)
        for col, key in ((0, "L1"), (1, "L2")):
            ref = apply_coefficients(filters[key], x)
            assert _rel(out[:, col], ref) < 1e-9, (label, key)
        np.testing.assert_array_equal(out[:, 2], out[:, 0])   # in place: the same numbers
    # the float variant: its error on the reference trial is the one stated in the files
    x = signals["reference"]
    out = _run(exe, x)
    header = (tmp_path / "filters.h").read_text()
    for col, key in ((3, "L1"), (4, "L2")):
        err = _rel(out[:, col], apply_coefficients(filters[key], x))
        assert err == pytest.approx(stated[key], rel=0.01), key
        assert f"{stated[key]:.2e} ({key})" in header
        assert f"{stated[key]:.2e} ({key})" in (tmp_path / "README.md").read_text()


def test_c_direct_forms_match_python(cc, tmp_path):
    """Filters without sections: a FIR with advance (the fir method) and an IIR given as num/den."""
    from scipy import signal

    rng = np.random.default_rng(7)
    b, a = signal.butter(3, 0.2)
    filters = {"from": "X", "to": "Y", "method": "fir", "sample_time": 0.02,
               "L1": {"num": rng.standard_normal(12).tolist(), "den": [1.0], "advance": 5},
               "L2": {"num": b.tolist(), "den": a.tolist(), "advance": 2}}
    code = c_code(filters, prefix="xy_")
    (tmp_path / "filters.h").write_text(code.header)
    (tmp_path / "filters.c").write_text(code.source)
    exe = _build(cc, tmp_path, False, "xy_")
    for x in (rng.standard_normal(700), np.array([1.0, -2.0])):
        out = _run(exe, x)
        for col, key in ((0, "L1"), (1, "L2")):
            assert _rel(out[:, col], apply_coefficients(filters[key], x)) < 1e-12, key


def test_direct_form_written_only_when_it_matches_the_sections(lagged, fleet):
    # lagged fleet: the clustered poles of L1 ruin the multiplied-out polynomials
    for src, tgt in (("A", "B"), ("A", "C"), ("C", "A")):
        l1 = design_pair(lagged, src, tgt).filters["L1"]
        assert "num" not in l1 and "den" not in l1
        assert "disagree with the sections" in l1["num_den_omitted"] and l1["num_den_omitted"].endswith("use sos")
    # default fleet: whichever happens, written polynomials agree with the sections
    for src, tgt in (("UAV1", "UAV2"), ("UAV2", "UAV3"), ("UAV3", "UAV1")):
        filters = design_pair(fleet, src, tgt).filters
        for key in ("L1", "L2"):
            f = filters[key]
            if "num" in f:
                rel, _ = direct_form_disagreement(f["num"], f["den"], f["sos"], fleet.sample_time)
                assert rel <= DIRECT_FORM_RTOL, (src, tgt, key)
            else:
                assert "num_den_omitted" in f


def test_apply_coefficients_needs_sos_or_num_den():
    with pytest.raises(SpecError, match="neither `sos` nor `num`/`den`.*use sos"):
        apply_coefficients({"advance": 3, "num_den_omitted": "disagree; use sos"}, np.ones(20))


def test_two_pairs_link_into_one_program(cc, lagged, tmp_path):
    folders = []
    for src, tgt in (("A", "B"), ("B", "C")):
        folder = tmp_path / f"{src}{tgt}"
        write_design_folder(folder, design_pair(lagged, src, tgt).filters, float_variant=True)
        folders.append(folder)
    headers = [(f / "filters.h").read_text() for f in folders]
    assert "#ifndef ILCDOB_A_B_FILTERS_H" in headers[0] and "#ifndef ILCDOB_B_C_FILTERS_H" in headers[1]
    main_c = tmp_path / "main.c"
    main_c.write_text('#include "AB/filters.h"\n#include "BC/filters.h"\n#include "AB/filters.h"\n'
                      "int main(void)\n{\n    double x[40] = {0.0};\n    float xf[40] = {0.0f};\n"
                      "    ilcdob_a_b_l1_apply(x, x, 40);\n    ilcdob_b_c_l1_apply(x, x, 40);\n"
                      "    ilcdob_a_b_l2_apply_f(xf, xf, 40);\n    ilcdob_b_c_l2_apply_f(xf, xf, 40);\n"
                      "    return (int)(x[39] + xf[39]) + ILCDOB_A_B_L2_ADVANCE + ILCDOB_B_C_L2_ADVANCE;\n}\n")
    exe = tmp_path / "both"
    res = subprocess.run([cc, *CFLAGS, f"-I{tmp_path}", str(main_c), *(str(f / "filters.c") for f in folders),
                          "-o", str(exe)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert subprocess.run([str(exe)]).returncode == 0


def test_c_prefix_is_checked(tmp_path, capsys):
    for bad in ("9lives_", "uav-1_", "_uav_", ""):
        out = tmp_path / "bad"
        assert main(["design", "--from", "UAV1", "--to", "UAV2", "--c-prefix", bad, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "--c-prefix" in err and repr(bad) in err and "C identifier" in err
        assert not out.exists()
    assert check_c_prefix("uav1_uav2_") == "uav1_uav2_"
    assert default_c_prefix("UAV 1", "Tarot-650") == "ilcdob_uav_1_tarot_650_"


def test_design_cli_writes_the_folder(lagged_file, tmp_path, capsys):
    out = tmp_path / "ab"
    assert main(["design", "--fleet", str(lagged_file), "--from", "A", "--to", "B", "--out", str(out)]) == 0
    assert {p.name for p in out.iterdir()} == {"filters.json", "filters.h", "filters.c", "README.md", "manifest.json"}
    filters = json.loads((out / "filters.json").read_text())
    assert filters["c"]["prefix"] == "ilcdob_a_b_" and "float" not in filters["c"]
    assert "num_den_omitted" in filters["L1"]
    readme = (out / "README.md").read_text()
    for needed in ("filters.json", "filters.h", "filters.c", "ilcdob_a_b_l1_apply", "ilcdob_a_b_l2_apply",
                   "0.01 s", "m/s^2"):
        assert needed in readme, needed
    capsys.readouterr()
    # a chosen prefix and the float variant
    out2 = tmp_path / "mine"
    assert main(["design", "--fleet", str(lagged_file), "--from", "A", "--to", "B", "--c-prefix", "ab_",
                 "--c-float", "--out", str(out2)]) == 0
    header = (out2 / "filters.h").read_text()
    assert "void ab_l1_apply_f(const float *u, float *y, size_t n);" in header and "#ifndef AB_FILTERS_H" in header
    assert set(json.loads((out2 / "filters.json").read_text())["c"]["float"]["max_relative_error"]) == {"L1", "L2"}
    # a lifted method: no C code, the README lists what is there
    out3 = tmp_path / "no"
    assert main(["design", "--fleet", str(lagged_file), "--from", "A", "--to", "B", "--method", "norm-optimal",
                 "--n", "40", "--out", str(out3)]) == 0
    assert {p.name for p in out3.iterdir()} == {"filters.json", "lifted.npz", "README.md", "manifest.json"}
    assert "lifted.npz" in (out3 / "README.md").read_text()


def test_default_fleet_code_compiles_cleanly(cc, tmp_path):
    filters = design_pair(default_fleet(), "UAV1", "UAV3").filters
    data = write_design_folder(tmp_path, filters, float_variant=True)
    exe = _build(cc, tmp_path, True, data["c"]["prefix"])
    x = reference_trial(filters["sample_time"])
    out = _run(exe, x)
    assert _rel(out[:, 0], apply_coefficients(filters["L1"], x)) < 1e-9
