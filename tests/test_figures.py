"""Figures of the reproduction (``ilcdob.validation.figures``), of a design (``ilcdob.design.checks.figure``,
``bode.png`` of ``ilcdob design``) and of the comparison: every learning iteration is drawn, and
iterations that coincide are one line said so in words; Bode curves that coincide are drawn once,
phases are wrapped; the design's curves are the paper's block formulas; line styles are distinct,
axes carry units, and no legend lies on the data."""

from __future__ import annotations

import json
import os
from dataclasses import replace

import control as ct
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.lines import Line2D

import ilcdob
from ilcdob.app.cli import main
from ilcdob.design.filters.band import LearningBand
from ilcdob.design.checks.figure import COINCIDE_RTOL, pair_bode_figure
from ilcdob.fleet import fleet_from_dict
from ilcdob.validation.compare import Comparison, MethodComparison
from ilcdob.validation.figures import ITERATIONS_RTOL, comparison_figure, reproduction_figures
from ilcdob.validation.reproduce import reproduce

ITERATIONS = 2


@pytest.fixture(scope="module")
def run():
    """Scenario 4 (order UAV1 -> UAV3 -> UAV2), two learning iterations per system (exact models:
    the iterations coincide)."""
    res = reproduce(ilcdob.default_fleet(), [4], ITERATIONS)
    return res, reproduction_figures(res)


@pytest.fixture(scope="module")
def distinct(run):
    """The same run with learning iterations that differ (iteration i's error scaled by 1 + 0.5 i, its
    learning signal shifted by 0.1 i m/s^2), as with model errors or noise."""
    res = run[0]
    sr = res.scenarios[0]
    systems = {name: replace(s, learning=tuple(replace(f, e=f.e * (1 + 0.5 * i), d_f=f.d_f + 0.1 * i)
                                               for i, f in enumerate(s.learning)))
               for name, s in sr.systems.items()}
    res = replace(res, scenarios=[replace(sr, systems=systems)])
    return res, reproduction_figures(res)


def _lines(ax) -> list[Line2D]:
    """The data lines of an axes (grid lines are not in ``ax.lines``)."""
    return [ln for ln in ax.lines if not ln.get_label().startswith("_")]


def _rows(fig, res):
    """(system, left axes, right axes) per row, in the scenario's learning order."""
    sr = res.scenarios[0]
    axes = np.asarray(fig.axes).reshape(len(sr.order), 2)
    for name, (left, right) in zip(sr.order, axes):
        assert name in left.get_ylabel() and name in right.get_ylabel()
        yield sr.systems[name], left, right


def _distinct_styles(lines: list[Line2D]) -> None:
    styles = [(ln.get_color(), str(ln.get_linestyle()), ln.get_linewidth()) for ln in lines]
    assert len(set(styles)) == len(styles), styles


def test_error_figure_has_every_iteration(distinct):
    res, figs = distinct
    fig = figs["error_s4.png"]
    learning = [f"learning {i + 1}" for i in range(ITERATIONS)]
    for system, left, right in _rows(fig, res):
        assert [ln.get_label() for ln in _lines(left)] == ["no DOB", "only DOB", *learning]
        assert [ln.get_label() for ln in _lines(right)] == learning  # the zoom: learning iterations alone
        # each line is its own flight, not a copy of the first learning flight
        flights = [system.no_dob, system.dob, *system.learning]
        for ln, flight in zip(_lines(left), flights):
            np.testing.assert_array_equal(ln.get_ydata(), flight.e)
        for ln, flight in zip(_lines(right), system.learning):
            np.testing.assert_array_equal(ln.get_ydata(), flight.e)
        _distinct_styles(_lines(left))
        assert "(m)" in left.get_ylabel() and "(m)" in right.get_ylabel()
    assert all(ax.get_xlabel() == "time (s)" for ax in fig.axes[-2:])
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == ["no DOB", "only DOB", *learning]


