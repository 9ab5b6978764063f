"""Benchmark: per-sample state-space loops against the compiled kernel (ilcdob/statespace.py).

Part 1, the two functions, each against a copy of its implementation before the kernel (kept
here as the baseline), at N = 3000 and N = 300000 samples:

* ``simulate_map`` (design/maps/closed_form.py): the built-in fleet's ``G_f`` of UAV1 driven by white
  noise; baseline: python-control's ``forced_response`` (a Python loop over the samples);
* ``simulate_flight`` (validation/simulate.py): UAV1's DOB loop with a learning signal, sensor
  noise and a reference; baseline: the plant and the :class:`~ilcdob.controller.OuterLoopController`
  stepped sample by sample, as the function did.

Part 2, large loops: the stress loops at Ts = 1 ms with ``q_order`` 8 (``a8``: 22 states; ``b8``:
109 states, two delay lines of 44) and ``b8`` at 2 ms (65 states), maps (``G_f``; ``G_d`` of ``b8``)
and flights, at N = 3000 and N = 100000: the Python loop of Part 1, the previous kernel (a Schur
solve with a refinement pass, the plain recursion above 50 states: :func:`schur_simulate`, a copy
kept here) and the kernel; the ratios Python loop / kernel and previous kernel / kernel; the largest
difference of the kernel from the Python loop and, for the maps, from the recursion in 80-bit
arithmetic (``numpy.longdouble``), relative to each signal's peak.

CPU time (``time.process_time``: BLAS threads included), the methods interleaved (A B A B ...),
medians of ``--repeat`` runs (fewer at the long trials).

Part 3 (``--methods``), the approaches measured to choose the kernel, on ``G_f`` of UAV1 (11 states)
and of the stress loop ``a8`` at Ts = 1 ms (``q_order`` 8, 22 states; tests/test_statespace.py):

* ``plain``: the recursion, a Python loop (what ``forced_response`` runs);
* ``schur``: the previous kernel without its refinement pass (the Schur solve alone);
* ``schur+refine``: the previous kernel, :func:`schur_simulate`;
* ``blocks``: the kernel, :func:`ilcdob.statespace.simulate` (the recursion in all blocks at once);
* ``casadi``: the step as a CasADi SX Function (sparse: only the nonzero entries of A, B, C, D),
  ``mapaccum(N)`` evaluated in CasADi's virtual machine (no JIT); its build time is given apart;
* ``numba``: the recursion compiled by numba (not a dependency of ilcdob: this row only when it is
  installed; compile time excluded).

with the largest difference from the plain recursion, relative to the output's peak. Part 4
(``--sweep``): the kernel and the previous kernel against the plain recursion over the stress
loops' maps (3 to 109 states), N = 3000.

Run:  python benchmarks/bench_loops.py [--repeat 5] [--methods] [--sweep]
"""

from __future__ import annotations

import argparse
import copy
import os
import statistics
import time
from functools import lru_cache

import control as ct
import numpy as np
from scipy.linalg import schur
from scipy.signal import lfilter
from threadpoolctl import ThreadpoolController

import ilcdob
import ilcdob.statespace as kernel
from ilcdob.design import simulate_map
from ilcdob.design.maps.closed_form import one_minus
from ilcdob.fleet import fleet_from_dict
import ilcdob.validation.simulate as flight_module
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
    """The trial loop of ``simulate_flight`` before the kernel (mode "dob"): plant and controller stepped sample by
    sample, the path ``simulate_flight(..., stepped=True)`` still runs."""
    f = simulate_flight(loop, r, d, d_f=d_f, a_ref=a_ref, sensor_noise=noise, stepped=True)
    return {"y": f.y, "e_meas": f.e_meas, "d_hat": f.d_hat, "u2": f.u2}


# --- the previous kernel: a Schur solve with one refinement pass (the plain recursion above 50 states) ---

_OLD_DENSE_MAX_STATES, _OLD_CHUNK_ENTRIES, _OLD_MIN_CHUNK, _OLD_GROUP = 50, 1 << 16, 4096, 16


