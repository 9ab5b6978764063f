"""C code of the learning filters: the same numbers as Python, sections canonical, CLI files."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.app.output import OutputFolder, Provenance
from ilcdob.design.export.c_export import c_code, check_c_prefix, default_c_prefix, design_files, reference_trial
from ilcdob.design.law import apply_learning
from ilcdob.design.filters.coefficients import (DIRECT_FORM_RTOL, apply_coefficients, apply_lookahead,
                                                coefficients_freqresp, direct_form_disagreement, section_growth,
                                                zpk_to_coefficients)
from ilcdob.design.filters.noncausal import ZPKFilter, lookahead
from ilcdob.design.pair import design_pair
from ilcdob.design.law.limit import LearningLimitWarning
from ilcdob.errors import SpecError
from ilcdob.fleet import default_fleet, load_fleet
from ilcdob.signals import extend_smoothly

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
#define NMAX 12000
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


def _learn_driver(prefix: str) -> str:
    """Read n, then n samples of e and n of df_prev from stdin; print the return codes, then per
    sample learn's output into a separate array, in place over e and in place over df_prev."""
    p, m = prefix, prefix.upper()
    return f"""#include <stdio.h>
#include "filters.h"
#define NMAX 6000
static double e[NMAX], df[NMAX], out[NMAX], in_e[NMAX], in_df[NMAX], work[{m}LEARN_WORK(NMAX)];
int main(void)
{{
    unsigned long count = 0;
    size_t n, k;
    int empty, null_e, null_df, null_out, null_work, rc, rc_e, rc_df;

    if (scanf("%lu", &count) != 1 || count > NMAX)
        return 9;
    n = (size_t)count;
    for (k = 0; k < 2 * n; ++k)
        if (scanf("%lf", k < n ? &e[k] : &df[k - n]) != 1)
            return 9;
    out[0] = 12345.0;
    empty = {p}learn(e, df, out, 0, work);
    null_e = {p}learn(NULL, df, out, n, work);
    null_df = {p}learn(e, NULL, out, n, work);
    null_out = {p}learn(e, df, NULL, n, work);
    null_work = {p}learn(e, df, out, n, NULL);
    printf("%d %d %d %d %d %d\\n", empty, null_e, null_df, null_out, null_work, out[0] == 12345.0);
    for (k = 0; k < n; ++k) {{
        in_e[k] = e[k];
        in_df[k] = df[k];
    }}
    rc = {p}learn(e, df, out, n, work);
    rc_e = {p}learn(in_e, df, in_e, n, work);
    rc_df = {p}learn(e, in_df, in_df, n, work);
    printf("%d %d %d\\n", rc, rc_e, rc_df);
    for (k = 0; k < n; ++k)
        printf("%.17g %.17g %.17g\\n", out[k], in_e[k], in_df[k]);
    return 0;
}}
"""


