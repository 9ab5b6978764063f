"""Benchmark: the FIR learning-filter fit, Clarabel against IPOPT, and the design's status over three fleets.

Part 1 solves the same constrained fits (:func:`ilcdob.design.methods.fir.fit_fir`, default options: 80 taps,
advance 8, 200 grid points) in one process with

* ``clarabel``: the cone program in orthonormal coordinates (the default);
* ``ipopt``: the same problem in the same coordinates, CasADi/IPOPT with the exact Hessian,
  warm-started at the unconstrained least-squares fit;
* ``ipopt-legacy``: the formulation used before (coefficients scaled by ``max |L1|``, the same
  warm start, the same IPOPT settings).

Single fits on the design grid: fits whose |Te1| <= 0.9 constraint is active (the conftest fleets with a 20 % bound);
the no-harm fit of the scenario-1 comparison (UAV1 -> UAV2, 6 samples, bound 0.6, seed 0: the bounds
``FIRDesign.limit``); and that comparison's strict problem, which no filter can meet (reported:
time to the verdict). Then two whole designs (:func:`ilcdob.design.methods.fir.design_fir` with each solver: the
exchange rounds on the check grid included). Every objective is recomputed from the returned coefficients
with one formula, and ``viol`` is the largest ``|Te1| / bound - 1`` (<= 1e-6 counts as met).

Part 2 designs every ordered pair of each fleet with :func:`ilcdob.design.methods.fir.design_fir` at its
defaults, with the model only, with the fleet's own Delta set (the built-in fleet: its identification,
8 samples; the others: a 20 % bound, 4 samples) and with the comparison's Delta set (6 samples, bound
0.6, seed 0), and prints each design's status: ``ok`` (the margin held on the whole grid), ``no-harm``
(the margin given up in the stated bands, where no filter can meet it: ``unattainable``) or the error.

Times are wall times with BLAS single-threaded (as :func:`~ilcdob.design.methods.fir.design_fir` runs), best of
``--repeat`` for the single fits; on a shared machine they vary by a factor of 2-3 from run to run.

Run:  python benchmarks/bench_fir.py [--part 1|2|all] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

import ilcdob
from ilcdob.design import closed_form_filters
from ilcdob.design.methods.fir import (CHECK_REFINE, FIRGuaranteeWarning, FIROptions, _quadrature, _realify,
                                       design_fir, fit_fir)
from ilcdob.design.pair import fleet_delta_sets
from ilcdob.response import fir_matrix
from ilcdob.fleet import fleet_from_dict
from ilcdob.loop import freqresp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from conftest import FEEDFORWARD_FLEET, UNEQUAL_FLEET  # noqa: E402  (the fleets of the test fixtures)

COMPARE = {"k": 6, "bound": 0.6, "seed": 0}


def fleets() -> dict[str, ilcdob.Fleet]:
    """The built-in fleet and the two fleets of the test fixtures ``unequal_fleet``, ``feedforward_fleet``."""
    return {"default": ilcdob.default_fleet(),
            "unequal": fleet_from_dict(UNEQUAL_FLEET, source="unequal_fleet"),
            "feedforward": fleet_from_dict(FEEDFORWARD_FLEET, source="feedforward_fleet")}


def deltas(fleet: ilcdob.Fleet, src: str, tgt: str, kind: str):
    """(delta_prev, delta_next) of a kind: ``model`` (None), ``own`` or ``compare``."""
    if kind == "model":
        return None, None
    if kind == "own":
        identified = all(s.identification is not None for s in fleet.systems)
        d = fleet_delta_sets(fleet, [src, tgt]) if identified else fleet_delta_sets(fleet, [src, tgt], k=4, bound=0.2)
    else:
        d = fleet_delta_sets(fleet, [src, tgt], **COMPARE)
    return d[src], d[tgt]


def problem(fleet: ilcdob.Fleet, src: str, tgt: str, kind: str, options: FIROptions):
    """Grid, target L1 and the Te1 data ``(c, g)`` of one pair."""
    a, b = fleet.loop(src), fleet.loop(tgt)
    w = options.grid(a.ts)
    dp, dn = deltas(fleet, src, tgt, kind)
    srcs, tgts = (dp.loops, dn.loops) if dp is not None else ((a,), (b,))
    c = np.array([freqresp(t.G_d, w) / freqresp(s.G_d, w) for s, t in zip(srcs, tgts)])
    g = np.array([freqresp(t.G_f, w) for t in tgts])
    return a.ts, w, closed_form_filters(a, b).l1_response(w), c, g


def objective(h: np.ndarray, target: np.ndarray, w: np.ndarray, ts: float, o: FIROptions) -> float:
    """The weighted least-squares objective of the module docstring of :mod:`ilcdob.design.methods.fir`."""
    wt = np.sqrt(o.weights(w) * _quadrature(w)) / np.abs(target)
    res = (fir_matrix(w, o.n_taps, o.advance, ts) @ h - target) * wt
    s = float(np.max(np.abs(target)))
    return float(np.sum(np.abs(res) ** 2) + max(o.ridge, 1e-14) * np.sum((h / s) ** 2))


def legacy_ipopt(target, w, ts, o: FIROptions, c, g, bound) -> tuple[np.ndarray, str, float]:
    """The fit as it was solved before: IPOPT on the coefficients scaled by ``max |L|`` (CasADi MX)."""
    import casadi as cs

    t0 = time.perf_counter()  # like fit_fir's time: set-up included
    n, adv = o.n_taps, o.advance
    e_mat = fir_matrix(w, n, adv, ts)
    mag = np.abs(target)
    wt = np.sqrt(o.weights(w) * _quadrature(w)) / mag
    s = float(np.max(mag))
    a_s, y = _realify(e_mat * wt[:, None]) * s, _realify(target * wt)
    reg = np.sqrt(max(o.ridge, 1e-14)) * np.eye(n)
    x0 = np.linalg.lstsq(np.vstack([a_s, reg]), np.concatenate([y, np.zeros(n)]), rcond=None)[0]
    x = cs.MX.sym("x", n)
    b = (g[:, :, None] * e_mat[None, :, :]).reshape(-1, n) * s
    cc = c.reshape(-1)
    re = cs.DM(cc.real) - cs.mtimes(cs.DM(b.real), x)
    im = cs.DM(cc.imag) - cs.mtimes(cs.DM(b.imag), x)
    nlp = {"x": x, "f": cs.sumsqr(cs.mtimes(cs.DM(a_s), x) - cs.DM(y)) + o.ridge * cs.sumsqr(x), "g": re**2 + im**2}
    solver = cs.nlpsol("legacy", "ipopt", nlp, {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                                                 "ipopt.max_iter": o.max_iter, "ipopt.tol": 1e-8,
                                                 "ipopt.acceptable_tol": 1e-6, "ipopt.acceptable_iter": 5})
    sol = solver(x0=x0, lbg=-np.inf * np.ones(cc.size), ubg=np.broadcast_to(bound, c.shape).reshape(-1) ** 2)
    return np.asarray(sol["x"], float).reshape(-1) * s, str(solver.stats()["return_status"]), time.perf_counter() - t0


def compare_solvers(repeat: int) -> list[dict]:
    """Part 1: one row per (problem, solver), best of ``repeat`` times."""
    o = FIROptions()
    fl = fleets()
    cases = [("unequal A1->A2, 20 %", fl["unequal"], "A1", "A2", "own", None),
             ("unequal A2->A1, 20 %", fl["unequal"], "A2", "A1", "own", None),
             ("feedforward B2->B3, 20 %", fl["feedforward"], "B2", "B3", "own", None),
             ("scenario 1 no-harm", fl["default"], "UAV1", "UAV2", "compare", "no-harm"),
             ("scenario 1 strict (infeasible)", fl["default"], "UAV1", "UAV2", "compare", None)]
    rows = []
    for label, fleet, src, tgt, kind, mode in cases:
        ts, w, target, c, g = problem(fleet, src, tgt, kind, o)
        bound = np.full(c.shape, 1 - o.margin)
        if mode == "no-harm":
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", FIRGuaranteeWarning)
                bound = design_fir(fleet.loop(src), fleet.loop(tgt), *deltas(fleet, src, tgt, kind), o).limit
            bound = bound[:, ::CHECK_REFINE] * (1 + 5e-7)  # the design's bounds at the design-grid frequencies
        for name in ("clarabel", "ipopt", "ipopt-legacy"):
            best = None
            for _ in range(repeat):
                if name == "ipopt-legacy":
                    h, status, dt = legacy_ipopt(target, w, ts, o, c, g, bound)
                else:
                    t0 = time.perf_counter()
                    f = fit_fir(target, w, ts, FIROptions(solver=name), c, g, bound)
                    h, status, dt = f.filter.h, f.status, time.perf_counter() - t0
                if best is None or dt < best[2]:
                    best = (h, status, dt)
            h, status, dt = best
            te = np.abs(c - g * (fir_matrix(w, o.n_taps, o.advance, ts) @ h)[None, :])
            rows.append({"problem": label, "solver": name, "status": status, "time_s": dt,
                         "objective": objective(h, target, w, ts, o), "viol": float(np.max(te / bound - 1))})
    return rows


def compare_designs() -> list[dict]:
    """Part 1, whole designs (:func:`design_fir`: exchange rounds, and for scenario 1 the least-excess stage,
    which is Clarabel's in both): one row per (pair, solver)."""
    fl = fleets()
    rows = []
    for label, fleet, src, tgt, kind in (("unequal A2->A1, 20 %", fl["unequal"], "A2", "A1", "own"),
                                         ("scenario 1 (no-harm)", fl["default"], "UAV1", "UAV2", "compare")):
        dp, dn = deltas(fleet, src, tgt, kind)
        ts, w, target, _, _ = problem(fleet, src, tgt, kind, FIROptions())
        for name in ("clarabel", "ipopt"):
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", FIRGuaranteeWarning)
                d = design_fir(fleet.loop(src), fleet.loop(tgt), dp, dn, FIROptions(solver=name))
            rows.append({"problem": label, "solver": name, "status": d.solver_status,
                         "time_s": time.perf_counter() - t0, "objective": objective(d.L1.h, target, w, ts, d.options),
                         "viol": float(np.max(d.te1 / d.limit - 1))})
    return rows


def status_table() -> list[dict]:
    """Part 2: one row per (fleet, pair, Delta set)."""
    rows = []
    for fname, fleet in fleets().items():
        for src in fleet.names:
            for tgt in fleet.names:
                if src == tgt:
                    continue
                for kind in ("model", "own", "compare"):
                    dp, dn = deltas(fleet, src, tgt, kind)
                    t0 = time.perf_counter()
                    try:
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore", FIRGuaranteeWarning)
                            d = design_fir(fleet.loop(src), fleet.loop(tgt), dp, dn)
                    except ilcdob.IlcdobError as exc:  # counted as a failure
                        rows.append({"fleet": fname, "pair": f"{src}->{tgt}", "delta": kind, "status": "FAILED",
                                     "time_s": time.perf_counter() - t0, "detail": str(exc)})
                        continue
                    status = "no-harm" if d.relaxed_bands else "ok"
                    detail = (f"relaxed {_bands(d.relaxed_bands)}; unattainable {_bands(d.unattainable_bands)}"
                              if d.relaxed_bands else "")
                    rows.append({"fleet": fname, "pair": f"{src}->{tgt}", "delta": kind, "status": status,
                                 "time_s": time.perf_counter() - t0, "worst_te1": d.worst_te1,
                                 "fit": d.L1.fit_error, "detail": detail})
    return rows


def _bands(bands) -> str:
    return ", ".join(f"{lo:.3g}-{hi:.3g}" for lo, hi in bands) or "-"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=("1", "2", "all"), default="all")
    parser.add_argument("--repeat", type=int, default=3, help="solves per (problem, solver) in part 1; best time")
    args = parser.parse_args()
    with threadpool_limits(limits=1, user_api="blas"):  # as design_fir runs: every solver single-threaded BLAS
        _run(args)


