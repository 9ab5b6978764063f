"""Benchmark: nominal norm-optimal design, against the dense QP, the per-sample Python loop and the
lifted matrices.

1. At N = 3000 (``--n``), against the same problem posed as a dense cvxpy QP (design issue: under
   1 s and at least 20x faster): ``min w||e0 - Gf d_f||^2 + lam ||d_f||^2 + mu ||Diff d_f||^2`` for
   the built-in fleet's UAV2 (learning from UAV1, hover scenario). ilcdob: gains plus one trial
   solve (the whole design, from the loop); baseline in the same process: cvxpy with the lifted
   (dense, lower-triangular Toeplitz) Gf, solved by Clarabel. The optima are compared.
2. At N = 300,000 (``--big-n``): the compiled recursion of :mod:`ilcdob.design.methods.norm_optimal`
   (Chandrasekhar gains and the passes, the system's zero entries left out, compiled to native code
   by :mod:`ilcdob.native`) against the per-sample Python loop it replaced (kept below as
   :class:`LoopDesigner`, that implementation verbatim) and against the earlier compiled forms
   (:data:`FORMS`, :func:`compiled_form`): the same functions in CasADi's virtual machine, and the
   first compiled form, whose functions carried every entry of the system; interleaved
   A B C D A B C D, medians of CPU time (the native row only where a C compiler runs);
   the relative difference of the results, to each other and to the loop run in numpy's 80-bit
   extended precision (the rounding error of each). With numba installed, a further row runs the
   loop compiled by numba (a point of comparison only: numba is no dependency of ilcdob).

   Accuracy. The exact optimum is the 80-bit recursion. Relative to the peak of the learning
   signal the compiled form should be within 1e-12 of it, but at the default weights the problem
   is ill-conditioned (a closed-loop pole at 1 - 1e-8): the exact gains, merely rounded to float64
   (as any float64 method stores them), already move the optimum by 7e-13 to 8.4e-13, and rounding
   the passes' states does the same again at each sample. The tolerance is therefore scaled by
   that floor: ``max(1e-12, 8 x floor)`` (:data:`TOLERANCE`, :data:`FLOOR_FACTOR`), which is 1e-12
   at better conditioned weights. The previous loop is measured against the same reference.
3. The compact law (:meth:`NormOptimalDesigner.law`) against the lifted matrices at N = 500 and
   1000 (``--lifted-n``): CPU time and tracemalloc peak, and the law's difference; then the
   compact law at ``--big-n`` in each compiled form (interleaved).

Building the compiled functions (once per process and sparsity pattern; the native libraries once
per machine, here into an empty folder) is measured first, apart: sections 2 and 3 time warm
functions.

Run:  python benchmarks/bench_norm_optimal.py [--n 3000] [--big-n 300000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import tempfile
import time
import tracemalloc

import cvxpy as cp
import numpy as np

import ilcdob
from ilcdob.design import simulate_map
from ilcdob.design.methods import norm_optimal
from ilcdob.design.methods.norm_optimal import NormOptimalDesigner, NormOptimalOptions
from ilcdob.errors import NativeBuildError
from ilcdob.lifted import lifted_operator, markov_parameters

LAM, MU = 1e-6, 1e-5


class LoopDesigner:
    """The previous implementation: the Riccati recursion and the passes as per-sample numpy loops."""

    def __init__(self, target, n: int, options: NormOptimalOptions) -> None:
        self.n = n
        self.options = opts = options
        gf = target.nominal.G_f
        a, b, c, d = (np.asarray(m, float) for m in (gf.A, gf.B, gf.C, gf.D))
        nx = a.shape[0]
        w, lam, mu = opts.weight, opts.lam, opts.mu
        self._abar = np.zeros((nx + 1, nx + 1))
        self._abar[:nx, :nx] = a
        self._bbar = np.concatenate([b[:, 0], [1.0]])
        self._cz = np.concatenate([c[0], [0.0]])
        self._d = float(d.ravel()[0])
        sel = np.zeros(nx + 1)
        sel[-1] = 1.0
        q = w * np.outer(self._cz, self._cz) + mu * np.outer(sel, sel)
        s = w * self._cz * self._d - mu * sel
        r = w * self._d**2 + lam + mu
        p = np.zeros((nx + 1, nx + 1))
        self._gain = np.empty((self.n, nx + 1))
        self._huu = np.empty(self.n)
        self._closed = np.empty((self.n, nx + 1, nx + 1))
        abar, bbar = self._abar, self._bbar
        for t in range(self.n - 1, -1, -1):
            pb = p @ bbar
            huu = r + bbar @ pb
            huz = s + abar.T @ pb
            k = huz / huu
            p = q + abar.T @ p @ abar - np.outer(huz, k)
            p = 0.5 * (p + p.T)
            self._gain[t], self._huu[t] = k, huu
            self._closed[t] = (abar - np.outer(bbar, k)).T

    def solve(self, e0: np.ndarray) -> np.ndarray:
        w = self.options.weight
        nz = self._abar.shape[0]
        pvec = np.zeros(nz)
        kff = np.empty(self.n)
        for t in range(self.n - 1, -1, -1):
            r_t = -w * e0[t] * self._d
            h_u = r_t + self._bbar @ pvec
            kff[t] = h_u / self._huu[t]
            pvec = -w * e0[t] * self._cz + self._closed[t] @ pvec - self._gain[t] * r_t
        z = np.zeros(nz)
        u = np.empty(self.n)
        for t in range(self.n):
            u[t] = -self._gain[t] @ z - kff[t]
            z = self._abar @ z + self._bbar * u[t]
        return u


def _extended_gains(target, n: int, options: NormOptimalOptions) -> tuple[np.ndarray, np.ndarray]:
    """Gains and pivots of the loop's Riccati recursion in numpy's extended precision (80-bit on x86)."""
    ld = np.longdouble
    gf = target.nominal.G_f
    a, b, c, d = (np.asarray(m, ld) for m in (gf.A, gf.B, gf.C, gf.D))
    nx = a.shape[0]
    abar = np.zeros((nx + 1, nx + 1), ld)
    abar[:nx, :nx] = a
    at = abar.T.copy()
    bbar, cz, d = np.append(b[:, 0], ld(1)), np.append(c[0], ld(0)), d.ravel()[0]
    sel = np.zeros(nx + 1, ld)
    sel[-1] = 1
    w, lam, mu = ld(options.weight), ld(options.lam), ld(options.mu)
    q, s, r = w * np.outer(cz, cz) + mu * np.outer(sel, sel), w * cz * d - mu * sel, w * d * d + lam + mu
    p, gains, pivots = np.zeros((nx + 1, nx + 1), ld), np.empty((n, nx + 1), ld), np.empty(n, ld)
    for t in range(n - 1, -1, -1):
        pb = p @ bbar
        pivots[t] = r + bbar @ pb
        huz = s + at @ pb
        gains[t] = huz / pivots[t]
        p = q + at @ p @ abar - np.outer(huz, gains[t])
        p = (p + p.T) / 2
    return gains, pivots


def _extended_passes(target, gains: np.ndarray, pivots: np.ndarray, options: NormOptimalOptions,
                     e0: np.ndarray) -> np.ndarray:
    """The loop's backward and forward passes in extended precision, with the given gains and pivots."""
    ld = np.longdouble
    gf = target.nominal.G_f
    a, b, c, d = (np.asarray(m, ld) for m in (gf.A, gf.B, gf.C, gf.D))
    nx, n = a.shape[0], e0.size
    abar = np.zeros((nx + 1, nx + 1), ld)
    abar[:nx, :nx] = a
    at = abar.T.copy()
    bbar, cz, d = np.append(b[:, 0], ld(1)), np.append(c[0], ld(0)), d.ravel()[0]
    gains, pivots, w = np.asarray(gains, ld), np.asarray(pivots, ld), ld(options.weight)
    e, pvec, kff = e0.astype(ld), np.zeros(nx + 1, ld), np.empty(n, ld)
    for t in range(n - 1, -1, -1):
        r_t = -w * e[t] * d
        kff[t] = (r_t + bbar @ pvec) / pivots[t]
        pvec = -w * e[t] * cz + at @ pvec - gains[t] * (bbar @ pvec) - gains[t] * r_t
    z, u = np.zeros(nx + 1, ld), np.empty(n, ld)
    for t in range(n):
        u[t] = -(gains[t] @ z) - kff[t]
        z = abar @ z + bbar * u[t]
    return u


