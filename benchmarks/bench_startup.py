"""Benchmark: how fast ilcdob starts -- ``import ilcdob``, ``ilcdob --version`` and ``--help``.

Each command runs as a fresh interpreter ``--repeat`` times. The figure is the child's CPU
time (user + system, from ``os.wait4``), as the median over the repeats. Reported next to a
bare interpreter (``python -c pass``) measured in the same process, with each command's excess
over it. Also reported for contrast: the import of the whole library, which the commands load
only when they run. Targets: ``--help`` and ``--version`` under 0.5 s of CPU, ``import ilcdob``
under 1 s, ``identify`` to its first numerical step under 1 s (it writes its CSV in the child as well; the
numerical libraries it needs are timed beside it).

Run:  python benchmarks/bench_startup.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys

#: ``identify`` on a 6000-sample CSV up to its first numerical step: the fit is replaced by an exit that prints
#: nothing, so the child's CPU is the parser, the imports and the reading of the log.
_IDENTIFY_CHILD = r"""
import os, sys, tempfile
import numpy as np
import importlib
path = os.path.join(tempfile.mkdtemp(), "log.csv")
t = np.arange(6000) * 0.01
np.savetxt(path, np.column_stack([t, np.sin(t), np.cos(t)]), delimiter=",", header="time,u,y", comments="")
importlib.import_module("ilcdob.identification.tfest").tfest = lambda *a, **k: os._exit(0)
from ilcdob.app.cli import main
main(["--quiet", "identify", path, "--input", "u", "--output", "y", "--poles", "2", "--out", path + ".json"])
"""

CASES = {
    "python -c pass (baseline)": ["-c", "pass"],
    "import ilcdob": ["-c", "import ilcdob"],
    "ilcdob --version": ["-m", "ilcdob", "--version"],
    "ilcdob --help": ["-m", "ilcdob", "--help"],
    "ilcdob design --help": ["-m", "ilcdob", "design", "--help"],
    "import ilcdob.app.commands (every command's imports)": ["-c", "import ilcdob.app.commands"],
    "identify to its first numerical step (6000-sample CSV)": ["-c", _IDENTIFY_CHILD],
    "import numpy, scipy.signal, pandas (what identify needs)": ["-c", "import numpy, scipy.signal, pandas"],
}


def _cpu(args: list[str]) -> float:
    proc = subprocess.Popen([sys.executable, *args], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{args} failed with status {status}")
    return usage.ru_utime + usage.ru_stime


def run(repeat: int = 5) -> dict[str, float]:
    """Median CPU seconds of each case of :data:`CASES`."""
    return {name: statistics.median(_cpu(args) for _ in range(repeat)) for name, args in CASES.items()}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    figures = run(parser.parse_args().repeat)
    base = figures["python -c pass (baseline)"]
    for name, cpu in figures.items():
        print(f"{name:55s} {cpu:6.3f} s CPU  ({cpu - base:+.3f} s over the bare interpreter, "
              f"{cpu / base:5.1f}x)")
