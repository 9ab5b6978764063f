"""Figures of the reproduction, in the paper's layout (PNG, matplotlib Agg backend).

* ``rmse_bars.png`` - RMSE per scenario and system: no DOB, only DOB, learning 1..n;
* ``error_s<N>.png`` - tracking error against time per system;
* ``disturbance_s<N>.png`` - disturbance estimates against the true disturbance;
* ``bode_loops.png`` - G_r and G_d (with the no-DOB G_d for comparison);
* ``bode_learning.png`` - L1 and L2 of every learning pair flown;
* ``bode_te.png`` - Te1, Te2 (error propagation with learning, under a stated model error)
  and Omega (disturbance -> DOB estimate).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ilcdob.atomic import savefig_atomic  # noqa: E402
from ilcdob.design import LearningFilters  # noqa: E402
from ilcdob.fleet import Fleet  # noqa: E402
from ilcdob.loop import LoopSystem, build_loop, freqresp  # noqa: E402
from ilcdob.specs import PlantSpec  # noqa: E402
from ilcdob.uncertainty import ModelStructure, frequency_response, multiplicative_bound  # noqa: E402

from .reproduce import ReproductionResult  # noqa: E402

__all__ = ["write_figures", "frequency_grid", "identified_bounds", "TE_GAIN_ERROR"]

#: Model error used for the Te figure: every true plant 10 % stronger than its model.
TE_GAIN_ERROR = 0.10
_DPI = 110
_COLORS = ["#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860"]


def frequency_grid(ts: float, n: int = 400) -> np.ndarray:
    """Log-spaced frequencies from 0.01 rad/s to just below Nyquist (pi/ts)."""
    return np.logspace(-2, np.log10(0.999 * np.pi / ts), n)


def _db(x: np.ndarray) -> np.ndarray:
    return 20 * np.log10(np.maximum(np.abs(x), 1e-300))


def _phase(x: np.ndarray) -> np.ndarray:
    return np.degrees(np.unwrap(np.angle(x)))


def _save(fig, out: Path, name: str) -> Path:
    path = out / name
    fig.tight_layout()
    savefig_atomic(fig, path, dpi=_DPI)
    plt.close(fig)
    return path


def _rmse_bars(res: ReproductionResult, out: Path) -> Path:
    n = len(res.scenarios)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.6), squeeze=False)
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
                   label=lab, color=_COLORS[k % len(_COLORS)])
        ax.set_yscale("log")
        ax.set_xticks(np.arange(len(names)), names)
        ax.set_title(f"Scenario {sr.scenario.id}: {sr.scenario.title}", fontsize=9)
        ax.set_ylabel("tracking RMSE (m)")
        ax.grid(True, axis="y", which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    return _save(fig, out, "rmse_bars.png")


def _per_system(sr, out: Path, name: str, title: str, ylabel: str, draw) -> Path:
    """One row per system of scenario ``sr``; ``draw(ax, system_result)`` fills a row."""
    names = sr.order
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 2.2 * len(names)), sharex=True, squeeze=False)
    for ax, system in zip(axes[:, 0], names):
        draw(ax, sr.systems[system])
        ax.set_ylabel(f"{system}\n{ylabel}")
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=3, loc="upper right")
    axes[0, 0].set_title(f"Scenario {sr.scenario.id}: {title}")
    axes[-1, 0].set_xlabel("time (s)")
    return _save(fig, out, name)


def _draw_error(ax, s) -> None:
    ax.plot(s.no_dob.t, s.no_dob.e, color=_COLORS[0], lw=0.9, label="no DOB")
    ax.plot(s.dob.t, s.dob.e, color=_COLORS[1], lw=0.9, label="only DOB")
    ax.plot(s.learning[0].t, s.learning[0].e, color=_COLORS[2], lw=1.1, label="learning 1")


def _draw_disturbance(ax, s) -> None:
    lf = s.learning[0]
    ax.plot(s.dob.t, s.dob.d, color="k", lw=1.2, label="true d (wind + noise)")
    ax.plot(s.dob.t, s.dob.d_hat, color=_COLORS[1], lw=0.9, label="DOB estimate (only DOB)")
    ax.plot(lf.t, lf.d_hat + lf.d_f, color=_COLORS[2], lw=0.9, ls="--", label="d_hat + d_f (learning 1)")


def _time_series(res: ReproductionResult, out: Path) -> list[Path]:
    paths = []
    for sr in res.scenarios:
        sid = sr.scenario.id
        paths.append(_per_system(sr, out, f"error_s{sid}.png", "tracking error", "error e (m)", _draw_error))
        paths.append(_per_system(sr, out, f"disturbance_s{sid}.png", "disturbance estimates",
                                 "d (m/s$^2$)", _draw_disturbance))
    return paths


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


def _bode_loops(fleet: Fleet, out: Path) -> Path:
    w = frequency_grid(fleet.sample_time)
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), sharex=True)
    for i, lp in enumerate(fleet.loops):
        c = _COLORS[i % len(_COLORS)]
        _bode_pair(axes[:, 0], w, freqresp(lp.G_r, w), lp.name, c)
        _bode_pair(axes[:, 1], w, freqresp(lp.G_d, w), f"{lp.name} (DOB)", c)
        _bode_pair(axes[:, 1], w, freqresp(lp.G_d_no_dob, w), f"{lp.name} (no DOB)", c, ls=":")
    _finish_bode(axes, ["G_r: reference -> position", "G_d: disturbance -> position"], fleet.sample_time)
    return _save(fig, out, "bode_loops.png")


def _bode_learning(filters: dict[tuple[str, str], LearningFilters], ts: float, out: Path) -> Path:
    w = frequency_grid(ts)
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), sharex=True)
    for i, ((src, tgt), lf) in enumerate(sorted(filters.items())):
        c = _COLORS[i % len(_COLORS)]
        _bode_pair(axes[:, 0], w, lf.l1_response(w), f"{src} -> {tgt}", c)
        _bode_pair(axes[:, 1], w, lf.l2_response(w), f"{src} -> {tgt}", c)
    _finish_bode(axes, ["L1 (applied to e_{j-1})", "L2 (applied to d_f,{j-1})"], ts)
    return _save(fig, out, "bode_learning.png")


def _with_gain_error(lp: LoopSystem, gain: float) -> LoopSystem:
    model = lp.spec.nominal_plant
    true = PlantSpec(tuple(np.asarray(model.num) * gain), model.den, model.delay)
    return build_loop(replace(lp.spec, plant=true, model=model), lp.ts)


def _bode_te(fleet: Fleet, filters: dict[tuple[str, str], LearningFilters], out: Path) -> Path:
    ts = fleet.sample_time
    w = frequency_grid(ts)
    fig, axes = plt.subplots(2, 3, figsize=(14, 6.5), sharex=True)
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
    return _save(fig, out, "bode_te.png")


def identified_bounds(fleet: Fleet, w: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``name -> (G(jw), |Delta(jw)| at 3 sigma)`` for every system with an identified plant."""
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


def _identified_models(fleet: Fleet, out: Path) -> Path | None:
    w = np.logspace(-2, np.log10(0.999 * np.pi / fleet.sample_time), 300)
    models = identified_bounds(fleet, w)
    if not models:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
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
    return _save(fig, out, "identified_models.png")


def write_figures(res: ReproductionResult, out: str | Path) -> list[Path]:
    """Write every figure of the reproduction into ``out``; returns the paths written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [_rmse_bars(res, out)]
    paths += _time_series(res, out)
    paths.append(_bode_loops(res.fleet, out))
    ident = _identified_models(res.fleet, out)
    if ident is not None:
        paths.append(ident)
    if res.filters:
        paths.append(_bode_learning(res.filters, res.fleet.sample_time, out))
        paths.append(_bode_te(res.fleet, res.filters, out))
    return paths