def _run(args: argparse.Namespace) -> None:
    if args.part in ("1", "all"):
        for title, rows in (("single fits on the design grid", compare_solvers(args.repeat)),
                            ("whole designs (design_fir, check grid held)", compare_designs())):
            print(f"{title}\n{'problem':32s}{'solver':14s}{'status':28s}{'time s':>9s}{'objective':>14s}{'viol':>11s}")
            for r in rows:
                print(f"{r['problem']:32s}{r['solver']:14s}{r['status']:28s}{r['time_s']:9.3f}{r['objective']:14.6g}"
                      f"{r['viol']:11.2e}")
            print("time ratio (solver / clarabel):")
            for label in dict.fromkeys(r["problem"] for r in rows):
                t = {r["solver"]: r["time_s"] for r in rows if r["problem"] == label}
                print(f"  {label:32s}" + "  ".join(f"{k} {v / t['clarabel']:.1f}x" for k, v in t.items()
                                                   if k != "clarabel"))
            print()
    if args.part in ("2", "all"):
        rows = status_table()
        print(f"\n{'fleet':12s}{'pair':12s}{'delta':9s}{'status':9s}{'time s':>8s}{'worst':>8s}{'fit':>7s}  detail")
        for r in rows:
            print(f"{r['fleet']:12s}{r['pair']:12s}{r['delta']:9s}{r['status']:9s}{r['time_s']:8.2f}"
                  f"{r.get('worst_te1', float('nan')):8.3f}{r.get('fit', float('nan')):7.3f}  {r['detail']}")
        failed = sum(r["status"] == "FAILED" for r in rows)
        relaxed = sum(r["status"] == "no-harm" for r in rows)
        print(f"{len(rows)} designs: {len(rows) - failed - relaxed} ok, {relaxed} no-harm, {failed} failed; "
              f"{sum(r['time_s'] for r in rows):.1f} s")


if __name__ == "__main__":
    main()
