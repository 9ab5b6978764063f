"""Benchmark: one Monte Carlo campaign on a local Dask cluster of 2 workers against 1 worker.

The campaign is ``ilcdob campaign``'s default (every design, every scenario, robust SOCP with
1 + 1 models) with fewer samples by default, flown twice into fresh folders: on a local
cluster of 1 worker process, then of 2 (one thread each). Reported: wall-clock time of each
run (cluster start included), the speed-up ``t(1 worker) / t(2 workers)``, and the mean CPU and
wall-clock time per sample on the workers -- when other processes share the cores, wall
exceeds CPU and the speed-up says so. The ideal speed-up on 2 free cores is about 2 minus
the per-worker one-time cost (cluster start, building every design once per worker).

Run:  python benchmarks/bench_campaign.py [--samples 24] [--robust-models 1] [--duration SECONDS]
"""

from __future__ import annotations

import argparse
import tempfile

import ilcdob
from ilcdob.validation.campaign import CampaignOptions, CampaignResult, run_campaign


def _run(options: CampaignOptions, workers: int) -> CampaignResult:
    with tempfile.TemporaryDirectory() as out:
        return run_campaign(ilcdob.default_fleet(), options, out, workers=workers)


def run(samples: int = 24, robust_models: int = 1, duration: float | None = None) -> dict[str, float]:
    """Wall times of the same campaign on 1 and 2 local workers, and the speed-up."""
    opts = CampaignOptions(samples=samples, robust_models=robust_models, duration=duration)
    one, two = _run(opts, 1), _run(opts, 2)
    if one.methods != two.methods:
        raise RuntimeError("the campaign's statistics differ between 1 and 2 workers")
    return {"one_worker_s": one.wall_time_s, "two_workers_s": two.wall_time_s,
            "speedup": one.wall_time_s / two.wall_time_s,
            "cpu_per_sample_s": 0.5 * (one.sample_cpu_s + two.sample_cpu_s),
            "wall_per_sample_1_s": one.sample_time_s, "wall_per_sample_2_s": two.sample_time_s}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=24)
    parser.add_argument("--robust-models", type=int, default=1)
    parser.add_argument("--duration", type=float, default=None)
    a = parser.parse_args()
    res = run(a.samples, a.robust_models, a.duration)
    print(f"campaign: {a.samples} samples x 4 scenarios x 4 designs, robust 1 + {a.robust_models} models")
    print(f"local cluster, 1 worker:  {res['one_worker_s']:7.1f} s  "
          f"(per sample on the worker: {res['wall_per_sample_1_s']:.2f} s wall)")
    print(f"local cluster, 2 workers: {res['two_workers_s']:7.1f} s  "
          f"(per sample on a worker:  {res['wall_per_sample_2_s']:.2f} s wall)")
    print(f"speed-up 2 vs 1 worker:   {res['speedup']:7.2f} x   (CPU per sample {res['cpu_per_sample_s']:.2f} s)")
