"""Monte Carlo campaigns: every design, every scenario, many sampled true plants, on Dask.

A campaign of ``N`` samples answers "how often, and by how much, does each learning design
help when the vehicles are not what their models say?". Sample ``i`` draws one true plant per
vehicle of the fleet from its identified uncertainty (:func:`ilcdob.design.delta_set`:
parameters from the fit's Gaussian ``N(theta, scale^2 Cov)``; ``scale`` > 1 goes beyond the
identified uncertainty; or a multiplicative ``bound`` for fleets without identification),
from a generator seeded by ``(seed, i)`` only, so a sample is the same whichever worker flies
it and whenever. For every scenario the first pair of its learning order (j-1 -> j) is
flown as in :func:`ilcdob.validation.compare.evaluate_case`: system j-1 flies its DOB-only
trial under its true plant, every design turns the trial into system j's learning signal,
and system j flies with and without it under its true plant. The figure of merit is the
paper's improvement ratio ``||e_j|| / ||e'_j||`` (Theorem: < 1 means learning helped).

The designs only know the models: closed-form and norm-optimal are built from the nominal
models, FIR from the nominal models and 8 samples of the identified uncertainty (its robust
``|Te1|`` constraint), robust from the nominal pair plus ``robust_models`` paired samples
(its SOCP is solved per trial), robust-set from the nominal models and the Delta set's bound
(:mod:`ilcdob.design.robust_set`; its rho is ``rho`` capped at 1). These design samples are
drawn once from ``(seed, design)`` at scale 1 (the identified uncertainty, which is what a
designer knows) and are never the true plants of a sample. Every design is built once per
worker and pair and reused for all its samples and scenarios; only the robust SOCP is
re-solved per trial.

Results are written incrementally: one JSON line per finished sample, appended, flushed and
fsynced to ``DIR/samples.jsonl`` by the one client process (a lock on that file keeps a
second campaign out of ``DIR``). A campaign killed at any point is resumed by running the same
command again: finished samples are read back (a line torn by the kill is dropped), only the
missing ones are flown, and since each sample depends on ``(seed, i)`` alone the statistics
are those of an uninterrupted run. ``DIR/campaign_settings.json`` records the settings; a
run with different settings (other than a larger ``samples``, which extends the campaign)
is refused. The settings do not cover the code: resume with the ilcdob that started the campaign
(a changed design gives other ratios for the samples still to fly). At the end ``DIR/campaign.json`` (statistics per method and per scenario x
method: median, 95th percentile, worst ratio and share of runs that improved),
``DIR/campaign.txt`` and ``DIR/campaign_ratios.png`` are written.

Dask: a local cluster (``distributed.LocalCluster``, one single-threaded worker process per
core) unless a scheduler address ``tcp://HOST:PORT`` of a running cluster is given; its
workers need ilcdob installed.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import math
import os
import re
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from ilcdob.design.delta import DeltaSet, delta_set
from ilcdob.design.laws import DEFAULT_LAW, check_law
from ilcdob.design.pair import DEFAULT_METHODS, METHODS, PairDesign, design_pair, with_law
from ilcdob.design.robust import RobustOptions
from ilcdob.errors import IlcdobError
from ilcdob.fleet import Fleet
from ilcdob.loop import LoopSystem

from .compare import PairScenario, evaluate_case, pair_scenario
from .scenarios import SCENARIOS

__all__ = ["CampaignError", "CampaignOptions", "CampaignResult", "MethodStatistics", "SampleStore",
           "campaign_settings", "draw_true_loops", "run_sample", "campaign_statistics", "run_campaign",
           "write_campaign", "SAMPLES_FILE", "SETTINGS_FILE"]

SAMPLES_FILE = "samples.jsonl"
SETTINGS_FILE = "campaign_settings.json"
FORMAT_VERSION = 1
FIR_DESIGN_SAMPLES = 8  # Delta samples of the FIR design's robust |Te1| constraint (its default K)
_SCHEDULER_RE = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})$")


class CampaignError(IlcdobError, ValueError):
    """A campaign cannot run: bad settings, an output folder holding another campaign, no cluster."""


@dataclass(frozen=True)
class CampaignOptions:
    """Settings of a Monte Carlo campaign (see module docstring).

    Attributes
    ----------
    samples : int
        Number of samples N (each: one true plant per vehicle), >= 1.
    seed : int
        Campaign seed, >= 0; sample ``i`` uses the generator of ``SeedSequence(seed, spawn_key=(0, i))``.
    scale : float
        Scale of the identified standard deviations for the true plants (> 0; 1: the
        identified uncertainty, > 1 beyond it).
    bound : float, optional
        Multiplicative uncertainty bound in (0, 1) instead of the identification (for true
        plants and design samples alike).
    scenarios : tuple of int
        Scenario ids, each 1-4.
    methods : tuple of str
        Designs, a subset of :data:`ilcdob.design.pair.METHODS` (default
        :data:`~ilcdob.design.pair.DEFAULT_METHODS`).
    duration : float, optional
        Fly only the first ``duration`` seconds of each scenario (s, > 0; default: all).
    robust_models : int
        Delta samples per system in the robust SOCP besides the nominal pair (>= 0); its cost
        per trial grows about linearly with ``1 + robust_models``.
    rho : float
        Robust design's guaranteed improvement factor on its models (> 0).
    law : {"paper", "exact-reference"}
        Learning law applied around every design (:mod:`ilcdob.design.laws`); ``multi-source``
        is refused (one pair from one DOB-only trial per scenario, where it is the paper's law).
        The default is left out of the settings hash, so campaigns started before the law
        existed resume.
    """

    samples: int = 200
    seed: int = 0
    scale: float = 1.0
    bound: float | None = None
    scenarios: tuple[int, ...] = (1, 2, 3, 4)
    methods: tuple[str, ...] = DEFAULT_METHODS
    duration: float | None = None
    robust_models: int = 1
    rho: float = 0.95
    law: str = DEFAULT_LAW

    def __post_init__(self) -> None:
        def integer(v: object) -> bool:
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        if not integer(self.samples) or self.samples < 1:
            raise CampaignError(f"`samples`: got {self.samples!r}, expected an integer >= 1")
        if not integer(self.seed) or self.seed < 0:
            raise CampaignError(f"`seed`: got {self.seed!r}, expected an integer >= 0")
        if not (isinstance(self.scale, (int, float)) and np.isfinite(self.scale) and self.scale > 0):
            raise CampaignError(f"`scale`: got {self.scale!r}, expected a factor > 0 (1: identified uncertainty)")
        if self.bound is not None and not (np.isfinite(self.bound) and 0 < self.bound < 1):
            raise CampaignError(f"`bound`: got {self.bound!r}, expected a relative error in (0, 1)")
        scenarios = tuple(self.scenarios)
        if not scenarios or any(not integer(s) or s not in SCENARIOS for s in scenarios):
            raise CampaignError(f"`scenarios`: got {list(scenarios)!r}, expected a non-empty list from "
                                f"{sorted(SCENARIOS)}")
        methods = tuple(self.methods)
        bad = [m for m in methods if m not in METHODS]
        if bad or not methods:
            raise CampaignError(f"`methods`: got {list(methods)!r} (unknown: {bad}), expected a non-empty list "
                                f"from {list(METHODS)}")
        if self.duration is not None and not (np.isfinite(self.duration) and self.duration > 0):
            raise CampaignError(f"`duration`: got {self.duration!r}, expected a duration > 0 s")
        if not integer(self.robust_models) or self.robust_models < 0:
            raise CampaignError(f"`robust_models`: got {self.robust_models!r}, expected an integer >= 0 "
                                "(Delta samples besides the nominal pair)")
        if not (np.isfinite(self.rho) and self.rho > 0):
            raise CampaignError(f"`rho`: got {self.rho!r}, expected an improvement factor > 0 (e.g. 0.95)")
        try:
            law = check_law(self.law)
        except IlcdobError as exc:
            raise CampaignError(str(exc)) from None
        if law == "multi-source":
            raise CampaignError("`law`: 'multi-source' learns from every earlier system's trial, but a campaign flies "
                                "one pair (j-1 -> j) per scenario from a single DOB-only trial of j-1, where it is the "
                                "paper's law; use 'paper' or 'exact-reference'")
        object.__setattr__(self, "scenarios", tuple(int(s) for s in dict.fromkeys(scenarios)))
        object.__setattr__(self, "methods", tuple(dict.fromkeys(methods)))
        object.__setattr__(self, "samples", int(self.samples))
        object.__setattr__(self, "seed", int(self.seed))
        object.__setattr__(self, "robust_models", int(self.robust_models))
        object.__setattr__(self, "scale", float(self.scale))


def _fleet_fingerprint(fleet: Fleet) -> str:
    """SHA-256 of the fleet's specifications (sample time, every system's parameters)."""
    return hashlib.sha256(repr((fleet.sample_time, fleet.systems)).encode()).hexdigest()


def campaign_settings(fleet: Fleet, options: CampaignOptions) -> dict[str, Any]:
    """The settings that determine every sample's result (all options but ``samples``).

    Two runs with equal settings produce the same record for sample ``i``; ``id`` is their hash.
    """
    opts = asdict(options)
    opts.pop("samples")
    if opts.get("law") == DEFAULT_LAW:  # the default law keeps the ids of campaigns started before laws existed
        opts.pop("law")
    opts["scenarios"], opts["methods"] = list(options.scenarios), list(options.methods)
    sources = {s.name: ("identification" if s.uncertainty is None and s.identification is not None
                        else f"bound {s.uncertainty.bound:g}" if s.uncertainty is not None else "none")
               for s in fleet.systems}
    body = {"format": FORMAT_VERSION, "fleet": {"source": fleet.source, "sha256": _fleet_fingerprint(fleet),
                                                  "systems": fleet.names, "uncertainty": sources}, **opts}
    ident = dict(body)
    ident["fleet"] = body["fleet"]["sha256"]  # the file's location does not change the results
    body["id"] = hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:16]
    return body


def _rng(seed: int, *key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def draw_true_loops(fleet: Fleet, options: CampaignOptions, index: int) -> tuple[dict[str, LoopSystem], int]:
    """Sample ``index``'s true loops, one per vehicle in fleet order, and the redraws of unstable loops.

    Depends on ``(options.seed, index)``, ``scale`` and ``bound`` only.
    """
    rng = _rng(options.seed, 0, index)
    loops, rejected = {}, 0
    for spec in fleet.systems:
        ds = delta_set(spec, fleet.sample_time, 1, rng, scale=options.scale, bound=options.bound,
                       w=np.array([1.0]))
        loops[spec.name], rejected = ds.loops[0], rejected + ds.rejected
    return loops, rejected


def _design_deltas(fleet: Fleet, options: CampaignOptions) -> dict[str, DeltaSet]:
    """The designers' Delta samples: identified uncertainty (scale 1) or the bound, seeded ``(seed, 1)``."""
    k = max(FIR_DESIGN_SAMPLES, options.robust_models, 1)
    rng = _rng(options.seed, 1)
    return {s.name: delta_set(s, fleet.sample_time, k, rng, bound=options.bound) for s in fleet.systems}


