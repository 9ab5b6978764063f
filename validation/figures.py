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

:func:`reproduction_figures` returns them by file name; nothing here writes a file (the
figures are laid out for PNG at 110 dpi, :data:`FIGURE_DPI`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from ilcdob.design import LearningFilters
from ilcdob.fleet import Fleet
from ilcdob.loop import LoopSystem, build_loop, freqresp
from ilcdob.specs import PlantSpec
from ilcdob.uncertainty import ModelStructure, frequency_response, multiplicative_bound

if TYPE_CHECKING:
    from .reproduce import ReproductionResult

__all__ = ["reproduction_figures", "frequency_grid", "identified_bounds", "TE_GAIN_ERROR", "FIGURE_DPI"]

#: Model error used for the Te figure: every true plant 10 % stronger than its model.
TE_GAIN_ERROR = 0.10
#: Resolution the figures are made for (dots per inch of the PNG files).
FIGURE_DPI = 110
_COLORS = ["#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860"]


def frequency_grid(ts: float, n: int = 400) -> np.ndarray:
    """Log-spaced frequencies from 0.01 rad/s to just below Nyquist (pi/ts).

    Parameters
    ----------
    ts : float
        Sample time, s.
    n : int
        Number of frequencies.
    """
    return np.logspace(-2, np.log10(0.999 * np.pi / ts), n)


def _db(x: np.ndarray) -> np.ndarray:
    return 20 * np.log10(np.maximum(np.abs(x), 1e-300))


def _phase(x: np.ndarray) -> np.ndarray:
    return np.degrees(np.unwrap(np.angle(x)))


def _subplots(nrows: int, ncols: int, figsize: tuple[float, float], **kwargs) -> tuple[Figure, object]:
    """A new :class:`Figure` (no pyplot, no backend) and its grid of axes."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def _done(fig: Figure) -> Figure:
    fig.tight_layout()
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
        ax.set_title(f"Scenario {sr.scenario.id}: {sr.scenario.title}", fontsize=9)
        ax.set_ylabel("tracking RMSE (m)")
        ax.grid(True, axis="y", which="both", alpha=0.3)
    _legend_below(fig, *axes[0][0].get_legend_handles_labels(), ncol=len(labels))
    return fig


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


def _per_system(sr, iterations: int, title: str, panels: tuple[str, str], ylabel: tuple[str, str],
                draw) -> Figure:
    """One row per system of scenario ``sr``, two panels per row (all trials | a zoom);
    ``draw(ax_left, ax_right, system_result, iterations)`` fills a row. One legend below."""
    names = sr.order
    fig = Figure(figsize=(13, 2.3 * len(names) + 0.9), layout="constrained")
    axes = fig.subplots(len(names), 2, sharex=True, squeeze=False)
    for row, system in zip(axes, names):
        draw(row[0], row[1], sr.systems[system], iterations)
        for ax, lab in zip(row, ylabel):
            ax.set_ylabel(f"{system}\n{lab}")
            ax.grid(True, alpha=0.3)
    for ax, panel in zip(axes[0], panels):
        ax.set_title(panel, fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(f"Scenario {sr.scenario.id}: {title}")
    seen: dict[str, object] = {}
    for ax in axes[0]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lab, h)
    _legend_below(fig, list(seen.values()), list(seen), ncol=min(len(seen), 6))
    return fig


def _draw_error(left, right, s, iterations: int) -> None:
    left.plot(s.no_dob.t, s.no_dob.e, color=_COLORS[0], lw=0.9, label="no DOB")
    left.plot(s.dob.t, s.dob.e, color=_COLORS[1], lw=0.9, label="only DOB")
    for i, f in enumerate(s.learning):
        left.plot(f.t, f.e, **_iteration_style(i, iterations))
        right.plot(f.t, f.e, **_iteration_style(i, iterations))


def _draw_disturbance(left, right, s, iterations: int) -> None:
    # the true disturbance on top of the estimates (zorder), so that it stays visible
    left.plot(s.dob.t, s.dob.d, color="k", lw=1.0, zorder=5, label="true d (wind + noise)")
    left.plot(s.dob.t, s.dob.d_hat, color=_COLORS[1], lw=0.9, label="only DOB: d_hat")
    right.plot(s.dob.t, s.dob.d_hat - s.dob.d, color=_COLORS[1], lw=0.9, label="only DOB: d_hat")
    for i, f in enumerate(s.learning):
        style = _iteration_style(i, iterations)
        style["label"] = f"learning {i + 1}: d_hat + d_f"
        left.plot(f.t, f.d_hat + f.d_f, **style)
        right.plot(f.t, f.d_hat + f.d_f - f.d, **style)


def _time_series(res: ReproductionResult) -> dict[str, Figure]:
    figs = {}
    n = res.iterations
    for sr in res.scenarios:
        sid = sr.scenario.id
        figs[f"error_s{sid}.png"] = _per_system(
            sr, n, f"tracking error of every trial ({n} learning iteration{'s' * (n != 1)})",
            ("no DOB, only DOB and every learning iteration", "learning iterations only (zoom)"),
            ("error e (m)", "error e (m)"), _draw_error)
        figs[f"disturbance_s{sid}.png"] = _per_system(
            sr, n, f"disturbance estimates of every trial ({n} learning iteration{'s' * (n != 1)})",
            ("true disturbance and its estimates", "estimate minus true disturbance"),
            ("d (m/s$^2$)", "estimate - d (m/s$^2$)"), _draw_disturbance)
    return figs


def _bode_pair(axes, w, resp, label, color, ls="-"):
    axes[0].semilogx(w, _db(resp), color=color, ls=ls, label=label)
    axes[1].semilogx(w, _phase(resp), color=color, ls=ls)


def _min_span(ax, span: float) -> None:
    """Keep matplotlib from zooming into rounding noise (L2 = 1 to 1e-8 with exact models)."""
    lo, hi = ax.get_ylim()
    if hi - lo < span:
        mid = 0.5 * (lo + hi)
        ax.set_ylim(mid - span / 2, mid + span / 2)


def _finish_bode(axes, titles, ts):
    for col, title in enumerate(titles):
        _min_span(axes[0, col], 10.0)
        _min_span(axes[1, col], 30.0)
        axes[0, col].set_title(title)
        axes[0, col].set_ylabel("magnitude (dB)")
        axes[1, col].set_ylabel("phase (deg)")
        axes[1, col].set_xlabel("frequency (rad/s)")
        for row in range(2):
            axes[row, col].grid(True, which="both", alpha=0.3)
            axes[row, col].axvline(np.pi / ts, color="0.6", lw=0.8)
        axes[0, col].legend(fontsize=7)


def _bode_loops(fleet: Fleet) -> Figure:
    w = frequency_grid(fleet.sample_time)
    fig, axes = _subplots(2, 2, (11, 6.5), sharex=True)
    for i, lp in enumerate(fleet.loops):
        c = _COLORS[i % len(_COLORS)]
        _bode_pair(axes[:, 0], w, freqresp(lp.G_r, w), lp.name, c)
        _bode_pair(axes[:, 1], w, freqresp(lp.G_d, w), f"{lp.name} (DOB)", c)
        _bode_pair(axes[:, 1], w, freqresp(lp.G_d_no_dob, w), f"{lp.name} (no DOB)", c, ls=":")
    _finish_bode(axes, ["G_r: reference -> position", "G_d: disturbance -> position"], fleet.sample_time)
    return _done(fig)


def _bode_learning(filters: dict[tuple[str, str], LearningFilters], ts: float) -> Figure:
    w = frequency_grid(ts)
    fig, axes = _subplots(2, 2, (11, 6.5), sharex=True)
    for i, ((src, tgt), lf) in enumerate(sorted(filters.items())):
        c = _COLORS[i % len(_COLORS)]
        _bode_pair(axes[:, 0], w, lf.l1_response(w), f"{src} -> {tgt}", c)
        _bode_pair(axes[:, 1], w, lf.l2_response(w), f"{src} -> {tgt}", c)
    _finish_bode(axes, ["L1 (applied to e_{j-1})", "L2 (applied to d_f,{j-1})"], ts)
    return _done(fig)


def _with_gain_error(lp: LoopSystem, gain: float) -> LoopSystem:
    model = lp.spec.nominal_plant
    true = PlantSpec(tuple(np.asarray(model.num) * gain), model.den, model.delay)
    return build_loop(replace(lp.spec, plant=true, model=model), lp.ts)


def _bode_te(fleet: Fleet, filters: dict[tuple[str, str], LearningFilters]) -> Figure:
    ts = fleet.sample_time
    w = frequency_grid(ts)
    fig, axes = _subplots(2, 3, (14, 6.5), sharex=True)
    true = {lp.name: _with_gain_error(lp, 1 + TE_GAIN_ERROR) for lp in fleet.loops}
    for i, ((src, tgt), lf) in enumerate(sorted(filters.items())):
        c = _COLORS[i % len(_COLORS)]
        te1, te2 = lf.te_responses(w, true[src], true[tgt])
        _bode_pair(axes[:, 0], w, te1, f"{src} -> {tgt}", c)
        _bode_pair(axes[:, 1], w, te2, f"{src} -> {tgt}", c)
    for i, lp in enumerate(fleet.loops):
        _bode_pair(axes[:, 2], w, freqresp(lp.Omega, w), lp.name, _COLORS[i % len(_COLORS)])
    pct = f"{100 * TE_GAIN_ERROR:.0f} %"
    _finish_bode(axes, [f"Te1 (true plants {pct} stronger than models)",
                        f"Te2 (true plants {pct} stronger than models)",
                        "Omega: disturbance -> DOB estimate"], ts)
    return _done(fig)


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
        theta = np.asarray(ident.parameters)
        delay = spec.nominal_plant.delay
        out[spec.name] = (frequency_response(structure, theta, delay, w),
                          multiplicative_bound(structure, theta, np.asarray(ident.covariance), delay,
                                               ident.delay_estimated, w))
    return out


def _identified_models(fleet: Fleet) -> Figure | None:
    w = np.logspace(-2, np.log10(0.999 * np.pi / fleet.sample_time), 300)
    models = identified_bounds(fleet, w)
    if not models:
        return None
    fig, axes = _subplots(1, 2, (11, 3.8))
    for i, (name, (g, bound)) in enumerate(models.items()):
        c = _COLORS[i % len(_COLORS)]
        mag = _db(g)
        axes[0].semilogx(w, mag, color=c, label=name)
        axes[0].fill_between(w, mag + _db(np.maximum(1 - bound, 1e-6)), mag + _db(1 + bound), color=c, alpha=0.25)
        axes[1].loglog(w, bound, color=c, label=name)
    axes[0].set_title("identified plants with 3-sigma uncertainty band")
    axes[0].set_ylabel("magnitude (dB)")
    axes[1].set_title("|Delta(jw)|: 3-sigma multiplicative uncertainty")
    for ax in axes:
        ax.set_xlabel("frequency (rad/s)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    return _done(fig)


def reproduction_figures(res: ReproductionResult) -> dict[str, Figure]:
    """Every figure of a reproduction, by PNG file name, in the order of the report.

    Parameters
    ----------
    res : ReproductionResult
        The reproduction (linear or nonlinear plant).

    Returns
    -------
    dict of str to matplotlib.figure.Figure
        ``rmse_bars.png``, ``error_s<N>.png`` and ``disturbance_s<N>.png`` per scenario,
        ``bode_loops.png``, ``identified_models.png`` (systems with an identified plant only),
        ``bode_learning.png`` and ``bode_te.png`` (when ``res.filters`` holds pairs). Laid
        out; save each at :data:`FIGURE_DPI`.
    """
    figs = {"rmse_bars.png": _rmse_bars(res)}
    figs.update(_time_series(res))
    figs["bode_loops.png"] = _bode_loops(res.fleet)
    ident = _identified_models(res.fleet)
    if ident is not None:
        figs["identified_models.png"] = ident
    if res.filters:
        figs["bode_learning.png"] = _bode_learning(res.filters, res.fleet.sample_time)
        figs["bode_te.png"] = _bode_te(res.fleet, res.filters)
    return figs
