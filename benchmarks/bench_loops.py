"""Benchmark: per-sample state-space loops against the compiled kernel (ilcdob/statespace.py).

Part 1, the two functions, each against a copy of its implementation before the kernel (kept
here as the baseline), at N = 3000 and N = 300000 samples:

* ``simulate_map`` (design/closed_form.py): the built-in fleet's ``G_f`` of UAV1 driven by white
  noise; baseline: python-control's ``forced_response`` (a Python loop over the samples);
* ``simulate_flight`` (validation/simulate.py): UAV1's DOB loop with a learning signal, sensor
  noise and a reference; baseline: the plant and the :class:`~ilcdob.controller.OuterLoopController`
  stepped sample by sample, as the function did.

CPU time (``time.process_time``: BLAS threads included), the methods interleaved (A B A B ...),
medians of ``--repeat`` runs; the ratio baseline / new; and the largest difference of the results,
relative to each signal's peak.

Part 2 (``--methods``), the approaches measured to choose the kernel, on ``G_f`` of UAV1 (11 states)
and of the stress loop ``a8`` at Ts = 1 ms (``q_order`` 8, 22 states; tests/test_statespace.py):

* ``plain``: the recursion, a Python loop (what ``forced_response`` runs);
* ``schur``: the kernel without its refinement pass (the Schur solve alone);
* ``schur+refine``: the kernel, :func:`ilcdob.statespace.simulate`;
* ``casadi``: the step as a CasADi SX Function (sparse: only the nonzero entries of A, B, C, D),
  ``mapaccum(N)`` evaluated in CasADi's virtual machine (no JIT); its build time is given apart;
* ``numba``: the recursion compiled by numba (not a dependency of ilcdob: this row only when it is
  installed; compile time excluded).

with the largest difference from the plain recursion, relative to the output's peak. Part 3
(``--sweep``): the kernel's Schur path against its plain recursion over the stress loops' maps
(3 to 109 states), which sets :data:`ilcdob.statespace.DENSE_MAX_STATES`.

Run:  python benchmarks/bench_loops.py [--repeat 5] [--methods] [--sweep]
"""

from __future__ import annotations

import argparse
import copy
import os
import statistics
import time

import control as ct
import numpy as np

import ilcdob
import ilcdob.statespace as kernel
from ilcdob.controller import OuterLoopController
from ilcdob.design import simulate_map
from ilcdob.design.closed_form import one_minus
from ilcdob.fleet import fleet_from_dict
from ilcdob.validation.simulate import simulate_flight

STRESS = {  # the stress loops of tests/test_conditioning.py
    "a": {"plant": {"num": [0.8, 8.0], "den": [1.0, 4.0, 0.0, 0.0]},
          "controller": {"kp": 2.0, "ki": 0.2, "kd": 2.0, "derivative_filter": 0.05},
          "dob": {"q_order": 3, "q_time_constant": 0.15}},
    "b": {"plant": {"num": [10.37568301], "den": [1.0, 10.32326473, 0.0, 0.0]}, "delay": 0.0437,
          "controller": {"kp": 3.0, "ki": 0.3, "kd": 2.42, "derivative_filter": 0.05},
          "dob": {"q_order": 3, "q_time_constant": 0.15}},
}


def _load() -> str:
    return "load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg()) + f" on {os.cpu_count()} cores"


def stress_loop(name: str, q_order: int, ts: float):
    spec = copy.deepcopy(STRESS[name])
    spec["dob"]["q_order"] = q_order
    return fleet_from_dict({"sample_time": ts, "system": [{"name": f"{name}{q_order}", **spec}]}).loops[0]


# --- the baselines: the implementations before the kernel ---------------------------------------------

def old_simulate_map(sys: ct.StateSpace, u: np.ndarray) -> np.ndarray:
    """``simulate_map`` before the kernel."""
    resp = ct.forced_response(sys, U=np.asarray(u, dtype=float))
    return np.asarray(resp.outputs, dtype=float).reshape(-1)


