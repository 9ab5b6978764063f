"""Figures of the reproduction, in the paper's layout, as :class:`matplotlib.figure.Figure` objects.

* ``rmse_bars.png`` - RMSE per scenario and system: no DOB, only DOB, learning 1..n;
* ``error_s<N>.png`` - tracking error against time per system (one row each): no DOB, only
  DOB and every learning iteration, and beside it the learning iterations alone (zoom);
* ``disturbance_s<N>.png`` - the true disturbance, the DOB-only estimate d_hat and the
  estimate d_hat + d_f of every learning iteration, and beside it each estimate's error;
* ``bode_loops.png`` - G_r and G_d (with the no-DOB G_d for comparison);
* ``bode_learning.png`` - L1 and L2 of every learning pair flown;
* ``bode_te.png`` - Te1, Te2 (error propagation with learning, under a stated model error)
  and Omega (disturbance -> DOB estimate).

The Bode figures follow :mod:`ilcdob.design.checks.figure`: phase wrapped to (-180, 180] degrees,
and curves that coincide (L2 of pairs with equal Q, Omega of equal Q) drawn once with one
legend entry naming them all. In the time series, learning iterations that coincide (within
:data:`ITERATIONS_RTOL` of their peak, as with exact models) are drawn as one line, and the
legend and the figure say so in words (a member that differs on a few samples, as at a trial's
end, is drawn there too).

and, for the other results, ``compare_ratios.png`` (:func:`comparison_figure`) and
``campaign_ratios.png`` (:func:`campaign_figure`). The application composes them into each result's
report (``files(figures)``). :func:`reproduction_figures` returns them by file name; nothing here writes a file (the
figures are laid out for PNG at 110 dpi, :data:`FIGURE_DPI`).

Rendering. Drawing the figures as PNG costs more than building them and, for the linear plant,
more than the simulations. :func:`figure_png` draws a figure once: it lays it out (its
constrained or tight layout engine, at :data:`FIGURE_DPI`, with the renderer that draws it, so
that text is measured once) and renders it with the layout engine removed, where ``savefig``
lays the figure out in a first full draw (rendering disabled) and renders it in a second; the
PNG bytes are the same.
:class:`FigureRenderer` builds and renders figures (built ones, or :class:`PendingFigure` to be
built where they are rendered) in parallel: on Linux in forked worker processes, which take
the next figure of their batch from a shared counter, build and render it and send the bytes
back, so a reproduction can render each scenario's figures while it flies the next
(:func:`scenario_figures`); elsewhere, or with one worker, in this process.
:func:`render_figures` does it for a whole content map. A worker ignores Ctrl-C (the caller
stops it) and ends with its caller (it is killed when the caller dies, and stops at the next
figure when it cannot send); the caller's objects are frozen for the collector while it
forks, so that the workers share their pages instead of copying them.
"""

from __future__ import annotations

import io
import math
import os
import sys
import textwrap
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from ilcdob.design import LearningFilters
from ilcdob.design.methods import METHODS
from ilcdob.design.checks.figure import (TE_GAIN_ERROR, TITLE_Y, BodeCurve, draw_bode, finish_bode_axes, frequency_grid,
                                         loop_maps, magnitude_db, minor_log_grid, with_gain_error)
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet
from ilcdob.loop import freqresp
from ilcdob.uncertainty import ModelStructure, frequency_response

if TYPE_CHECKING:
    from .campaign.statistics import CampaignResult
    from .compare import Comparison
    from .reproduce import ReproductionResult

__all__ = ["reproduction_figures", "scenario_figures", "fleet_figures", "frequency_grid", "identified_bounds",
           "TE_GAIN_ERROR", "FIGURE_DPI", "PNG_COMPRESS_LEVEL", "ITERATIONS_RTOL", "ITERATIONS_APART", "PendingFigure",
           "FigureRenderer", "figure_png", "render_figures", "render_workers", "comparison_figure", "campaign_figure"]

#: Resolution the figures are made for (dots per inch of the PNG files).
FIGURE_DPI = 110
#: zlib level of the PNG files :func:`figure_png` writes: 5 % larger files than the default level
#: 6 for a third less encoding time (docs/performance.md, "Reproduce and figures").
PNG_COMPRESS_LEVEL = 3
#: Learning iterations whose curves differ by at most this share of their peak coincide: they
#: are drawn as one line (0.1 %, well below a pixel of the figures).
ITERATIONS_RTOL = 1e-3
#: ... also when they differ on at most this share of the samples (with exact models the
#: disturbance estimates of the iterations differ at the trial's last samples only): each is
#: then drawn where it differs.
ITERATIONS_APART = 0.05
_COLORS = ["#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860"]