class _OldSchur:
    """Real Schur form of ``A`` and the solve of ``s[k + 1] = T s[k] + drive[:, k]`` (the previous kernel)."""

    def __init__(self, a, b, c):
        self.t, self.z = schur(a, output="real")
        self.zt = np.ascontiguousarray(self.z.T)
        self.bz, self.cz = self.zt @ b, c @ self.z
        blocks, i = [], a.shape[0] - 1
        while i >= 0:
            pair = i > 0 and self.t[i, i - 1] != 0.0
            blocks.append((i - 1, True) if pair else (i, False))
            i -= 2 if pair else 1
        self.groups = []
        for i, pair in blocks:
            if pair:
                (t11, t12), (t21, t22) = self.t[i:i + 2, i:i + 2]
                block = (i, np.array([[-t22, t12], [t21, -t11]]), np.array([1.0, -(t11 + t22), t11 * t22 - t12 * t21]))
            else:
                block = (i, None, np.array([1.0, -self.t[i, i]]))
            if not self.groups or self.groups[-1][1] - i > _OLD_GROUP:
                self.groups.append((i, i + 2 if pair else i + 1, []))
            self.groups[-1] = (i, self.groups[-1][1], self.groups[-1][2] + [block])

    def solve(self, drive):
        t, n, s = self.t, drive.shape[0], np.empty_like(drive)
        for g0, g1, members in self.groups:
            if g1 < n:
                drive[g0:g1, 1:] += (t[g0:g1, g1:] @ s[g1:])[:, :-1]
            for i, fir, den in members:
                if fir is None:
                    dr = drive[i]
                    if i + 1 < g1:
                        dr[1:] += (t[i, i + 1:g1] @ s[i + 1:g1])[:-1]
                    s[i] = lfilter(np.ones(1), den, dr)
                    continue
                dr = drive[i:i + 2]
                if i + 2 < g1:
                    dr[:, 1:] += (t[i:i + 2, i + 2:g1] @ s[i + 2:g1])[:, :-1]
                v = dr.copy()
                v[:, 1:] += fir @ dr[:, :-1]
                s[i:i + 2] = lfilter(np.ones(1), den, v, axis=1)
        return s


@lru_cache(maxsize=1)
def _old_blas() -> ThreadpoolController:
    return ThreadpoolController()


@lru_cache(maxsize=32)
def _old_schur_cached(a, b, c, n, m, p):
    return _OldSchur(np.frombuffer(a).reshape(n, n), np.frombuffer(b).reshape(n, m), np.frombuffer(c).reshape(p, n))


def _old_product(b, u):
    return b * u if b.shape[1] == 1 else b @ u


def _old_plain(a, b, u, x0, evaluate):
    x, prev = np.empty((a.shape[0], u.shape[1])), x0
    if evaluate is None:
        w = _old_product(b, u)
        for k in range(u.shape[1]):
            prev = x[:, k] = a @ prev + w[:, k]
    else:
        for k in range(u.shape[1]):
            prev = x[:, k] = evaluate(prev[:, None], u[:, k:k + 1])[0][:, 0]
    return x


def _old_previous(x, x0):
    prev = np.empty_like(x)
    prev[:, 0], prev[:, 1:] = x0, x[:, :-1]
    return prev


def _old_outputs(c, d, u, x, x0, evaluate):
    if evaluate is not None:
        return evaluate(_old_previous(x, x0), u)[1]
    y = _old_product(d, u)
    y[:, 0] += c @ x0
    y[:, 1:] += (c @ x)[:, :-1]
    return y


def _old_chunk(a, b, c, d, form, u, x0, evaluate, refine=True):
    at_rest = not np.any(x0)
    if at_rest:
        x = form.z @ form.solve(_old_product(form.bz, u))
    else:
        x = form.z @ form.solve(np.hstack([(form.zt @ x0)[:, None], _old_product(form.bz, u)]))[:, 1:]
    if not refine:
        return _old_outputs(c, d, u, x, x0, evaluate), x[:, -1]
    w = _old_product(b, u) if evaluate is None else None
    for _ in range(4):
        if evaluate is None:
            ax = a @ x
            defect = w - x
            defect[:, 1:] += ax[:, :-1]
            if not at_rest:
                defect[:, 0] += a @ x0
        else:
            defect = evaluate(_old_previous(x, x0), u)[0] - x
        corr = form.solve(form.zt @ defect)
        size = float(np.max(np.abs(corr)))
        if size <= 1e-7 * float(np.max(np.abs(x))):
            x += form.z @ corr
            return _old_outputs(c, d, u, x, x0, evaluate), x[:, -1]
        if not np.isfinite(size):
            break
        x += form.z @ corr
    x = _old_plain(a, b, u, x0, evaluate)
    return _old_outputs(c, d, u, x, x0, evaluate), x[:, -1]