def _extended_reference(target, n: int, options: NormOptimalOptions, e0: np.ndarray) -> dict[str, np.ndarray]:
    """The loop's recursion in numpy's extended precision (80-bit on x86): the exact optimum of the
    problem as stated in float64 (``exact``), to compare each method's rounding error with; and the
    floor of any method that keeps its gains in float64: the same passes with the exact gains and
    pivots rounded to float64 (``rounded_gains``)."""
    gains, pivots = _extended_gains(target, n, options)
    return {"exact": _extended_passes(target, gains, pivots, options, e0).astype(float),
            "rounded_gains": _extended_passes(target, gains.astype(float), pivots.astype(float), options,
                                              e0).astype(float)}


#: Agreement asked of the compiled form with the exact optimum, relative to the peak of the learning
#: signal: 1e-12, or ``FLOOR_FACTOR`` times the floor (the exact gains rounded to float64) where the
#: conditioning makes that larger (the default weights: floor 7e-13 to 8.4e-13).
TOLERANCE, FLOOR_FACTOR = 1e-12, 8.0


def _numba_design():
    """The loop compiled by numba (None without numba): gains and one solve, same arithmetic."""
    try:
        import numba
    except ImportError:
        return None

    @numba.njit(cache=False)
    def design(abar, bbar, cz, d, q, s, r, w, e0):
        n, nz = e0.size, abar.shape[0]
        p = np.zeros((nz, nz))
        gain, huu_all = np.empty((n, nz)), np.empty(n)
        closed = np.empty((n, nz, nz))
        for t in range(n - 1, -1, -1):
            pb = p @ bbar
            huu = r + bbar @ pb
            huz = s + abar.T @ pb
            k = huz / huu
            p = q + abar.T @ p @ abar - np.outer(huz, k)
            p = 0.5 * (p + p.T)
            gain[t], huu_all[t] = k, huu
            closed[t] = (abar - np.outer(bbar, k)).T
        pvec = np.zeros(nz)
        kff = np.empty(n)
        for t in range(n - 1, -1, -1):
            r_t = -w * e0[t] * d
            kff[t] = (r_t + bbar @ pvec) / huu_all[t]
            pvec = -w * e0[t] * cz + closed[t] @ pvec - gain[t] * r_t
        z = np.zeros(nz)
        u = np.empty(n)
        for t in range(n):
            u[t] = -(gain[t] @ z) - kff[t]
            z = abar @ z + bbar * u[t]
        return u

    def run(target, n, opts, e0):
        ref = LoopDesigner(target, 2, opts)  # the matrices of the problem
        nz = ref._abar.shape[0]
        sel = np.zeros(nz)
        sel[-1] = 1.0
        q = opts.weight * np.outer(ref._cz, ref._cz) + opts.mu * np.outer(sel, sel)
        s = opts.weight * ref._cz * ref._d - opts.mu * sel
        r = opts.weight * ref._d**2 + opts.lam + opts.mu
        return design(ref._abar, ref._bbar, ref._cz, ref._d, q, s, r, opts.weight, e0)

    return run