def _subplots(nrows: int, ncols: int, figsize: tuple[float, float], **kwargs) -> tuple[Figure, object]:
    """A new :class:`Figure` (no pyplot, no backend) and its grid of axes."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def _done(fig: Figure) -> Figure:
    minor_log_grid(fig)
    fig.set_layout_engine("tight")  # laid out where it is drawn, at the resolution it is drawn
    return fig


def _legend_below(fig: Figure, handles, labels, ncol: int) -> None:
    """One legend for the whole figure, below every axes (constrained layout keeps it off the data)."""
    fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize=8, frameon=False)


def _rmse_bars(res: ReproductionResult) -> Figure:
    n = len(res.scenarios)
    fig = Figure(figsize=(4.2 * n, 3.9), layout="constrained")
    axes = fig.subplots(1, n, squeeze=False)
    labels = ["no DOB", "only DOB"] + [f"learning {i + 1}" for i in range(res.iterations)]
    for ax, sr in zip(axes[0], res.scenarios):
        names = sr.order
        width = 0.8 / len(labels)
        for k, lab in enumerate(labels):
            vals = []
            for name in names:
                m = sr.systems[name].metrics()
                vals.append([m["rmse_no_dob"], m["rmse_dob"], *m["rmse_learning"]][k])
            ax.bar(np.arange(len(names)) + (k - (len(labels) - 1) / 2) * width, vals, width,
                   label=lab, color=_trial_color(k, res.iterations))
        ax.set_yscale("log")
        ax.set_xticks(np.arange(len(names)), names)
        ax.set_title(f"Scenario {sr.scenario.id}: {sr.scenario.title}", fontsize=9, y=TITLE_Y)
        ax.set_ylabel("tracking RMSE (m)")
        ax.grid(True, axis="y", which="both", alpha=0.3)
    _legend_below(fig, *axes[0][0].get_legend_handles_labels(), ncol=len(labels))
    return minor_log_grid(fig)


#: Line styles of the learning iterations 1, 2, ... (cycled), widest first so that iterations
#: that coincide (exact models) stay visible on top of each other.
_ITERATION_STYLES = ["-", "--", ":", "-.", (0, (5, 1, 1, 1, 1, 1)), (0, (1, 3))]


def _trial_color(k: int, iterations: int) -> str:
    """Colour of trial ``k``: 0 no DOB, 1 only DOB, 2.. learning iterations (distinct for any count)."""
    if k < 2:
        return _COLORS[k]
    if iterations <= len(_COLORS) - 2:
        return _COLORS[k]
    from matplotlib import colormaps
    from matplotlib.colors import to_hex

    return to_hex(colormaps["viridis"](0.15 + 0.75 * (k - 2) / max(iterations - 1, 1)))


def _iteration_style(i: int, iterations: int) -> dict[str, object]:
    """Plot keywords of learning iteration ``i`` (0-based) of ``iterations``."""
    return {"color": _trial_color(i + 2, iterations), "ls": _ITERATION_STYLES[i % len(_ITERATION_STYLES)],
            "lw": max(2.4 - 0.5 * i, 0.9), "label": f"learning {i + 1}"}


def _iteration_names(group: list[int]) -> str:
    """``"1"``, ``"1 and 2"``, ``"1-3"`` or ``"1, 3 and 4"`` for 0-based iteration indices."""
    nums = [i + 1 for i in group]
    if len(nums) >= 3 and nums == list(range(nums[0], nums[-1] + 1)):
        return f"{nums[0]}-{nums[-1]}"
    return str(nums[0]) if len(nums) == 1 else ", ".join(map(str, nums[:-1])) + f" and {nums[-1]}"


def _iteration_groups(curves: list[tuple[np.ndarray, ...]]) -> list[tuple[list[int], dict[int, np.ndarray]]]:
    """Groups of learning iterations that coincide: in every panel within :data:`ITERATIONS_RTOL` of
    the first iteration's peak there, at all samples but at most :data:`ITERATIONS_APART` of them.
    Each group: its members, and per later member the samples where it differs from the first."""
    if not curves:
        return []
    peaks = [max(float(np.max(np.abs(part), initial=0.0)), 1e-300) for part in curves[0]]
    norm = [np.stack([part / peak for part, peak in zip(parts, peaks)]) for parts in curves]
    groups: list[tuple[list[int], dict[int, np.ndarray]]] = []
    for i, v in enumerate(norm):
        for members, apart in groups:
            ref = norm[members[0]]
            if ref.shape != v.shape:
                continue
            off = np.any(np.abs(v - ref) > ITERATIONS_RTOL, axis=0)
            if np.mean(off) <= ITERATIONS_APART:
                members.append(i)
                apart[i] = off
                break
        else:
            groups.append(([i], {}))
    return groups


@dataclass(frozen=True)
class _Coincide:
    """Learning iterations drawn as one line (0-based ``members``); ``differ``: those drawn too on
    ``samples`` samples (``seconds``) where they differ from it."""

    members: tuple[int, ...]
    differ: tuple[int, ...] = ()
    samples: int = 0
    seconds: float = 0.0


def _draw_iterations(axes, curves: list[tuple[np.ndarray, ...]], t: list[np.ndarray], iterations: int,
                     suffix: str = "") -> tuple[_Coincide, ...]:
    """Draw the learning iterations (``curves[i][k]`` on ``axes[k]`` against ``t[i]``): each group of
    coinciding ones once, labelled with all of them, and a member only where it differs from the
    group's line. Returns the groups of more than one iteration."""
    found = []
    for members, apart in _iteration_groups(curves):
        style = _iteration_style(members[0], iterations)
        style["label"] = f"learning {members[0] + 1}{suffix}"
        if len(members) > 1:  # one line for several iterations: nothing hides under it, so no wide line
            style.update(lw=1.0, label=f"learning {_iteration_names(members)}{suffix} (coincide)")
        for ax, y in zip(axes, curves[members[0]]):
            ax.plot(t[members[0]], y, **style)
        if len(members) == 1:
            continue
        differ = [i for i in members[1:] if apart[i].any()]
        n = int(np.count_nonzero(np.any([apart[i] for i in differ], axis=0))) if differ else 0
        dt = float(t[members[0]][1] - t[members[0]][0]) if len(t[members[0]]) > 1 else 0.0
        for i in differ:
            show = np.convolve(apart[i], np.ones(3), "same") > 0  # the differing samples and their neighbours
            style = _iteration_style(i, iterations)
            style["label"] = f"learning {i + 1}{suffix} (where it differs)"
            for ax, y in zip(axes, curves[i]):
                ax.plot(t[i], np.where(show, y, np.nan), **style)
        found.append(_Coincide(tuple(members), tuple(differ), n, n * dt))
    return tuple(found)


