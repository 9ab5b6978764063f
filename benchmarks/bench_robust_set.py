"""Benchmark: the robust-set design (:func:`ilcdob.design.robust_set.design_robust_set`), before and after.

Per pair, the whole design (the FIR ``F``, its verification, the closed form and the whole-trial figure
``rho_N``) is timed in one process with

* ``before``: the formulation as it was (copied below, ``_old_*``): the structured set's polygon and
  sagitta built from every value of its grid on all 20,199 verification frequencies, the 60 worst
  violations per exchange round, ``F`` on the verification grid as a dense ``20,199 x n_taps`` matrix;
* ``after``: the current :mod:`ilcdob.design.robust_set` / :mod:`ilcdob.design.value_set` (the
  set's boundary values where they decide the polygon, runs of violations in the exchange, ``F`` by
  Horner's rule).

The design cache is cleared before every design; the two are interleaved (before, after, before,
after, ...) and the median CPU time (``time.process_time``: every thread of the process, Clarabel's
included) of ``--repeat`` designs is reported with their ratio. The figures of each design (rho_best,
rho_guaranteed, nominal_worst) are printed for both, and the largest tap difference.

Pairs: the built-in fleet's default design (``ilcdob design --method robust-set``: the source's Delta
set from its identification, guaranteed over its parameter ellipsoid) for UAV1->UAV2, UAV2->UAV3 and
UAV1->UAV3; ``delta_set="structured"`` (for an identified source: the same ellipsoid); the README's
example (UAV2->UAV3, rho 0.8, disc of bound 0.3). ``--extra`` adds the fleet-bound sets of
reports/robust_set (UAV1->UAV2 at bound 0.5 and 0.9: disc, and the structured gain/high-pass family at
margins 0.5, 0.2 and 0), which take 14-70 s each before.

Run:  python benchmarks/bench_robust_set.py [--repeat 3] [--extra] [--only NAME,...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

import ilcdob
from ilcdob.design import robust_set as rs
from ilcdob.design.fir import FIRFilter
from ilcdob.design.pair import fleet_delta_sets
from ilcdob.design.robust_set import (_DESIGN_DIRECTIONS, _DIRECT_METHOD, _OK, _STATIC_REGULARISATION,
                                      RobustSetDesign, RobustSetOptions, RobustSetSolverError, bound_on_grid,
                                      structured_set)
from ilcdob.design.worst_case import mask_intervals, uncertainty_cones
from ilcdob.design.value_set import DIRECTIONS, EllipseFamily, ValueSet, complementary_sensitivity, worst_over_set
from ilcdob.errors import SpecError


# ---------------------------------------------------------------------------------------------------------------
# Before: the formulation as it was (design/robust_set.py and design/value_set.py), kept callable here.
# ---------------------------------------------------------------------------------------------------------------

def _old_values(family, source, w, margin):
    """``family.values`` as it was: the ellipse's grid by ``einsum``."""
    if isinstance(family, EllipseFamily):
        a = family.axes(source.ts, w)
        phi = np.linspace(0, 2 * np.pi, 2 * family.n_phi + 1)
        rho = np.linspace(0, 1, 2 * family.n_rad - 1)
        u = rho[:, None, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)[None]
        xy = np.einsum("wij,rpj->wrpi", a, u)
        return ValueSet(w, (xy[..., 0] + 1j * xy[..., 1],), family.describe())
    return family.values(source, w, margin)