def _build_learn(cc: str, folder: Path, filters: dict, prefix: str = "p_") -> Path:
    """Write ``filters.h``/``filters.c`` of ``filters`` into ``folder`` and compile the learn driver."""
    code = c_code(filters, prefix=prefix)
    (folder / "filters.h").write_text(code.header)
    (folder / "filters.c").write_text(code.source)
    (folder / "learn.c").write_text(_learn_driver(prefix))
    exe = folder / "learn"
    res = subprocess.run([cc, *CFLAGS, f"-I{folder}", str(folder / "learn.c"), str(folder / "filters.c"), "-o",
                          str(exe), "-lm"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return exe


def _run_learn(exe: Path, e: np.ndarray, df: np.ndarray, code: str = "0") -> np.ndarray:
    """``learn(e, df)`` by the compiled driver; checks its return codes (``code``: of each call on the
    trial, 3 when it clipped to the acceleration limit) and that in place gives the same."""
    text = "\n".join([str(e.size), *(f"{v:.17g}" for v in np.concatenate([e, df]))])
    res = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
    lines = res.stdout.splitlines()
    assert lines[0].split() == ["1", "2", "2", "2", "2", "1"]   # n == 0, each NULL pointer; nothing written
    assert lines[1].split() == [code] * 3
    out = np.loadtxt(lines[2:], ndmin=2)
    np.testing.assert_array_equal(out[:, 1], out[:, 0])   # df_next == e: the same numbers
    np.testing.assert_array_equal(out[:, 2], out[:, 0])   # df_next == df_prev
    return out[:, 0]


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
                      "    static double work[ILCDOB_A_B_LEARN_WORK(40) + ILCDOB_B_C_LEARN_WORK(40)];\n"
                      "    int rc = ilcdob_a_b_learn(x, x, x, 40, work) + ilcdob_b_c_learn(x, x, x, 40, work);\n"
                      "    return rc + (int)(x[39] + xf[39]) + ILCDOB_A_B_L2_ADVANCE + ILCDOB_B_C_L2_ADVANCE;\n}\n")
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
    assert {p.name for p in out.iterdir()} == {"filters.json", "filters.h", "filters.c", "filters.mat", "README.md",
                                               "bode.png", "manifest.json"}
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
    assert {p.name for p in out3.iterdir()} == {"filters.json", "lifted.npz", "README.md", "bode.png", "manifest.json"}
    assert "lifted.npz" in (out3 / "README.md").read_text()


def test_default_fleet_code_compiles_cleanly(cc, tmp_path):
    filters = design_pair(default_fleet(), "UAV1", "UAV3").filters
    data = write_design_folder(tmp_path, filters, float_variant=True)
    exe = _build(cc, tmp_path, True, data["c"]["prefix"])
    x = reference_trial(filters["sample_time"])
    out = _run(exe, x)
    assert _rel(out[:, 0], apply_coefficients(filters["L1"], x)) < 1e-9


# --------------------------------------------------------------------------- the learning law in C


@pytest.fixture(scope="module")
def learn_designs():
    """Closed-form UAV1 -> UAV2 designs: a stated band, the band with the airframe correction, no band."""
    fleet = default_fleet()
    return {"band": design_pair(fleet, "UAV1", "UAV2", band=10.0),
            "band + airframe": design_pair(fleet, "UAV1", "UAV2", band=10.0, disturbance="airframe"),
            "no band": design_pair(fleet, "UAV1", "UAV2", band=None),
            "no band + airframe": design_pair(fleet, "UAV1", "UAV2", band=None, disturbance="airframe")}


@pytest.fixture(scope="module")
def fir_design():
    """The FIR design of UAV1 -> UAV2 with a band (about 5 s)."""
    return design_pair(default_fleet(), "UAV1", "UAV2", method="fir", band=10.0)


def _learn_trials(ts: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Trials (e in m, df_prev in m/s^2): a noisy one with a learning signal flown, and ones shorter
    than the band's pad and end fit (5 samples) down to a single sample."""
    rng = np.random.default_rng(11)
    t = np.arange(1500) * ts
    e = 0.01 * np.sin(0.7 * t) + 0.003 * np.sin(2.1 * t + 0.3) + 5e-4 * rng.standard_normal(t.size)
    df = 0.2 * np.sin(0.4 * t + 1.0) + 0.01 * rng.standard_normal(t.size)
    return {"noisy, df flown": (e, df), "5 samples": (rng.standard_normal(5) * 0.01, rng.standard_normal(5) * 0.1),
            "2 samples": (np.array([0.004, -0.002]), np.array([0.1, 0.3])),
            "1 sample": (np.array([0.003]), np.array([-0.2]))}


def _check_learn(exe: Path, design) -> dict[str, tuple[float, float]]:
    """C learn against apply_learning (1e-12) and against the design's own Python law (1e-9).

    Both the Python law and C learn clip to the learning vehicle's acceleration limit (C returns
    LEARN_CLIPPED, 3): a trial whose learning signal goes beyond it is checked clipped against both,
    then scaled down (the law is linear) for the comparison of the unclipped law. Returns the two
    measured errors per trial.
    """
    filters = design.filters
    lim = design.limits.max_acceleration if design.limits is not None else np.inf
    measured = {}
    for label, (e, df) in _learn_trials(filters["sample_time"]).items():
        ref = apply_learning(filters, e, df)
        peak = np.max(np.abs(ref))
        if peak > lim:
            y = _run_learn(exe, e, df, code="3")
            assert _rel(y, np.clip(ref, -lim, lim)) < 1e-12, label
            with pytest.warns(LearningLimitWarning):
                assert _rel(y, design.learn(e, df)) < 1e-9, label
            scale = 0.5 * lim / peak
            e, df = scale * e, scale * df
            ref = apply_learning(filters, e, df)
        y = _run_learn(exe, e, df)
        measured[label] = (_rel(y, ref), _rel(y, design.learn(e, df)))
        assert measured[label][0] < 1e-12, (label, measured[label])
        assert measured[label][1] < 1e-9, (label, measured[label])
    return measured


@pytest.mark.parametrize("case", ["band", "band + airframe", "no band", "no band + airframe"])
def test_c_learn_matches_python(cc, learn_designs, case, tmp_path):
    design = learn_designs[case]
    band = design.filters["band"]
    assert (band.get("sos") is not None) == case.startswith("band")
    assert ("W" in design.filters["disturbance"]) == case.endswith("airframe")
    if case.startswith("band"):
        assert band["pad"] > 5 and band["end_fit"] > 5   # the 5-sample trial is shorter than both
    _check_learn(_build_learn(cc, tmp_path, design.filters), design)


def test_c_learn_matches_python_for_a_fir_design(cc, fir_design, tmp_path):
    filters = fir_design.filters
    assert "sos" not in filters["L1"] and filters["band"]["cutoff_rad_s"] == 10.0
    _check_learn(_build_learn(cc, tmp_path, filters), fir_design)


@pytest.mark.parametrize("disturbance", ["command", "airframe"])
def test_c_learn_is_the_paper_filter_times_the_band_on_a_sinusoid(cc, tmp_path, disturbance):
    """Independent of the exported coefficients: inside a long trial, a sinusoid comes out of C learn
    multiplied by L1(e^{jwTs}) |F(w)| W(e^{jwTs}), each built here from its definition.

    L1 is the paper's block formula ``-(1 - Q_j) (1/P_hat + (M + C)/(1 - Q_{j-1}))`` of the loop
    blocks evaluated at ``z = e^{jwTs}`` (python-control); ``|F| = |B|^4`` with B the Butterworth
    prototype from ``scipy.signal.butter`` at the stated corner (two forward-backward passes); W
    the ratio of the two continuous models ``P_hat_{j-1}(s)/P_hat_j(s)`` (their rigid bodies
    1/s^2 cancel: ``A_hat_{j-1}/A_hat_j``) at the Tustin map ``s = 2/Ts (z - 1)/(z + 1)``.

    L1 has a pole at z = 1 (the PID integrator): a sinusoid switched on would leave a constant
    (the integral of the switch-on) in its output. The input is therefore the first difference
    ``e(k) = g(k) - g(k-1)`` of a sinusoid ``g`` faded in over 6 s: the integrator's state is
    ``g`` itself, and past the fade ``e`` is the sinusoid of complex amplitude
    ``B (1 - e^{-jwTs})``.

    Tolerance 1e-7 of the output's amplitude. Measured: ~1e-10, what the coefficients
    reproduce of the block formula (zeros and poles from eigenvalue solvers; the integrator pole
    lands within 1e-8 of z = 1; the stable-inversion series is cut at 1e-12). The compared
    samples start two pads (12 periods of the corner) after the fade and end two pads before
    the trial's end, where F's transients (slowest decay rate ``w_c sin(pi/8)``) have fallen
    below 1e-12. 1e-7 leaves room for other LAPACK builds and is far below what a wrong law
    gives: one pass of F instead of two is off by 4e-3 at 5 rad/s, a missing W by ~1e-2.
    """
    import control as ct

    from ilcdob.design.filters.band import FILTER_ORDER
    from scipy import signal

    fleet = default_fleet()
    ts, wc = fleet.sample_time, 10.0
    design = design_pair(fleet, "UAV1", "UAV2", band=wc, disturbance=disturbance)
    pad = design.filters["band"]["pad"]
    exe = _build_learn(cc, tmp_path, design.filters)
    src, tgt = fleet.loop("UAV1").nominal, fleet.loop("UAV2")
    specs = {s.name: s.nominal_plant for s in fleet.systems}
    assert specs["UAV1"].delay == specs["UAV2"].delay

    def at(sys: ct.LTI, w: float) -> complex:
        return complex(np.squeeze(sys(np.exp(1j * w * sys.dt))))

    def l1(w: float) -> complex:
        return -(1 - at(tgt.Q, w)) * (1 / at(src.P, w) + (at(src.M, w) + at(src.C, w)) / (1 - at(src.Q, w)))

    def w_corr(w: float) -> complex:
        if disturbance == "command":
            return 1.0
        z = np.exp(1j * w * ts)
        s = 2.0 / ts * (z - 1) / (z + 1)
        p = {k: np.polyval(v.num, s) / np.polyval(v.den, s) for k, v in specs.items()}
        return p["UAV1"] / p["UAV2"]

    b, a = signal.butter(FILTER_ORDER, wc / (np.pi / ts))
    n, fade = 3000, 300
    k = np.arange(n)
    inside = slice(fade + 2 * pad, n - 2 * pad)
    for w in (0.5, 5.0, 8.0):
        amp_g = 0.01 * np.exp(0.3j)
        g = np.real(amp_g * np.exp(1j * w * k * ts)) * np.where(k < fade, np.sin(0.5 * np.pi * k / fade) ** 2, 1.0)
        e = np.diff(np.concatenate([[0.0], g]))
        amp = amp_g * (1 - np.exp(-1j * w * ts))
        gain_f = abs(signal.freqz(b, a, worN=[w * ts])[1][0]) ** 4
        expect = np.real(l1(w) * gain_f * w_corr(w) * amp * np.exp(1j * w * k * ts))
        y = _run_learn(exe, e, np.zeros(n))
        assert _rel(y[inside], expect[inside]) < 1e-7, w


def _band_filters() -> dict:
    """A small valid design with a band and the airframe correction, for breaking one entry at a time."""
    from scipy import signal

    sos = signal.butter(4, 0.2, output="sos")
    return {"from": "X", "to": "Y", "method": "closed-form", "sample_time": 0.02,
            "L1": {"sos": [[1.0, -1.0, 0.0, 1.0, -0.5, 0.0]], "advance": 2},
            "L2": {"sos": [[1.0, 0.0, 0.0, 1.0, 0.0, 0.0]], "advance": 0},
            "band": {"cutoff_rad_s": 31.4, "sos": sos.tolist(), "zi": signal.sosfilt_zi(sos).tolist(),
                     "pad": 20, "end_fit": 6},
            "disturbance": {"at": "airframe", "W": {"sos": [[1.0, -0.9, 0.0, 1.0, -0.8, 0.0]]}}}


@pytest.mark.parametrize("where, value, key", [
    ("band", [1, 2], "`band`"),
    ("band.sos", [[1.0, 2.0, 1.0, 1.0, 0.5]], "`band.sos`"),
    ("band.sos", [[1.0, 2.0, float("nan"), 1.0, 0.5, 0.1]], "`band.sos`"),
    ("band.sos", [[1.0, 2.0, 1.0, 2.0, 0.5, 0.1]], "`band.sos`"),
    ("band.zi", [[0.1, 0.2]], "`band.zi`"),
    ("band.zi", [[0.1, float("inf")]], "`band.zi`"),
    ("band.zi", None, "`band.zi`"),
    ("band.pad", -1, "`band.pad`"),
    ("band.pad", 2.5, "`band.pad`"),
    ("band.pad", True, "`band.pad`"),
    ("band.end_fit", 0, "`band.end_fit`"),
    ("band.end_fit", None, "`band.end_fit`"),
    ("band.cutoff_rad_s", None, "`band.cutoff_rad_s`"),
    ("band.cutoff_rad_s", -3.0, "`band.cutoff_rad_s`"),
    ("band.sos", None, "`band.sos`"),            # a corner without sections
    ("disturbance.W", {"num": [1.0]}, "`disturbance.W`"),
    ("disturbance.W", None, "`disturbance.W`"),  # at 'airframe' without W
    ("disturbance.W.sos", [[1.0, 0.0, 0.0, 1.0]], "`disturbance.W.sos`"),
    ("disturbance.W.sos", [[1.0, 0.0, 0.0, 0.5, 0.1, 0.0]], "`disturbance.W.sos`"),
    ("disturbance.W.sos", "loud", "`disturbance.W.sos`"),
])
def test_c_code_refuses_bad_band_and_w(where, value, key):
    filters = _band_filters()
    c_code(filters)   # the unbroken design is fine
    parts = where.split(".")
    node = filters
    for part in parts[:-1]:
        node = node[part]
    node[parts[-1]] = value
    with pytest.raises(SpecError, match="expected") as err:
        c_code(filters)
    assert str(err.value).startswith(key), str(err.value)


def test_c_learn_on_a_hand_made_band(cc, tmp_path):
    """A band of 2 sections with a short pad and end fit, W of 1 section, L1 with an advance."""
    filters = _band_filters()
    exe = _build_learn(cc, tmp_path, filters)
    rng = np.random.default_rng(5)
    for n in (400, 7, 1):
        e, df = rng.standard_normal(n), rng.standard_normal(n)
        assert _rel(_run_learn(exe, e, df), apply_learning(filters, e, df)) < 1e-12, n
    filters["band"]["pad"] = 0   # no extension: H is the trial itself
    exe = _build_learn(cc, tmp_path, filters)
    e, df = rng.standard_normal(50), rng.standard_normal(50)
    assert _rel(_run_learn(exe, e, df), apply_learning(filters, e, df)) < 1e-12


def test_header_and_readme_recommend_learn(learn_designs):
    for case, design in learn_designs.items():
        files, data = design_files(design.filters)
        header, readme = files["filters.h"], files["README.md"]
        p, m = "ilcdob_uav1_uav2_", "ILCDOB_UAV1_UAV2_"
        assert data["c"]["functions"][0] == f"{p}learn"
        assert data["c"]["learn"]["work"].startswith(f"{m}LEARN_WORK(n)")
        assert f"int {p}learn(const double *e, const double *df_prev, double *df_next, size_t n, double *work);" \
            in header
        for macro in ("PAD", "BAND_CUTOFF", "LEARN_WORK(n)", "LEARN_EMPTY 1", "LEARN_NULL 2"):
            assert f"#define {m}{macro}" in header, (case, macro)
        assert f"{p}learn(e, d_f, d_next, n, work)" in readme and f"{m}LEARN_WORK(N_MAX)" in readme
        if case.startswith("band"):
            assert f"#define {m}BAND_CUTOFF 10.0 " in header and f"#define {m}PAD {design.filters['band']['pad']} " \
                in header
            assert "corner 10 rad/s" in readme and "crop(F{" in readme
        else:
            assert f"#define {m}BAND_CUTOFF 0.0 /* no learning band" in header and f"#define {m}PAD 0 " in header
            assert "No learning band (no filter)" in readme
        assert ("W is the airframe correction" in readme) == case.endswith("airframe")
        assert bool(re.search(r"W +is the airframe correction", header)) == case.endswith("airframe")
        if design.limits is not None:
            assert "Beyond the learning vehicle's acceleration limit" in header and "LEARN_CLIPPED 3" in header
            assert "Beyond the acceleration limit" in readme
    # exact-reference: the reference terms go around learn
    design = learn_designs["band"]
    readme = design_files({**design.filters, "law": "exact-reference"})[0]["README.md"]
    assert "pass `e - e_ref_source` instead of `e` to `ilcdob_uav1_uav2_learn`" in readme
    assert "add `correction` to `d_next`" in readme
    # the float variant covers L1, L2 only
    files, data = design_files(design.filters, float_variant=True)
    assert "learn" not in " ".join(data["c"]["float"]["functions"])
    assert "has no float variant" in files["filters.h"] and "`learn` runs in double" in files["README.md"]


# --------------------------------------------------------------------------- the look-ahead pre-stage


def _exact_filter(zeros, poles, gain: float, ts: float) -> ZPKFilter:
    """The filter; its anti-causal poles in the right half-plane are inverted exactly (the images of
    continuous non-minimum-phase zeros: their look-ahead, ~27.6/z s, is physics, design/filters/noncausal.py)."""
    f = ZPKFilter(np.asarray(zeros, dtype=complex), np.asarray(poles, dtype=complex), gain, ts)
    assert not f.substituted.size, "expected an exact inversion of right-half-plane poles"
    return f


def _independent_response(coeffs: dict, w: np.ndarray, ts: float) -> np.ndarray:
    """``e^{jwTs advance} sum_m g_m e^{jwTs (m - M)} S(e^{-jwTs})``, from the definition term by term."""
    from scipy import signal

    _, s = signal.sosfreqz(np.asarray(coeffs["sos"], float), worN=w * ts)
    g = np.asarray(coeffs.get("lookahead", [1.0]), float)
    m = np.arange(g.size)
    fir = (g[None, :] * np.exp(1j * np.outer(w * ts, m - (g.size - 1)))).sum(axis=1)
    return np.exp(1j * w * ts * coeffs["advance"]) * fir * s


TS_FAST = 0.001
#: Anti-causal poles near +1: 1.01, and the image e^{z Ts} of a continuous non-minimum-phase zero
#: at z = 10 rad/s sampled at 1 ms (look-ahead 2777 and 2764 samples).
NEAR_ONE = {"1.01": 1.01, "e^(10 Ts)": float(np.exp(10.0 * TS_FAST))}


@pytest.fixture(scope="module")
def near_one() -> dict:
    """Each pole near +1 in ``zeros [0.9, 0.95], poles [0.5, p]``: the filter and its export.

    Measured (2 cores): export 0.03 s each, 1 section and 2778 or 2765 look-ahead taps; through the
    roots of the series (the form before the pre-stage) p = 1.01 took 70 s and gave 1390 sections
    whose partial cascades reached 2.5e184 times the output (section_growth)."""
    out = {}
    for label, p in NEAR_ONE.items():
        f = _exact_filter([0.9, 0.95], [0.5, p], 1.0, TS_FAST)
        out[label] = (f, zpk_to_coefficients(f))
    return out


@pytest.mark.parametrize("label", list(NEAR_ONE))
def test_lookahead_near_plus_one_is_exact_and_bounded(near_one, label):
    """The series of an anti-causal pole near +1 is stored as taps, not as the roots of a degree-2777
    polynomial: one section (the zeros and the causal pole), the look-ahead the pole needs, the
    rational response to 1e-9 (measured 4e-12), no intermediate signal above 1e6 times the output
    (measured 100: the pre-stage's output v is 1/|S| times it, 100 at DC)."""
    f, c = near_one[label]
    p = NEAR_ONE[label]
    taps = np.asarray(c["lookahead"])
    assert taps.size - 1 == lookahead(p) and c["advance"] == taps.size - 1 + 1   # one surplus zero
    assert len(c["sos"]) == 1
    w = np.geomspace(0.1, 0.8 * np.pi / TS_FAST, 400)
    exact = f.exact_freqresp(w)
    assert np.max(np.abs(_independent_response(c, w, TS_FAST) / exact - 1)) < 1e-9
    assert np.max(np.abs(coefficients_freqresp(c, w, TS_FAST) / exact - 1)) < 1e-9
    # steady state (section_growth, pre-stage output included) and in time, on the Python computation
    growth = section_growth(np.asarray(c["sos"]), TS_FAST, taps)
    assert 1.0 <= growth <= 1e6
    assert section_growth(np.asarray(c["sos"]), TS_FAST) <= 1e6
    x = reference_trial(TS_FAST, 6000)
    y = apply_coefficients(c, x)
    v = apply_lookahead(taps, extend_smoothly(x, c["advance"] + 8))
    assert np.max(np.abs(v)) <= 1e6 * np.max(np.abs(y))
    # the direct form, when written, includes the pre-stage and agrees with it
    if "num" in c:
        assert len(c["num"]) == taps.size + 2
        assert direct_form_disagreement(c["num"], c["den"], c["sos"], TS_FAST, taps)[0] <= DIRECT_FORM_RTOL


def test_c_lookahead_near_plus_one_matches_python_and_the_inversion(cc, near_one, tmp_path):
    """Compiled C with 2778- and 2765-tap pre-stages (L1, L2), double and float, in place: equal to
    apply_coefficients (1e-9 over the whole trial, measured 1.7e-13; 1e-12 in the interior, measured 0)
    and, in the trial's interior, to ZPKFilter.apply, the stable inversion run backwards (1e-9;
    measured 1.1e-12).
    Interior: from 0.1 s to the look-ahead (2.8 s) before the end, beyond which both continue the
    trial by a cubic fitted to its last 16 samples (fitted differently; they agree there to ~1e-10)."""
    (f1, c1), (f2, c2) = near_one["1.01"], near_one["e^(10 Ts)"]
    filters = {"from": "N", "to": "M", "method": "closed-form", "sample_time": TS_FAST, "L1": c1, "L2": c2}
    data = write_design_folder(tmp_path, filters, float_variant=True)
    exe = _build(cc, tmp_path, True, data["c"]["prefix"])
    x = reference_trial(TS_FAST, 10000)
    out = _run(exe, x)
    interior = slice(100, x.size - c1["advance"])
    for col, (f, c) in enumerate(((f1, c1), (f2, c2))):
        ref = apply_coefficients(c, x)
        assert _rel(out[:, col], ref) < 1e-9
        assert _rel(out[interior, col], ref[interior]) < 1e-12
        inv = f.apply(x)
        assert _rel(out[interior, col], inv[interior]) < 1e-9
    np.testing.assert_array_equal(out[:, 2], out[:, 0])   # in place: the same numbers
    stated = data["c"]["float"]["max_relative_error"]
    x = reference_trial(TS_FAST)
    out = _run(exe, x)
    for col, key in ((3, "L1"), (4, "L2")):
        assert _rel(out[:, col], apply_coefficients(filters[key], x)) == pytest.approx(stated[key], rel=0.01), key
    header, readme = (tmp_path / "filters.h").read_text(), (tmp_path / "README.md").read_text()
    assert "#define ILCDOB_N_M_L1_LOOKAHEAD_TAPS 2778 " in header and "#define ILCDOB_N_M_L1_ADVANCE 2778 " in header
    assert "L1 looks ahead 2778 samples (2.778 s): a look-ahead FIR of 2778 taps" in readme
    assert "L2 looks ahead 2765 samples (2.765 s): a look-ahead FIR of 2765 taps" in readme
    assert "then 1 second-order section run on v, read 1 sample ahead" in readme


def test_lookahead_with_more_causal_poles_than_zeros(cc, tmp_path):
    """A filter whose causal poles outnumber its zeros delays by their difference: delay sections keep
    the sections' own advance >= 0, so the C code runs in place; response exact to 1e-9."""
    ts = 0.01
    f = _exact_filter([0.3], [0.5, 0.6, -0.4, 3.0], 2.0, ts)
    c = zpk_to_coefficients(f)
    taps = len(c["lookahead"])
    assert taps - 1 == lookahead(3.0) and c["advance"] == taps - 1   # 3 causal poles over 1 zero: a delay of 2
    assert sum(row[:3] == [0.0, 1.0, 0.0] or row[:3] == [0.0, 0.0, 1.0] for row in c["sos"]) == 1
    w = np.geomspace(0.1, 0.8 * np.pi / ts, 200)
    assert np.max(np.abs(_independent_response(c, w, ts) / f.exact_freqresp(w) - 1)) < 1e-9
    g = _exact_filter([0.9, 0.95, 0.2], [0.5, -3.7], 0.5, ts)   # the sampling zero near -3.7: 22 + 1 taps
    cg = zpk_to_coefficients(g)
    assert len(cg["lookahead"]) == lookahead(-3.7) + 1 and cg["advance"] == lookahead(-3.7) + 2
    filters = {"from": "X", "to": "Y", "method": "closed-form", "sample_time": ts, "L1": c, "L2": cg}
    data = write_design_folder(tmp_path, filters)
    exe = _build(cc, tmp_path, False, data["c"]["prefix"])
    rng = np.random.default_rng(2)
    for x in (reference_trial(ts, 900), rng.standard_normal(30), np.array([0.7])):
        out = _run(exe, x)
        for col, key in ((0, "L1"), (1, "L2")):
            assert _rel(out[:, col], apply_coefficients(filters[key], x)) < 1e-12, (x.size, key)
        np.testing.assert_array_equal(out[:, 2], out[:, 0])


@pytest.mark.parametrize("value, why", [
    ([1.0, float("nan")], "finite"),
    ([], "non-empty"),
    ("taps", "list of numbers"),
    ([1.0] * 9, "more than `advance`"),
])
def test_lookahead_entry_is_checked(value, why):
    coeffs = {"advance": 4, "sos": [[1.0, -0.5, 0.0, 1.0, -0.2, 0.0]], "lookahead": value}
    with pytest.raises(SpecError, match="`lookahead`") as err:
        apply_coefficients(coeffs, np.ones(10))
    assert why in str(err.value)
    filters = {"from": "X", "to": "Y", "method": "closed-form", "sample_time": 0.01, "L1": coeffs,
               "L2": {"advance": 0, "sos": [[1.0, 0.0, 0.0, 1.0, 0.0, 0.0]]}}
    with pytest.raises(SpecError, match="`L1.lookahead`"):
        c_code(filters)
    with pytest.raises(SpecError, match="`sos` is missing"):
        apply_coefficients({"advance": 4, "num": [1.0], "den": [1.0], "lookahead": [1.0, 0.5]}, np.ones(10))