def old_simulate_flight(loop, r, d, d_f, a_ref, noise) -> dict[str, np.ndarray]:
    """The trial loop of ``simulate_flight`` before the kernel (mode "dob"): plant and controller stepped."""
    ap, bp, cp = np.asarray(loop.P.A, float), np.asarray(loop.P.B, float)[:, 0], np.asarray(loop.P.C, float)[0]
    n = r.size
    aff = a_ref if loop.spec.controller.acceleration_feedforward else np.zeros(n)
    ctl = OuterLoopController(loop, dob=True)
    xp = np.zeros(ap.shape[0])
    y, e, dh, u2 = (np.zeros(n) for _ in range(4))
    r_l, aff_l, df_l, nz_l, d_l = r.tolist(), aff.tolist(), d_f.tolist(), noise.tolist(), d.tolist()
    for k in range(n):
        yk = float(cp @ xp)
        ymk = yk + nz_l[k]
        u2k = ctl.step(r_l[k], ymk, feedforward=aff_l[k], learning=df_l[k])
        xp = ap @ xp + bp * (u2k + d_l[k])
        y[k], e[k], dh[k], u2[k] = yk, r_l[k] - ymk, ctl.d_hat, u2k
    return {"y": y, "e_meas": e, "d_hat": dh, "u2": u2}


def _worst(got: dict | np.ndarray, want: dict | np.ndarray) -> float:
    """Largest difference relative to each signal's peak."""
    if isinstance(want, dict):
        return max(_worst(got[k], want[k]) for k in want)
    peak = float(np.max(np.abs(want)))
    return float(np.max(np.abs(np.asarray(got) - want))) / (peak if peak > 0 else 1.0)


def _interleaved(funcs: dict, repeat: int) -> tuple[dict[str, float], dict]:
    """Median CPU seconds of each callable, run A B A B ...; and the last result of each."""
    times = {k: [] for k in funcs}
    results = {}
    for _ in range(repeat):
        for k, f in funcs.items():
            t0 = time.process_time()
            results[k] = f()
            times[k].append(time.process_time() - t0)
    return {k: statistics.median(v) for k, v in times.items()}, results