def test_disturbance_figure_has_every_iteration(distinct):
    res, figs = distinct
    fig = figs["disturbance_s4.png"]
    learning = [f"learning {i + 1}: d_hat + d_f" for i in range(ITERATIONS)]
    for system, left, right in _rows(fig, res):
        assert [ln.get_label() for ln in _lines(left)] == ["true d (wind + noise)", "only DOB: d_hat", *learning]
        assert [ln.get_label() for ln in _lines(right)] == ["only DOB: d_hat", *learning]
        lines = _lines(left)
        np.testing.assert_array_equal(lines[0].get_ydata(), system.dob.d)
        np.testing.assert_array_equal(lines[1].get_ydata(), system.dob.d_hat)
        for ln, err, flight in zip(lines[2:], _lines(right)[1:], system.learning):
            np.testing.assert_array_equal(ln.get_ydata(), flight.d_hat + flight.d_f)
            np.testing.assert_array_equal(err.get_ydata(), flight.d_hat + flight.d_f - flight.d)
        _distinct_styles(lines)
        assert "m/s$^2$" in left.get_ylabel() and "m/s$^2$" in right.get_ylabel()
    assert all(ax.get_xlabel() == "time (s)" for ax in fig.axes[-2:])


def test_rmse_bars_have_every_iteration(run):
    res, figs = run
    fig = figs["rmse_bars.png"]
    (ax,) = fig.axes
    (legend,) = fig.legends
    labels = ["no DOB", "only DOB"] + [f"learning {i + 1}" for i in range(ITERATIONS)]
    assert [t.get_text() for t in legend.get_texts()] == labels
    assert len(ax.patches) == len(labels) * len(res.fleet.systems)
    assert ax.get_ylabel() == "tracking RMSE (m)"


def _extents(fig):
    """Window extents of every legend and every axes, after the layout has run."""
    canvas = FigureCanvasAgg(fig)
    fig.draw_without_rendering()
    renderer = canvas.get_renderer()
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    return [lg.get_window_extent(renderer) for lg in legends], [ax.get_window_extent(renderer) for ax in fig.axes]


def _overlap(a, b) -> float:
    """Area (pixels^2) shared by two boxes."""
    return max(0.0, min(a.x1, b.x1) - max(a.x0, b.x0)) * max(0.0, min(a.y1, b.y1) - max(a.y0, b.y0))


@pytest.mark.parametrize("name", ["rmse_bars.png", "error_s4.png", "disturbance_s4.png"])
def test_legends_lie_outside_every_axes(run, name):
    fig = run[1][name]
    legends, axes = _extents(fig)
    assert legends, "no legend"
    for lg in legends:
        assert lg.width > 0 and lg.height > 0
        for ax in axes:
            assert _overlap(lg, ax) == 0, (name, lg, ax)
        # and inside the figure, so that the saved PNG shows it whole
        assert lg.x0 >= 0 and lg.y0 >= 0 and lg.x1 <= fig.bbox.width + 0.5 and lg.y1 <= fig.bbox.height + 0.5


def _comparison(failed: bool) -> Comparison:
    ok = MethodComparison("closed-form", "L1", 0.01, 1e-4, 5e-4, 0.05, 0.2, 0.02, 1.0, [5e-4, 0.02, 0.2, 0.01])
    rows = [ok, MethodComparison.failed("fir", "convergence constraint not met", 2.0)] if failed else [ok]
    return Comparison(1, "UAV1", "UAV2", 3, "fleet bound", 0.2, 0.25, rows)


def test_compare_figure_names_failed_designs_and_keeps_its_legend_off_the_data():
    fig = comparison_figure(_comparison(failed=True), rho=0.13)
    (ax,) = fig.axes
    assert [t.get_text() for t in ax.get_xticklabels()] == ["closed-form", "fir\n(design failed)"]
    assert len(ax.collections) == 2  # the Delta samples and the nominal point of the one design made
    legends, axes = _extents(fig)
    (lg,) = legends
    assert _overlap(lg, axes[0]) == 0 and lg.x1 <= fig.bbox.width + 0.5
    assert "robust rho = 0.13" in [t.get_text() for t in ax.get_legend().get_texts()]
    fig = comparison_figure(_comparison(failed=False))
    assert [t.get_text() for t in fig.axes[0].get_xticklabels()] == ["closed-form"]


# ------------------------------------------------------------------------------ coinciding iterations