def _hover(fleet, n: int):
    target = fleet.loops[1]
    t = np.arange(n) * fleet.sample_time
    return target, -simulate_map(target.G_d, np.sin(0.9425 * t) + 0.3 * np.sin(2.7 * t))


def against_qp(n: int = 3000) -> dict[str, float]:
    """Section 1: ilcdob against the dense cvxpy QP (wall time, one run each, as before)."""
    fleet = ilcdob.default_fleet()
    target, e0 = _hover(fleet, n)
    opts = NormOptimalOptions(LAM, MU)
    t0 = time.perf_counter()
    ours = NormOptimalDesigner(target, n, opts).solve(e0)
    t_ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    gf = lifted_operator(markov_parameters(target.G_f, n))
    u = cp.Variable(n)
    obj = cp.sum_squares(e0 - gf @ u) + LAM * cp.sum_squares(u) + MU * cp.sum_squares(cp.diff(cp.hstack([0.0, u])))
    prob = cp.Problem(cp.Minimize(obj))
    prob.solve(solver=cp.CLARABEL)
    t_qp = time.perf_counter() - t0
    rel = float(np.linalg.norm(ours - u.value) / np.linalg.norm(u.value))
    return {"ilcdob_s": t_ours, "cvxpy_qp_s": t_qp, "ratio": t_qp / t_ours, "relative_difference": rel}


#: Samples per compiled call of the previous implementation (16 for every recursion then).
PREVIOUS_UNROLL = dict.fromkeys(("gains", "backward", "forward", "simulate"), 16)