class _WorkerState:
    """Per worker thread: the fleet's scenarios and designs of one campaign, built on first use."""

    def __init__(self, fleet: Fleet, options: CampaignOptions):
        self.fleet, self.options = fleet, options
        self.pairs: dict[int, PairScenario] = {}
        self.designs: dict[tuple[str, str, str], PairDesign | str] = {}
        self._deltas: dict[str, DeltaSet] | None = None
        self.lawful: dict[tuple[int, str], PairDesign] = {}

    def pair(self, sid: int) -> PairScenario:
        if sid not in self.pairs:
            self.pairs[sid] = pair_scenario(self.fleet, sid, self.options.duration)
        return self.pairs[sid]

    def design(self, source: str, target: str, method: str, n: int) -> PairDesign | str:
        """The design (built once), or the error message of a design that cannot be made."""
        key = (source, target, method)
        if key not in self.designs:
            if self._deltas is None:
                self._deltas = _design_deltas(self.fleet, self.options)
            k = self.options.robust_models if method == "robust" else FIR_DESIGN_SAMPLES
            deltas = {name: replace(self._deltas[name], loops=self._deltas[name].loops[:k])
                      for name in (source, target)}
            try:
                self.designs[key] = design_pair(self.fleet, source, target, method, n=n, deltas=deltas,
                                                robust=RobustOptions(rho=self.options.rho), lifted=False)
            except IlcdobError as exc:  # e.g. FIR constraint not met: every run of it is recorded as failed
                self.designs[key] = f"design failed: {exc}"
        return self.designs[key]

    def with_law(self, sid: int, method: str, design: PairDesign) -> PairDesign:
        """``design`` learning with the campaign's law on scenario ``sid`` (its reference terms, built once)."""
        if self.options.law == DEFAULT_LAW:
            return design
        if (sid, method) not in self.lawful:
            pair = self.pair(sid)
            self.lawful[(sid, method)] = with_law(design, self.fleet, pair.source, pair.target, self.options.law,
                                                   pair.r, pair.a_ref)
        return self.lawful[(sid, method)]


