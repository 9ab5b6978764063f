"""Figures of the reproduction (``ilcdob.validation.figures``) and of the comparison: every learning
iteration is drawn, line styles are distinct, axes carry units, and no legend lies on the data."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.lines import Line2D

import ilcdob
from ilcdob.validation.compare import Comparison, MethodComparison
from ilcdob.validation.figures import reproduction_figures
from ilcdob.validation.reproduce import reproduce

ITERATIONS = 2


@pytest.fixture(scope="module")
def run():
    """Scenario 4 (order UAV1 -> UAV3 -> UAV2), two learning iterations per system."""
    res = reproduce(ilcdob.default_fleet(), [4], ITERATIONS)
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


def test_error_figure_has_every_iteration(run):
    res, figs = run
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


def test_disturbance_figure_has_every_iteration(run):
    res, figs = run
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
    fig = _comparison(failed=True).figure(rho=0.13)
    (ax,) = fig.axes
    assert [t.get_text() for t in ax.get_xticklabels()] == ["closed-form", "fir\n(design failed)"]
    assert len(ax.collections) == 2  # the Delta samples and the nominal point of the one design made
    legends, axes = _extents(fig)
    (lg,) = legends
    assert _overlap(lg, axes[0]) == 0 and lg.x1 <= fig.bbox.width + 0.5
    assert "robust rho = 0.13" in [t.get_text() for t in ax.get_legend().get_texts()]
    fig = _comparison(failed=False).figure()
    assert [t.get_text() for t in fig.axes[0].get_xticklabels()] == ["closed-form"]