def test_coinciding_iterations_are_one_line_said_in_words(run):
    res, figs = run
    fig = figs["error_s4.png"]
    for system, left, right in _rows(fig, res):
        for ax in (left, right):
            (line,) = [ln for ln in _lines(ax) if ln.get_label().startswith("learning")]
            assert line.get_label() == "learning 1 and 2 (coincide)"
            np.testing.assert_array_equal(line.get_ydata(), system.learning[0].e)
            peak = np.max(np.abs(system.learning[0].e))
            for flight in system.learning[1:]:  # what the one line stands for
                assert np.max(np.abs(flight.e - line.get_ydata())) <= ITERATIONS_RTOL * peak
    assert "every system: learning 1 and 2 coincide (within 0.1 % of their peak)" in fig.get_suptitle()
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == ["no DOB", "only DOB", "learning 1 and 2 (coincide)"]

    # the disturbance estimates coincide but at the trial's last samples: there the second is drawn too
    fig = figs["disturbance_s4.png"]
    for system, left, right in _rows(fig, res):
        first, second = system.learning
        for ax, want in ((left, lambda f: f.d_hat + f.d_f), (right, lambda f: f.d_hat + f.d_f - f.d)):
            one, apart = [ln for ln in _lines(ax) if ln.get_label().startswith("learning")]
            assert one.get_label() == "learning 1 and 2: d_hat + d_f (coincide)"
            assert apart.get_label() == "learning 2: d_hat + d_f (where it differs)"
            np.testing.assert_array_equal(one.get_ydata(), want(first))
            shown = np.isfinite(apart.get_ydata())
            np.testing.assert_array_equal(apart.get_ydata()[shown], want(second)[shown])
            assert 0 < shown.sum() < 0.05 * shown.size and shown[-1]
            # where the second is not drawn it lies on the first
            peak = np.max(np.abs(want(first)))
            assert np.max(np.abs(want(second) - want(first))[~shown]) <= ITERATIONS_RTOL * peak
    assert "learning 1 and 2 coincide (within 0.1 % of their peak) except on at most" in fig.get_suptitle()
    assert "where learning 2 is drawn too" in fig.get_suptitle()


# ------------------------------------------------------------------------------ Bode figures

BODE = ("bode_loops.png", "bode_learning.png", "bode_te.png")


def _phase_axes(fig):
    return [ax for ax in fig.axes if ax.get_ylabel() == "phase (deg)"]


@pytest.mark.parametrize("name", BODE)
def test_bode_phases_are_wrapped(run, name):
    fig = run[1][name]
    axes = _phase_axes(fig)
    assert axes and len(axes) == len(fig.axes) // 2
    for ax in axes:
        for ln in _lines(ax):
            y = np.asarray(ln.get_ydata(), float)
            y = y[np.isfinite(y)]
            assert y.size and np.all(y > -180) and np.all(y <= 180), (name, ln.get_label(), y.min(), y.max())
        assert ax.get_ylim()[0] >= -200 and ax.get_ylim()[1] <= 200


def _names_in(label: str, names: list[str]) -> bool:
    return all(n in label.replace("\n", " ") for n in names)


def test_coinciding_bode_curves_are_drawn_once(run):
    res, figs = run
    pairs = sorted(res.filters)
    label = [f"{a} -> {b}" for a, b in pairs]
    mag_l1, mag_l2 = [ax for ax in figs["bode_learning.png"].axes if ax.get_ylabel() == "magnitude (dB)"]
    # every Q of the built-in fleet is the same: L2 = 1 for every pair, one line naming all of them
    (l2,) = _lines(mag_l2)
    assert l2.get_label().startswith("coincide:") and _names_in(l2.get_label(), label)
    assert [t.get_text() for t in mag_l2.get_legend().get_texts()] == [l2.get_label()]
    np.testing.assert_allclose(l2.get_ydata(), 0.0, atol=1e-6)
    # L1 depends on the source only: one line per source, naming its pairs
    lines = _lines(mag_l1)
    sources = sorted({a for a, _ in pairs})
    assert len(lines) == len(sources)
    w = lines[0].get_xdata()
    for ln, src in zip(lines, sources):
        mine = [(a, b) for a, b in pairs if a == src]
        assert _names_in(ln.get_label(), [f"{a} -> {b}" for a, b in mine])
        for key in mine:
            want = 20 * np.log10(np.abs(res.filters[key].l1_response(w)))
            assert np.max(np.abs(ln.get_ydata() - want)) <= 20 * np.log10(1 + COINCIDE_RTOL)
    # Omega of the three vehicles (same Q): one line naming all three
    omega = [ax for ax in figs["bode_te.png"].axes if "Omega" in ax.get_title()]
    (line,) = _lines(omega[0])
    assert _names_in(line.get_label(), res.fleet.names)
    # Te1 of the six pairs differ: six lines, each its own pair
    te1 = [ax for ax in figs["bode_te.png"].axes if ax.get_title().startswith("Te1")][0]
    assert [ln.get_label() for ln in _lines(te1)] == label


