"""C code of robust-set designs: the coefficients reproduce the design's law, C reproduces the
coefficients, and the law on a sinusoid is the block formula times the robustness FIR."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.design.export.c_export import c_code, check_filters
from ilcdob.design.law import apply_learning
from ilcdob.design.pair import design_pair
from ilcdob.errors import SpecError
from ilcdob.fleet import default_fleet
from ilcdob.identification.loaders import load_csv
from ilcdob.signals import FlightData

from test_c_export import _build_learn, _rel, _run_learn  # noqa: E402

CASES = {"no band": (None, "command"), "band 3 rad/s": (3.0, "command"), "band, airframe": (3.0, "airframe")}


@pytest.fixture(scope="module")
def designs():
    """Robust-set designs UAV1 -> UAV2 of the built-in fleet (its identification's Delta set)."""
    fleet = default_fleet()
    return {label: design_pair(fleet, "UAV1", "UAV2", method="robust-set", band=bw, disturbance=dist)
            for label, (bw, dist) in CASES.items()}


def _trial(n: int, ts: float, fade_in: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """A smooth error (m), faded in over ``fade_in`` s and ending mid-slope, and a learning signal
    (m/s^2): faded in, small enough that the plant inverse stays within the acceleration limit."""
    t = np.arange(n) * ts
    ramp = np.sin(0.5 * np.pi * np.minimum(t / fade_in, 1.0)) ** 2 if fade_in else np.ones(n)
    e = ramp * (0.01 * np.sin(0.9 * t) + 0.003 * np.sin(4.1 * t + 0.3) + 0.002 * t / max(t[-1], ts))
    return e, 0.05 * ramp * np.sin(0.7 * t + 0.2)


@pytest.mark.parametrize("label", list(CASES))
def test_coefficients_reproduce_the_design(designs, label):
    """filters.json alone (through JSON) gives the design's learning signal: the exported maps, taps and
    trial-end rule are the law. Tolerance 1e-9 of the signal's peak: the stable inversion's series is
    cut at 1e-12 and the two state-space simulations differ in summation order only (measured
    1e-12)."""
    design = designs[label]
    filters = json.loads(json.dumps(design.filters))
    check_filters(filters, "filters.json")
    e, df = _trial(1500, filters["sample_time"])
    for df_prev in (np.zeros_like(df), df):
        ref = design.learning(e, df_prev).d_f
        assert np.max(np.abs(ref)) < filters["limit"]["acceleration_m_s2"]   # no clipping in the comparison
        assert _rel(apply_learning(filters, e, df_prev), ref) < 1e-9


@pytest.mark.parametrize("label", list(CASES))
def test_c_learn_matches_the_coefficients(cc, designs, label, tmp_path):
    """The compiled learn equals apply_learning to 1e-10 of the peak on whole trials of every length that
    changes the trial-end rule: 1 sample, shorter than the fade, shorter than the trend's fit, long
    (the law without the acceleration limit, whose stage has its own contract: tests/test_law_stages.py)."""
    filters = {k: v for k, v in designs[label].filters.items() if k != "limit"}
    exe = _build_learn(cc, tmp_path, filters)
    ts, adv, fade = filters["sample_time"], filters["F"]["advance"], filters["trial_ends"]["fade_samples"]
    for n in (1, 2, fade - 3, fade + 1, fade + 2 * adv - 7, 1500):
        e, df = _trial(n, ts, fade_in=0.0)
        e[0] = 1e-3   # a first sample that is not zero: the one-sample trial has something to learn
        for df_prev in (np.zeros(n), df):
            ref = apply_learning(filters, e, df_prev)
            assert _rel(_run_learn(exe, e, df_prev), ref) < 1e-10, (n, bool(df_prev.any()))


def test_c_learn_is_the_block_formula_times_the_fir_on_a_sinusoid(cc, designs, tmp_path):
    """Independent of the exported maps: inside a long trial, C learn turns a sinusoid into
    ``(1 - Q_j) Fr (-Gd_hat_{j-1}^{-1})`` times it, the blocks' formula evaluated at z = e^{jwTs}
    (python-control, ``Gd^-1 = 1/P + (M + C)/(1 - Q)``, paper Sec. II) and ``Fr`` summed from its taps.

    ``Gd^-1`` has two poles at z = 1, so the input is the second difference of a sinusoid faded in
    over 6 s (the integrators then hold the sinusoid and its first difference, no residue). The
    compared samples start two FIR look-aheads after the fade and stop two look-aheads plus the fade
    before the end, where the trial-end rule has no reach.

    Tolerance: 1e-7 of the output's amplitude (what exported coefficients reproduce of a block formula,
    about 1e-9 measured) plus 3e-8 of ``g``'s (0.01 m), the largest signal inside the law: its two
    integrators carry it before the rest of ``Gd^-1`` and ``1 - Q_j`` shrink it to the output (2e-6
    m/s^2 at 0.4 rad/s, 0.03 at 9 rad/s), and the rounding of the integration stays at the size it
    had there. Measured: 1.6e-11, 4e-11 and 1e-10 m/s^2 at 0.4, 2 and 9 rad/s against bounds of 3e-10,
    3e-10 and 3e-9. A missing ``1 - Q_j`` is off by order 1 of the output, a sign error by 2.
    """
    design = designs["no band"]
    exe = _build_learn(cc, tmp_path, design.filters)
    fleet = default_fleet()
    src, tgt = fleet.loop("UAV1").nominal, fleet.loop("UAV2")
    ts = fleet.sample_time
    h, adv = np.asarray(design.filters["F"]["num"]), design.filters["F"]["advance"]
    fade_end = design.filters["trial_ends"]["fade_samples"]

    def at(sys, w: float) -> complex:
        return complex(np.squeeze(sys(np.exp(1j * w * ts))))

    n, fade = 3000, 300
    k = np.arange(n)
    inside = slice(fade + 2 * adv, n - 2 * adv - fade_end)
    for w in (0.4, 2.0, 9.0):
        g_amp = 0.01 * np.exp(0.3j)
        g = np.real(g_amp * np.exp(1j * w * k * ts)) * np.where(k < fade, np.sin(0.5 * np.pi * k / fade) ** 2, 1.0)
        e = np.diff(np.concatenate([[0.0, 0.0], g]), n=2)
        amp = g_amp * (1 - np.exp(-1j * w * ts)) ** 2
        ginv = 1 / at(src.P, w) + (at(src.M, w) + at(src.C, w)) / (1 - at(src.Q, w))
        fr = np.sum(h * np.exp(1j * w * ts * (adv - np.arange(h.size))))
        expect = np.real((1 - at(tgt.Q, w)) * fr * -ginv * amp * np.exp(1j * w * k * ts))
        y = _run_learn(exe, e, np.zeros(n))
        assert np.max(np.abs(y - expect)[inside]) < 1e-7 * np.max(np.abs(expect)) + 3e-8 * abs(g_amp), w


def test_design_cli_writes_robust_set_c_code(cc, tmp_path, capsys):
    out = tmp_path / "rs"
    assert main(["design", "--method", "robust-set", "--from", "UAV1", "--to", "UAV2", "--bandwidth", "3",
                 "--c-prefix", "rs_", "--out", str(out)]) == 0
    capsys.readouterr()
    data = json.loads((out / "filters.json").read_text())
    assert data["c"]["functions"] == ["rs_learn", "rs_ginv_apply"]
    assert "3 * (n + 2 * " in data["c"]["learn"]["work"]
    readme = (out / "README.md").read_text()
    assert "rs_learn(e, d_f, d_next, n, work)" in readme and "R is the robust-set law" in readme
    assert "int rs_learn(const double *e" in (out / "filters.h").read_text()
    # the folder's own files compile into the test driver
    exe = _build_learn(cc, tmp_path, data, prefix="rs_")
    e, df = _trial(400, data["sample_time"])
    assert _rel(_run_learn(exe, e, df), apply_learning(data, e, df)) < 1e-10
    # and `ilcdob learn --design` runs the same law on a recorded trial
    trial = tmp_path / "trial.csv"
    FlightData(np.arange(e.size) * data["sample_time"], {"error": e, "learning": df},
               {"error": "m", "learning": "m/s^2"}).to_csv(trial)
    assert main(["learn", str(trial), "--design", str(out), "--error", "error", "--learning", "learning", "--out",
                 str(tmp_path / "learned")]) == 0
    capsys.readouterr()
    learned = load_csv(tmp_path / "learned" / "learning_signal.csv", {"d_f": "learning"})["d_f"]
    # the CSVs hold 10 significant digits (FlightData.to_csv): 1e-8 of the peak covers both round trips
    assert _rel(learned, apply_learning(data, e, df)) < 1e-8


def test_float_variant_of_a_robust_set_design_is_refused(designs):
    with pytest.raises(SpecError, match="robust-set design has no L1/L2 functions"):
        c_code(designs["no band"].filters, float_variant=True)


@pytest.mark.parametrize("key, value, why", [
    ("law_maps", [1, 2], "expected a mapping"),
    ("F", {"num": [1.0, float("nan")], "advance": 1}, "finite"),
    ("trial_ends", {"fade_samples": -1}, "fade_samples"),
    ("trial_ends.start", {"kind": "fold"}, "expected {'kind': 'matched'"),
    ("trial_ends.start", {"kind": "matched", "target_map": {"A": [[0.5]], "B": [[1.0]], "C": [[1.0]], "D": 0.0},
                          "gain": [[1.0, 2.0]]}, "1 states"),
    ("law_maps.source_gf", {"A": [[1.0, 0.0]], "B": [1.0], "C": [1.0], "D": 0.0}, "A of shape"),
    ("law_maps.one_minus_q", {"A": [[0.5]], "B": [1.0], "C": [float("inf")], "D": 1.0}, "non-finite"),
])
def test_robust_set_entries_are_checked(designs, key, value, why):
    filters = json.loads(json.dumps(designs["no band"].filters))
    if "." in key:
        top, sub = key.split(".")
        filters[top][sub] = value
    else:
        filters[key] = value
    with pytest.raises(SpecError, match=why):
        check_filters(filters, "filters.json")


@pytest.mark.slow  # 9 s (-m slow); the Python law keeps a file's start law by default in test_whole_trial
def test_a_file_without_the_start_entry_keeps_the_fold(cc, tmp_path):
    """``trial_ends.start`` (the continuation of F's output before t = 0, design/filters/trial_edges.py) changes the
    law only where it acts. On the right-half-plane-zero source of tests/test_band_exact.py (10 ms, bound 0.3; its F
    is far from a delta, where the built-in UAV1's is within 3e-8 of one) the signals with and without it differ
    over the first second by a share of the peak, and agree past the continuation and the target's 1 - Q (1e-9 of
    the peak after 5 s). The file without it is what its C code computes (1e-10), as files written before the
    entry existed run; with it, C computes the law with the continuation (1e-10)."""
    from test_band_exact import TEN_MS, _fleet

    design = design_pair(_fleet(0.01, 0.3, TEN_MS), "rhp", "drag", method="robust-set", band=None)
    filters = {k: v for k, v in json.loads(json.dumps(design.filters)).items() if k != "limit"}
    start = filters["trial_ends"]["start"]
    assert start["kind"] == "matched" and len(start["gain"]) == 100   # 1 s at 100 Hz
    old = {**filters, "trial_ends": {k: v for k, v in filters["trial_ends"].items() if k != "start"}}
    e, df = _trial(3000, filters["sample_time"], fade_in=0.0)
    new_d, old_d = apply_learning(filters, e, df), apply_learning(old, e, df)
    peak = np.max(np.abs(new_d))
    assert np.max(np.abs(new_d - old_d)[:100]) > 1e-2 * peak
    assert np.max(np.abs(new_d - old_d)[500:]) < 1e-9 * peak
    for name, f, ref in (("old", old, old_d), ("new", filters, new_d)):
        (tmp_path / name).mkdir()
        assert _rel(_run_learn(_build_learn(cc, tmp_path / name, f), e, df), ref) < 1e-10, name