def _coincide_note(rows: list[tuple[_Coincide, ...]]) -> str:
    """Words for the coinciding iterations that every row of ``rows`` shares (largest sample counts)."""
    parts = []
    for k, c in enumerate(rows[0]):
        text = f"learning {_iteration_names(list(c.members))} coincide"
        if k == 0:
            text += f" (within {100 * ITERATIONS_RTOL:g} % of their peak)"
        if c.differ:
            n = max(r[k].samples for r in rows)
            sec = max(r[k].seconds for r in rows)
            text += (f" except on {'at most ' if len(rows) > 1 else ''}{n} sample{'s' * (n != 1)} ({sec:.3g} s), "
                     f"where learning {_iteration_names(list(c.differ))} {'is' if len(c.differ) == 1 else 'are'} "
                     "drawn too")
        parts.append(text)
    return "; ".join(parts)


def _per_system(sr, iterations: int, title: str, panels: tuple[str, str], ylabel: tuple[str, str],
                draw) -> Figure:
    """One row per system of scenario ``sr``, two panels per row (all trials | a zoom);
    ``draw(ax_left, ax_right, system_result, iterations)`` fills a row and returns its coinciding
    iterations (:class:`_Coincide`). One legend below; coinciding iterations are stated in the
    title when every row has the same, else above their row's right panel."""
    names = sr.order
    fig = Figure(figsize=(13, 2.3 * len(names) + 1.1), layout="constrained")
    axes = fig.subplots(len(names), 2, sharex=True, squeeze=False)
    found = []
    for row, system in zip(axes, names):
        found.append(draw(row[0], row[1], sr.systems[system], iterations))
        for ax, lab in zip(row, ylabel):
            ax.set_ylabel(f"{system}\n{lab}")
            ax.grid(True, alpha=0.3)
    titles = list(panels)
    suptitle = f"Scenario {sr.scenario.id}: {title}"
    shape = [[(c.members, c.differ) for c in f] for f in found]
    if found and found[0] and all(s == shape[0] for s in shape):  # the same iterations coincide for every system
        suptitle += f"\nevery system: {_coincide_note(found)}"
    else:
        for r, (row, f) in enumerate(zip(axes, found)):
            if f:
                note = textwrap.fill(_coincide_note([f]), 100)
                if r == 0:
                    titles[1] += "\n" + note
                else:
                    row[1].set_title(note, fontsize=7, y=TITLE_Y)
    for ax, panel in zip(axes[0], titles):
        ax.set_title(panel, fontsize=9 if "\n" not in panel else 7, y=TITLE_Y)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(suptitle, fontsize=11)
    seen: dict[str, object] = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lab, h)
    _legend_below(fig, list(seen.values()), list(seen), ncol=min(len(seen), 6))
    return fig


def _draw_error(left, right, s, iterations: int) -> tuple[_Coincide, ...]:
    left.plot(s.no_dob.t, s.no_dob.e, color=_COLORS[0], lw=0.9, label="no DOB")
    left.plot(s.dob.t, s.dob.e, color=_COLORS[1], lw=0.9, label="only DOB")
    return _draw_iterations([left, right], [(f.e, f.e) for f in s.learning], [f.t for f in s.learning], iterations)


def _draw_disturbance(left, right, s, iterations: int) -> tuple[_Coincide, ...]:
    # the true disturbance on top of the estimates (zorder), so that it stays visible
    left.plot(s.dob.t, s.dob.d, color="k", lw=1.0, zorder=5, label="true d (wind + noise)")
    left.plot(s.dob.t, s.dob.d_hat, color=_COLORS[1], lw=0.9, label="only DOB: d_hat")
    right.plot(s.dob.t, s.dob.d_hat - s.dob.d, color=_COLORS[1], lw=0.9, label="only DOB: d_hat")
    curves = [(f.d_hat + f.d_f, f.d_hat + f.d_f - f.d) for f in s.learning]
    return _draw_iterations([left, right], curves, [f.t for f in s.learning], iterations, ": d_hat + d_f")


def _bode_columns(fig: Figure, ts: float, w: np.ndarray, columns: list[tuple[str, list[BodeCurve]]]) -> Figure:
    """One column per response: magnitude above, phase below (:func:`~ilcdob.design.checks.figure.draw_bode`)."""
    axes = fig.subplots(2, len(columns), sharex=True, squeeze=False)
    for col, (title, curves) in enumerate(columns):
        draw_bode(axes[0, col], axes[1, col], w, curves)
        finish_bode_axes(axes[0, col], axes[1, col], title, ts)
    return _done(fig)


