"""Benchmark: one Monte Carlo campaign on local Dask clusters of 1 and 2 worker processes.

The campaign is ``ilcdob campaign``'s default designs over every scenario (robust SOCP with
1 + 1 models), with few samples and a short flight by default. For each worker count a local
cluster (``LocalCluster``, processes, one thread each) is started, its workers import the
campaign (the fixed per-worker start cost: process spawn and imports, timed until every worker
has imported ilcdob's campaign), then the campaign flies on it through its scheduler address.

Two settings are interleaved (A B A B ...), rounds apart:

* ``limited``: today's campaign, whose worker plugin limits BLAS and Clarabel's KKT solver to
  one thread per worker process;
* ``baseline``: the same with a plugin that limits nothing, as before the plugin existed
  (Dask's nanny still sets OMP/MKL/OPENBLAS_NUM_THREADS=1 in its workers, so what differs is
  Clarabel's multithreaded KKT solver).

Reported per setting and worker count (medians over the rounds): samples/s on the wall clock
(cluster start excluded), the 2-vs-1 worker ratio, the worker processes' CPU seconds per sample
(``time.process_time`` of every worker process, all its threads), the CPU ratio limited /
baseline, and the fixed start cost. The load (``uptime``) is printed: the cores are shared.

Run:  python benchmarks/bench_campaign.py [--samples 8] [--duration 60] [--rounds 3]
"""

from __future__ import annotations

import argparse
import logging
import statistics
import subprocess
import tempfile
import time
from contextlib import contextmanager, nullcontext
from typing import Any, Iterator

import ilcdob
from ilcdob.validation.campaign import CampaignOptions, run_campaign
from ilcdob.validation.campaign import cluster as campaign_cluster


def _import_campaign() -> float:
    import ilcdob.validation.campaign  # noqa: F401 - what a worker imports for its first sample

    return time.process_time()


def _worker_cpu() -> float:
    return time.process_time()


@contextmanager
def _no_limits() -> Iterator[None]:
    """The baseline: the campaign registers a worker plugin that limits nothing."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class NoLimits(WorkerPlugin):
        name = "ilcdob-campaign-thread-limits"
        idempotent = True

    original = campaign_cluster._thread_limits_class
    campaign_cluster._thread_limits_class = lambda: NoLimits
    try:
        yield
    finally:
        campaign_cluster._thread_limits_class = original


def _one(options: CampaignOptions, workers: int, limited: bool) -> dict[str, float]:
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.CRITICAL) as cluster, Client(cluster) as client:
        client.run(_import_campaign)
        start = time.perf_counter() - t0
        cpu0 = client.run(_worker_cpu)
        with tempfile.TemporaryDirectory() as out, (_no_limits() if not limited else nullcontext()):
            t1 = time.perf_counter()
            res = run_campaign(ilcdob.default_fleet(), options, out, scheduler=cluster.scheduler_address)
            wall = time.perf_counter() - t1
        cpu1 = client.run(_worker_cpu)
    cpu = sum(cpu1[w] - cpu0[w] for w in cpu1)
    return {"start_s": start, "samples_per_s": options.samples / wall, "cpu_per_sample_s": cpu / options.samples,
            "methods": res.methods}


def run(samples: int = 8, duration: float | None = 60.0, rounds: int = 3) -> dict[str, Any]:
    """Medians over ``rounds`` interleaved runs of each (setting, worker count)."""
    opts = CampaignOptions(samples=samples, duration=duration)
    runs: dict[tuple[str, int], list[dict[str, float]]] = {}
    for _ in range(rounds):
        for workers in (1, 2):
            for setting in ("baseline", "limited"):
                runs.setdefault((setting, workers), []).append(_one(opts, workers, setting == "limited"))
    ref = runs[("limited", 1)][0]["methods"]
    if any(r["methods"] != ref for rs in runs.values() for r in rs):
        raise RuntimeError("the campaign's statistics differ between settings or worker counts")
    med = {k: {q: statistics.median(r[q] for r in rs) for q in ("start_s", "samples_per_s", "cpu_per_sample_s")}
           for k, rs in runs.items()}
    return {"median": med,
            "scaling": {s: med[(s, 2)]["samples_per_s"] / med[(s, 1)]["samples_per_s"]
                        for s in ("baseline", "limited")},
            "cpu_ratio": {w: med[("limited", w)]["cpu_per_sample_s"] / med[("baseline", w)]["cpu_per_sample_s"]
                          for w in (1, 2)}}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--duration", type=float, default=60.0, help="seconds of each scenario (0: all)")
    parser.add_argument("--rounds", type=int, default=3)
    a = parser.parse_args()
    print("load:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    res = run(a.samples, a.duration or None, a.rounds)
    print(f"campaign: {a.samples} samples x 4 scenarios x 4 designs, {a.duration or 'full'} s flights, "
          f"medians of {a.rounds} interleaved rounds")
    print(f"{'setting':<10}{'workers':>8}{'start s':>9}{'samples/s':>11}{'worker CPU s/sample':>21}")
    for (setting, workers), m in sorted(res["median"].items()):
        print(f"{setting:<10}{workers:>8}{m['start_s']:>9.1f}{m['samples_per_s']:>11.3f}{m['cpu_per_sample_s']:>21.2f}")
    for s, r in res["scaling"].items():
        print(f"{s}: samples/s with 2 workers / with 1 worker = {r:.2f}")
    for w, r in res["cpu_ratio"].items():
        print(f"{w} worker(s): worker CPU per sample, limited / baseline = {r:.2f}")
    print("load:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