_local = threading.local()


def _worker_state(fleet: Fleet, options: CampaignOptions, settings_id: str) -> _WorkerState:
    cache = getattr(_local, "state", None)
    if cache is None or cache[0] != settings_id:  # keep one campaign per thread (long-lived workers)
        _local.state = cache = (settings_id, _WorkerState(fleet, options))
    return cache[1]


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def run_sample(fleet: Fleet, options: CampaignOptions, settings_id: str, index: int) -> dict[str, Any]:
    """Fly sample ``index`` through every scenario with every design (the Dask task).

    Returns
    -------
    dict
        The JSON record of the sample: ``{"sample", "settings", "rejected", "plants": {name:
        {"num", "den", "delay"}}, "scenarios": {id: {"source", "target", "rmse_without",
        "ratios": {method: ratio or null}, "errors": {method: message}}}, "time_s", "cpu_s"}``
        (wall-clock and CPU time of the worker, s; they differ when the cores are shared).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    state = _worker_state(fleet, options, settings_id)
    loops, rejected = draw_true_loops(fleet, options, index)
    scenarios = {}
    for sid in options.scenarios:
        pair = state.pair(sid)
        designs, errors = {}, {}
        for method in options.methods:
            d = state.design(pair.source, pair.target, method, pair.t.size)
            if isinstance(d, str):
                errors[method] = d
            else:
                designs[method] = state.with_law(sid, method, d)
        case = evaluate_case(pair, loops[pair.source], loops[pair.target], designs)
        errors.update(case.errors)
        scenarios[str(sid)] = {"source": pair.source, "target": pair.target, "rmse_without": case.rmse_without,
                               "ratios": {m: _finite(case.ratios[m]) if m in case.ratios else None
                                          for m in options.methods},
                               "errors": errors}
    plants = {name: {"num": list(lp.spec.plant.num), "den": list(lp.spec.plant.den), "delay": lp.spec.plant.delay}
              for name, lp in loops.items()}
    return {"sample": index, "settings": settings_id, "rejected": rejected, "plants": plants,
            "scenarios": scenarios, "time_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}


class SampleStore:
    """``DIR/samples.jsonl``: one JSON record per finished sample, appended and fsynced.

    Parameters
    ----------
    path : path
        The JSONL file.
    settings_id : str
        Every record must carry this ``settings`` id (records of another campaign are refused).
    """

    def __init__(self, path: str | Path, settings_id: str):
        self.path = Path(path)
        self.settings_id = settings_id

    def load(self) -> dict[int, dict[str, Any]]:
        """Finished samples by index; a final line torn by a kill is cut off the file.

        Raises
        ------
        CampaignError
            A complete line that is not a record of this campaign, or two different records of
            one sample.
        """
        if not self.path.exists():
            return {}
        raw = self.path.read_bytes()
        end = raw.rfind(b"\n") + 1
        if end < len(raw):  # torn last line (killed mid-write): drop it, the sample is flown again
            with open(self.path, "r+b") as f:
                f.truncate(end)
                f.flush()
                os.fsync(f.fileno())
        records: dict[int, dict[str, Any]] = {}
        for no, line in enumerate(raw[:end].splitlines(), 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                idx = rec["sample"]
                ok = rec["settings"] == self.settings_id and isinstance(idx, int) and idx >= 0
            except (ValueError, KeyError, TypeError):
                ok = False
            if not ok:
                raise CampaignError(f"{self.path}, line {no}: not a sample record of campaign "
                                    f"{self.settings_id}; the file is corrupted or from another campaign. "
                                    "Start fresh with another --out folder (or delete the folder)")
            if idx in records and records[idx] != rec:
                raise CampaignError(f"{self.path}, line {no}: a second, different record of sample {idx}; "
                                    "two campaigns wrote to this folder. Start fresh with another --out folder")
            records[idx] = rec
        return records

    def append(self, record: Mapping[str, Any]) -> None:
        """Append one record as a line, flushed and fsynced before returning."""
        line = json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n"
        with open(self.path, "a", encoding="utf-8") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())


@dataclass(frozen=True)
class MethodStatistics:
    """Improvement ratios ``||e_j|| / ||e'_j||`` of one design over a campaign's runs.

    Attributes
    ----------
    runs : int
        Sample x scenario runs.
    failed : int
        Runs without a learning signal (design could not be made or its SOCP failed).
    median, p95, worst : float
        Median, 95th percentile and largest ratio of the runs that flew (NaN if none did).
    share_improved : float
        Share of all runs with ratio < 1 (failed runs count as not improved).
    """

    runs: int
    failed: int
    median: float
    p95: float
    worst: float
    share_improved: float

    @classmethod
    def of(cls, ratios: Sequence[float | None]) -> "MethodStatistics":
        flown = np.array([r for r in ratios if r is not None], float)
        nan = float("nan")
        if flown.size == 0:
            return cls(len(ratios), len(ratios), nan, nan, nan, 0.0)
        return cls(len(ratios), len(ratios) - flown.size, float(np.median(flown)),
                   float(np.percentile(flown, 95)), float(flown.max()),
                   float(np.sum(flown < 1.0) / len(ratios)))

    def to_dict(self) -> dict[str, float | int | None]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class CampaignResult:
    """Statistics of a finished campaign.

    Attributes
    ----------
    options : CampaignOptions
    settings : dict
        :func:`campaign_settings`.
    methods : dict method -> MethodStatistics
        Over every sample and scenario.
    scenarios : dict scenario id -> dict method -> MethodStatistics
    pairs : dict scenario id -> (source, target)
    ratios : dict scenario id -> dict method -> list of (float or None)
        Per sample, in sample order.
    errors : dict method -> str
        One failure message per design that failed in some run.
    rejected : int
        Sampled true plants redrawn because their loop was unstable.
    resumed : int
        Samples read back from an earlier run.
    wall_time_s : float
        Time of this run (s), including the cluster's start.
    sample_time_s, sample_cpu_s : float
        Mean wall-clock and CPU time per sample on a worker (s; they differ when the cores are shared).
    workers : int
        Workers of the cluster (0 when nothing was left to fly).
    """

    options: CampaignOptions
    settings: dict[str, Any]
    methods: dict[str, MethodStatistics]
    scenarios: dict[int, dict[str, MethodStatistics]]
    pairs: dict[int, tuple[str, str]]
    ratios: dict[int, dict[str, list[float | None]]] = field(repr=False)
    errors: dict[str, str]
    rejected: int
    resumed: int
    wall_time_s: float
    sample_time_s: float
    sample_cpu_s: float
    workers: int

    @property
    def uncertainty(self) -> str:
        """Where the true plants come from: ``bound B``, or per system its stated bound / identification."""
        o = self.options
        if o.bound is not None:
            return f"bound {o.bound:g}"
        srcs = self.settings["fleet"]["uncertainty"]
        if all(v == "identification" for v in srcs.values()):
            return f"identification x {o.scale:g}"
        return ", ".join(f"{n}: {v}" + (f" x {o.scale:g}" if v == "identification" else "") for n, v in srcs.items())

    def to_dict(self) -> dict[str, Any]:
        """``campaign.json`` content (statistics per method, then per scenario x method)."""
        o = self.options
        return {
            "samples": o.samples, "seed": o.seed,
            "uncertainty": self.uncertainty,
            "scale": o.scale, "robust_models": o.robust_models, "rho": o.rho, "law": o.law,
            "duration": o.duration, "runs_per_method": o.samples * len(o.scenarios),
            "rejected_plants": self.rejected, "resumed_samples": self.resumed, "workers": self.workers,
            "wall_time_s": self.wall_time_s, "sample_time_s": self.sample_time_s,
            "sample_cpu_s": self.sample_cpu_s,
            "ratio": "||e_j|| / ||e'_j|| (< 1: learning improved on the DOB-only flight)",
            "methods": {m: s.to_dict() for m, s in self.methods.items()},
            "scenarios": {f"scenario {sid}: {self.pairs[sid][0]} -> {self.pairs[sid][1]}":
                          {"methods": {m: s.to_dict() for m, s in per.items()}}
                          for sid, per in self.scenarios.items()},
            "errors": self.errors,
            "settings": self.settings,
        }

    def table(self) -> str:
        """Plain-text tables: every run, then per scenario."""
        o = self.options
        head = (f"campaign: {o.samples} samples x {len(o.scenarios)} scenarios, true plants from "
                f"{self.uncertainty}, robust: 1 + {o.robust_models} models, rho {o.rho:g}, law {o.law}; "
                "ratio = ||e_j|| / ||e'_j||\n")

        def block(title: str, stats: Mapping[str, MethodStatistics]) -> str:
            rows = "".join(f"{m:<13}{s.median:>10.4f}{s.p95:>10.4f}{s.worst:>10.4f}{100 * s.share_improved:>9.1f}%"
                           f"{s.runs:>7}{s.failed:>8}\n" for m, s in stats.items())
            return (f"{title}\n{'method':<13}{'median':>10}{'p95':>10}{'worst':>10}{'improved':>10}"
                    f"{'runs':>7}{'failed':>8}\n{rows}")

        out = head + block("all scenarios", self.methods)
        for sid, per in self.scenarios.items():
            out += block(f"scenario {sid} ({self.pairs[sid][0]} -> {self.pairs[sid][1]})", per)
        return out


def campaign_statistics(records: Mapping[int, Mapping[str, Any]], options: CampaignOptions,
                        settings: dict[str, Any], resumed: int = 0, wall_time_s: float = float("nan"),
                        workers: int = 0) -> CampaignResult:
    """Statistics of samples ``0 .. options.samples - 1`` from their records.

    Raises
    ------
    CampaignError
        A sample is missing.
    """
    missing = [i for i in range(options.samples) if i not in records]
    if missing:
        raise CampaignError(f"samples {missing[:10]}{' ...' if len(missing) > 10 else ''} have no record; "
                            "run the campaign again to fly them")
    recs = [records[i] for i in range(options.samples)]
    ratios = {sid: {m: [r["scenarios"][str(sid)]["ratios"][m] for r in recs] for m in options.methods}
              for sid in options.scenarios}
    first = recs[0]["scenarios"]
    pairs = {sid: (first[str(sid)]["source"], first[str(sid)]["target"]) for sid in options.scenarios}
    errors: dict[str, str] = {}
    for r in recs:
        for sc in r["scenarios"].values():
            for m, msg in sc["errors"].items():
                errors.setdefault(m, msg)
    return CampaignResult(
        options=options, settings=settings,
        methods={m: MethodStatistics.of([x for sid in options.scenarios for x in ratios[sid][m]])
                 for m in options.methods},
        scenarios={sid: {m: MethodStatistics.of(ratios[sid][m]) for m in options.methods}
                   for sid in options.scenarios},
        pairs=pairs, ratios=ratios, errors=errors, rejected=int(sum(r["rejected"] for r in recs)),
        resumed=resumed, wall_time_s=wall_time_s, sample_time_s=float(np.mean([r["time_s"] for r in recs])),
        sample_cpu_s=float(np.mean([r["cpu_s"] for r in recs])),
        workers=workers)


@contextmanager
def _lock(out: Path) -> Iterator[None]:
    """Exclusive lock on ``DIR/samples.jsonl`` for this process (released by the OS if the process dies)."""
    f = open(out / SAMPLES_FILE, "a")
    try:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise CampaignError(f"{out}: another campaign is running in this folder; wait for it or use "
                                "another --out folder") from None
        yield
    finally:
        f.close()


def _check_settings(out: Path, settings: dict[str, Any]) -> None:
    """Write ``campaign_settings.json``, or check that the folder's campaign has the same settings."""
    from ilcdob.atomic import write_json_atomic

    path = out / SETTINGS_FILE
    if path.exists():
        try:
            old = json.loads(path.read_text(encoding="utf-8"))
        except ValueError as exc:
            raise CampaignError(f"{path}: not valid JSON ({exc}); start fresh with another --out folder") from None
        if old.get("id") != settings["id"]:
            diff = [k for k in sorted(set(old) | set(settings)) if k not in ("id",) and old.get(k) != settings.get(k)
                    and not (k == "fleet" and isinstance(old.get(k), dict)
                             and old[k].get("sha256") == settings[k]["sha256"])]
            shown = ", ".join(f"{k}: {old.get(k)!r} there, {settings.get(k)!r} now" for k in diff) or "format"
            raise CampaignError(f"{out} holds a campaign with different settings ({shown}); refusing to mix "
                                "samples. Resume it with its settings (see its campaign_settings.json), or start "
                                "fresh with another --out folder (or delete this one)")
    else:
        if (out / SAMPLES_FILE).stat().st_size > 0:
            raise CampaignError(f"{out}: {SAMPLES_FILE} exists without {SETTINGS_FILE}, so its settings are "
                                "unknown; start fresh with another --out folder (or delete this one)")
        write_json_atomic(path, settings)


