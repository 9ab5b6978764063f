"""Benchmark of the output-error engine (``ilcdob.identification.tfest``), five targets.

0. The start search: the whole fit against its filtering floor (the filtering passes one SRIVC
   refinement pass makes on the full record, :func:`_floor_passes`), with the former start search
   (:func:`baseline_candidates`, every candidate solved on the whole record) and the shipped one
   (ranked on the band-limited decimated record, batched), interleaved in one process, median CPU
   time; on the 30,000-sample log of 1. and (``--long``) the 2,000,000-sample log of 4. Target:
   the fit within 10 x its floor at 30,000 samples, the same parameters.

1. Speed against a plain baseline: a 4-parameter fit on 30,000 samples (20 dB SNR), ilcdob's
   ``tfest`` with its default options (SRIVC + pole-grid starts, LM with filtered
   sensitivities on two starts, initial condition and offset estimated, covariance and
   residual tests) against ``scipy.optimize.least_squares`` (trust-region reflective,
   finite-difference Jacobian, zero initial state) started from the same SRIVC estimate, in
   the same process on the same data; both timed end to end, best of ``--repeat``, with the
   parameter errors. Target: ratio >= 5. Also timed: both refining the same SRIVC estimate
   (``FitOptions(initial=...)``: the optimiser and the result assembly alone).
2. ``delay="auto"`` against the delay fixed at its true value, on a closed-loop log of
   ``1/(s^2 (0.1 s + 1))`` with a 0.03 s delay under a PID (60 s at 100 Hz). Target: <= 2.
3. A 5-parameter fit with delay (3 poles, 1 zero) on 7 files of together 25,000 samples
   (100 Hz, unequal lengths, coloured noise). Target: well under 10 s.
4. Peak resident memory of a 2-pole fit on one 2,000,000-sample log (1 kHz, 33 min), in a
   fresh subprocess. Target: <= 1.5 GB.

Run:  python benchmarks/bench_tfest.py [--repeat 3] [--skip-memory] [--search-only] [--long]
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import math
import os
import statistics
import subprocess
import sys
import time

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from ilcdob.signals import FlightData
from ilcdob.identification.oe import simulate_zoh
from ilcdob.uncertainty import ModelStructure
from ilcdob.identification.srivc import srivc
from ilcdob.identification.synthetic import closed_loop_flight
from ilcdob.identification.tfest import FitOptions, tfest
from ilcdob.specs import PIDSpec, PlantSpec

_tf = importlib.import_module("ilcdob.identification.tfest")


def baseline_candidates(model, delay: float, say):
    """The start search as it was before the decimated, batched ranking (the reference of the start-search
    comparison): SRIVC on the record (chunked beyond ``RANKING_SAMPLES``), then every candidate solved
    on it one at a time by ``_Model.evaluate``."""
    full = model
    model = _tf._chunked(full)
    s = model.s
    dens = []
    try:
        th = srivc(s, [(e.u, e.y) for e in model.exps], model.ts, delay=delay, iterations=4, tol=1e-4)
        if np.all(np.isfinite(th)):
            dens.append(th[: s.n_free_poles])
    except (np.linalg.LinAlgError, ValueError):
        say(0, 0, "SRIVC gave no estimate; starting from the pole grid only")
    dens += _tf._grid_denominators(s, model.ts) + _tf._frequency_domain_denominators(s, model.exps, model.ts, delay)
    extra = [delay] if model.estimate_delay else []
    out = []
    for a in dens:
        p = model.evaluate(np.concatenate([a, extra]), delay)
        if math.isfinite(p.sse):
            p.cols = None
            out.append(p)
    out.sort(key=lambda p: p.sse)
    ranking = {"decimation": 1, "samples": sum(e.n for e in model.exps)}
    if model is full:
        return out, ranking
    best = [full.evaluate(p.alpha, delay) for p in _tf._distinct(out, max(full.opts.starts, 1))]
    return sorted((p for p in best if math.isfinite(p.sse)), key=lambda p: p.sse), ranking


@contextlib.contextmanager
def search(which: str):
    """``with search("baseline"):`` runs ``tfest`` with :func:`baseline_candidates`; ``"new"``: as shipped."""
    if which not in ("baseline", "new"):
        raise ValueError(f"search: got {which!r}, expected 'baseline' or 'new'")
    shipped = _tf._candidates
    _tf._candidates = baseline_candidates if which == "baseline" else shipped
    try:
        yield
    finally:
        _tf._candidates = shipped

TS = 0.02
N = 30_000
STRUCTURE = ModelStructure(2, 1, 0)
TRUE = STRUCTURE.join([2.0, 3.0], [1.0, 1.4, 4.0])  # (a1, a0, b1, b0)
QUIET = {"progress": None}


def _data(seed: int = 0) -> FlightData:
    rng = np.random.default_rng(seed)
    t = np.arange(N) * TS
    u = np.sin(2 * np.pi * (0.02 * t + 3.0 * t**2 / (2 * t[-1]))) + 0.5 * np.repeat(
        rng.choice([-1.0, 1.0], N // 200 + 1), 200)[:N]
    y = simulate_zoh(STRUCTURE, TRUE, u, TS)
    y = y + np.std(y) / 10 * rng.standard_normal(N)  # 20 dB SNR
    return FlightData(t, {"u": u, "y": y})


def _best(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def speed(repeat: int = 3) -> dict[str, float]:
    data = _data()
    u, y = data["u"], data["y"]

    def ours():
        return tfest(data, "u", "y", STRUCTURE, **QUIET).theta

    def baseline():
        theta0 = srivc(STRUCTURE, [(u, y)], TS)
        res = least_squares(lambda th: y - simulate_zoh(STRUCTURE, th, u, TS), theta0, xtol=1e-12, ftol=1e-12)
        return res.x

    theta0 = srivc(STRUCTURE, [(u, y)], TS)

    def ours_from_start():
        return tfest(data, "u", "y", STRUCTURE, FitOptions(initial=theta0), **QUIET).theta

    def baseline_from_start():
        return least_squares(lambda th: y - simulate_zoh(STRUCTURE, th, u, TS), theta0, xtol=1e-12, ftol=1e-12).x

    t_ours, th_ours = _best(ours, repeat)
    t_base, th_base = _best(baseline, repeat)
    t_ours0, th_ours0 = _best(ours_from_start, repeat)
    t_base0, th_base0 = _best(baseline_from_start, repeat)
    err = lambda th: float(np.max(np.abs(th / TRUE - 1)))  # noqa: E731
    return {"ilcdob_s": t_ours, "scipy_s": t_base, "ratio": t_base / t_ours,
            "ilcdob_max_rel_err": err(th_ours), "scipy_max_rel_err": err(th_base),
            "ilcdob_from_start_s": t_ours0, "scipy_from_start_s": t_base0, "ratio_from_start": t_base0 / t_ours0,
            "ilcdob_from_start_err": err(th_ours0), "scipy_from_start_err": err(th_base0)}


def _closed_loop_log(n: int = 6000, ts: float = 0.01, seed: int = 0) -> FlightData:
    """PID (kp 3, ki 0.3, kd 2.4) around 1/(s^2 (0.1 s + 1)) e^{-0.03 s}; reference steps and a
    chirp; 1 mm position noise fed back."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * ts
    r = np.repeat(rng.choice([-0.5, 0.5], n // 300 + 1), 300)[:n] + 0.2 * np.sin(
        2 * np.pi * (0.05 * t + 1.5 * t**2 / (2 * t[-1])))
    noise = 1e-3 * rng.standard_normal(n)
    u, y = closed_loop_flight(PlantSpec([10.0], [1.0, 10.0, 0.0, 0.0], 0.03), PIDSpec(3.0, 0.3, 2.4, 0.05), r, ts,
                              noise)
    return FlightData(t, {"u": u, "y": y + noise})


def delay_auto(repeat: int = 3) -> dict[str, float]:
    data = _closed_loop_log()
    structure = ModelStructure(3, 0, 2)
    t_fixed, fixed = _best(lambda: tfest(data, "u", "y", structure, FitOptions(delay=0.03), **QUIET), repeat)
    t_auto, auto = _best(lambda: tfest(data, "u", "y", structure, FitOptions(delay="auto"), **QUIET), repeat)
    return {"fixed_s": t_fixed, "auto_s": t_auto, "ratio_auto_fixed": t_auto / t_fixed,
            "auto_delay_s": auto.delay, "auto_a0": float(auto.theta[0]), "fixed_a0": float(fixed.theta[0])}


def easy(n: int, repeat: int = 3) -> dict[str, float]:
    """Easy data against a plain fit from the same start: the closed-loop log of :func:`_closed_loop_log` (``n``
    samples), the paper's structure (3 poles, 2 integrators) with the delay estimated. ilcdob: ``tfest`` end to
    end with its defaults (start search, delay profile, LM, covariance, residual tests). Plain:
    ``scipy.optimize.least_squares`` (``method="lm"``, finite-difference Jacobian) over ``(a0, b0, delay)``,
    each model simulated by ``simulate_zoh`` from rest, started from ilcdob's best start at delay 0 (the start
    ilcdob's own search begins from; its search is not timed for the plain fit). Median CPU time of
    ``repeat`` interleaved runs; the criterion each reaches."""
    data = _closed_loop_log(n)
    structure = ModelStructure(3, 0, 2)
    u, y = data["u"], data["y"]
    opts = FitOptions(delay="auto")
    model, delay0 = _tf._fit_problem(data, "u", "y", structure, opts, _tf._silent)
    start = _tf._initial_points(model, delay0, _tf._silent)[0][0]
    x0 = np.concatenate([start.theta, [0.0]])

    def plain():
        return least_squares(lambda x: y - simulate_zoh(structure, x[:2], u, data.ts, x[2]), x0, method="lm")

    cpu: dict[str, list[float]] = {"ours": [], "plain": []}
    wall: dict[str, list[float]] = {"ours": [], "plain": []}
    last: dict[str, object] = {}
    for _ in range(repeat):
        for key, fn in (("ours", lambda: tfest(data, "u", "y", structure, opts, **QUIET)), ("plain", plain)):
            c0, w0 = time.process_time(), time.perf_counter()
            last[key] = fn()
            cpu[key].append(time.process_time() - c0)
            wall[key].append(time.perf_counter() - w0)
    est, res = last["ours"], last["plain"]
    r = y - simulate_zoh(structure, est.theta, u, data.ts, est.delay)
    med = {f"{k}_{kind}": statistics.median(v) for kind, d in (("cpu", cpu), ("wall", wall)) for k, v in d.items()}
    return {"samples": n, **med, "ratio_cpu": med["plain_cpu"] / med["ours_cpu"],
            "ratio_wall": med["plain_wall"] / med["ours_wall"],
            "sse_ilcdob_from_rest": float(r @ r), "sse_plain": float(res.fun @ res.fun), "plain_nfev": int(res.nfev),
            "delay_ilcdob": est.delay, "delay_plain": float(res.x[2])}


def seven_files(repeat: int = 1) -> dict[str, float]:
    """(s + 6) * 20 / ((s^2 + 5 s + 20)(s + 6)) -like position loop: 3 poles, 1 zero, delay."""
    structure = ModelStructure(3, 1, 0)
    theta = structure.join([4.0, 24.0], [1.0, 7.0, 30.0, 24.0])
    ts, delay = 0.01, 0.04
    rng = np.random.default_rng(3)
    lengths = [5200, 2300, 4100, 3300, 2700, 4000, 3400]          # 25,000 samples
    flights = []
    for i, n in enumerate(lengths):
        steps = np.repeat(rng.uniform(-1, 1, n // 250 + 1), 250)[:n]
        u = steps + 0.2 * np.sin(2 * np.pi * rng.uniform(0.2, 2.0) * np.arange(n) * ts)
        y = simulate_zoh(structure, theta, u, ts, delay)
        noise = lfilter([1.0], [1.0, -0.9], rng.standard_normal(n))
        flights.append(FlightData(np.arange(n) * ts, {"u": u, "y": y + 0.01 * noise / np.std(noise)},
                                  source=f"file{i}"))
    t, est = _best(lambda: tfest(flights, "u", "y", structure, FitOptions(delay="auto", max_delay=0.2), **QUIET),
                   repeat)
    return {"seconds": t, "samples": sum(lengths), "delay_s": est.delay, "fit": est.fit_estimation,
            "max_rel_err": float(np.max(np.abs(est.theta / theta - 1)))}


def _floor_passes(u: np.ndarray, y: np.ndarray, structure: ModelStructure, theta: np.ndarray, ts: float) -> None:
    """The filtering floor: the filtering passes of one SRIVC refinement pass on the full record, through
    SRIVC's own functions -- the state-variable filter bank of the output (orders 0..n, first-order hold),
    of the input (orders 0..m, zero-order hold), the model's simulated output (the instrument) and its
    filter bank -- with the prefilter of ``theta`` (the discretisations included)."""
    from ilcdob.identification import srivc as sv

    n = structure.n_poles
    lpoly = sv._stable_prefilter(theta, structure, 0.1 * np.pi / ts / 5)
    bank = sv._bank(lpoly, ts)
    sv._filter_bank(y, lpoly, bank, range(n + 1), "foh")
    sv._filter_bank(u, lpoly, bank, range(structure.n_zeros + 1), "zoh")
    sv._filter_bank(simulate_zoh(structure, theta, u, ts), lpoly, bank, range(n + 1), "foh")


def _long_data(n: int = 2_000_000, ts: float = 0.001):
    """The 2-pole log of the memory benchmark (1 kHz, 33 min)."""
    s = ModelStructure(2, 0, 0)
    theta = s.join([30.0], [1.0, 6.0, 30.0])
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(-1, 1, n // 2000 + 1), 2000)[:n] + 0.3 * np.sin(2 * np.pi * 1.3 * np.arange(n) * ts)
    y = simulate_zoh(s, theta, u, ts) + 0.01 * rng.standard_normal(n)
    return FlightData(np.arange(n) * ts, {"u": u, "y": y}), s, theta


def start_search(repeat: int = 7, long: bool = False) -> list[dict]:
    """The fit against its filtering floor (:func:`_floor_passes`), with the former start search
    (:func:`baseline_candidates`) and the shipped one, interleaved (floor, baseline, shipped, floor, ...),
    median CPU time (``time.process_time``; the fit runs single-threaded) of ``repeat`` rounds, on the
    30,000-sample log of :func:`speed` and, with ``long``, the 2,000,000-sample log of :func:`memory`.
    Also: the share of the fit spent choosing the starts, and how far the two fits' parameters lie apart
    in the baseline's standard deviations."""
    cases = [("30,000 samples, 2 poles 1 zero", _data(), STRUCTURE, TRUE, repeat)]
    if long:
        cases.append(("2,000,000 samples, 2 poles", *_long_data(), max(1, repeat // 3)))
    rows = []
    for name, data, structure, theta, rounds in cases:
        u, y, ts = data["u"], data["y"], data.ts
        times = {"floor": [], "baseline": [], "new": []}
        share = {"baseline": [], "new": []}
        ests = {}
        for _ in range(rounds):
            with _tf._blas_controller().limit(limits=1, user_api="blas"):
                t0 = time.process_time()
                _floor_passes(u, y, structure, theta, ts)
                times["floor"].append(time.process_time() - t0)
            for which in ("baseline", "new"):
                with search(which):
                    chosen, spent = _tf._candidates, [0.0]

                    def timed(*args, chosen=chosen, spent=spent):
                        t1 = time.process_time()
                        try:
                            return chosen(*args)
                        finally:
                            spent[0] += time.process_time() - t1
                    _tf._candidates = timed
                    t0 = time.process_time()
                    ests[which] = tfest(data, "u", "y", structure, **QUIET)
                    times[which].append(time.process_time() - t0)
                    share[which].append(spent[0] / times[which][-1])
        med = {k: statistics.median(v) for k, v in times.items()}
        b, n = ests["baseline"], ests["new"]
        rows.append({"case": name, "floor_s": med["floor"], "baseline_s": med["baseline"], "new_s": med["new"],
                     "baseline_x_floor": med["baseline"] / med["floor"], "new_x_floor": med["new"] / med["floor"],
                     "speedup": med["baseline"] / med["new"],
                     "search_share_baseline": statistics.median(share["baseline"]),
                     "search_share_new": statistics.median(share["new"]),
                     "decimation": n.solver.get("ranking", {}).get("decimation", 1),
                     "d_sigma": float(np.max(np.abs(n.theta - b.theta) / b.std)),
                     "fit_baseline": b.fit_estimation, "fit_new": n.fit_estimation})
    return rows


_MEMORY_CHILD = r"""
import json, resource, sys, time
import numpy as np
from ilcdob.signals import FlightData
from ilcdob.identification.oe import simulate_zoh
from ilcdob.uncertainty import ModelStructure
from ilcdob.identification.tfest import tfest
n, ts = 2_000_000, 0.001
s = ModelStructure(2, 0, 0)
theta = s.join([30.0], [1.0, 6.0, 30.0])
rng = np.random.default_rng(0)
u = np.repeat(rng.uniform(-1, 1, n // 2000 + 1), 2000)[:n] + 0.3 * np.sin(2 * np.pi * 1.3 * np.arange(n) * ts)
y = simulate_zoh(s, theta, u, ts) + 0.01 * rng.standard_normal(n)
data = FlightData(np.arange(n) * ts, {"u": u, "y": y})
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
est = tfest(data, "u", "y", s)
print(json.dumps({"seconds": time.perf_counter() - t0, "peak_rss_mb": resource.getrusage(
    resource.RUSAGE_SELF).ru_maxrss / 1024, "rss_before_fit_mb": before / 1024,
    "max_rel_err": float(np.max(np.abs(est.theta / theta - 1)))}))
"""


def memory() -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", _MEMORY_CHILD], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--skip-memory", action="store_true", help="skip the 2,000,000-sample subprocess")
    parser.add_argument("--search-only", action="store_true", help="only the start search against the filtering floor")
    parser.add_argument("--long", action="store_true", help="the start search on the 2,000,000-sample log too")
    args = parser.parse_args()
    print(f"start search, fit against its filtering floor (one SRIVC pass's filtering on the full record); median "
          f"CPU time, interleaved; load {os.getloadavg()[0]:.2f}")
    for r in start_search(max(args.repeat, 7), args.long):
        print(f"  {r['case']}: floor {r['floor_s'] * 1e3:.2f} ms; baseline {r['baseline_s'] * 1e3:.1f} ms = "
              f"{r['baseline_x_floor']:.1f} x floor (start search {100 * r['search_share_baseline']:.0f} %); shipped "
              f"{r['new_s'] * 1e3:.1f} ms = {r['new_x_floor']:.1f} x floor (start search "
              f"{100 * r['search_share_new']:.0f} %, ranked decimated {r['decimation']}x); speed-up "
              f"{r['speedup']:.2f}; parameters {r['d_sigma']:.1e} sigma apart, fit {r['fit_baseline']:.4f} / "
              f"{r['fit_new']:.4f} %")
    if args.search_only:
        sys.exit(0)
    r = speed(args.repeat)
    print(f"ilcdob tfest (LM, filtered sensitivities): {r['ilcdob_s']:.3f} s, max relative parameter error "
          f"{r['ilcdob_max_rel_err']:.2e}")
    print(f"scipy least_squares output error:         {r['scipy_s']:.3f} s, max relative parameter error "
          f"{r['scipy_max_rel_err']:.2e}")
    print(f"speed ratio scipy / ilcdob: {r['ratio']:.2f}")
    print(f"from the same SRIVC estimate (start search skipped, FitOptions(initial=...)): ilcdob "
          f"{r['ilcdob_from_start_s']:.4f} s (error {r['ilcdob_from_start_err']:.2e}), scipy "
          f"{r['scipy_from_start_s']:.4f} s (error {r['scipy_from_start_err']:.2e}); refinement speed ratio "
          f"scipy / ilcdob: {r['ratio_from_start']:.2f}")
    for n in (6000, 300_000):
        e = easy(n, args.repeat)
        print(f"easy data, {n} samples (closed loop, 3 poles 2 integrators, delay estimated): ilcdob "
              f"{e['ours_cpu']:.3f} s CPU / {e['ours_wall']:.3f} s wall, plain least_squares from ilcdob's start "
              f"{e['plain_cpu']:.3f} / {e['plain_wall']:.3f} s ({e['plain_nfev']} simulations); ratio plain / ilcdob "
              f"{e['ratio_cpu']:.2f} CPU, {e['ratio_wall']:.2f} wall; SSE from rest {e['sse_ilcdob_from_rest']:.6g} / "
              f"{e['sse_plain']:.6g}; delay {e['delay_ilcdob']:.5f} / {e['delay_plain']:.5f} s")
    d = delay_auto(args.repeat)
    print(f"closed-loop 1/(s^2(0.1s+1)) log: delay fixed {d['fixed_s']:.3f} s, delay auto {d['auto_s']:.3f} s "
          f"(found {d['auto_delay_s']:.4f} s, a0 {d['auto_a0']:.3f}); time ratio auto / fixed: "
          f"{d['ratio_auto_fixed']:.2f}")
    f = seven_files()
    print(f"7 files, {f['samples']} samples, 5 parameters + delay: {f['seconds']:.2f} s (delay {f['delay_s']:.4f} s, "
          f"fit {f['fit']:.2f} %, max relative parameter error {f['max_rel_err']:.2e})")
    if not args.skip_memory:
        m = memory()
        print(f"2,000,000-sample log, 2 poles: {m['seconds']:.1f} s, peak RSS {m['peak_rss_mb']:.0f} MB "
              f"({m['rss_before_fit_mb']:.0f} MB before the fit, the log loaded: the fit's own "
              f"{(m['peak_rss_mb'] - m['rss_before_fit_mb']) * 2**20 / 2e6:.0f} bytes per sample; max relative "
              f"parameter error {m['max_rel_err']:.1e})")