#: The compiled forms compared, oldest first, with their labels.
FORMS = {"previous": "VM, dense (first compiled)", "vm": "VM, sparse", "native": "native C, sparse (now)"}


@contextlib.contextmanager
def compiled_form(name: str):
    """Run the compiled recursions in form ``name`` of :data:`FORMS`.

    * ``previous``: as they were before they skipped the system's zero entries: every system counts
      as dense (all entries of ``A``, ``b``, ``c`` and ``d`` in the accumulated state) and every
      recursion runs 16 samples per call, in CasADi's virtual machine; the functions built are those
      of that implementation, instruction for instruction (cached under their own, dense, pattern).
    * ``vm``: today's functions in CasADi's virtual machine (``ILCDOB_NATIVE=off``).
    * ``native``: today's functions compiled to native code (``ILCDOB_NATIVE=required``).
    """
    sparse, unroll = norm_optimal._pattern, norm_optimal._UNROLL

    def all_entries(sys):
        nx = sys[0].shape[0]
        return nx, tuple(range(nx * nx)), tuple(range(nx)), tuple(range(nx)), True

    if name == "previous":
        norm_optimal._pattern, norm_optimal._UNROLL = all_entries, PREVIOUS_UNROLL
    try:
        with environment("ILCDOB_NATIVE", "required" if name == "native" else "off"):
            yield
    finally:
        norm_optimal._pattern, norm_optimal._UNROLL = sparse, unroll


@contextlib.contextmanager
def environment(name: str, value: str):
    """Environment variable ``name`` set to ``value`` inside, as it was (or unset) afterwards."""
    before = os.environ.get(name)
    os.environ[name] = value
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = before


def native_available() -> bool:
    """Whether this machine builds native libraries (a working C compiler)."""
    fleet = ilcdob.default_fleet()
    target, e0 = _hover(fleet, 64)
    try:
        with compiled_form("native"):
            NormOptimalDesigner(target, 64).solve(e0)
    except NativeBuildError as err:
        print(f"   no native form on this machine: {err}")
        return False
    return True


def _clear_caches() -> None:
    for cached in (norm_optimal._base, norm_optimal._native, norm_optimal._block):
        cached.cache_clear()


def build_cost(forms: tuple[str, ...], n: int = 3000) -> dict[str, dict[str, float]]:
    """Cost of building the compiled functions (gains, passes; once per process and pattern): the first
    design of a trial from empty caches, less a second one. CPU of this process, wall time, and the
    compiler's CPU (child processes; native only, built into an empty library folder)."""
    fleet = ilcdob.default_fleet()
    target, e0 = _hover(fleet, n)
    out = {}
    for name in forms:
        _clear_caches()
        with (tempfile.TemporaryDirectory() as folder, compiled_form(name),
              environment("ILCDOB_CACHE_DIR", folder)):
            runs = []
            for _ in range(2):
                t0, w0, c0 = time.process_time(), time.perf_counter(), os.times()
                NormOptimalDesigner(target, n).solve(e0)
                c1 = os.times()
                runs.append((time.process_time() - t0, time.perf_counter() - w0,
                             c1.children_user + c1.children_system - c0.children_user - c0.children_system))
        _clear_caches()  # the libraries of the folder just removed are not used again
        out[name] = {"cpu_s": runs[0][0] - runs[1][0], "wall_s": runs[0][1] - runs[1][1],
                     "compiler_cpu_s": runs[0][2]}
    return out


