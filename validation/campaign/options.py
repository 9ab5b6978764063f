"""Settings of a Monte Carlo campaign and their identity (:func:`campaign_settings`)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ilcdob.design.sets.delta import MAX_DELTA_SAMPLES, check_scale
from ilcdob.design.law.laws import DEFAULT_LAW, check_law
from ilcdob.design.methods import DEFAULT_METHODS, METHODS
from ilcdob.design.methods.robust_set import DELTA_SETS
from ilcdob.errors import IlcdobError
from ilcdob.fleet import Fleet

from ..scenarios import SCENARIOS

__all__ = ["CampaignError", "CampaignOptions", "campaign_settings", "FORMAT_VERSION", "MAX_SAMPLES",
           "SAMPLE_CPU_S"]

#: Version of the sample records and the settings file.
FORMAT_VERSION = 1

#: Most samples of one campaign (its records are held in memory; a larger study is several campaigns).
MAX_SAMPLES = 100_000
#: Measured CPU seconds of one sample with the default designs over the four scenarios (the robust SOCP ~70 %).
SAMPLE_CPU_S = 4.2


def _duration(seconds: float) -> str:
    """``seconds`` in the largest unit that keeps it at least 1 (s, min, h, days)."""
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


class CampaignError(IlcdobError, ValueError):
    """A campaign cannot run: bad settings, an output folder holding another campaign, no cluster."""


@dataclass(frozen=True)
class CampaignOptions:
    """Settings of a Monte Carlo campaign (see :mod:`ilcdob.validation.campaign`).

    Attributes
    ----------
    samples : int
        Number of samples N (each: one true plant per vehicle), 1 to :data:`MAX_SAMPLES`.
    seed : int
        Campaign seed, >= 0; sample ``i`` uses the generator of ``SeedSequence(seed, spawn_key=(0, i))``.
    scale : float
        Scale of the identified standard deviations for the true plants (> 0; 1: the
        identified uncertainty, > 1 beyond it; 1 with ``bound``, which replaces it).
    bound : float, optional
        Multiplicative uncertainty bound in (0, 1) instead of the identification (for true
        plants and design samples alike).
    scenarios : tuple of int
        Scenario ids, each 1-4.
    methods : tuple of str
        Designs, a subset of :data:`ilcdob.design.methods.METHODS` (default
        :data:`~ilcdob.design.methods.DEFAULT_METHODS`).
    duration : float, optional
        Fly only the first ``duration`` seconds of each scenario (s, > 0; default: all).
    robust_models : int
        Delta samples per system in the robust SOCP besides the nominal pair (0 to
        :data:`~ilcdob.design.sets.delta.MAX_DELTA_SAMPLES`); its cost per trial grows about linearly
        with ``1 + robust_models``.
    rho : float
        Robust design's guaranteed improvement factor on its models (> 0); robust-set's on every
        plant of its Delta set, so in (0, 1] when robust-set is among the methods.
    law : {"paper", "exact-reference"}
        Learning law applied around every design (:mod:`ilcdob.design.law.laws`); ``multi-source``
        is refused (one pair from one DOB-only trial per scenario, where it is the paper's law).
        The default is left out of the settings hash, so campaigns started before the law
        existed resume.
    delta_set : {"structured", "disc", "auto"}
        The Delta set robust-set designs guarantee over
        (:attr:`ilcdob.design.methods.robust_set.RobustSetOptions.delta_set`;
        default: the family the true plants are drawn from). In the settings hash only when
        robust-set is flown over another set than the disc (so campaigns from before the option resume).
    margin : float
        ``m`` in [0, 1): a sampled true plant (and a design sample) is redrawn when its disturbance
        map exceeds ``1/m`` times its model's at some frequency (:func:`ilcdob.design.sets.delta.delta_set`),
        and robust-set designs over the structured family guarantee over the same plants
        (:attr:`~ilcdob.design.methods.robust_set.RobustSetOptions.margin`; the disc keeps its own margin).
        Default 0.5: within 6 dB of the model. 0 keeps every stable plant, as campaigns did before
        the option; it is then left out of the settings hash (they resume) unless robust-set flies
        over the structured family, whose design it changes.
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
    delta_set: str = "structured"
    margin: float = 0.5

    def __post_init__(self) -> None:
        def integer(v: object) -> bool:
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        if not integer(self.samples) or self.samples < 1:
            raise CampaignError(f"`samples`: got {self.samples!r}, expected an integer >= 1")
        if self.samples > MAX_SAMPLES:
            raise CampaignError(
                f"`samples`: got {self.samples}, expected at most {MAX_SAMPLES}: a sample flies every scenario with "
                f"every design (measured: {SAMPLE_CPU_S:g} s of CPU with the default designs over the four "
                f"scenarios), so {self.samples} samples would take about {_duration(self.samples * SAMPLE_CPU_S)} "
                "of CPU; split a larger study into campaigns of different --seed")
        if not integer(self.seed) or self.seed < 0:
            raise CampaignError(f"`seed`: got {self.seed!r}, expected an integer >= 0")
        if not (isinstance(self.scale, (int, float)) and np.isfinite(self.scale) and self.scale > 0):
            raise CampaignError(f"`scale`: got {self.scale!r}, expected a factor > 0 (1: identified uncertainty)")
        if self.bound is not None and not (np.isfinite(self.bound) and 0 < self.bound < 1):
            raise CampaignError(f"`bound`: got {self.bound!r}, expected a relative error in (0, 1)")
        try:
            check_scale(self.scale, self.bound)
        except IlcdobError as exc:
            raise CampaignError(str(exc)) from None
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
        if not integer(self.robust_models) or not 0 <= self.robust_models <= MAX_DELTA_SAMPLES:
            raise CampaignError(f"`robust_models`: got {self.robust_models!r}, expected an integer from 0 to "
                                f"{MAX_DELTA_SAMPLES} (Delta samples besides the nominal pair; the robust SOCP's "
                                "time per trial grows about linearly with 1 + robust_models: 4.2 / 5.6 / 10.7 s of "
                                "CPU per sample at 1 / 2 / 4)")
        if not (np.isfinite(self.rho) and self.rho > 0):
            raise CampaignError(f"`rho`: got {self.rho!r}, expected an improvement factor > 0 (e.g. 0.95)")
        if "robust-set" in tuple(self.methods) and self.rho > 1:
            raise CampaignError(f"`rho`: got {self.rho!r}, expected a factor in (0, 1] with robust-set among the "
                                "methods: it guarantees |e_j| <= rho |e'_j| on every plant (1: never worse than "
                                "without learning)")
        if self.delta_set not in DELTA_SETS:
            raise CampaignError(f"`delta_set`: got {self.delta_set!r}, expected one of {list(DELTA_SETS)}")
        if not (isinstance(self.margin, (int, float)) and np.isfinite(self.margin) and 0 <= self.margin < 1):
            raise CampaignError(f"`margin`: got {self.margin!r}, expected a number in [0, 1) (0.5: true disturbance "
                                "maps within 6 dB of the models'; 0: every stable plant)")
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
        object.__setattr__(self, "margin", float(self.margin))


def _fleet_fingerprint(fleet: Fleet) -> str:
    """SHA-256 of the fleet's specifications (sample time, every system's parameters)."""
    return hashlib.sha256(repr((fleet.sample_time, fleet.systems)).encode()).hexdigest()


def campaign_settings(fleet: Fleet, options: CampaignOptions) -> dict[str, Any]:
    """The settings that determine every sample's result (all options but ``samples``).

    Two runs with equal settings produce the same record for sample ``i``; ``id`` is their hash.

    Parameters
    ----------
    fleet : Fleet
        The fleet flown (identified by the SHA-256 of its specifications, not its file's location).
    options : CampaignOptions
        The campaign's options.

    Returns
    -------
    dict
        ``{"format", "fleet": {"source", "sha256", "systems", "uncertainty"}, <options but
        samples>, "id"}``, the content of ``campaign_settings.json``.
    """
    opts = asdict(options)
    opts.pop("samples")
    if opts.get("law") == DEFAULT_LAW:  # the default law keeps the ids of campaigns started before laws existed
        opts.pop("law")
    if "robust-set" not in options.methods or options.delta_set == "disc":  # only robust-set depends on it, and
        opts.pop("delta_set")                                                # the disc was its set before the option
    designs_on_margin = "robust-set" in options.methods and options.delta_set == "structured"
    if options.margin == 0 and not designs_on_margin:  # every stable plant: how campaigns sampled before the option
        opts.pop("margin")
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
