"""Benchmark: a 4-parameter output-error fit on 30,000 samples.

ilcdob's ``tfest`` (initialisation + CasADi/IPOPT with exact Jacobians and a Gauss-Newton
Hessian, initial state estimated) against a plain ``scipy.optimize.least_squares``
output-error fit (trust-region reflective, finite-difference Jacobian, zero initial state)
started from the same SRIVC initial estimate, in the same process on the same data.
Both are timed end to end (best of ``--repeat``); the parameter errors are printed too.

Run:  python benchmarks/bench_tfest.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import least_squares

from ilcdob.identification.data import FlightData
from ilcdob.identification.model import ModelStructure, simulate_zoh
from ilcdob.identification.srivc import srivc
from ilcdob.identification.tfest import tfest

TS = 0.02
N = 30_000
STRUCTURE = ModelStructure(2, 1, 0)
TRUE = STRUCTURE.join([2.0, 3.0], [1.0, 1.4, 4.0])  # (a1, a0, b1, b0)


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


def run(repeat: int = 3) -> dict[str, float]:
    data = _data()
    u, y = data["u"], data["y"]

    def ours():
        return tfest(data, "u", "y", STRUCTURE, progress=lambda msg: None).theta

    def baseline():
        theta0 = srivc(STRUCTURE, [(u, y)], TS)
        res = least_squares(lambda th: y - simulate_zoh(STRUCTURE, th, u, TS), theta0, xtol=1e-12, ftol=1e-12)
        return res.x

    t_ours, th_ours = _best(ours, repeat)
    t_base, th_base = _best(baseline, repeat)
    return {"ilcdob_s": t_ours, "scipy_s": t_base, "ratio": t_base / t_ours,
            "ilcdob_max_rel_err": float(np.max(np.abs(th_ours / TRUE - 1))),
            "scipy_max_rel_err": float(np.max(np.abs(th_base / TRUE - 1)))}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    r = run(parser.parse_args().repeat)
    print(f"ilcdob tfest (CasADi/IPOPT):          {r['ilcdob_s']:.3f} s, max relative parameter error "
          f"{r['ilcdob_max_rel_err']:.2e}")
    print(f"scipy least_squares output error:     {r['scipy_s']:.3f} s, max relative parameter error "
          f"{r['scipy_max_rel_err']:.2e}")
    print(f"speed ratio scipy / ilcdob: {r['ratio']:.2f}")
