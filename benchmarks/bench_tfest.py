"""Benchmark of the output-error engine (``ilcdob.identification.tfest``), four targets.

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

Run:  python benchmarks/bench_tfest.py [--repeat 3] [--skip-memory]
"""

from __future__ import annotations

import argparse
import json
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
    args = parser.parse_args()
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
              f"({m['rss_before_fit_mb']:.0f} MB before the fit; max relative parameter error {m['max_rel_err']:.1e})")
