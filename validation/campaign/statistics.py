"""Statistics of a campaign's samples and its report (:meth:`CampaignResult.files`)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ilcdob.display import fmt, html_table

from ..reproduce import json_document
from .cluster import LIBRARY_THREADS
from .options import CampaignError, CampaignOptions

__all__ = ["CPU_S", "MethodStatistics", "CampaignResult", "campaign_statistics"]

#: What a record's ``cpu_s`` measures (written into ``campaign.json`` beside the mean).
CPU_S = ("CPU time of the worker thread that flew the sample (time.thread_time): a sample runs in one thread, with "
         "BLAS and Clarabel limited to one thread on the workers, so other threads of the worker process (its "
         "event loop, other samples) are not counted")


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
        """Statistics of a list of run ratios.

        Parameters
        ----------
        ratios : sequence of float or None
            One ratio per run; None for a run without a learning signal (failed).
        """
        flown = np.array([r for r in ratios if r is not None], float)
        nan = float("nan")
        if flown.size == 0:
            return cls(len(ratios), len(ratios), nan, nan, nan, 0.0)
        return cls(len(ratios), len(ratios) - flown.size, float(np.median(flown)),
                   float(np.percentile(flown, 95)), float(flown.max()),
                   float(np.sum(flown < 1.0) / len(ratios)))

    def to_dict(self) -> dict[str, float | int | None]:
        """The fields as JSON values (NaN becomes None)."""
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class CampaignResult:
    """Statistics of a finished campaign.

    Attributes
    ----------
    options : CampaignOptions
    settings : dict
        :func:`~ilcdob.validation.campaign.options.campaign_settings`.
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
        Mean wall-clock and CPU time per sample on a worker (s; they differ when the cores are shared; CPU time:
        :data:`CPU_S`).
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

    def __repr__(self) -> str:
        stats = ", ".join(f"{m} median {fmt(st.median, 3)} worst {fmt(st.worst, 3)}" for m, st in self.methods.items())
        return (f"<CampaignResult {self.options.samples} samples ({self.uncertainty}), "
                f"{len(self.scenarios)} scenario(s): {stats}>")

    def _repr_html_(self) -> str:
        rows = [[m, st.median, st.p95, st.worst, "-" if st.share_improved is None else f"{100 * st.share_improved:.1f} %",
                 st.runs] for m, st in self.methods.items()]
        return html_table(f"Ratio ||e_j|| / ||e'_j|| over {self.options.samples} samples ({self.uncertainty})",
                          ["method", "median", "p95", "worst", "improved", "runs"], rows)

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
            "sample_cpu_s": self.sample_cpu_s, "cpu_s": CPU_S,
            "library_threads": {"blas": LIBRARY_THREADS, "clarabel": LIBRARY_THREADS,
                                "per": "worker process, set by a worker plugin on every worker of the cluster"},
            "ratio": "||e_j|| / ||e'_j|| over whole trials (< 1: learning improved on the DOB-only flight)",
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

    def files(self, figures: Mapping[str, object] | None = None) -> dict[str, object]:
        """The report of the campaign: file name -> content.

        Parameters
        ----------
        figures : mapping, optional
            The figures the application composes (``campaign_ratios.png``:
            :func:`~ilcdob.validation.figures.campaign_figure`), added as they are.

        Returns
        -------
        dict of str to object
            ``campaign.json`` (JSON document, :meth:`to_dict` with non-finite numbers as null),
            ``campaign.txt`` (:meth:`table`), then ``figures``. The sample store and the settings
            file beside them are kept by :func:`~ilcdob.validation.campaign.run.run_campaign`.
        """
        return {"campaign.json": json_document(self.to_dict()), "campaign.txt": self.table(), **(figures or {})}


def campaign_statistics(records: Mapping[int, Mapping[str, Any]], options: CampaignOptions,
                        settings: dict[str, Any], resumed: int = 0, wall_time_s: float = float("nan"),
                        workers: int = 0) -> CampaignResult:
    """Statistics of samples ``0 .. options.samples - 1`` from their records.

    Parameters
    ----------
    records : mapping of int to dict
        Sample records by index (:func:`~ilcdob.validation.campaign.run.run_sample`); extra
        indices are ignored.
    options : CampaignOptions
        The campaign's options.
    settings : dict
        Its :func:`~ilcdob.validation.campaign.options.campaign_settings`.
    resumed : int
        Samples read back from an earlier run.
    wall_time_s : float
        Time of this run, s (NaN: unknown, written as null).
    workers : int
        Workers of the cluster (0 when nothing was flown).

    Returns
    -------
    CampaignResult

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