def _color(i: int) -> str:
    return _COLORS[i % len(_COLORS)]


def _bode_loops(fleet: Fleet) -> Figure:
    w = frequency_grid(fleet.sample_time)
    g_r, g_d = [], []
    for i, lp in enumerate(fleet.loops):
        g_r.append(BodeCurve(lp.name, freqresp(lp.G_r, w), _color(i)))
        g_d.append(BodeCurve(f"{lp.name} (DOB)", freqresp(lp.G_d, w), _color(i)))
        g_d.append(BodeCurve(f"{lp.name} (no DOB)", freqresp(lp.G_d_no_dob, w), _color(i), ":"))
    return _bode_columns(Figure(figsize=(11, 6.5)), fleet.sample_time, w,
                         [("G_r: reference -> position", g_r), ("G_d: disturbance -> position", g_d)])


def _pair(src: str, tgt: str) -> str:
    return f"{src} -> {tgt}"


def _bode_learning(filters: dict[tuple[str, str], LearningFilters], ts: float) -> Figure:
    w = frequency_grid(ts)
    pairs = sorted(filters.items())
    l1 = [BodeCurve(_pair(*key), lf.l1_response(w), _color(i)) for i, (key, lf) in enumerate(pairs)]
    l2 = [BodeCurve(_pair(*key), lf.l2_response(w), _color(i)) for i, (key, lf) in enumerate(pairs)]
    return _bode_columns(Figure(figsize=(11, 6.5)), ts, w,
                         [("L1 (applied to e_{j-1})", l1), ("L2 (applied to d_f,{j-1})", l2)])


def _bode_te(fleet: Fleet, filters: dict[tuple[str, str], LearningFilters]) -> Figure:
    ts = fleet.sample_time
    w = frequency_grid(ts)
    true = {lp.name: with_gain_error(lp, 1 + TE_GAIN_ERROR) for lp in fleet.loops}
    te1, te2 = [], []
    for i, ((src, tgt), lf) in enumerate(sorted(filters.items())):
        r1, r2 = lf.te_responses(w, true[src], true[tgt])
        te1.append(BodeCurve(_pair(src, tgt), r1, _color(i)))
        te2.append(BodeCurve(_pair(src, tgt), r2, _color(i)))
    omega = [BodeCurve(lp.name, loop_maps(lp, w)["Omega"], _color(i)) for i, lp in enumerate(fleet.loops)]
    pct = f"{100 * TE_GAIN_ERROR:.0f} %"
    return _bode_columns(Figure(figsize=(14, 6.5)), ts, w,
                         [(f"Te1 (true plants {pct} stronger than models)", te1),
                          (f"Te2 (true plants {pct} stronger than models)", te2),
                          ("Omega: disturbance -> DOB estimate", omega)])