def part1(repeat: int) -> None:
    fleet = ilcdob.default_fleet()
    lp = fleet.loop("UAV1")
    print(f"Part 1: baseline (before) against the kernel, UAV1 of the built-in fleet; {_load()}")
    print(f"{'function':16s} {'N':>7s} {'before [s]':>11s} {'kernel [s]':>11s} {'ratio':>7s} {'max rel. diff':>14s}")
    for n in (3000, 300000):
        rng = np.random.default_rng(0)
        t = np.arange(n) * lp.ts
        u = rng.standard_normal(n)
        reps = repeat if n <= 3000 else max(1, repeat // 2)
        simulate_map(lp.G_f, u[:10])  # warm the imports
        med, res = _interleaved({"old": lambda: old_simulate_map(lp.G_f, u), "new": lambda: simulate_map(lp.G_f, u)},
                                reps)
        print(f"{'simulate_map':16s} {n:7d} {med['old']:11.4f} {med['new']:11.4f} {med['old'] / med['new']:6.1f}x "
              f"{_worst(res['new'], res['old']):14.1e}")
        r, a_ref = np.sin(0.5 * t), -0.25 * np.sin(0.5 * t)
        d, d_f, noise = 0.3 * rng.standard_normal(n), 0.1 * np.cos(2.0 * t), 1e-3 * rng.standard_normal(n)

        def new_flight():
            f = simulate_flight(lp, r, d, d_f=d_f, a_ref=a_ref, sensor_noise=noise)
            return {"y": f.y, "e_meas": f.e_meas, "d_hat": f.d_hat, "u2": f.u2}

        med, res = _interleaved({"old": lambda: old_simulate_flight(lp, r, d, d_f, a_ref, noise), "new": new_flight},
                                reps)
        print(f"{'simulate_flight':16s} {n:7d} {med['old']:11.4f} {med['new']:11.4f} {med['old'] / med['new']:6.1f}x "
              f"{_worst(res['new'], res['old']):14.1e}")


def _plain(a, b, c, d, u):
    x = np.zeros(a.shape[0])
    y = np.empty(u.size)
    for k in range(u.size):
        y[k] = c @ x + d * u[k]
        x = a @ x + b * u[k]
    return y


def _schur_only(a, b, c, d, u):
    """The kernel without its refinement pass (the same chunks)."""
    def unrefined(a_, b_, c_, d_, form, u_, x0, evaluate):
        x = form.z @ form.solve(np.hstack([(form.zt @ x0)[:, None], kernel._product(form.bz, u_)]))[:, 1:]
        return kernel._outputs(c_, d_, u_, x, x0, evaluate), x[:, -1]

    refined, kernel._chunk = kernel._chunk, unrefined
    try:
        return kernel.simulate(a, b, c, d, u)[0]
    finally:
        kernel._chunk = refined


def _casadi(a, b, c, d, n):
    import casadi as cs

    x, u = cs.SX.sym("x", a.shape[0]), cs.SX.sym("u")
    step = cs.Function("step", [x, u], [cs.mtimes(cs.sparsify(cs.DM(a)), x) + cs.sparsify(cs.DM(b)) * u,
                                        cs.dot(cs.sparsify(cs.DM(c)), x) + float(d) * u])
    return step.mapaccum("trial", n)


def part2(repeat: int) -> None:
    n_values = (3000, 300000)
    print(f"\nPart 2: approaches on G_f (median CPU s; max rel. diff from the plain recursion); {_load()}")
    try:
        import numba
    except ImportError:
        numba = None
    if numba is not None:
        @numba.njit(cache=False)
        def _numba(a, b, c, d, u):
            x = np.zeros(a.shape[0])
            y = np.empty(u.size)
            for k in range(u.size):
                y[k] = c @ x + d * u[k]
                x = a @ x + b * u[k]
            return y
    for label, lp in (("UAV1 (11 states)", ilcdob.default_fleet().loop("UAV1")),
                      ("a8 at 1 ms (22 states)", stress_loop("a", 8, 0.001))):
        g = lp.G_f
        a, b, c = np.asarray(g.A, float), np.asarray(g.B, float)[:, 0], np.asarray(g.C, float)[0]
        d = float(np.asarray(g.D)[0, 0])
        for n in n_values:
            u = np.random.default_rng(1).standard_normal(n)
            reps = repeat if n <= 3000 else 1
            funcs = {"plain": lambda: _plain(a, b, c, d, u), "schur": lambda: _schur_only(a, b, c, d, u),
                     "schur+refine": lambda: kernel.simulate(a, b, c, d, u)[0]}
            t0 = time.process_time()
            trial = _casadi(a, b, c, d, n)
            build = time.process_time() - t0
            funcs["casadi"] = lambda: np.asarray(trial(np.zeros(a.shape[0]), u[None, :])[1]).ravel()
            if numba is not None:
                t0 = time.process_time()
                _numba(a, b, c, d, u[:5])
                compile_s = time.process_time() - t0
                funcs["numba"] = lambda: _numba(a, b, c, d, u)
            med, res = _interleaved(funcs, reps)
            ref = res["plain"]
            print(f"{label}, N = {n}:")
            for k in funcs:
                extra = ""
                if k == "casadi":
                    extra = f"  (+ {build:.3f} s to build the mapaccum Function)"
                if k == "numba":
                    extra = f"  (+ {compile_s:.2f} s to compile)"
                print(f"  {k:13s} {med[k]:9.4f} s  {med['plain'] / med[k]:6.1f}x  {_worst(res[k], ref):9.1e}{extra}")


def part3(repeat: int) -> None:
    print(f"\nPart 3: the kernel's Schur path against its plain recursion (N = 3000, median CPU ms); {_load()}")
    rows = []
    for name in ("a", "b"):
        for q in (3, 8):
            for ts in (0.001, 0.005, 0.02):
                lp = stress_loop(name, q, ts)
                tag = f"{name}{q} {ts * 1e3:g} ms"
                rows += [(f"{tag} G_d", lp.G_d), (f"{tag} 1 - Q", one_minus(lp.Q))]
    u = np.random.default_rng(2).standard_normal(3000)
    limit = kernel.DENSE_MAX_STATES
    try:
        out = []
        for label, g in sorted(rows, key=lambda r: r[1].nstates):
            a, b, c, d = (np.asarray(m, float) for m in (g.A, g.B, g.C, g.D))
            kernel.DENSE_MAX_STATES = 10**9
            med_s, _ = _interleaved({"schur": lambda: kernel.simulate(a, b, c, d, u)}, repeat)
            kernel.DENSE_MAX_STATES = 0
            med_p, _ = _interleaved({"plain": lambda: kernel.simulate(a, b, c, d, u)}, repeat)
            out.append((label, a.shape[0], med_s["schur"], med_p["plain"]))
    finally:
        kernel.DENSE_MAX_STATES = limit
    for label, n, ts_, tp in out:
        print(f"  {label:20s} {n:4d} states  schur {ts_ * 1e3:7.2f}  plain {tp * 1e3:7.2f}  "
              f"plain/schur {tp / ts_:5.2f}")
    print(f"  (the kernel takes the plain recursion above {limit} states)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--methods", action="store_true", help="part 2: the approaches compared")
    parser.add_argument("--sweep", action="store_true", help="part 3: Schur path against plain recursion by size")
    args = parser.parse_args()
    part1(args.repeat)
    if args.methods:
        part2(args.repeat)
    if args.sweep:
        part3(args.repeat)