# ------------------------------------------------------------------------------ the design's figure

#: Two vehicles with unequal Q (so L2 != 1); A's model differs from its plant (so Te is the fleet's own).
PAIR_FLEET = {"sample_time": 0.01, "description": "a pair with a model error", "system": [
    {"name": "A", "plant": {"num": [1.0], "den": [0.08, 1.0, 0.0, 0.0]},
     "model": {"num": [0.9], "den": [0.1, 1.0, 0.0, 0.0]},
     "controller": {"kp": 3.0, "ki": 0.3, "kd": 2.4, "derivative_filter": 0.05},
     "dob": {"q_order": 3, "q_time_constant": 0.15}},
    {"name": "B", "plant": {"num": [1.0], "den": [0.12, 1.0, 0.0, 0.0]},
     "controller": {"kp": 1.2, "ki": 0.12, "kd": 1.53, "derivative_filter": 0.05},
     "dob": {"q_order": 3, "q_time_constant": 0.2}},
]}


def _blocks(system: dict, ts: float, true: bool):
    """The blocks P, C, Q, M of a fleet entry as python-control transfer functions, discretised here
    (plant and Q by zero-order hold, PID and M = Q / P_hat by Tustin), evaluated on z."""
    s = ct.tf("s")
    plant = system["plant"] if true or "model" not in system else system["model"]
    model = system.get("model", system["plant"])
    c, q = system["controller"], system["dob"]
    q_s = 1 / (q["q_time_constant"] * s + 1) ** q["q_order"]
    blocks = {"P": ct.c2d(ct.tf(plant["num"], plant["den"]), ts, "zoh"),
              "C": ct.c2d(c["kp"] + c["ki"] / s + c["kd"] * s / (c["derivative_filter"] * s + 1), ts, "tustin"),
              "Q": ct.c2d(q_s, ts, "zoh"),
              "M": ct.c2d(q_s * ct.tf(model["den"], model["num"]), ts, "tustin")}
    return lambda z: {k: np.array([complex(sys(zk)) for zk in z]) for k, sys in blocks.items()}


def _paper_formulas(w: np.ndarray) -> dict[str, np.ndarray]:
    """The paper's block formulas (Sec. II-III) on z = e^{j w Ts} for A -> B of :data:`PAIR_FLEET`."""
    ts = PAIR_FLEET["sample_time"]
    sys_a, sys_b = PAIR_FLEET["system"]
    z = np.exp(1j * w * ts)
    a_hat, a, b = _blocks(sys_a, ts, False)(z), _blocks(sys_a, ts, True)(z), _blocks(sys_b, ts, True)(z)
    l1 = -(1 - b["Q"]) * (1 / a_hat["P"] + (a_hat["M"] + a_hat["C"]) / (1 - a_hat["Q"]))
    l2 = (1 - b["Q"]) / (1 - a_hat["Q"])

    def maps(k):  # D = 1 - Q + P (M + C); Gd = P (1 - Q) / D, Gf = -P / D, Omega = (M + Q C) P / D
        d = 1 - k["Q"] + k["P"] * (k["M"] + k["C"])
        return k["P"] * (1 - k["Q"]) / d, -k["P"] / d, (k["M"] + k["Q"] * k["C"]) * k["P"] / d

    (gd_a, gf_a, om_a), (gd_b, gf_b, om_b) = maps(a), maps(b)
    te1 = gd_b / gd_a - gf_b * l1
    return {"L1": l1, "L2": l2, "Te1": te1, "Te2": te1 * gf_a, "Omega A": om_a, "Omega B": om_b}


def _axes(fig) -> dict[str, object]:
    return {ax.get_label(): ax for ax in fig.axes}


