"""Benchmark: the slowest setups of the default test run, as they were and as they are now.

Each row runs the work of one fixture or test both ways in this process, interleaved (old, new,
old, new, ...), ``--repeat`` times each, and prints the medians of the wall time
(``time.perf_counter``) and of the CPU time (this process's ``time.process_time`` plus the user and
system time of the worker processes it waited for, ``resource.getrusage(RUSAGE_CHILDREN)``), with
the ratios old / new, and checks that both ways give the same results:

* ``short``: the rotorpy reproduction of tests/test_vehicle_reproduction.py (crazyflie and PX4,
  hover and diamond, 10 s, one iteration, the paper's disturbance and Dryden wind) with one
  process (old) and two (new, ``VehicleSettings.workers``, what the fixture does where two cores
  are usable); same: every flight's error signal and RMSE equal, and the fits.
* ``identify``: the crazyflie and hummingbird identification that test_vehicle_chain and
  test_vehicle_interface each flew (old: twice) and now share (new: once, tests/conftest.py);
  same: equal fleets.
* ``wind``: the DOB-only wind flights of
  ``test_wind_through_the_drag_is_learned_through_the_drag_ratio``: four (old: each direction flew
  its source and its target) against two (new: each vehicle's flight once); same: the repeated
  flights are equal.

``short`` can only gain wall time where a second core is idle (the serial test run uses one); its
CPU time does not shrink. The machine's load (``os.getloadavg``) is printed beside
the figures: other processes stretch the wall times, and take the second core.

Run:  python benchmarks/bench_test_fixtures.py [--repeat 2] [--only short,identify,wind]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

ROWS = ("short", "identify", "wind")


def _load() -> str:
    return "load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg()) + f" on {os.cpu_count()} cores"


def _cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ru.ru_utime + ru.ru_stime


def _timed(fn):
    w, c = time.perf_counter(), _cpu()
    out = fn()
    return out, time.perf_counter() - w, _cpu() - c


# --------------------------------------------------------------------------- rotorpy


def _short(workers: int):
    from ilcdob.validation.scenarios import scenario
    from ilcdob.validation.vehicle_reproduction import VehicleSettings, reproduce_vehicles

    settings = VehicleSettings(vehicles=("crazyflie", "px4"), disturbances=("dryden",), workers=workers)
    return reproduce_vehicles(iterations=1, settings=settings,
                              scenarios=[replace(scenario(i), duration=10.0) for i in (1, 4)])


def _same_short(a, b) -> str:
    count = 0
    for dist, laws in a.runs.items():
        for lab, srs in laws.items():
            for sa, sb in zip(srs, b.runs[dist][lab], strict=True):
                for name in sa.order:
                    x, y = sa.systems[name], sb.systems[name]
                    for fa, fb in [(x.no_dob, y.no_dob), (x.dob, y.dob), *zip(x.learning, y.learning, strict=True)]:
                        assert fa.rmse == fb.rmse and np.array_equal(fa.e, fb.e), (dist, lab, name)
                        count += 1
    assert {n: f.fit for n, f in a.fits.items()} == {n: f.fit for n, f in b.fits.items()}
    return f"{count} flights: equal errors"


def _identify():
    import ilcdob
    from conftest import ROTORPY_NAMES, ROTORPY_TS, make_rotorpy
    from ilcdob.validation.vehicle_chain import identify_vehicles

    names = list(ROTORPY_NAMES)
    return identify_vehicles(make_rotorpy, names, {n: ilcdob.PIDSpec(2.5, 0.3, 2.2, 0.05) for n in names},
                             {n: ilcdob.DOBSpec(3, 0.2) for n in names}, ROTORPY_TS)


_FLEET = {}


def _wind_flights(pairs: list[tuple[str, str]]) -> list:
    """The DOB-only flights in the test's wind, one per vehicle named (in order)."""
    from ilcdob.vehicles.interface import fly_vehicle
    from ilcdob.vehicles.rotorpy_vehicle import RotorpyVehicle

    if "fleet" not in _FLEET:
        _FLEET["fleet"] = _identify()[0]
    fleet = _FLEET["fleet"]
    n = 2000
    wind = lambda t: np.array([2.0 * np.sin(0.9425 * t), 0.0, 0.0])  # noqa: E731
    out = []
    for name in pairs:
        loop = fleet.loop(name)
        out.append(fly_vehicle(RotorpyVehicle(name, 0.01, noise_std=5e-4, seed=3, wind=wind),
                               {"x": loop, "y": loop, "z": loop}, np.zeros((n, 3))))
    return out


# --------------------------------------------------------------------------- main


def _row(name: str, old, new, same, repeat: int) -> None:
    t = {"old": [], "new": []}
    outs = {}
    for _ in range(repeat):
        for key, fn in (("old", old), ("new", new)):
            out, wall, cpu = _timed(fn)
            t[key].append((wall, cpu))
            outs[key] = out
    check = same(outs["old"], outs["new"])
    med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in t.items()}
    print(f"{name:<9} old wall {med['old'][0]:7.1f} s  cpu {med['old'][1]:7.1f} s | new wall {med['new'][0]:7.1f} s  "
          f"cpu {med['new'][1]:7.1f} s | old/new wall {med['old'][0] / med['new'][0]:.2f}  "
          f"cpu {med['old'][1] / med['new'][1]:.2f} | {check} | {_load()}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--only", default=",".join(ROWS))
    a = ap.parse_args()
    only = a.only.split(",")
    print(_load(), flush=True)
    if "short" in only:
        _row("short", lambda: _short(1), lambda: _short(2), _same_short, a.repeat)
    if "identify" in only:
        def same_fleet(x, y):
            assert x[0].systems == y[0].systems
            return "equal fleets"
        _row("identify", lambda: (_identify(), _identify())[0], _identify, same_fleet, a.repeat)
    if "wind" in only:
        names = ["crazyflie", "hummingbird"]
        _FLEET["fleet"] = _identify()[0]  # the fleet both ways fly, identified before the timing

        def same_flights(x, y):
            for i, name in enumerate(names):  # old flew [src, tgt, src', tgt'] = [c, h, h, c]
                again = x[{0: 3, 1: 2}[i]]
                assert np.array_equal(x[i].e_meas, again.e_meas) and np.array_equal(x[i].e_meas, y[i].e_meas), name
            return "repeated flights equal"
        _row("wind", lambda: _wind_flights(["crazyflie", "hummingbird", "hummingbird", "crazyflie"]),
             lambda: _wind_flights(names), same_flights, a.repeat)


if __name__ == "__main__":
    main()