def identified_bounds(fleet: Fleet, w: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``name -> (G(jw), |Delta(jw)| at 3 sigma)`` for every system with an identified plant.

    Parameters
    ----------
    fleet : Fleet
        Systems without an identification are left out.
    w : array
        Frequencies, rad/s.
    """
    out = {}
    for spec in fleet.systems:
        ident = spec.identification
        if ident is None:
            continue
        structure = ModelStructure(ident.poles, ident.zeros, ident.integrators)
        delay = spec.nominal_plant.delay
        out[spec.name] = (frequency_response(structure, np.asarray(ident.parameters), delay, w),
                          ident.bound(w, delay))
    return out


def _identified_models(fleet: Fleet) -> Figure | None:
    w = np.logspace(-2, np.log10(0.999 * np.pi / fleet.sample_time), 300)
    models = identified_bounds(fleet, w)
    if not models:
        return None
    fig, axes = _subplots(1, 2, (11, 3.8))
    for i, (name, (g, bound)) in enumerate(models.items()):
        c = _COLORS[i % len(_COLORS)]
        mag = magnitude_db(g)
        axes[0].semilogx(w, mag, color=c, label=name)
        axes[0].fill_between(w, mag + magnitude_db(np.maximum(1 - bound, 1e-6)), mag + magnitude_db(1 + bound),
                             color=c, alpha=0.25)
        axes[1].loglog(w, bound, color=c, label=name)
    axes[0].set_title("identified plants with 3-sigma uncertainty band", y=TITLE_Y)
    axes[0].set_ylabel("magnitude (dB)")
    axes[1].set_title("|Delta(jw)|: 3-sigma multiplicative uncertainty", y=TITLE_Y)
    for ax in axes:
        ax.set_xlabel("frequency (rad/s)")
        ax.grid(True, which="both", alpha=0.3)  # minor lines of long log views: minor_log_grid (_done)
        ax.legend(fontsize=7)
    return _done(fig)


@dataclass(frozen=True)
class PendingFigure:
    """A figure not built yet, as content of a file: :func:`render_figures` builds it where it renders it.

    Attributes
    ----------
    make : callable
        ``make()`` builds the figure (a :class:`~matplotlib.figure.Figure` with its layout engine).
    axes : int
        The axes the figure will have. Building and drawing a figure costs about in proportion to
        its axes: :class:`FigureRenderer` starts the figures with more first, so that its workers end
        together.
    """

    make: Callable[[], Figure]
    axes: int = 1

    def build(self) -> Figure:
        """The figure, built now.

        Returns
        -------
        matplotlib.figure.Figure
        """
        fig = self.make()
        if not isinstance(fig, Figure):
            raise TypeError(f"PendingFigure.make returned {type(fig).__name__}, expected a matplotlib Figure")
        return fig


def _per_scenario(sr, iterations: int, kind: str) -> Figure:
    """The ``error_s<N>.png`` or ``disturbance_s<N>.png`` figure of scenario ``sr``."""
    n = iterations
    if kind == "error":
        return _per_system(sr, n, f"tracking error of every trial ({n} learning iteration{'s' * (n != 1)})",
                           ("no DOB, only DOB and every learning iteration", "learning iterations only (zoom)"),
                           ("error e (m)", "error e (m)"), _draw_error)
    return _per_system(sr, n, f"disturbance estimates of every trial ({n} learning iteration{'s' * (n != 1)})",
                       ("true disturbance and its estimates", "estimate minus true disturbance"),
                       ("d (m/s$^2$)", "estimate - d (m/s$^2$)"), _draw_disturbance)


def scenario_figures(sr, iterations: int, pending: bool = False) -> dict[str, Figure | PendingFigure]:
    """The figures of one scenario as :func:`reproduction_figures` names them: ``error_s<N>.png`` and
    ``disturbance_s<N>.png``.

    Parameters
    ----------
    sr : ScenarioResult
        The scenario's flights (:class:`~ilcdob.validation.reproduce.ScenarioResult`).
    iterations : int
        Learning iterations of the reproduction.
    pending : bool
        Return them unbuilt (:class:`PendingFigure`).

    Returns
    -------
    dict of str to matplotlib.figure.Figure or PendingFigure
    """
    figs = {f"{kind}_s{sr.scenario.id}.png": PendingFigure(partial(_per_scenario, sr, iterations, kind),
                                                            axes=2 * len(sr.order))
            for kind in ("error", "disturbance")}
    return _pending_or_built(figs, pending)


def fleet_figures(fleet: Fleet, pending: bool = False) -> dict[str, Figure | PendingFigure]:
    """The figures of a reproduction that need the fleet alone (they can be rendered before it flies).

    Parameters
    ----------
    fleet : Fleet
        The fleet flown.
    pending : bool
        Return each figure unbuilt, as a :class:`PendingFigure`.

    Returns
    -------
    dict of str to matplotlib.figure.Figure or PendingFigure
        ``bode_loops.png``, and ``identified_models.png`` when a system has an identified plant.
    """
    figs = {"bode_loops.png": PendingFigure(partial(_bode_loops, fleet), axes=4)}
    if any(spec.identification is not None for spec in fleet.systems):  # the systems identified_bounds draws
        figs["identified_models.png"] = PendingFigure(partial(_identified_models, fleet), axes=2)
    return _pending_or_built(figs, pending)


def reproduction_figures(res: ReproductionResult, pending: bool = False) -> dict[str, Figure | PendingFigure]:
    """Every figure of a reproduction, by PNG file name, in the order of the report.

    Parameters
    ----------
    res : ReproductionResult
        The reproduction (linear or nonlinear plant).
    pending : bool
        Return each figure unbuilt, as a :class:`PendingFigure` (for :func:`render_figures`,
        which builds and renders them in parallel).

    Returns
    -------
    dict of str to matplotlib.figure.Figure or PendingFigure
        ``rmse_bars.png``, ``error_s<N>.png`` and ``disturbance_s<N>.png`` per scenario
        (:func:`scenario_figures`), ``bode_loops.png``, ``identified_models.png`` (systems with
        an identified plant only), ``bode_learning.png`` and ``bode_te.png`` (when
        ``res.filters`` holds pairs). Each lays itself out when drawn; save each at :data:`FIGURE_DPI`
        (:func:`figure_png`).
    """
    figs = {"rmse_bars.png": PendingFigure(partial(_rmse_bars, res), axes=len(res.scenarios))}
    for sr in res.scenarios:
        figs.update(scenario_figures(sr, res.iterations, pending=True))
    figs.update(fleet_figures(res.fleet, pending=True))
    if res.filters:
        figs["bode_learning.png"] = PendingFigure(partial(_bode_learning, res.filters, res.fleet.sample_time), axes=4)
        figs["bode_te.png"] = PendingFigure(partial(_bode_te, res.fleet, res.filters), axes=6)
    return _pending_or_built(figs, pending)


def _pending_or_built(figs: dict[str, PendingFigure], pending: bool) -> dict[str, Figure | PendingFigure]:
    return figs if pending else {name: p.make() for name, p in figs.items()}


def figure_png(fig: Figure) -> bytes:
    """The PNG file of a figure at :data:`FIGURE_DPI`, drawn once (module docstring, "Rendering").

    The bytes are those of ``fig.savefig(f, format="png", dpi=FIGURE_DPI, pil_kwargs={"compress_level":
    PNG_COMPRESS_LEVEL})``; the figure is left laid out at that resolution, on an Agg canvas, without a
    layout engine.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        A figure with a layout engine (constrained or tight), or laid out already.

    Returns
    -------
    bytes
    """
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.layout_engine import PlaceHolderLayoutEngine

    FigureCanvasAgg(fig)  # one renderer for the layout and the drawing: text is measured once
    engine = fig.get_layout_engine()
    if engine is not None and not isinstance(engine, PlaceHolderLayoutEngine):
        fig.set_dpi(FIGURE_DPI)  # the layout savefig would compute, at the resolution it renders
        engine.execute(fig)
    with matplotlib.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        fig.set_layout_engine(None)  # laid out: savefig draws once
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=FIGURE_DPI, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return buf.getvalue()


def render_workers(workers: object = None, jobs: int | None = None, name: str = "workers") -> int:
    """Processes :func:`render_figures` uses: ``workers``, or one per usable core, at most one per job.

    Parameters
    ----------
    workers : int or None
        Processes asked for (>= 1); None: the usable cores of this process.
    jobs : int, optional
        Figures to render (caps the count; 0 or 1: this process alone).
    name : str
        The name ``workers`` was given under, for the error message.

    Returns
    -------
    int
        1 means this process renders alone (also where worker processes cannot be forked: not
        Linux).

    Raises
    ------
    SpecError
        ``workers`` not an integer >= 1.
    """
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise SpecError(f"`{name}` (figure rendering processes): got {workers!r}, expected an integer >= 1, or "
                        "None for one per usable core")
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if jobs is not None:
        workers = min(workers, jobs)
    return max(1, workers) if sys.platform.startswith("linux") else 1


def _is_figure(content: object) -> bool:
    return isinstance(content, (Figure, PendingFigure))


def _axes(content: object) -> int:
    """Axes of a figure, built or pending (:attr:`PendingFigure.axes`)."""
    return content.axes if isinstance(content, PendingFigure) else len(content.axes)


def _figure_of(content: object) -> Figure:
    return content.build() if isinstance(content, PendingFigure) else content


@dataclass
class _Batch:
    """Figures submitted together: their names, the shared counter of the next one to take, how many
    have come back and how many workers are on them."""

    names: list[str]
    counter: object = None
    received: int = 0
    workers: int = 0


@dataclass
class _Worker:
    """A forked worker process, the caller's end of its pipe and its batch."""

    proc: object
    conn: object
    batch: _Batch


class FigureRenderer:
    """Builds and renders figures to PNG bytes in forked worker processes while the caller goes on.

    :meth:`submit` starts figures as soon as their data exist (e.g. each scenario's when it is
    flown), in workers forked then, which see the caller's objects as they are at that moment;
    :meth:`finish` renders the rest of a content map and returns it with every figure as PNG
    bytes. While the caller works, the submitted figures use one worker fewer than
    ``workers`` (the caller's core); :meth:`finish` uses all, and renders the submitted figures
    no worker has started yet with the rest, as one batch (a fork per worker, not per batch), the
    figures with the most axes first (:attr:`PendingFigure.axes`). With one worker (one usable
    core, not Linux) everything is rendered in this process by :meth:`finish`. Use as a context
    manager: leaving it with an exception stops the workers (module docstring, "Rendering").

    Parameters
    ----------
    workers : int, optional
        Worker processes (:func:`render_workers`; default one per usable core).

    Raises
    ------
    SpecError
        Bad ``workers``.
    """

    def __init__(self, workers: int | None = None) -> None:
        self.workers = render_workers(workers)
        self._content: dict[str, object] = {}
        self._batches: list[_Batch] = []  # with figures not back yet
        self._running: list[_Worker] = []
        self._out: dict[str, bytes] = {}

    def __enter__(self) -> FigureRenderer:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def submit(self, figures: Mapping[str, object]) -> None:
        """Start building and rendering ``figures`` (name -> Figure or PendingFigure; other values ignored).

        Parameters
        ----------
        figures : mapping of str to object
            Figures not submitted before.
        """
        names = [name for name, c in figures.items() if _is_figure(c)]
        again = [name for name in names if name in self._content]
        if again:
            raise ValueError(f"FigureRenderer.submit: {again} submitted twice")
        self._content.update({name: figures[name] for name in names})
        if self.workers > 1 and names:
            self._batches.append(_Batch(names))
            self._collect(block=False)
            self._start(max(1, self.workers - 1))

    def finish(self, content: Mapping[str, object]) -> dict[str, object]:
        """``content`` with every figure as its PNG bytes: those submitted, the others rendered now.

        Parameters
        ----------
        content : mapping of str to object
            File name -> content (:mod:`ilcdob.app.output`); its figures (Figure or
            PendingFigure) whose names were submitted are replaced by what was rendered for them.

        Returns
        -------
        dict of str to object
            The content map in the same order, each figure as the bytes of its PNG file.

        Raises
        ------
        RuntimeError
            A worker process ended without sending its figure (killed, out of memory).
        Exception
            What building or rendering a figure raised, with the worker's traceback as a note.
        """
        rest = {name: c for name, c in content.items() if _is_figure(c) and name not in self._content}
        if self.workers > 1:
            # the batches no worker has started join the rest: one batch, taken by every worker in turn,
            # costs a fork per worker instead of one per figure; the figures with the most axes first (the
            # longest first: the last ones taken are short, so the workers end closer together)
            waiting = [name for b in self._batches if b.counter is None for name in b.names]
            self._batches = [b for b in self._batches if b.counter is not None]
            self._content.update(rest)
            if waiting or rest:
                self._batches.append(_Batch(sorted([*rest, *waiting], key=lambda n: -_axes(self._content[n]))))
            while self._running or self._wanted() is not None:
                self._start(self.workers)
                self._collect(block=True)
        else:
            self._content.update(rest)
            for name, c in self._content.items():
                if name not in self._out:
                    self._out[name] = figure_png(_figure_of(c))
        missing = [name for name in self._content if name not in self._out]
        if missing:
            raise RuntimeError(f"figure workers ended without rendering {missing} (killed, or out of memory)")
        return {name: self._out[name] if _is_figure(c) else c for name, c in content.items()}

    def close(self) -> None:
        """Stop the workers still running (their figures are dropped)."""
        for w in self._running:
            if w.proc.is_alive():
                w.proc.terminate()
        for w in self._running:
            w.proc.join()
            w.conn.close()
        self._running = []
        self._batches = []

    def _wanted(self) -> _Batch | None:
        """The first batch with more figures to come than workers on it (a worker would find one)."""
        return next((b for b in self._batches if len(b.names) - b.received > b.workers
                     and (b.counter is None or b.counter.value < len(b.names))), None)

    def _start(self, slots: int) -> None:
        """Fork workers for the batches that want one while fewer than ``slots`` run."""
        import gc
        import multiprocessing

        if len(self._running) >= slots or self._wanted() is None:
            return
        ctx = multiprocessing.get_context("fork")
        for stream in (sys.stdout, sys.stderr):  # written before the fork, not by a worker too
            if stream is not None:
                stream.flush()
        gc.freeze()  # a worker's collector leaves the caller's objects alone: their pages stay shared
        try:
            while len(self._running) < slots and (batch := self._wanted()) is not None:
                if batch.counter is None:
                    batch.counter = ctx.Value("i", 0)
                recv, send = ctx.Pipe(duplex=False)
                _widen(send)
                theirs = [w.conn for w in self._running] + [recv]
                proc = ctx.Process(target=_render_worker, name="ilcdob-figures", daemon=True,
                                   args=(self._content, batch.names, batch.counter, send, os.getpid(), theirs))
                proc.start()
                send.close()
                self._running.append(_Worker(proc, recv, batch))
                batch.workers += 1
        finally:
            gc.unfreeze()

    def _collect(self, block: bool) -> None:
        """Read what the workers sent (waiting for a message when ``block``); drop the ended ones."""
        from multiprocessing.connection import wait

        if not self._running:
            return
        for conn in wait([w.conn for w in self._running], timeout=None if block else 0):
            worker = next(w for w in self._running if w.conn is conn)
            try:
                msg = conn.recv()
            except EOFError:  # the worker ended
                worker.proc.join()
                conn.close()
                self._running.remove(worker)
                worker.batch.workers -= 1
                if worker.batch.workers == 0 and worker.batch.counter.value >= len(worker.batch.names):
                    self._batches.remove(worker.batch)  # every figure taken, and no worker left on it
                continue
            if msg[0] == "error":
                _, name, exc, text = msg
                exc.add_note(f"while rendering {name} in a worker process:\n{text}")
                raise exc
            self._out[msg[1]] = msg[2]
            worker.batch.received += 1


def _widen(conn) -> None:
    """Make a pipe hold a few figures (1 MiB, Linux), so that a worker rarely waits for the caller to read."""
    try:
        import fcntl

        fcntl.fcntl(conn.fileno(), fcntl.F_SETPIPE_SZ, 1 << 20)
    except (ImportError, AttributeError, OSError):
        pass  # the default size: a worker waits for the caller to read


def render_figures(content: Mapping[str, object], workers: int | None = None) -> dict[str, object]:
    """A content map with every figure (built, or :class:`PendingFigure`) replaced by its PNG bytes.

    Parameters
    ----------
    content : mapping of str to object
        File name -> content (:mod:`ilcdob.app.output`); the values that are a
        :class:`~matplotlib.figure.Figure` or a :class:`PendingFigure` are rendered
        (:func:`figure_png`), the others kept as they are, in the same order.
    workers : int, optional
        Processes that build and render (:func:`render_workers`; default one per usable core).

    Returns
    -------
    dict of str to object
        The content map, each figure as the bytes of its PNG file.

    Raises
    ------
    SpecError
        Bad ``workers``.
    RuntimeError
        A worker process ended without sending its figure (killed, out of memory).
    Exception
        What building or rendering a figure raised, with the worker's traceback as a note.
    """
    n = render_workers(workers, sum(1 for c in content.values() if _is_figure(c)))
    with FigureRenderer(n) as renderer:
        return renderer.finish(content)


def _die_with_parent(parent: int) -> None:
    """Have the kernel kill this worker when its parent dies (Linux), and end now if it has already."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, 9)  # PR_SET_PDEATHSIG, SIGKILL
    except (OSError, AttributeError):
        pass  # no prctl: the worker still stops when it cannot send
    if os.getppid() != parent:
        os._exit(0)


def _render_worker(content: Mapping[str, object], names: list[str], counter, conn, parent: int,
                   theirs: list) -> None:
    """A forked worker: render the next figure of ``names`` (shared ``counter``) until none is left,
    sending each to ``conn``; ``theirs``: the caller's ends of the pipes, closed here. It ends with
    ``os._exit``: nothing of the caller's state (buffered output, exit handlers) runs twice."""
    import gc
    import signal

    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C: the caller stops the workers
        _die_with_parent(parent)
        for other in theirs:  # so that a send fails (and the worker ends) once the caller is gone
            other.close()
        # one collection per figure instead of the collector's own runs while matplotlib builds thousands of
        # artists: a figure is cycles of artists, all garbage once sent (the caller's objects are frozen)
        gc.disable()
        while True:
            with counter.get_lock():
                i = counter.value
                counter.value = i + 1
            if i >= len(names):
                return
            name = names[i]
            try:
                png = figure_png(_figure_of(content[name]))
            except Exception as exc:  # sent to the caller, which raises it
                text = traceback.format_exc()
                try:
                    conn.send(("error", name, exc, text))
                except Exception:  # an exception that does not pickle: its text
                    conn.send(("error", name, RuntimeError(f"{type(exc).__name__}: {exc}"), text))
                return
            conn.send(("png", name, png))
            gc.collect()
    except (BrokenPipeError, EOFError, OSError):
        return  # the caller is gone
    finally:
        try:
            conn.close()
        finally:
            os._exit(0)


def comparison_figure(cmp: Comparison, rho: float | None = None) -> Figure:
    """``compare_ratios.png``: the ratio of every case per design (log scale).

    A design that failed has its place on the axis, labelled "design failed", and no points.

    Parameters
    ----------
    cmp : Comparison
        The comparison (:func:`~ilcdob.validation.compare.compare_designs`).
    rho : float, optional
        The robust design's guaranteed factor, drawn as a line when given.
    """
    fig = Figure(figsize=(8, 3.8), layout="constrained")
    ax = fig.subplots()
    first = True
    for i, m in enumerate(cmp.methods):
        if m.error is not None:
            continue
        ax.scatter(np.full(len(m.ratios) - 1, i) + np.linspace(-0.15, 0.15, len(m.ratios) - 1), m.ratios[1:],
                   s=14, color="0.4", label="Delta samples" if first else None)
        ax.scatter([i], [m.ratio_nominal], marker="D", color="C3", label="nominal" if first else None)
        first = False
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="no improvement (ratio 1)")
    if rho is not None:
        ax.axhline(rho, color="C0", lw=0.8, ls=":", label=f"robust rho = {rho:g}")
    ax.set_xticks(range(len(cmp.methods)),
                  [m.method + ("\n(design failed)" if m.error is not None else "") for m in cmp.methods])
    ax.set_xlim(-0.5, len(cmp.methods) - 0.5)
    ax.set_yscale("log")
    ax.set_ylabel("||e_j|| / ||e'_j||")
    ax.set_title(f"Scenario {cmp.scenario}: {cmp.target} learning from {cmp.source} (law {cmp.law})",
                 fontsize=10, y=TITLE_Y)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    return fig


