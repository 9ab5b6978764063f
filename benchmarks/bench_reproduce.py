"""Benchmark: the full ``ilcdob reproduce`` run on the built-in fleet, figures included.

Target: under 30 s on a 2-core machine. Reported against a baseline
measured in the same process: one block-diagram trial of 60 s (3000 samples), so the ratio
says how many trials' worth of time the whole run costs (it flies 4 scenarios x 3 systems x
(no DOB + DOB + 3 learning) = 60 trials, plus filter design and 12 figures).

Run:  python benchmarks/bench_reproduce.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

import ilcdob
from ilcdob.app.cli import main
from ilcdob.validation.simulate import simulate_flight


def _best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def run(repeat: int = 3) -> dict[str, float]:
    fleet = ilcdob.default_fleet()
    t = np.arange(3000) * fleet.sample_time
    d = np.sin(0.9425 * t)
    baseline = _best(lambda: simulate_flight(fleet.loops[0], np.zeros_like(t), d), repeat)

    def full():
        with tempfile.TemporaryDirectory() as out:
            assert main(["reproduce", "--out", out]) == 0

    total = _best(full, repeat)
    return {"reproduce_s": total, "one_trial_s": baseline, "ratio": total / baseline}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    res = run(parser.parse_args().repeat)
    print(f"ilcdob reproduce (4 scenarios, 3 iterations, figures): {res['reproduce_s']:.2f} s "
          f"(target < 30 s)")
    print(f"baseline, one 3000-sample block-diagram trial:         {res['one_trial_s'] * 1e3:.1f} ms")
    print(f"ratio: {res['ratio']:.0f} trials' worth")