def against_loop(n: int, repeat: int, options: NormOptimalOptions, forms: tuple[str, ...],
                 reference: bool = True) -> dict[str, object]:
    """Section 2: the compiled forms against the Python loop (and numba), interleaved, CPU medians;
    gains and solve timed apart for the compiled forms."""
    fleet = ilcdob.default_fleet()
    target, e0 = _hover(fleet, n)
    for name in forms:  # their functions (and native libraries), built once per process
        with compiled_form(name):
            NormOptimalDesigner(target, n, options).solve(np.zeros(n))
    numba_run = _numba_design()
    if numba_run is not None:
        numba_run(target, 64, options, np.zeros(64))  # compile outside the timing
    names = ("loop", *forms, "numba")
    rows: dict[str, list[float]] = {name: [] for name in names}
    parts: dict[str, list[tuple[float, float]]] = {name: [] for name in forms}
    results: dict[str, np.ndarray] = {}
    for _ in range(repeat):
        for name in names:
            if name == "numba" and numba_run is None:
                continue
            t0 = time.process_time()
            if name == "loop":
                results[name] = LoopDesigner(target, n, options).solve(e0)
            elif name in parts:
                with compiled_form(name):
                    des = NormOptimalDesigner(target, n, options)
                    t1 = time.process_time()
                    results[name] = des.solve(e0)
                parts[name].append((t1 - t0, time.process_time() - t1))
            else:
                results[name] = numba_run(target, n, options, e0)
            rows[name].append(time.process_time() - t0)
    ref = results["loop"]
    exact = _extended_reference(target, n, options, e0) if reference else None
    out: dict[str, object] = {"n": n, "options": options}
    for name, times in rows.items():
        if times:
            diff = results[name] - ref
            out[name] = {"cpu_s": statistics.median(times), "runs": times,
                         "rel_max": float(np.max(np.abs(diff)) / np.max(np.abs(ref))),
                         "rel_2": float(np.linalg.norm(diff) / np.linalg.norm(ref)),
                         "exact_max": (float(np.max(np.abs(results[name] - exact["exact"]))
                                             / np.max(np.abs(exact["exact"])))
                                       if exact is not None else float("nan"))}
            if name in parts:
                out[name]["gains_s"] = statistics.median(g for g, _ in parts[name])
                out[name]["solve_s"] = statistics.median(v for _, v in parts[name])
    out["identical"] = all(np.array_equal(results[name], results["previous"]) for name in forms)
    # the floor: the loop itself with its input moved by one unit in the last place
    bumped = LoopDesigner(target, n, options).solve(np.nextafter(e0, np.inf))
    out["one_ulp_floor_rel_max"] = float(np.max(np.abs(bumped - ref)) / np.max(np.abs(ref)))
    if exact is not None:
        peak = np.max(np.abs(exact["exact"]))
        floor = float(np.max(np.abs(exact["rounded_gains"] - exact["exact"])) / peak)
        out["rounded_gains_floor"] = floor
        out["tolerance"] = max(TOLERANCE, FLOOR_FACTOR * floor)
    return out


