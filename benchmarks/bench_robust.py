"""Benchmark: robust design over K = 20 models at N = 1000 (design issue: under 20 s).

The SOCP of :mod:`ilcdob.design.methods.robust` (worst case over K sampled UAV2 loops with the
improvement constraints ``||e_k|| <= rho ||e0_k||``) for a hover-scenario disturbance.
ilcdob: sparse state-space constraints on balanced-truncated ``Gf_k`` (Clarabel called with the
conic data assembled once; a second trial re-solves with new right-hand sides only). Baseline
in the same process: the same SOCP posed in cvxpy with the dense lifted ``Gf_k`` (N x N
lower-triangular Toeplitz) and solved by Clarabel, at ``--baseline-k`` models (default 20;
the dense form needs about 1 GB per 10 models at N = 1000). The cvxpy DPP form of the sparse
problem cannot be compiled at this size (cvxpy's parameter tensor grows as parameters x
variables: > 24 GB, killed; cvxpy issues #886/#1622), so it is not the baseline.

Run:  python benchmarks/bench_robust.py [--k 20] [--n 1000] [--baseline-k 20]
"""

from __future__ import annotations

import argparse
import time

import cvxpy as cp
import numpy as np

import ilcdob
from ilcdob.design import delta_set
from ilcdob.design.methods.robust import RobustDesigner, RobustOptions, predicted_errors
from ilcdob.lifted import lifted_operator, markov_parameters

RHO, LAM, MU = 0.5, 1e-6, 1e-4


def _dense_baseline(loops, e0: np.ndarray) -> tuple[float, np.ndarray]:
    n = e0.shape[1]
    t0 = time.perf_counter()
    d = cp.Variable(n)
    t = cp.Variable()
    cons = []
    for k, lp in enumerate(loops):
        e = e0[k] - lifted_operator(markov_parameters(lp.G_f, n)) @ d
        cons += [cp.sum_squares(e) <= t, cp.norm(e, 2) <= RHO * np.linalg.norm(e0[k])]
    prob = cp.Problem(cp.Minimize(t + LAM * cp.sum_squares(d) + MU * cp.sum_squares(cp.diff(d))), cons)
    prob.solve(solver=cp.CLARABEL)
    return time.perf_counter() - t0, np.asarray(d.value)


def run(k: int = 20, n: int = 1000, baseline_k: int = 20) -> dict[str, float]:
    fleet = ilcdob.default_fleet()
    ds = delta_set(fleet.systems[1], fleet.sample_time, k, np.random.default_rng(0), bound=0.3)
    t = np.arange(n) * fleet.sample_time
    e0 = predicted_errors(np.sin(0.9425 * t) + 0.3 * np.sin(6.5 * t), ds.loops)
    opts = RobustOptions(rho=RHO, lam=LAM, mu=MU)

    t0 = time.perf_counter()
    designer = RobustDesigner(ds.loops, n, opts)
    t_build = time.perf_counter() - t0
    first = designer.solve(e0)
    t_first = time.perf_counter() - t0
    t1 = time.perf_counter()
    designer.solve(0.7 * e0)
    t_second = time.perf_counter() - t1
    out = {"k": k, "n": n, "build_s": t_build, "first_design_s": t_first, "resolve_s": t_second,
           "worst_ratio": first.worst_ratio, "iterations": first.iterations,
           "states": float(np.mean([r.nstates for r in designer.realisations]))}
    if baseline_k > 0:
        t_dense, d_dense = _dense_baseline(ds.loops[:baseline_k], e0[:baseline_k])
        out["dense_cvxpy_s"] = t_dense
        out["baseline_k"] = baseline_k
        if baseline_k == k:
            out["ratio"] = t_dense / t_first
            out["relative_difference"] = float(np.linalg.norm(first.d_f - d_dense) / np.linalg.norm(d_dense))
    return out


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--k", type=int, default=20)
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--baseline-k", type=int, default=20, help="models in the dense cvxpy baseline (0: skip)")
    args = parser.parse_args()
    r = run(args.k, args.n, args.baseline_k)
    print(f"ilcdob robust SOCP, K = {r['k']}, N = {r['n']} ({r['states']:.1f} states per model after "
          f"truncation, {r['iterations']} iterations, worst ratio {r['worst_ratio']:.3g} <= rho {RHO}):")
    print(f"  build {r['build_s']:.2f} s, first design {r['first_design_s']:.2f} s (target < 20 s), "
          f"re-solve for a new trial {r['resolve_s']:.2f} s")
    if "dense_cvxpy_s" in r:
        print(f"dense lifted cvxpy SOCP (Clarabel), K = {r['baseline_k']}: {r['dense_cvxpy_s']:.2f} s")
    if "ratio" in r:
        print(f"speed-up: {r['ratio']:.1f}x; designs differ by {r['relative_difference']:.1e} (relative)")