def campaign_figure(result: CampaignResult) -> Figure:
    """``campaign_ratios.png``: the ratio distribution per method and scenario (log scale).

    Parameters
    ----------
    result : CampaignResult
        The campaign (:func:`~ilcdob.validation.campaign.run.run_campaign`).
    """
    methods = list(result.options.methods)
    sids = list(result.options.scenarios)
    fig = Figure(figsize=(1.9 * len(methods) + 2.5, 4.2))
    ax = fig.subplots()
    width = 0.8 / len(sids)
    floor = np.inf
    for k, sid in enumerate(sids):
        pos = np.arange(len(methods)) - 0.4 + width * (k + 0.5)
        data = [np.array([r for r in result.ratios[sid][m] if r is not None], float) for m in methods]
        for p, d in zip(pos, data):
            if d.size:
                floor = min(floor, float(d.min()))
                ax.boxplot(d, positions=[p], widths=0.8 * width, whis=(0, 100), showfliers=False,
                           patch_artist=True, boxprops={"facecolor": f"C{k}", "alpha": 0.5},
                           medianprops={"color": "k"})
                jitter = np.random.default_rng(k).uniform(-0.3, 0.3, d.size) * width
                ax.scatter(p + jitter, d, s=3, color=f"C{k}", alpha=0.6, zorder=3)
        a, b = result.pairs[sid]
        ax.plot([], [], "s", color=f"C{k}", alpha=0.6, label=f"scenario {sid} ({a} -> {b})")
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="no improvement")
    if any("--rho" in METHODS[m].cli_options for m in methods):  # a design asked for rho
        ax.axhline(result.options.rho, color="C3", lw=0.8, ls=":", label=f"rho = {result.options.rho:g} (asked for)")
    ax.set_xticks(range(len(methods)), [f"{m}\n{100 * result.methods[m].share_improved:.0f}% improved"
                                        for m in methods])
    ax.set_yscale("log")
    if math.isfinite(floor):
        ax.set_ylim(bottom=0.5 * floor)
    ax.set_ylabel("||e_j|| / ||e'_j||")
    ax.set_title(f"{result.options.samples} samples, true plants from {result.uncertainty} (box: quartiles, "
                 "whiskers: range)", fontsize=9, y=TITLE_Y)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.set_layout_engine("tight")
    return fig