def _old_image(values, t0, margin):
    t0 = np.asarray(t0).reshape((-1,) + (1,) * (values.ndim - 1))
    den = 1 + t0 * values
    keep = np.isfinite(values) & (np.abs(den) >= margin * np.abs(1 + values)) & (np.abs(den) > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(keep, (1 + values) / den, np.nan), keep


def _old_sagitta(g):
    out = np.zeros(g.shape[0])
    for arr in (g, np.swapaxes(g, 1, 2)):
        a, m, b = arr[:, 0:-2:2], arr[:, 1:-1:2], arr[:, 2::2]
        chord = b - a
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(np.real((m - a) * np.conj(chord)) / np.abs(chord) ** 2, 0, 1)
            d = np.abs(m - (a + np.where(np.abs(chord) > 0, t, 0) * chord))
        d = np.where(np.isfinite(d), d, 0.0).reshape(g.shape[0], -1)
        if d.shape[1]:
            out = np.maximum(out, d.max(axis=1))
    return out


def _old_outer_polygon(g, keep, k=0):
    k = k or DIRECTIONS
    theta = 2 * np.pi * np.arange(k) / k
    pts = np.where(keep, g, np.nan)
    support = np.full((g.shape[0], k), -np.inf)
    for i in range(k):
        proj = pts.real * np.cos(theta[i]) + pts.imag * np.sin(theta[i])
        support[:, i] = np.max(np.where(np.isfinite(proj), proj, -np.inf), axis=1)
    s0, s1 = support, np.roll(support, -1, axis=1)
    t0, t1 = theta, np.roll(theta, -1)
    det = np.sin(2 * np.pi / k)
    with np.errstate(invalid="ignore"):
        x = (s0 * np.sin(t1) - s1 * np.sin(t0)) / det
        y = (s1 * np.cos(t0) - s0 * np.cos(t1)) / det
    return np.where(np.isfinite(support).all(axis=1, keepdims=True), x + 1j * y, np.nan)


def _old_cone_rows(vs, t0, margin, directions=0):
    images = [_old_image(piece, t0, margin) for piece in vs.values]
    eps = np.max([_old_sagitta(g) for g, _ in images], axis=0)
    n = vs.w.size
    vert = _old_outer_polygon(np.concatenate([g[:, ::2, ::2].reshape(n, -1) for g, _ in images], axis=1),
                              np.concatenate([k[:, ::2, ::2].reshape(n, -1) for _, k in images], axis=1), directions)
    idx = np.repeat(np.arange(n), vert.shape[1])
    ok = np.isfinite(vert.reshape(-1))
    excluded = ~np.all([k.all(axis=(1, 2)) for _, k in images], axis=0)
    return (idx[ok], np.ones(int(ok.sum())), vert.reshape(-1)[ok], np.repeat(eps, vert.shape[1])[ok], excluded)


def _old_family_cones(source, family, w, margin=0.5, directions=0, chunk=400):
    if not 0 <= margin < 1:
        raise SpecError(f"`margin`: got {margin!r}, expected a number in [0, 1)")
    w = np.asarray(w, float).reshape(-1)
    t0 = complementary_sensitivity(source, w)
    parts = [_old_cone_rows(_old_values(family, source, w[lo:lo + chunk], margin), t0[lo:lo + chunk], margin,
                            directions)
             for lo in range(0, w.size, chunk)]
    starts = range(0, w.size, chunk)
    return (np.concatenate([p[0] + lo for p, lo in zip(parts, starts)]),
            *(np.concatenate([p[k] for p in parts]) for k in range(1, 5)))


def _old_set_rows(source, w, w_bound, bound, structure, margin, directions=0):
    if structure is not None:
        return _old_family_cones(source, structure, w, margin, directions)
    a, b, r, _, kind = uncertainty_cones(source, w, bound_on_grid(w_bound, bound, w), margin)
    return np.arange(w.size), a, b, r, kind == 1


class _OldProblem:
    """The SOCP on one grid, as it was (unchanged since)."""

    def __init__(self, ts, w, rows, opts, structured=False):
        idx, a, b, r = rows[:4]
        self.structured = structured
        scale = np.maximum.reduce([np.abs(a), np.abs(b), r])
        self.idx, self.a, self.b, self.r = idx, a / scale, b / scale, r / scale
        self.w, self.opts = w, opts
        self.phi = np.exp(-1j * np.outer(w * ts, np.arange(opts.n_taps) - opts.lead))

    def solve(self, rho):
        o = self.opts
        h = cp.Variable(o.n_taps)
        fr, fi = cp.Variable(self.w.size), cp.Variable(self.w.size)
        hard = (self.a <= 1e-9) | (self.r >= np.abs(self.b) * (1 - 1e-9))
        ok, zero = np.flatnonzero(~hard), np.flatnonzero(hard)
        i_ok = self.idx[ok]
        br, bi = self.b[ok].real, self.b[ok].imag
        u, v = cp.Variable(ok.size), cp.Variable(self.w.size)
        cons = [fr == self.phi.real @ h, fi == self.phi.imag @ h,
                cp.SOC(u, cp.vstack([self.a[ok] - (cp.multiply(br, fr[i_ok]) - cp.multiply(bi, fi[i_ok])),
                                     -(cp.multiply(br, fi[i_ok]) + cp.multiply(bi, fr[i_ok]))]), axis=0),
                cp.SOC(v, cp.vstack([fr, fi]), axis=0)]
        if zero.size:
            az = np.maximum(self.a[zero], 0.0)
            cap = 0.5 * o.tol * az / (np.abs(self.b[zero]) + self.r[zero])
            iz = self.idx[zero]
            cons.append(cp.SOC(cap, cp.vstack([fr[iz], fi[iz]]), axis=0))
        t = cp.Variable() if rho is None else rho + (0.5 * o.tol if self.structured and rho >= 1 else 0.0)
        cons.append(u + cp.multiply(self.r[ok], v[i_ok]) <= t * self.a[ok])
        if rho is None:
            obj = t + 1e-6 * cp.sum_squares(h)
        else:
            sw = np.sqrt(o.weights(self.w) / self.w.size)
            obj = (cp.sum_squares(cp.multiply(sw, 1 - fr)) + cp.sum_squares(cp.multiply(sw, fi))
                   + o.ridge * cp.sum_squares(h))
        prob = cp.Problem(cp.Minimize(obj), cons)
        for k, reg in enumerate(_STATIC_REGULARISATION):
            try:
                with warnings.catch_warnings():
                    warnings.filterwarnings("ignore", message="Solution may be inaccurate", category=UserWarning)
                    prob.solve(solver="CLARABEL", direct_solve_method=_DIRECT_METHOD,
                               static_regularization_constant=reg)
                break
            except cp.error.SolverError as exc:
                if k + 1 == len(_STATIC_REGULARISATION):
                    raise RobustSetSolverError(f"robust-set design: Clarabel failed ({exc})") from exc
        if prob.status not in _OK or h.value is None:
            raise RobustSetSolverError(f"robust-set design: solver status {prob.status!r} at rho = {rho}")
        return np.asarray(h.value, float), float(t.value) if rho is None else float(rho)


def _old_design_filter(source, target, w_bound, bound, o, structure):
    """``_design_filter`` as it was."""
    ts = source.ts
    t_start = time.perf_counter()
    wv = o.verify_grid(ts)
    rows_v = _old_set_rows(source, wv, w_bound, bound, structure, o.margin)
    excluded_v = rows_v[4]
    described = "disc |Delta| <= W" if structure is None else structure.describe()
    phi_v = np.exp(-1j * np.outer(wv * ts, np.arange(o.n_taps) - o.lead))

    def run(rho):
        grid, rounds = o.grid(ts), 0
        while True:
            rows = _old_set_rows(source, grid, w_bound, bound, structure, o.margin, _DESIGN_DIRECTIONS)
            h, level = _OldProblem(ts, grid, rows, o, structure is not None).solve(rho)
            worst = worst_over_set(phi_v @ h, *rows_v[:4], wv.size)
            bad = worst > level + o.tol
            if not np.any(bad) or rounds >= o.max_exchange:
                return h, worst, level, rounds
            idx = np.flatnonzero(bad)
            idx = idx[np.argsort(-np.nan_to_num(worst[idx], posinf=1e12))][:60]
            grid = np.unique(np.concatenate([grid, wv[idx]]))
            rounds += 1

    h_best, worst_best, _, _ = run(None)
    rho_best = float(np.max(worst_best))
    feasible = o.rho >= rho_best
    rho_design = o.rho if feasible else float(min(1.0, rho_best + o.slack))
    if not feasible and not o.relax:
        return RobustSetDesign(None, FIRFilter(h_best, o.lead, ts), o.rho, rho_best, rho_best, rho_best, False,
                               float(np.max(np.abs(1 - phi_v @ h_best))), mask_intervals(wv, excluded_v), wv,
                               worst_best, 0, time.perf_counter() - t_start, described, trial=o.trial)
    h, worst, _, rounds = run(rho_design)
    guaranteed = float(np.max(worst))
    if guaranteed > max(rho_design + o.tol, rho_best):
        h, worst, guaranteed = h_best, worst_best, rho_best
    rho_best = min(rho_best, guaranteed)
    if not guaranteed <= 1.0 + o.tol:
        raise RobustSetSolverError(f"robust-set design {source.name!r} -> {target.name!r}: worst-case ratio "
                                   f"{guaranteed:.4g} > 1 on the verification grid after {rounds} exchange rounds")
    nominal = float(np.max(np.abs(1 - phi_v @ h)))
    return RobustSetDesign(filters=None, F=FIRFilter(h, o.lead, ts), rho=o.rho, rho_best=rho_best,
                           rho_design=rho_design, rho_guaranteed=guaranteed, feasible=feasible,
                           nominal_worst=nominal, margin_bands=mask_intervals(wv, excluded_v), w=wv, worst=worst,
                           exchanges=rounds, solve_time=time.perf_counter() - t_start,
                           delta_set=described, trial=o.trial)


# ---------------------------------------------------------------------------------------------------------------
# The pairs and the timing
# ---------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Case:
    """One design: source, target, a common bound (None: the fleet's own Delta sets) and options."""

    name: str
    source: str
    target: str
    bound: float | None
    options: RobustSetOptions


CASES = [
    Case("UAV1->UAV2 default", "UAV1", "UAV2", None, RobustSetOptions()),
    Case("UAV2->UAV3 default", "UAV2", "UAV3", None, RobustSetOptions()),
    Case("UAV1->UAV3 default", "UAV1", "UAV3", None, RobustSetOptions()),
    Case("UAV1->UAV2 structured", "UAV1", "UAV2", None, RobustSetOptions(delta_set="structured")),
    Case("UAV2->UAV3 disc 0.3", "UAV2", "UAV3", 0.3, RobustSetOptions(rho=0.8, delta_set="disc")),
]
EXTRA = [
    Case("UAV1->UAV2 disc 0.5", "UAV1", "UAV2", 0.5, RobustSetOptions(rho=0.8, delta_set="disc")),
    Case("UAV1->UAV2 disc 0.9", "UAV1", "UAV2", 0.9, RobustSetOptions(rho=0.8, delta_set="disc")),
    Case("UAV1->UAV2 family 0.9", "UAV1", "UAV2", 0.9, RobustSetOptions(delta_set="structured")),
    Case("UAV1->UAV2 family 0.9 m0.2", "UAV1", "UAV2", 0.9, RobustSetOptions(delta_set="structured", margin=0.2)),
    Case("UAV1->UAV2 family 0.9 m0", "UAV1", "UAV2", 0.9, RobustSetOptions(delta_set="structured", margin=0.0)),
    Case("UAV1->UAV2 family 0.5", "UAV1", "UAV2", 0.5, RobustSetOptions(rho=0.8, delta_set="structured")),
]


def _design(fleet, case: Case, before: bool) -> tuple[float, RobustSetDesign]:
    """One whole design (cache cleared), its CPU time and result; ``before`` swaps in the old F design."""
    ds = fleet_delta_sets(fleet, [case.source, case.target], bound=case.bound)[case.source]
    spec = next(s for s in fleet.systems if s.name == case.source)
    structure = structured_set(spec, ds.source, ds.bound, case.options.delta_set)
    rs._CACHE.clear()
    new_filter = rs._design_filter
    if before:
        rs._design_filter = _old_design_filter
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            t0 = time.process_time()
            d = rs.design_robust_set(fleet.loop(case.source), fleet.loop(case.target), ds.w, ds.bound,
                                     case.options, structure)
            return time.process_time() - t0, d
    finally:
        rs._design_filter = new_filter


def run(cases: list[Case], repeat: int = 3) -> list[dict]:
    """Interleaved before/after designs of every case; medians of the CPU times and both designs' figures."""
    fleet = ilcdob.default_fleet()
    for case in cases[:1]:  # warm caches shared by both (sampled blocks, admissible ranges, imports)
        _design(fleet, case, False)
    out = []
    for case in cases:
        times = {True: [], False: []}
        result = {}
        for _ in range(repeat):
            for before in (True, False):
                t, d = _design(fleet, case, before)
                times[before].append(t)
                result[before] = d
        b, a = result[True], result[False]
        out.append({"case": case.name, "before_s": statistics.median(times[True]),
                    "after_s": statistics.median(times[False]),
                    **{f"{k}_{tag}": getattr(d, k) for tag, d in (("before", b), ("after", a))
                       for k in ("rho_best", "rho_guaranteed", "nominal_worst", "rho_design", "exchanges")},
                    "taps_diff": float(np.max(np.abs(a.F.h - b.F.h)))})
        r = out[-1]
        print(f"{r['case']:28s} {r['before_s']:7.2f} {r['after_s']:6.2f} {r['before_s'] / r['after_s']:6.1f}x  "
              f"{r['rho_best_before']:.6f} {r['rho_best_after']:.6f}  {r['rho_guaranteed_before']:.6f} "
              f"{r['rho_guaranteed_after']:.6f}  {r['nominal_worst_before']:.3e} {r['nominal_worst_after']:.3e}  "
              f"{r['exchanges_before']}/{r['exchanges_after']}  {r['taps_diff']:.1e}", flush=True)
    return out


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="designs per method and case (median)")
    parser.add_argument("--extra", action="store_true", help="add the fleet-bound sets of reports/robust_set")
    parser.add_argument("--only", default="", help="comma-separated case names (substrings) to run")
    args = parser.parse_args()
    chosen = CASES + (EXTRA if args.extra else [])
    if args.only:
        keys = [k.strip() for k in args.only.split(",")]
        chosen = [c for c in CASES + EXTRA if any(k in c.name for k in keys)]
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}; "
          f"CPU time = time.process_time (all threads), median of {args.repeat}")
    print(f"{'case':28s} {'before':>7s} {'after':>6s} {'ratio':>7s}  {'rho_best before/after':21s}  "
          f"{'rho_guaranteed before/after':27s}  {'nominal_worst before/after':21s}  exch  max|dh|")
    run(chosen, args.repeat)
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
