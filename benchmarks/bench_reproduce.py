"""Benchmark: the full ``ilcdob reproduce`` run on the built-in fleet, with and without figures.

Three parts, each measured in this process and printed as a table with its ratios:

1. **The command** (``python -m ilcdob --quiet reproduce --out DIR``, 4 scenarios, 3 iterations),
   with figures and with ``--no-figures``, each a fresh interpreter, the runs interleaved
   (with, without, with, ...), ``--repeat`` of each. Figures: wall time (``time.perf_counter``
   around the run, on this machine's cores) and CPU time (user + system of the command and
   of the worker processes it waited for, from ``os.wait4``), medians. The ratio with / without
   figures is the figure's cost. With ``--baseline DIR`` (a source tree of the project, e.g.
   the last commit's files), the same two commands of that tree are interleaved with them and
   the ratios new / baseline are printed too.
2. **The Theorem check of the report** (``theorem.json``, both learning orders of the
   reproduction), in this process: the check on Delta sets of 8 sampled plants, as the report
   built it before (:func:`_sampled_check`, kept here as the reference), against the check on
   the sets' bounds (:func:`ilcdob.app.html._theorem_data`); CPU time (``time.thread_time``),
   medians of interleaved runs, and the check that both give the same ``theorem.json``.
3. **Rendering the figures** in this process, one process: ``savefig`` of each built figure
   (the writer's path before) against :func:`ilcdob.validation.figures.figure_png`; CPU time,
   medians of interleaved runs, and the check that the images are equal (decoded pixels: the PNG files
   differ in their zlib level, :data:`ilcdob.validation.figures.PNG_COMPRESS_LEVEL`).

``--trial`` adds the benchmark's older figure: the run against one block-diagram trial of
60 s (3000 samples), i.e. how many trials' worth of time the whole run costs (it flies 4
scenarios x 3 systems x (no DOB + DOB + 3 learning) = 60 trials).

The machine's load (``os.getloadavg``) is printed beside the figures: other processes on the
same cores stretch the wall times (and, less, the CPU times).

Run:  python benchmarks/bench_reproduce.py [--repeat 3] [--baseline DIR] [--trial]
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import ilcdob

ROOT = Path(__file__).resolve().parents[1]
#: The sub-packages that the installed package maps from top-level folders of the tree.
SUBPACKAGES = ("design", "identification", "validation")


def _load() -> str:
    return "load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg()) + f" on {os.cpu_count()} cores"


def _shim(tree: Path, where: Path) -> Path:
    """A folder to put on PYTHONPATH that imports ``ilcdob`` from ``tree`` (its sub-packages too)."""
    pkg = where / "ilcdob"
    pkg.mkdir(parents=True)
    for entry in (tree / "ilcdob").iterdir():
        (pkg / entry.name).symlink_to(entry)
    for sub in SUBPACKAGES:
        (pkg / sub).symlink_to(tree / sub)
    return where


def _command(pythonpath: str | None, figures: bool, out: Path) -> tuple[float, float]:
    """(wall s, CPU s) of one ``ilcdob reproduce`` in a fresh interpreter."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    args = [sys.executable, "-m", "ilcdob", "--quiet", "reproduce", "--overwrite", "--out", str(out)]
    if not figures:
        args.append("--no-figures")
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=tempfile.gettempdir())
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: keep Popen from waiting again
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({status}): {err.decode(errors='replace')[-2000:]}")
    return wall, usage.ru_utime + usage.ru_stime


def bench_command(repeat: int, baseline: Path | None) -> dict[str, tuple[float, float]]:
    """Median (wall, CPU) of each variant of part 1, runs interleaved."""
    with tempfile.TemporaryDirectory() as tmp:
        variants = {"new, figures": (None, True), "new, --no-figures": (None, False)}
        if baseline is not None:
            shim = str(_shim(baseline.resolve(), Path(tmp) / "shim"))
            variants.update({"baseline, figures": (shim, True), "baseline, --no-figures": (shim, False)})
        runs: dict[str, list[tuple[float, float]]] = {k: [] for k in variants}
        for _ in range(repeat):
            for k, (path, figures) in variants.items():
                runs[k].append(_command(path, figures, Path(tmp) / "out"))
        return {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in runs.items()}


def _sampled_check(fleet, orders: list[list[str]]) -> dict:
    """The report's Theorem check as built before: Delta sets of 8 sampled plants per order (the reference)."""
    from ilcdob.app.html import THEOREM_SAMPLES, _theorem_pair
    from ilcdob.design.pair import fleet_delta_sets, pair_band
    from ilcdob.design.checks.theorem import format_theorem_table, learning_pairs, theorem_check

    data = {"samples": THEOREM_SAMPLES, "seed": 0, "orders": []}
    for order in orders:
        deltas = fleet_delta_sets(fleet, order, k=THEOREM_SAMPLES, seed=0)
        bands = {(a, b): pair_band(fleet, a, b, deltas=deltas) for a, b in learning_pairs(fleet.names, order)}
        checks = theorem_check(fleet, order, deltas, bands=bands)
        data["orders"].append({"order": order, "table": format_theorem_table(checks),
                               "pairs": [_theorem_pair(c) for c in checks]})
    return data