def compact_against_lifted(sizes: tuple[int, ...], big_n: int, forms: tuple[str, ...],
                           repeat: int = 3) -> list[dict[str, float]]:
    """Section 3: the compact law against the lifted matrices (CPU time, tracemalloc peak, difference);
    at ``big_n`` the compact law in each compiled form (interleaved, medians)."""
    fleet = ilcdob.default_fleet()
    source, target = fleet.loops[0], fleet.loops[1]
    opts = NormOptimalOptions(1e-4, 1e-3)
    rows = []
    for n in (*sizes, big_n):
        t = np.arange(n) * fleet.sample_time
        e, df = 0.01 * np.sin(0.9 * t), 0.1 * np.sin(1.3 * t)
        row: dict[str, float] = {"n": n}
        tracemalloc.start()
        t0 = time.process_time()
        law = NormOptimalDesigner(target, n, opts).law(source, 1e-8)
        got = law.apply(e, df)
        row["compact_cpu_s"] = time.process_time() - t0
        row["compact_peak_mb"] = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
        if n != big_n:
            tracemalloc.start()
            t0 = time.process_time()
            l1, l2 = NormOptimalDesigner(target, n, opts).lifted_matrices(source, 1e-8)
            ref = l1 @ e + l2 @ df
            row["lifted_cpu_s"] = time.process_time() - t0
            row["lifted_peak_mb"] = tracemalloc.get_traced_memory()[1] / 1e6
            tracemalloc.stop()
            row["law_difference"] = float(np.max(np.abs(got - ref)) / np.max(np.abs(ref)))
        else:
            times: dict[str, list[float]] = {name: [] for name in forms}
            out = {}
            for _ in range(repeat):
                for name in times:
                    with compiled_form(name):
                        t0 = time.process_time()
                        out[name] = NormOptimalDesigner(target, n, opts).law(source, 1e-8).apply(e, df)
                        times[name].append(time.process_time() - t0)
            row["forms_cpu_s"] = {name: statistics.median(t) for name, t in times.items()}
            row["identical"] = all(np.array_equal(out[name], out["previous"]) for name in forms)
        rows.append(row)
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=3000)
    parser.add_argument("--big-n", type=int, default=300000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--lifted-n", type=int, nargs="*", default=[500, 1000])
    parser.add_argument("--no-reference", action="store_true",
                        help="skip the extended-precision reference of section 2 (about 13 s per run at 3e5)")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} "
          f"on {os.cpu_count()} cores")
    r = against_qp(args.n)
    print(f"\n1. N = {args.n}: ilcdob norm-optimal (gains + solve): {r['ilcdob_s']:.3f} s (target < 1 s)")
    print(f"   dense cvxpy QP (Clarabel):                  {r['cvxpy_qp_s']:.3f} s")
    print(f"   speed-up: {r['ratio']:.0f}x (target >= 20x); optima differ by {r['relative_difference']:.1e} (relative)")
    forms = tuple(name for name in FORMS if name != "native" or native_available())
    print("\nbuilding the compiled functions (once per process and sparsity pattern; native: once per machine):")
    for name, b in build_cost(forms).items():
        print(f"   {FORMS[name]:<28} {b['cpu_s']:.3f} s CPU, {b['wall_s']:.3f} s wall"
              + (f" (the compiler: {b['compiler_cpu_s']:.3f} s CPU)" if name == "native" else ""))
    for opts in (NormOptimalOptions(), NormOptimalOptions(LAM, MU)):
        r = against_loop(args.big_n, args.repeat, opts, forms, not args.no_reference)
        loop = r["loop"]["cpu_s"]
        print(f"\n2. N = {args.big_n}, lam = {opts.lam:g}, mu = {opts.mu:g}: gains + one solve, median CPU of "
              f"{args.repeat} interleaved runs")
        print(f"   {'':<28}{'CPU s':>9}{'ratio':>9}{'gains s':>9}{'solve s':>9}{'diff to loop (max)':>20}"
              f"{'(2-norm)':>10}{'to 80-bit':>11}")
        for name, label in (("loop", "Python loop (first form)"), *FORMS.items(), ("numba", "numba (not a dependency)")):
            if name in r:
                row = r[name]
                split = f"{row['gains_s']:9.3f}{row['solve_s']:9.3f}" if "gains_s" in row else f"{'':18}"
                print(f"   {label:<28}{row['cpu_s']:9.3f}{loop / row['cpu_s']:8.1f}x{split}{row['rel_max']:20.1e}"
                      f"{row['rel_2']:10.1e}{row['exact_max']:11.1e}")
        now = r[forms[-1]]
        print(f"   the compiled forms' results are {'bit-identical' if r['identical'] else 'DIFFERENT'}")
        print(f"   floor: the loop itself with e0 moved by 1 ulp differs by {r['one_ulp_floor_rel_max']:.1e} (max)")
        if "tolerance" in r:
            ok = now["exact_max"] <= r["tolerance"]
            print(f"   floor: the exact gains rounded to float64 move the exact optimum by "
                  f"{r['rounded_gains_floor']:.1e}; tolerance max({TOLERANCE:g}, {FLOOR_FACTOR:g} x floor) = {r['tolerance']:.1e}: "
                  f"{'met' if ok else 'NOT MET'} ({now['exact_max']:.1e})")
    print("\n3. compact law (gains of both recursions + sigma_max) against the lifted matrices, "
          "lam = 1e-4, mu = 1e-3, regularisation 1e-8")
    print(f"   {'N':>7}{'compact CPU s':>15}{'peak MB':>10}{'lifted CPU s':>14}{'peak MB':>10}{'law diff':>10}")
    for row in compact_against_lifted(tuple(args.lifted_n), args.big_n, forms, args.repeat):
        lifted = (f"{row['lifted_cpu_s']:14.3f}{row['lifted_peak_mb']:10.1f}{row['law_difference']:10.1e}"
                  if "lifted_cpu_s" in row else f"{'-':>14}{'-':>10}{'-':>10}")
        print(f"   {row['n']:>7}{row['compact_cpu_s']:15.3f}{row['compact_peak_mb']:10.1f}{lifted}")
        if "forms_cpu_s" in row:
            cpu = row["forms_cpu_s"]
            print(f"   N = {row['n']}, median of {args.repeat} interleaved: "
                  + ", ".join(f"{FORMS[name]} {t:.3f} s" for name, t in cpu.items())
                  + f"; laws {'bit-identical' if row['identical'] else 'DIFFERENT'}")
