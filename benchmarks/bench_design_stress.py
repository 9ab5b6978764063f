"""Benchmark: closed-form design of every ordered pair of a stress fleet (target: under 10 s per pair).

The stress fleet has what users fly and the built-in fleet does not: a relative-degree-2
plant (its ZOH sampling zero near -1), a fractional input delay (0.0437 s), a
non-minimum-phase continuous zero, at sample times from 1 ms to 50 ms and DOB filters of
order 3 to 8. For each pair it reports the design time of ``design_pair`` (closed form, the
filters and their exported coefficients), the filters' size (sections, look-ahead taps and
advance) and
whether a plant zero was inverted with the zero-phase substitute. Baseline in the same
process: the built-in fleet's pair UAV1 -> UAV2 at 20 ms; the ratio column is the pair's time
over the baseline's.

Run:  python benchmarks/bench_design_stress.py [--ts 0.001 0.005 0.02 0.05] [--q 3 6 8]
"""

from __future__ import annotations

import argparse
import itertools
import time

import ilcdob
from ilcdob.design.pair import design_pair
from ilcdob.fleet import fleet_from_dict

SYSTEMS = [
    {"name": "R2", "plant": {"num": [0.8, 8.0], "den": [1, 4, 0, 0]},
     "controller": {"kp": 1.0, "ki": 0.1, "kd": 1.0, "derivative_filter": 0.05},
     "dob": {"q_time_constant": 0.15}},
    {"name": "DELAY", "plant": {"num": [10.37568301], "den": [1, 10.32326473, 0, 0]}, "delay": 0.0437,
     "controller": {"kp": 1.2, "ki": 0.12, "kd": 1.53, "derivative_filter": 0.05},
     "dob": {"q_time_constant": 0.2}},
    {"name": "NMP", "plant": {"num": [-1.0, 10.0], "den": [1, 8, 0, 0]},
     "controller": {"kp": 1.0, "ki": 0.1, "kd": 1.2, "derivative_filter": 0.05},
     "dob": {"q_time_constant": 0.2}},
]


def stress_fleet(ts: float, q_order: int) -> ilcdob.Fleet:
    """The stress fleet at sample time ``ts`` (s) with every DOB filter of order ``q_order``."""
    systems = [{**s, "dob": {**s["dob"], "q_order": q_order}} for s in SYSTEMS]
    return fleet_from_dict({"sample_time": ts, "system": systems}, source=f"stress fleet, Ts = {ts} s, q = {q_order}")


def _timed(fleet: ilcdob.Fleet, src: str, tgt: str) -> tuple[float, dict]:
    t0 = time.perf_counter()
    filters = design_pair(fleet, src, tgt).filters
    return time.perf_counter() - t0, filters


def run(sample_times: list[float], q_orders: list[int]) -> list[dict]:
    base, _ = _timed(ilcdob.default_fleet(), "UAV1", "UAV2")
    print(f"baseline: built-in fleet UAV1 -> UAV2 at 20 ms: {base:.3f} s")
    print(f"{'Ts (s)':>7} {'q':>2} {'pair':<14} {'time (s)':>9} {'x base':>7} {'L1 sos':>6} {'L1 taps':>7} "
          f"{'L1 adv':>6} {'L2 sos':>6} substitute")
    rows = []
    for ts, q in itertools.product(sample_times, q_orders):
        try:
            fleet = stress_fleet(ts, q)
        except ilcdob.IlcdobError as exc:
            print(f"{ts:7.3f} {q:2d} fleet not built: {str(exc)[:100]}")
            continue
        for src, tgt in itertools.permutations(fleet.names, 2):
            try:
                dt, f = _timed(fleet, src, tgt)
            except ilcdob.IlcdobError as exc:
                print(f"{ts:7.3f} {q:2d} {src + '->' + tgt:<14} failed: {str(exc)[:90]}")
                continue
            sub = f["L1"].get("inversion", {}).get("poles", [])
            row = {"ts": ts, "q": q, "pair": f"{src}->{tgt}", "time_s": dt, "ratio": dt / base,
                   "l1_sections": len(f["L1"]["sos"]), "l1_taps": len(f["L1"].get("lookahead", [1.0])),
                   "l1_advance": f["L1"]["advance"],
                   "l2_sections": len(f["L2"]["sos"]), "substituted": sub}
            rows.append(row)
            print(f"{ts:7.3f} {q:2d} {row['pair']:<14} {dt:9.3f} {dt / base:7.1f} {row['l1_sections']:6d} "
                  f"{row['l1_taps']:7d} {row['l1_advance']:6d} {row['l2_sections']:6d} {', '.join(f'{p[0]:.4g}' for p in sub) or '-'}")
    if rows:
        print(f"slowest pair: {max(r['time_s'] for r in rows):.3f} s")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ts", type=float, nargs="+", default=[0.001, 0.005, 0.02, 0.05])
    parser.add_argument("--q", type=int, nargs="+", default=[3, 6, 8])
    args = parser.parse_args()
    run(args.ts, args.q)


if __name__ == "__main__":
    main()