def _medians(cases: dict, repeat: int) -> dict[str, float]:
    """Median ``time.thread_time`` of each callable of ``cases``, runs interleaved."""
    times: dict[str, list[float]] = {k: [] for k in cases}
    for _ in range(repeat):
        for k, fn in cases.items():
            t0 = time.thread_time()
            fn()
            times[k].append(time.thread_time() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


def bench_theorem(repeat: int) -> tuple[dict[str, float], bool]:
    """Part 2: median CPU of the sampled (before) and bound-only (now) check, and whether they agree."""
    from ilcdob.app.html import _theorem_data
    from ilcdob.app.output import json_text

    orders = [["UAV1", "UAV2", "UAV3"], ["UAV1", "UAV3", "UAV2"]]  # the reproduction's (scenario 4 the second)

    def fresh():  # a new fleet each run: no loop or response cached from the run before
        return ilcdob.default_fleet()

    same = json_text(_sampled_check(fresh(), orders), "a") == json_text(_theorem_data(fresh(), orders)[0], "b")
    cases = {"sampled Delta sets (before)": lambda: _sampled_check(fresh(), orders),
             "bound only (now)": lambda: _theorem_data(fresh(), orders)}
    return _medians(cases, repeat), same


def bench_render(repeat: int) -> tuple[dict[str, float], bool]:
    """Part 3: median CPU of rendering every figure with savefig (before) and figure_png (now)."""
    from ilcdob.validation.figures import FIGURE_DPI, figure_png, reproduction_figures
    from ilcdob.validation.reproduce import reproduce

    res = reproduce(ilcdob.default_fleet(), [1, 2, 3, 4], 3)

    def savefig_all() -> list[bytes]:
        out = []
        for fig in reproduction_figures(res).values():
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=FIGURE_DPI)
            out.append(buf.getvalue())
        return out

    def png_all() -> list[bytes]:
        return [figure_png(fig) for fig in reproduction_figures(res).values()]

    def pixels(png: bytes) -> np.ndarray:
        from PIL import Image

        return np.asarray(Image.open(io.BytesIO(png)))

    same = all(np.array_equal(pixels(a), pixels(b)) for a, b in zip(savefig_all(), png_all()))
    return _medians({"build + savefig (before)": savefig_all, "build + figure_png (now)": png_all}, repeat), same


def bench_trial(repeat: int) -> dict[str, float]:
    """The older figure: the whole run (in this process, figures included) against one 3000-sample trial."""
    from ilcdob.app.cli import main
    from ilcdob.validation.simulate import simulate_flight

    fleet = ilcdob.default_fleet()
    t = np.arange(3000) * fleet.sample_time
    d = np.sin(0.9425 * t)

    def best(fn) -> float:
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return min(times)

    baseline = best(lambda: simulate_flight(fleet.loops[0], np.zeros_like(t), d))

    def full():
        with tempfile.TemporaryDirectory() as out:
            assert main(["--quiet", "reproduce", "--overwrite", "--out", out]) == 0

    total = best(full)
    return {"reproduce_s": total, "one_trial_s": baseline, "ratio": total / baseline}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--baseline", type=Path, default=None,
                        help="a source tree of the project to compare with (folders ilcdob, design, identification, "
                             "validation)")
    parser.add_argument("--trial", action="store_true", help="also the run against one 3000-sample trial")
    args = parser.parse_args(argv)
    if args.baseline is not None and not (args.baseline / "ilcdob" / "__init__.py").is_file():
        parser.error(f"--baseline: {args.baseline} holds no ilcdob/__init__.py; expected a source tree of the project")

    print(f"1. ilcdob reproduce (4 scenarios, 3 iterations), median of {args.repeat} interleaved runs; {_load()}")
    res = bench_command(args.repeat, args.baseline)
    print(f"   {'variant':<26} {'wall s':>8} {'CPU s':>8}")
    for k, (wall, cpu) in res.items():
        print(f"   {k:<26} {wall:8.2f} {cpu:8.2f}")
    cost = {}
    for who in ("new", "baseline"):
        if f"{who}, figures" in res:
            (wf, cf), (wn, cn) = res[f"{who}, figures"], res[f"{who}, --no-figures"]
            cost[who] = (wf - wn, cf - cn)
            print(f"   {who}: with / without figures  wall {wf / wn:.2f}x  CPU {cf / cn:.2f}x; the figures add "
                  f"{wf - wn:.2f} s wall, {cf - cn:.2f} s CPU")
    if args.baseline is not None:
        for kind in ("figures", "--no-figures"):
            (wn, cn), (wb, cb) = res[f"new, {kind}"], res[f"baseline, {kind}"]
            print(f"   {kind}: new / baseline  wall {wn / wb:.2f}x  CPU {cn / cb:.2f}x")
        print(f"   what the figures add: new / baseline  wall {cost['new'][0] / cost['baseline'][0]:.2f}x  "
              f"CPU {cost['new'][1] / cost['baseline'][1]:.2f}x")
    print(f"   ({_load()})")

    for title, bench, same_what in (("2. The report's Theorem check (two orders)", bench_theorem, "theorem.json"),
                                    ("3. Building and rendering the 13 figures in one process", bench_render,
                                     "image (pixels)")):
        print(f"\n{title}, CPU s, median of {args.repeat} interleaved runs")
        times, same = bench(args.repeat)
        for k, v in times.items():
            print(f"   {k:<32} {v:7.3f}")
        before, now = times.values()
        print(f"   ratio now / before: {now / before:.3f}; the same {same_what}: {same}")
    print(f"   ({_load()})")

    if args.trial:
        res = bench_trial(args.repeat)
        print(f"\nilcdob reproduce in this process (figures): {res['reproduce_s']:.2f} s; one 3000-sample "
              f"block-diagram trial {res['one_trial_s'] * 1e3:.1f} ms; ratio {res['ratio']:.0f} trials' worth")


if __name__ == "__main__":
    main()