def _curve(ax, label: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(w, y) of the one data line of ``ax`` (or the one labelled ``label``), NaN breaks dropped."""
    lines = [ln for ln in _lines(ax) if label is None or ln.get_label() == label]
    assert len(lines) == 1, [ln.get_label() for ln in _lines(ax)]
    w, y = (np.asarray(v, float) for v in lines[0].get_data())
    keep = np.isfinite(y)
    return w[keep], y[keep]


def test_design_figure_is_the_paper_block_formulas():
    fleet = fleet_from_dict(PAIR_FLEET, source="pair")
    band = LearningBand(fleet.sample_time, 20.0, source="stated")
    fig = pair_bode_figure(fleet, "A", "B", band)
    axes = _axes(fig)
    # to 3e-4 relative (0.003 dB, 0.02 degrees): Te1 is a difference of terms that cancel to 1e-8 at
    # 0.01 rad/s, where the filter's own rounding (1e-13) leaves 2e-4 of it
    rtol = 3e-4
    for key, label in (("L1", None), ("L2", None), ("Te1", None), ("Te2", None), ("Omega", "A"), ("Omega", "B")):
        want_key = key if key != "Omega" else f"Omega {label}"
        w, mag = _curve(axes[f"{key} magnitude"], label)
        assert w[0] == pytest.approx(0.01) and w[-1] == pytest.approx(np.pi / fleet.sample_time, rel=2e-3)
        want = _paper_formulas(w)[want_key]
        np.testing.assert_allclose(mag, 20 * np.log10(np.abs(want)), rtol=0, atol=20 * np.log10(1 + rtol),
                                   err_msg=want_key)
        w, phase = _curve(axes[f"{key} phase"], label)
        assert np.all(phase > -180) and np.all(phase <= 180), want_key
        error = (phase - np.degrees(np.angle(_paper_formulas(w)[want_key])) + 180) % 360 - 180
        assert np.max(np.abs(error)) < np.degrees(rtol), (want_key, np.max(np.abs(error)))
    assert "the fleet's true plants" in axes["Te1 magnitude"].get_title()
    # L2 is not 1 here (unequal Q): the check above compared a curve, not a constant
    assert np.ptp(_curve(axes["L2 magnitude"])[1]) > 1.0
    # the learning band: its corner marked on every Bode axes, and stated
    for key, ax in axes.items():
        if key != "description":
            assert any(np.allclose(ln.get_xdata(), 20.0) for ln in ax.lines if ln.get_label() == "_band"), key
    text = " ".join(t.get_text() for t in axes["description"].texts)
    assert "learning band: corner 20 rad/s" in text and "A -> B" in text


def test_design_command_writes_the_bode_figure(tmp_path):
    out = tmp_path / "design"
    assert main(["design", "--from", "UAV1", "--to", "UAV2", "--out", str(out), "--quiet"]) == 0
    png = out / "bode.png"
    assert png.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    manifest = json.loads((out / "manifest.json").read_text())
    assert "bode.png" in manifest["files"]
    readme = (out / "README.md").read_text()
    assert "`bode.png`: Bode plots" in readme
    from PIL import Image

    with Image.open(png) as img:  # laid out for 110 dpi: 15 x 10.5 inches
        assert img.size == (1650, 1155)
    # the default fleet states no true plant besides the models: Te under the stated 10 % gain error,
    # and Omega of the two vehicles (equal Q) is one line naming both
    fig = pair_bode_figure(ilcdob.default_fleet(), "UAV1", "UAV2")
    axes = _axes(fig)
    assert "10 % stronger than models" in axes["Te1 magnitude"].get_title()
    (line,) = _lines(axes["Omega magnitude"])
    assert line.get_label() == "coincide: UAV1 and UAV2"
    assert not any(ln.get_label() == "_band" for ax in fig.axes for ln in ax.lines)  # band off: nothing marked


def test_design_figure_says_what_it_cannot_draw(monkeypatch):
    import ilcdob.design.checks.figure as module
    from ilcdob.errors import UnstableLoopError

    def unstable(loop, gain):
        raise UnstableLoopError(f"system {loop.name!r}: unstable")

    monkeypatch.setattr(module, "with_gain_error", unstable)
    axes = _axes(pair_bode_figure(ilcdob.default_fleet(), "UAV1", "UAV2", method="fir"))
    for key in ("Te1", "Te2"):
        assert not _lines(axes[f"{key} magnitude"])
        (note,) = axes[f"{key} magnitude"].texts
        assert "not drawn: a plant 10 % stronger than its model makes the loop of UAV1 unstable" in \
            note.get_text().replace("\n", " ")
    assert len(_lines(axes["L1 magnitude"])) == 1  # the rest is drawn
    text = " ".join(t.get_text() for t in axes["description"].texts)
    assert "Te1, Te2 not drawn" in text and "design method fir" in text


# ---- rendering: one draw per figure, in parallel worker processes ------------------------------------


def _savefig_png(fig) -> bytes:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, pil_kwargs={"compress_level": 3})  # figure_png's zlib level
    return buf.getvalue()


def _one(res, name: str):
    """Figure ``name`` of ``res``, built alone."""
    return reproduction_figures(res, pending=True)[name].build()


def _counting_draws(monkeypatch) -> list[object]:
    """Every ``Figure.draw`` call from now on, recorded (rendered or not)."""
    from matplotlib.figure import Figure

    calls: list[object] = []
    draw = Figure.draw

    def counted(self, renderer):
        calls.append(self)
        return draw(self, renderer)

    monkeypatch.setattr(Figure, "draw", counted)
    return calls


@pytest.mark.parametrize("name", ["rmse_bars.png", "bode_loops.png"])  # constrained layout; tight layout
def test_figure_png_draws_once_the_bytes_of_savefig(run, name, monkeypatch):
    from ilcdob.validation.figures import figure_png

    res = run[0]
    want = _savefig_png(_one(res, name))
    fig = _one(res, name)
    calls = _counting_draws(monkeypatch)
    assert figure_png(fig) == want
    assert calls == [fig]  # savefig draws it twice: the layout pass, then the rendering
    calls.clear()
    _savefig_png(_one(res, name))
    assert len(calls) == 2


@pytest.mark.parametrize("which, name", [("one_row_coincides", "error_s4.png"), ("run", "disturbance_s4.png"),
                                         ("run", "rmse_bars.png"), ("run", "bode_te.png"),
                                         ("run", "identified_models.png")])
def test_titles_stand_where_matplotlibs_automatic_placement_puts_them(which, name, run, distinct, monkeypatch):
    """Titles are given their height (TITLE_Y), which spares matplotlib's automatic placement; the image is
    the one automatic placement draws (TITLE_Y None: matplotlib places them), byte for byte. In
    ``one_row_coincides`` only the second row's iterations coincide: its note is the title of its right
    panel, in the row below the first row's x axis."""
    from ilcdob.design.checks import figure as design_figure
    from ilcdob.validation import figures
    from ilcdob.validation.figures import figure_png

    res = run[0]
    if which == "one_row_coincides":
        second = res.scenarios[0].order[1]
        systems = {k: res.scenarios[0].systems[k] if k == second else s
                   for k, s in distinct[0].scenarios[0].systems.items()}
        res = replace(res, scenarios=[replace(res.scenarios[0], systems=systems)])
    fixed = _one(res, name)
    titled = [ax for ax in fixed.axes if ax.get_title()]
    assert all(ax.title.get_position()[1] == 1.0 for ax in titled)
    if which == "one_row_coincides":
        assert len(titled) == 3  # the two panels' titles, and the note above row 2
    got = figure_png(fixed)
    for module in (figures, design_figure):
        monkeypatch.setattr(module, "TITLE_Y", None)
    assert figure_png(_one(res, name)) == got


def test_render_figures_in_workers_keeps_the_bytes_and_the_order(run):
    import multiprocessing

    from ilcdob.validation.figures import PendingFigure, render_figures

    res = run[0]
    pending = reproduction_figures(res, pending=True)
    assert all(isinstance(p, PendingFigure) for p in pending.values())
    assert list(pending) == list(run[1])  # the same figures, by the same names, in the same order
    names = ["rmse_bars.png", "identified_models.png", "bode_loops.png"]
    content = {"a.txt": "text", names[0]: pending[names[0]], names[1]: pending[names[1]],
               names[2]: _one(res, names[2]), "b.json": {"x": 1}}  # built, or built by the worker
    out = render_figures(content, workers=2)
    assert list(out) == list(content) and out["a.txt"] == "text" and out["b.json"] == {"x": 1}
    for name in names:
        assert out[name] == _savefig_png(_one(res, name)), name
    assert not multiprocessing.active_children()  # every worker joined


def test_submitted_figures_render_while_the_caller_goes_on(run):
    import multiprocessing

    from ilcdob.validation.figures import FigureRenderer, scenario_figures

    res = run[0]
    sr = res.scenarios[0]
    with FigureRenderer(2) as renderer:
        renderer.submit(scenario_figures(sr, ITERATIONS, pending=True))
        assert len(multiprocessing.active_children()) == 1  # started now, one core left to the caller
        with pytest.raises(ValueError, match=r"\['error_s4.png'\] submitted twice"):
            renderer.submit({"error_s4.png": scenario_figures(sr, ITERATIONS, pending=True)["error_s4.png"]})
        files = res.files(reproduction_figures(res, pending=True))  # finish renders those not submitted, takes the others as rendered
        out = renderer.finish({name: files[name] for name in ("error_s4.png", "disturbance_s4.png",
                                                              "identified_models.png", "README.md")})
    assert list(out) == ["error_s4.png", "disturbance_s4.png", "identified_models.png", "README.md"]
    assert out["error_s4.png"] == _savefig_png(_one(res, "error_s4.png"))
    assert out["identified_models.png"] == _savefig_png(_one(res, "identified_models.png"))
    assert isinstance(out["README.md"], str) and not multiprocessing.active_children()


def test_the_last_batch_starts_the_figures_with_most_axes_first(run, tmp_path, monkeypatch):
    """finish renders the submitted figures no worker has started with the rest as one batch, ordered by
    axes (most first, ties in the order given: the longest first, so that the workers end together); the
    batch each forked worker took is recorded by the worker itself."""
    from ilcdob.validation import figures
    from ilcdob.validation.figures import FigureRenderer, PendingFigure

    res = run[0]
    pending = reproduction_figures(res, pending=True)
    axes = {name: len(_one(res, name).axes) for name in pending}
    assert all(p.axes == axes[name] for name, p in pending.items())  # each figure's count, as built
    worker = figures._render_worker

    def recording(content, names, *args):
        (tmp_path / f"{os.getpid()}.txt").write_text("\n".join(names))
        return worker(content, names, *args)

    monkeypatch.setattr(figures, "_render_worker", recording)
    small = PendingFigure(pending["rmse_bars.png"].make, axes=1)
    with FigureRenderer(2) as renderer:
        renderer.submit({"bode_loops.png": pending["bode_loops.png"]})  # started now (one worker)
        renderer.submit({name: pending[name] for name in ("identified_models.png", "error_s4.png")})  # waits
        out = renderer.finish({"small.png": small, "bode_te.png": pending["bode_te.png"],
                               "disturbance_s4.png": pending["disturbance_s4.png"],
                               **{name: pending[name] for name in ("bode_loops.png", "identified_models.png",
                                                                   "error_s4.png")}})
    batches = sorted(f.read_text().split("\n") for f in tmp_path.glob("*.txt"))
    last = ["bode_te.png", "disturbance_s4.png", "error_s4.png", "identified_models.png", "small.png"]
    assert batches == [["bode_loops.png"], last, last]  # one worker, then two on the last batch
    assert axes["bode_te.png"] == axes["disturbance_s4.png"] == 6 > axes["identified_models.png"] == 2
    assert all(isinstance(png, bytes) for png in out.values())


def test_a_figure_that_fails_in_a_worker_fails_the_call_and_stops_the_workers(run):
    import multiprocessing

    from ilcdob.validation.figures import PendingFigure, render_figures

    def broken():
        raise ValueError("no data for this figure")

    content = {"bars.png": reproduction_figures(run[0], pending=True)["rmse_bars.png"],
               "broken.png": PendingFigure(broken)}
    with pytest.raises(ValueError, match="no data for this figure") as err:
        render_figures(content, workers=2)
    assert any("while rendering broken.png in a worker process" in note for note in err.value.__notes__)
    assert not multiprocessing.active_children()
    with pytest.raises(ValueError, match="no data for this figure"):  # the same in this process
        render_figures(content, workers=1)


@pytest.mark.parametrize("workers", [0, -2, 1.5, True, "2"])
def test_render_workers_must_be_a_count(workers):
    from ilcdob.errors import SpecError
    from ilcdob.validation.figures import render_figures

    with pytest.raises(SpecError, match=r"`workers` \(figure rendering processes\): got .*expected an integer >= 1"):
        render_figures({}, workers=workers)


def test_minor_log_grid_draws_matplotlibs_minor_positions_as_one_collection():
    """The minor grid of a long log view is one line collection at the positions matplotlib's own minor
    ticks had (read from a twin figure left as matplotlib draws it), on every axes of a shared group; a view
    of less than two decades (where matplotlib may label minor ticks) keeps its ticks."""
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    from ilcdob.design.checks.figure import minor_log_grid

    def build():
        fig = Figure(figsize=(6, 4))
        axes = fig.subplots(3, 1, sharex=True)
        for k, ax in enumerate(axes[:2]):
            ax.semilogx([0.013, 170.0], [k, k + 1])
            ax.grid(True, which="both", alpha=0.3)
        axes[2].loglog([1.0, 30.0], [2.0, 50.0])   # x shared (long), y 1.4 decades (short)
        axes[2].grid(True, which="both", alpha=0.3)
        FigureCanvasAgg(fig)
        return fig, axes

    ref, ref_axes = build()
    ref.canvas.draw()
    expect_x = [sorted(t.get_loc() for t in ax.xaxis.get_minor_ticks() if t.gridline.get_visible()
                       and ax.get_xlim()[0] <= t.get_loc() <= ax.get_xlim()[1]) for ax in ref_axes]
    expect_y = sorted(ref_axes[2].yaxis.get_minorticklocs())
    assert len(expect_x[0]) > 30 and len(expect_y) > 3   # five decades of 2..9; the short view's own ticks

    fig, axes = build()
    minor_log_grid(fig, alpha=0.3)
    fig.canvas.draw()
    for ax, want in zip(axes, expect_x):
        assert len(ax.xaxis.get_minorticklocs()) == 0
        lines = [c for c in ax.collections if isinstance(c, LineCollection)]
        assert len(lines) == 1
        got = sorted(seg[0, 0] for seg in lines[0].get_segments())
        np.testing.assert_allclose(got, want, rtol=1e-12)
        assert lines[0].get_alpha() == 0.3
    np.testing.assert_allclose(sorted(axes[2].yaxis.get_minorticklocs()), expect_y, rtol=1e-12)


def test_long_log_views_label_their_decades_as_matplotlib_does_without_mathtext():
    """minor_log_grid relabels a long log view's decades in plain text: the labels matplotlib draws as mathtext
    (``$\\mathdefault{10^{-2}}$``, read from a twin figure), each written as 10 and its exponent in Unicode
    superscripts; a short view keeps matplotlib's own labels, and a formatter set by the caller is kept."""
    import re

    from matplotlib.figure import Figure
    from matplotlib.ticker import FormatStrFormatter

    from ilcdob.design.checks.figure import minor_log_grid

    sup = {"-": "\u207b", "0": "\u2070", "1": "\u00b9", "2": "\u00b2", "3": "\u00b3", "4": "\u2074",
           "5": "\u2075", "6": "\u2076", "7": "\u2077", "8": "\u2078", "9": "\u2079"}

    def build():
        fig = Figure(figsize=(6, 5))
        axes = fig.subplots(3, 1)
        axes[0].loglog([2e-6, 3e3], [1e-12, 5e-3])   # nine and nine decades
        axes[1].loglog([1.0, 30.0], [2.0, 50.0])     # short views
        axes[2].semilogx([1e-3, 1e3], [0, 1])
        axes[2].xaxis.set_major_formatter(FormatStrFormatter("%g"))  # the caller's: kept
        FigureCanvasAgg(fig)
        return fig, axes

    def labels(ax):
        return [[(t.get_position(), t.get_text()) for t in ticks if t.get_text()]
                for ticks in (ax.get_xticklabels(), ax.get_yticklabels())]

    ref, ref_axes = build()
    ref.canvas.draw()
    fig, axes = build()
    minor_log_grid(fig)
    fig.canvas.draw()
    for axis_ref, axis_got in zip(labels(ref_axes[0]), labels(axes[0])):
        assert len(axis_ref) >= 4
        want = []
        for pos, text in axis_ref:
            exponent = re.fullmatch(r"\$\\mathdefault\{10\^\{(−?-?\d+)\}\}\$", text).group(1).replace("−", "-")
            want.append((pos, "10" + "".join(sup[c] for c in exponent)))
        assert axis_got == want
    assert labels(axes[1]) == labels(ref_axes[1]) and labels(axes[2]) == labels(ref_axes[2])
    assert "$" not in "".join(text for axis in labels(axes[0]) for _, text in axis)