def _check_scheduler(address: str) -> None:
    m = _SCHEDULER_RE.match(address)
    if not m or not 0 < int(m.group(3)) < 65536:
        raise CampaignError(f"`scheduler`: got {address!r}, expected a Dask scheduler address tcp://HOST:PORT "
                            "(e.g. tcp://10.0.0.5:8786, printed by `dask scheduler`), or none for a local cluster")


@contextmanager
def _client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A Dask client: on a new local cluster, or connected to ``scheduler``."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler is not None:
        _check_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise CampaignError(f"`scheduler`: cannot connect to {scheduler} ({exc}); is `dask scheduler` "
                                "running there and reachable? Omit --scheduler for a local cluster") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = workers if workers is not None else len(os.sched_getaffinity(0))
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client


def _fmt_duration(s: float) -> str:
    if not math.isfinite(s):
        return "?"
    s = int(round(s))
    return f"{s // 3600} h {s % 3600 // 60:02d} min" if s >= 3600 else f"{s // 60} min {s % 60:02d} s"


class _Progress:
    """``samples done / total, rate, ETA`` lines, at most one per ``every`` seconds (and the last)."""

    def __init__(self, say: Callable[[str], None], total: int, done: int, every: float = 2.0):
        self.say, self.total, self.done0, self.done, self.every = say, total, done, done, every
        self.t0 = time.perf_counter()
        self.last = -math.inf

    def step(self) -> None:
        self.done += 1
        now = time.perf_counter()
        if now - self.last < self.every and self.done < self.total:
            return
        self.last = now
        new = self.done - self.done0
        rate = new / (now - self.t0) if now > self.t0 else float("nan")
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        self.say(f"campaign: {self.done}/{self.total} samples ({self.done0} resumed), {rate:.2f} samples/s, "
                 f"ETA {_fmt_duration(eta)}, elapsed {_fmt_duration(now - self.t0)}")