def schur_simulate(a, b, c, d, u, x0=None, evaluate=None, refine=True):
    """The previous kernel, ``simulate`` before the block recursion (arguments as in
    :func:`ilcdob.statespace.simulate`, without the checks); ``refine=False``: its Schur solve alone."""
    a = np.asarray(a, float)
    u = np.atleast_2d(np.asarray(u, float))
    n, (m, length) = a.shape[0], u.shape
    b = np.asarray(b, float).reshape(n, m)
    c = np.asarray(c, float).reshape(-1, n)
    d = np.asarray(d, float).reshape(c.shape[0], m)
    state = np.zeros(n) if x0 is None else np.asarray(x0, float)
    if n > _OLD_DENSE_MAX_STATES and evaluate is None:
        return _old_outputs(c, d, u, _old_plain(a, b, u, state, None), state, None)
    with _old_blas().limit(limits=1, user_api="blas"):
        a_, b_, c_ = (np.ascontiguousarray(x) for x in (a, b, c))
        form = _old_schur_cached(a_.tobytes(), b_.tobytes(), c_.tobytes(), n, m, c.shape[0])
        chunk = max(_OLD_MIN_CHUNK, _OLD_CHUNK_ENTRIES // n)
        y = np.empty((c.shape[0], length))
        for k0 in range(0, length, chunk):
            k1 = min(k0 + chunk, length)
            y[:, k0:k1], state = _old_chunk(a, b, c, d, form, u[:, k0:k1], state, evaluate, refine)
    return y


def schur_simulate_flight(*args, **kwargs):
    """``simulate_flight`` on the previous kernel."""
    kernel_now, flight_module.simulate = flight_module.simulate, schur_simulate
    try:
        return simulate_flight(*args, **kwargs)
    finally:
        flight_module.simulate = kernel_now


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


def _plain(a, b, c, d, u, dtype=float):
    """The recursion, a Python loop; in ``numpy.longdouble`` (80-bit on x86) for the reference."""
    a, b, c = (np.asarray(m, dtype=dtype) for m in (a, b, c))
    d, u = dtype(d), np.asarray(u).astype(dtype)
    x = np.zeros(a.shape[0], dtype=dtype)
    y = np.empty(u.size, dtype=dtype)
    for k in range(u.size):
        y[k] = c @ x + d * u[k]
        x = a @ x + b * u[k]
    return y


def _siso(g):
    return (np.asarray(g.A, float), np.asarray(g.B, float)[:, 0], np.asarray(g.C, float)[0],
            float(np.asarray(g.D)[0, 0]))


def part2(repeat: int) -> None:
    print(f"\nPart 2: large loops; Python loop, previous kernel (Schur) and kernel; {_load()}")
    print(f"{'loop':26s} {'N':>6s} {'loop [s]':>9s} {'Schur [s]':>9s} {'kernel [s]':>10s} {'loop/kernel':>11s} "
          f"{'Schur/kernel':>12s} {'diff loop':>9s} {'diff 80-bit':>11s}")
    loops = {"a8 1 ms": stress_loop("a", 8, 0.001), "b8 2 ms": stress_loop("b", 8, 0.002),
             "b8 1 ms": stress_loop("b", 8, 0.001)}
    for n in (3000, 100000):
        reps = repeat if n <= 3000 else max(3, repeat // 2)
        rng = np.random.default_rng(0)
        u = rng.standard_normal(n)
        for name, lp in loops.items():
            g = lp.G_d if name == "b8 1 ms" else lp.G_f
            label = f"{name} {'G_d' if name == 'b8 1 ms' else 'G_f'} ({g.nstates} states)"
            simulate_map(g, u[:10])
            med, res = _interleaved({"loop": lambda: old_simulate_map(g, u),
                                     "schur": lambda: schur_simulate(g.A, g.B, g.C, g.D, u)[0],
                                     "new": lambda: simulate_map(g, u)}, reps)
            ref = _plain(*_siso(g), u, dtype=np.longdouble)
            print(f"{label:26s} {n:6d} {med['loop']:9.4f} {med['schur']:9.4f} {med['new']:10.4f} "
                  f"{med['loop'] / med['new']:10.1f}x {med['schur'] / med['new']:11.1f}x "
                  f"{_worst(res['new'], res['loop']):9.1e} {_worst(res['new'], ref):11.1e}")
        d, noise = 0.3 * rng.standard_normal(n), 1e-3 * rng.standard_normal(n)
        for name, lp in loops.items():
            label = f"{name} flight ({lp.closed_loop.nstates} states)"
            tt = np.arange(n) * lp.ts
            r, a_ref, d_f = np.sin(0.5 * tt), -0.25 * np.sin(0.5 * tt), 0.1 * np.cos(2.0 * tt)

            def run(func, lp=lp, r=r, a_ref=a_ref, d_f=d_f):
                f = func(lp, r, d, d_f=d_f, a_ref=a_ref, sensor_noise=noise)
                return {"y": f.y, "e_meas": f.e_meas, "d_hat": f.d_hat, "u2": f.u2}

            med, res = _interleaved({"loop": lambda: old_simulate_flight(lp, r, d, d_f, a_ref, noise),
                                     "schur": lambda: run(schur_simulate_flight),
                                     "new": lambda: run(simulate_flight)}, reps if n <= 3000 else 1)
            print(f"{label:26s} {n:6d} {med['loop']:9.4f} {med['schur']:9.4f} {med['new']:10.4f} "
                  f"{med['loop'] / med['new']:10.1f}x {med['schur'] / med['new']:11.1f}x "
                  f"{_worst(res['new'], res['loop']):9.1e} {'':>11s}")


def _casadi(a, b, c, d, n):
    import casadi as cs

    x, u = cs.SX.sym("x", a.shape[0]), cs.SX.sym("u")
    step = cs.Function("step", [x, u], [cs.mtimes(cs.sparsify(cs.DM(a)), x) + cs.sparsify(cs.DM(b)) * u,
                                        cs.dot(cs.sparsify(cs.DM(c)), x) + float(d) * u])
    return step.mapaccum("trial", n)


def part3(repeat: int) -> None:
    n_values = (3000, 300000)
    print(f"\nPart 3: approaches on G_f (median CPU s; max rel. diff from the plain recursion); {_load()}")
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
        a, b, c, d = _siso(lp.G_f)
        for n in n_values:
            u = np.random.default_rng(1).standard_normal(n)
            reps = repeat if n <= 3000 else 1
            funcs = {"plain": lambda: _plain(a, b, c, d, u),
                     "schur": lambda: schur_simulate(a, b, c, d, u, refine=False)[0],
                     "schur+refine": lambda: schur_simulate(a, b, c, d, u)[0],
                     "blocks": lambda: kernel.simulate(a, b, c, d, u)[0]}
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


def part4(repeat: int) -> None:
    print(f"\nPart 4: kernel and previous kernel against the plain recursion (N = 3000, median CPU ms); {_load()}")
    rows = []
    for name in ("a", "b"):
        for q in (3, 8):
            for ts in (0.001, 0.005, 0.02):
                lp = stress_loop(name, q, ts)
                tag = f"{name}{q} {ts * 1e3:g} ms"
                rows += [(f"{tag} G_d", lp.G_d), (f"{tag} 1 - Q", one_minus(lp.Q))]
    u = np.random.default_rng(2).standard_normal(3000)
    for label, g in sorted(rows, key=lambda r: r[1].nstates):
        a, b, c, d = _siso(g)
        kernel.simulate(a, b, c, d, u)
        med, res = _interleaved({"plain": lambda: _plain(a, b, c, d, u),
                                 "schur": lambda: schur_simulate(a, b, c, d, u)[0],
                                 "new": lambda: kernel.simulate(a, b, c, d, u)[0]}, repeat)
        print(f"  {label:20s} {a.shape[0]:4d} states  plain {med['plain'] * 1e3:7.2f}  "
              f"Schur {med['schur'] * 1e3:7.2f}  kernel {med['new'] * 1e3:7.2f}  "
              f"plain/kernel {med['plain'] / med['new']:5.1f}  "
              f"Schur/kernel {med['schur'] / med['new']:5.1f}  diff {_worst(res['new'], res['plain']):7.1e}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--methods", action="store_true", help="part 3: the approaches compared")
    parser.add_argument("--sweep", action="store_true", help="part 4: kernels against the plain recursion by size")
    args = parser.parse_args()
    part1(args.repeat)
    part2(args.repeat)
    if args.methods:
        part3(args.repeat)
    if args.sweep:
        part4(args.repeat)