def run_campaign(fleet: Fleet, options: CampaignOptions, out: str | Path, scheduler: str | None = None,
                 workers: int | None = None, progress: Callable[[str], None] | None = None) -> CampaignResult:
    """Run (or resume) a campaign into ``out`` and write its outputs (see module docstring).

    Parameters
    ----------
    fleet : Fleet
        Needs at least two systems; identified ones unless ``options.bound`` is given.
    options : CampaignOptions
    out : path
        Output folder (created); holds ``samples.jsonl`` and ``campaign_settings.json`` while running.
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running Dask scheduler (default: a local cluster).
    workers : int, optional
        Local cluster: worker processes (default: the usable cores).
    progress : callable, optional
        Receives progress lines (default: printed to stderr).

    Raises
    ------
    CampaignError
        Bad scheduler address or no connection, ``out`` holding a campaign with other settings
        or in use, a sample failing on a worker (finished samples are kept: run again to resume).
    """
    t_start = time.perf_counter()
    say = progress if progress is not None else (lambda msg: print(msg, file=sys.stderr, flush=True))
    if scheduler is not None:
        _check_scheduler(scheduler)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise CampaignError(f"`workers`: got {workers!r}, expected an integer >= 1")
    if len(fleet.systems) < 2:
        raise CampaignError(f"fleet {fleet.source}: a campaign needs at least two systems, got {fleet.names}")
    if options.bound is None:
        lacking = [s.name for s in fleet.systems if s.identification is None and s.uncertainty is None]
        if lacking:
            raise CampaignError(f"fleet {fleet.source}: systems {lacking} have neither an identification nor an "
                                "`uncertainty = { bound }` to draw true plants from; identify them (ilcdob "
                                "identify-fleet), state a bound in the fleet file, or give one (--bound 0.2)")
    settings = campaign_settings(fleet, options)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with _lock(out):
        _check_settings(out, settings)
        store = SampleStore(out / SAMPLES_FILE, settings["id"])
        records = store.load()
        resumed = sum(1 for i in records if i < options.samples)
        todo = [i for i in range(options.samples) if i not in records]
        n_workers = 0
        if todo:
            say(f"campaign: {len(todo)} of {options.samples} samples to fly ({resumed} already in {store.path})")
            with _client(scheduler, workers) as client:
                from distributed import as_completed

                n_workers = len(client.scheduler_info()["workers"])
                fleet_f = client.scatter(fleet, broadcast=True)
                futures = [client.submit(run_sample, fleet_f, options, settings["id"], i, pure=False,
                                         key=f"ilcdob-campaign-{settings['id']}-{i}") for i in todo]
                bar = _Progress(say, options.samples, resumed)
                for fut in as_completed(futures):
                    try:
                        rec = fut.result()
                    except Exception as exc:  # noqa: BLE001 - any worker failure stops the campaign, resumable
                        for f in futures:
                            f.cancel()
                        raise CampaignError(f"a sample failed on a worker: {type(exc).__name__}: {exc}; the "
                                            f"finished samples are kept in {store.path}, run the same command "
                                            "again to resume") from exc
                    store.append(rec)
                    records[rec["sample"]] = rec
                    bar.step()
        result = campaign_statistics(records, options, settings, resumed, time.perf_counter() - t_start,
                                     n_workers)
        write_campaign(result, out)
    return result


def write_campaign(result: CampaignResult, out: str | Path) -> list[Path]:
    """Write ``campaign.json``, ``campaign.txt`` and ``campaign_ratios.png`` (ratio distributions per method)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ilcdob.atomic import savefig_atomic, write_json_atomic, write_text_atomic

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "campaign.json", result.to_dict())
    write_text_atomic(out / "campaign.txt", result.table())
    methods = list(result.options.methods)
    sids = list(result.options.scenarios)
    fig, ax = plt.subplots(figsize=(1.9 * len(methods) + 2.5, 4.2))
    width = 0.8 / len(sids)
    floor = np.inf
    for k, sid in enumerate(sids):
        pos = np.arange(len(methods)) - 0.4 + width * (k + 0.5)
        data = [np.array([r for r in result.ratios[sid][m] if r is not None], float) for m in methods]
        for p, d in zip(pos, data):
            if d.size:
                floor = min(floor, float(d.min()))
                ax.boxplot(d, positions=[p], widths=0.8 * width, whis=(0, 100), showfliers=False,
                           patch_artist=True, boxprops={"facecolor": f"C{k}", "alpha": 0.5},
                           medianprops={"color": "k"})
                jitter = np.random.default_rng(k).uniform(-0.3, 0.3, d.size) * width
                ax.scatter(p + jitter, d, s=3, color=f"C{k}", alpha=0.6, zorder=3)
        a, b = result.pairs[sid]
        ax.plot([], [], "s", color=f"C{k}", alpha=0.6, label=f"scenario {sid} ({a} -> {b})")
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="no improvement")
    if "robust" in methods:
        ax.axhline(result.options.rho, color="C3", lw=0.8, ls=":", label=f"robust rho = {result.options.rho:g}")
    ax.set_xticks(range(len(methods)), [f"{m}\n{100 * result.methods[m].share_improved:.0f}% improved"
                                        for m in methods])
    ax.set_yscale("log")
    if math.isfinite(floor):
        ax.set_ylim(bottom=0.5 * floor)
    ax.set_ylabel("||e_j|| / ||e'_j||")
    o = result.options
    ax.set_title(f"{o.samples} samples, true plants from {result.uncertainty} (box: quartiles, "
                 "whiskers: range)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    savefig_atomic(fig, out / "campaign_ratios.png", dpi=110)
    plt.close(fig)
    return [out / "campaign.json", out / "campaign.txt", out / "campaign_ratios.png"]
