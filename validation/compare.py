"""Design comparison: every learning design flown through one scenario, nominal and over the Delta set.

For scenario ``N`` the first pair of its learning order (system j-1 -> system j) is flown
under ``1 + K`` cases: case 0 with the nominal plants (true plant = model), cases 1..K with
paired samples of both systems' Delta sets (:func:`ilcdob.design.delta_set`; the DOB, PID and
every learning design keep using the models). In every case system j-1 flies its DOB-only
trial, each design turns that trial into system j's learning signal, and system j flies with
it. The figure of merit is the paper's improvement ratio ``||e_j|| / ||e'_j||`` (Theorem:
< 1 means learning helped), ``e'_j`` being system j's DOB-only error in the same case, both
norms over the whole trial as flown (its first and last samples included: the designs'
guarantees are per frequency, and the ends of a trial are where a finite trial departs from
them, :mod:`ilcdob.design.maps.finite_horizon`). The
robust design's models are exactly these 1 + K cases (its own sample set), so theory promises
its ratio <= rho on them, up to what its predictions cannot know: the two systems' own
noises differ (paper Sec. IV; docs/theory.md section 4), and the reference term ``(1 - G_r) r`` of moving
scenarios enters its predictions only through the reconstruction.

Every design learns with the same learning law (``CompareOptions.law``,
:mod:`ilcdob.design.law.laws`): ``paper`` (default) or ``exact-reference``, which removes system
j-1's model reference error before the design's filter and adds system j's reference
correction after it.

Design time is the time to build the design plus its mean time per trial.

The report of a comparison is :meth:`Comparison.files` (``compare.json``, ``compare.txt``,
``compare_ratios.png``), as content to be written by the caller.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from ilcdob.design.methods.fir import FIROptions
from ilcdob.design.law.laws import DEFAULT_LAW, check_law, law_for
from ilcdob.design.methods import DEFAULT_METHODS, METHODS, MethodSettings, method_named
from ilcdob.design.methods.norm_optimal import NormOptimalOptions
from ilcdob.design.pair import PairDesign, design_pair, fleet_delta_sets
from ilcdob.design.methods.robust import RobustOptions
from ilcdob.errors import IlcdobError, NumericalError, SpecError
from ilcdob.fleet import Fleet
from ilcdob.loop import LoopSystem
from ilcdob.display import html_table

from .reproduce import json_document
from .scenarios import scenario
from .simulate import rmse, simulate_flight

__all__ = ["CompareOptions", "MethodComparison", "Comparison", "PairScenario", "CaseResult", "pair_scenario",
           "evaluate_case", "compare_designs"]


@dataclass(frozen=True)
class CompareOptions:
    """Options of :func:`compare_designs`.

    Attributes
    ----------
    samples : int
        Delta-set samples K per system (paired), >= 1.
    bound : float, optional
        Multiplicative uncertainty bound for both systems instead of their identification.
    scale : float
        Scale of the identified standard deviations (> 1 goes beyond the identified uncertainty).
    seed : int
        Seed of the Delta-set draw.
    duration : float, optional
        Fly only the first ``duration`` seconds of the scenario (default: all of it).
    robust : RobustOptions
        Options of the robust design.
    fir : FIROptions, optional
        Options of the FIR design (default: its own).
    norm_optimal : NormOptimalOptions, optional
        Options of the norm-optimal design (default: its own).
    law : {"paper", "exact-reference"}
        Learning law (:mod:`ilcdob.design.law.laws`) applied around every design. ``multi-source``
        is refused: a comparison flies one pair from one DOB-only trial, where it is the paper's law.
    """

    samples: int = 8
    bound: float | None = None
    scale: float = 1.0
    seed: int = 0
    duration: float | None = None
    robust: RobustOptions = field(default_factory=RobustOptions)
    fir: FIROptions | None = None
    norm_optimal: NormOptimalOptions | None = None
    law: str = DEFAULT_LAW

    def __post_init__(self) -> None:
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) or self.samples < 1:
            raise SpecError(f"`samples`: got {self.samples!r}, expected an integer >= 1")
        if self.duration is not None and not (np.isfinite(self.duration) and self.duration > 0):
            raise SpecError(f"`duration`: got {self.duration!r}, expected a duration > 0 s")
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise SpecError(f"`scale`: got {self.scale!r}, expected a factor > 0")
        if check_law(self.law) == "multi-source":
            raise SpecError("`law`: 'multi-source' learns from every earlier system's trial, but a comparison flies "
                            "one pair (j-1 -> j) from a single DOB-only trial of j-1, where it is the paper's law; "
                            "use 'paper' or 'exact-reference' here, or reproduce(..., law='multi-source')")


@dataclass(frozen=True)
class MethodComparison:
    """One design's row of the comparison (ratios ``||e_j|| / ||e'_j||``, RMSE in m).

    Attributes
    ----------
    method : str
        The design (:data:`ilcdob.design.methods.METHODS`).
    order : str
        Orders of its filters, as text ("-" for a failed design).
    design_time_s : float
        Time to build the design plus its mean time per trial, s.
    rmse_nominal, ratio_nominal : float
        RMSE and ratio of the nominal case (true plants = models).
    rmse_worst, ratio_worst, ratio_median : float
        Largest RMSE, largest and median ratio over the Delta samples.
    improved_share : float
        Share of the Delta samples with ratio < 1.
    ratios : list of float
        Ratio of every case: the nominal one first, then each Delta sample.
    error : str, optional
        Why the design could not be made or could not learn (its figures are NaN then).
    """

    method: str
    order: str
    design_time_s: float
    rmse_nominal: float
    ratio_nominal: float
    rmse_worst: float
    ratio_worst: float
    ratio_median: float
    improved_share: float
    ratios: list[float]
    error: str | None = None

    def to_dict(self) -> dict[str, object]:
        """Fields as JSON values (figures of a failed design become null)."""
        return {k: None if isinstance(v, float) and not np.isfinite(v) else v for k, v in asdict(self).items()}

    @classmethod
    def failed(cls, method: str, error: str, design_time_s: float) -> "MethodComparison":
        """A design that could not be made (e.g. FIR convergence constraint not met): no figures.

        Parameters
        ----------
        method : str
            The design.
        error : str
            Why it failed.
        design_time_s : float
            Time spent on it, s.
        """
        nan = float("nan")
        return cls(method, "-", design_time_s, nan, nan, nan, nan, nan, nan, [], error)


@dataclass(frozen=True)
class Comparison:
    """All designs on one scenario (see module docstring).

    Attributes
    ----------
    scenario : int
        Scenario id.
    source, target : str
        Systems j-1 and j of the pair flown.
    samples : int
        Delta samples per system.
    delta_set : str
        Where the Delta set comes from (identification or a bound).
    rmse_without_nominal, rmse_without_worst : float
        RMSE of system j's DOB-only flight, nominal and worst over the samples, m.
    methods : list of MethodComparison
        One row per design.
    law : str
        The learning law (:mod:`ilcdob.design.law.laws`).
    """

    scenario: int
    source: str
    target: str
    samples: int
    delta_set: str
    rmse_without_nominal: float
    rmse_without_worst: float
    methods: list[MethodComparison]
    law: str = DEFAULT_LAW

    def __repr__(self) -> str:
        ok = [m for m in self.methods if m.error is None]
        best = min(ok, key=lambda m: m.ratio_worst, default=None)
        lead = f"; best worst-case ratio {best.method} {best.ratio_worst:.3g}" if best else ""
        return (f"<Comparison scenario {self.scenario} {self.source} -> {self.target}, {len(self.methods)} designs, "
                f"{self.samples} Delta samples ({self.delta_set}){lead}>")

    def _repr_html_(self) -> str:
        rows = [[m.method, m.order, m.ratio_nominal, m.ratio_median, m.ratio_worst, m.design_time_s,
                 m.error or ""] for m in self.methods]
        return html_table(f"Scenario {self.scenario}, {self.source} -> {self.target}: ratio ||e_j|| / ||e'_j||",
                          ["method", "order", "nominal", "median", "worst", "design time (s)", "why no result"], rows)

    def row(self, method: str) -> MethodComparison:
        """The row of design ``method``.

        Parameters
        ----------
        method : str
            A design of the comparison.
        """
        return next(m for m in self.methods if m.method == method)

    def to_dict(self) -> dict[str, object]:
        """The content of ``compare.json`` (RMSE in m, design time in s)."""
        return {"scenario": self.scenario, "source": self.source, "target": self.target, "samples": self.samples,
                "delta_set": self.delta_set, "law": self.law,
                "units": {"rmse": "m", "ratio": "||e_j|| / ||e'_j|| (whole trials)", "design_time": "s"},
                "rmse_without_learning": {"nominal": self.rmse_without_nominal, "worst": self.rmse_without_worst},
                "methods": {m.method: m.to_dict() for m in self.methods}}

    def table(self) -> str:
        """Plain-text table, one row per design."""
        head = (f"scenario {self.scenario}: {self.target} learning from {self.source} (law {self.law}); "
                f"nominal plants and "
                f"{self.samples} Delta samples ({self.delta_set}); ratio = ||e_j|| / ||e'_j|| over whole trials\n"
                f"without learning: RMSE {1e3 * self.rmse_without_nominal:.2f} mm nominal, "
                f"{1e3 * self.rmse_without_worst:.2f} mm worst sample\n")
        cols = f"{'method':<13}{'RMSE nom mm':>12}{'ratio nom':>11}{'RMSE worst':>12}{'ratio worst':>12}" \
               f"{'median':>9}{'improved':>10}{'design s':>10}  order\n"
        rows = "".join(f"{m.method:<13}design failed: {m.error}\n" if m.error else
                       f"{m.method:<13}{1e3 * m.rmse_nominal:>12.3f}{m.ratio_nominal:>11.4f}"
                       f"{1e3 * m.rmse_worst:>12.3f}{m.ratio_worst:>12.4f}{m.ratio_median:>9.4f}"
                       f"{100 * m.improved_share:>9.0f}%{m.design_time_s:>10.2f}  {m.order}\n" for m in self.methods)
        return head + cols + rows

    def files(self, figures: Mapping[str, object] | None = None) -> dict[str, object]:
        """The report of the comparison: file name -> content.

        Parameters
        ----------
        figures : mapping, optional
            The figures the application composes (``compare_ratios.png``:
            :func:`~ilcdob.validation.figures.comparison_figure`), added as they are.

        Returns
        -------
        dict of str to object
            ``compare.json`` (JSON document, :meth:`to_dict` with non-finite numbers as null),
            ``compare.txt`` (:meth:`table`), then ``figures``.
        """
        return {"compare.json": json_document(self.to_dict()), "compare.txt": self.table(), **(figures or {})}


def _parse_methods(methods: Sequence[str]) -> list[str]:
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise SpecError(f"`methods`: got {list(methods)!r}, expected a non-empty list from {list(METHODS)}")
    return list(dict.fromkeys(methods))


@dataclass(frozen=True)
class PairScenario:
    """The signals of one scenario for the first pair of its learning order (system j-1 -> j).

    Attributes
    ----------
    scenario : int
    source, target : str
        Systems j-1 and j.
    t : array, s
    r : array, m
        Reference position.
    a_ref : array, m/s^2
        Reference acceleration.
    d_source, d_target : array, m/s^2
        Total disturbance of each system: the scenario's wind plus the system's own noise.
    """

    scenario: int
    source: str
    target: str
    t: np.ndarray
    r: np.ndarray
    a_ref: np.ndarray
    d_source: np.ndarray
    d_target: np.ndarray


@dataclass(frozen=True)
class CaseResult:
    """One case (a pair of true loops) flown with every design.

    Attributes
    ----------
    rmse_without : float, m
        RMSE of system j's DOB-only flight ``e'_j``.
    ratios : dict method -> float
        ``||e_j|| / ||e'_j||`` of system j's flight with the design's learning signal.
    rmses : dict method -> float, m
        RMSE of that flight.
    learn_times : dict method -> float, s
        Time the design took to turn system j-1's trial into the learning signal.
    errors : dict method -> str
        Designs that could not make a learning signal for this case (no ratio then).
    """

    rmse_without: float
    ratios: dict[str, float]
    rmses: dict[str, float]
    learn_times: dict[str, float]
    errors: dict[str, str]


def pair_scenario(fleet: Fleet, scenario_id: int, duration: float | None = None) -> PairScenario:
    """Signals of scenario ``scenario_id`` for the first pair of its learning order.

    Parameters
    ----------
    fleet : Fleet
    scenario_id : int
        1-4 (:mod:`ilcdob.validation.scenarios`).
    duration : float, optional
        Keep only the first ``duration`` seconds (default: the whole scenario).
    """
    sc = scenario(scenario_id)
    order = sc.order(fleet.names)
    if len(order) < 2:
        raise SpecError(f"fleet {fleet.source}: comparing designs needs at least two systems, got {order}")
    source, target = order[0], order[1]
    t = sc.time(fleet.sample_time)
    if duration is not None:
        t = t[t < duration]
        if t.size < 2:
            raise SpecError(f"`duration`: got {duration!r} s, which covers {t.size} sample of the fleet's "
                            f"{fleet.sample_time:g} s; a flight needs at least 2 samples: give a duration above "
                            f"{fleet.sample_time:g} s (scenario {scenario_id} lasts {sc.duration:g} s)")
    wind = sc.disturbance(t)
    specs = {s.name: s for s in fleet.systems}
    return PairScenario(scenario_id, source, target, t, sc.reference(t), sc.acceleration(t),
                        wind + specs[source].noise(t), wind + specs[target].noise(t))


def evaluate_case(pair: PairScenario, source_loop: LoopSystem, target_loop: LoopSystem,
                  designs: Mapping[str, PairDesign]) -> CaseResult:
    """Fly one case: system j-1's DOB-only trial, then system j without and with each design.

    Parameters
    ----------
    pair : PairScenario
    source_loop, target_loop : LoopSystem
        True loops of systems j-1 and j (true plants; C, Q, M from the models).
    designs : mapping method -> PairDesign
        Designs that turn system j-1's trial ``(e_{j-1}, d_f,{j-1} = 0)`` into system j's
        learning signal; a design raising :class:`IlcdobError` is recorded in ``errors``.
    """

    def fly(lp: LoopSystem, d: np.ndarray, d_f: np.ndarray | None = None) -> np.ndarray:
        return simulate_flight(lp, pair.r, d, d_f=d_f, a_ref=pair.a_ref).e

    e_prev = fly(source_loop, pair.d_source)
    e_wo = fly(target_loop, pair.d_target)
    norm_wo = float(np.linalg.norm(e_wo))
    if not np.isfinite(norm_wo):
        raise NumericalError(f"scenario {pair.scenario}: the error of {pair.target} without learning is not finite "
                             f"({norm_wo!r}); its loop diverged numerically")
    if norm_wo == 0:  # no ratio ||e_j|| / ||e'_j|| exists
        raise SpecError(f"scenario {pair.scenario}: the error of {pair.target} without learning is {norm_wo!r} m over "
                        f"the {pair.t.size} samples flown, so the ratio ||e_j|| / ||e'_j|| is undefined; fly a longer "
                        "duration")
    zero = np.zeros(pair.t.size)
    ratios: dict[str, float] = {}
    rmses: dict[str, float] = {}
    times: dict[str, float] = {}
    errors: dict[str, str] = {}
    for method, design in designs.items():
        t0 = time.perf_counter()
        try:
            d_f = design.learn(e_prev, zero)
        except IlcdobError as exc:  # e.g. a robust rho infeasible for this trial: a result, not a crash
            errors[method] = str(exc)
            continue
        times[method] = time.perf_counter() - t0
        e = fly(target_loop, pair.d_target, d_f)
        ratios[method] = float(np.linalg.norm(e) / norm_wo)
        rmses[method] = rmse(e)
    return CaseResult(rmse(e_wo), ratios, rmses, times, errors)


def compare_designs(fleet: Fleet, scenario_id: int, methods: Sequence[str] = DEFAULT_METHODS,
                    options: CompareOptions | None = None,
                    progress: Callable[[int, int, str], None] | None = None) -> Comparison:
    """Fly every design of ``methods`` through scenario ``scenario_id`` (see module docstring).

    Parameters
    ----------
    fleet : Fleet
        Needs at least two systems.
    scenario_id : int
        1-4 (:mod:`ilcdob.validation.scenarios`); its learning order's first pair is used.
    methods : sequence of str
        Subset of :data:`ilcdob.design.methods.METHODS` (default :data:`~ilcdob.design.methods.DEFAULT_METHODS`).
    options : CompareOptions, optional
        Samples, uncertainty, duration, design options and law (default: ``CompareOptions()``).
    progress : callable, optional
        Called as ``progress(done, total, what)`` after each design is built and after each
        case is flown (``total``: designs + 1 + samples); ``what`` says which. None: silent.

    Returns
    -------
    Comparison
        One row per design; :meth:`Comparison.files` makes its report.
    """
    opts = options or CompareOptions()
    methods = _parse_methods(methods)
    say = progress if progress is not None else (lambda done, total, what: None)
    pair = pair_scenario(fleet, scenario_id, opts.duration)
    source, target = pair.source, pair.target
    deltas = fleet_delta_sets(fleet, [source, target], k=opts.samples, bound=opts.bound, scale=opts.scale,
                              seed=opts.seed)
    cases: list[tuple[LoopSystem, LoopSystem]] = [(fleet.loop(source), fleet.loop(target))]
    cases += list(zip(deltas[source].loops, deltas[target].loops))
    designs: dict[str, PairDesign] = {}
    build: dict[str, float] = {}
    failed: dict[str, MethodComparison] = {}
    total, done = len(methods) + len(cases), 0
    for method in methods:
        t0 = time.perf_counter()
        try:
            settings = MethodSettings(n=pair.t.size, deltas=deltas, fir=opts.fir, norm_optimal=opts.norm_optimal,
                                      robust=opts.robust)
            designs[method] = design_pair(fleet, source, target, method_named(method).configured(settings),
                                          law=law_for(opts.law, pair.r, pair.a_ref))
        except IlcdobError as exc:  # a design that cannot be made is a result of the comparison
            failed[method] = MethodComparison.failed(method, str(exc), time.perf_counter() - t0)
        build[method] = time.perf_counter() - t0
        done += 1
        say(done, total, f"scenario {scenario_id} {method}: " + (f"design failed: {failed[method].error}"
                                                                 if method in failed else
                                                                 f"designed ({build[method]:.1f} s)"))
    results = []
    for k, (src, tgt) in enumerate(cases):
        t0 = time.perf_counter()
        results.append(evaluate_case(pair, src, tgt, designs))
        done += 1
        say(done, total, f"scenario {scenario_id}: " + ("nominal case" if k == 0 else f"Delta sample {k}")
            + f" flown ({time.perf_counter() - t0:.1f} s)")
    rows = []
    for method in methods:
        error = failed[method].error if method in failed else next(
            (r.errors[method] for r in results if method in r.errors), None)
        if error is not None:
            spent = build[method] + sum(r.learn_times.get(method, 0.0) for r in results)
            rows.append(failed.get(method) or MethodComparison.failed(method, error, spent))
            continue
        ratios = [r.ratios[method] for r in results]
        rmses = [r.rmses[method] for r in results]
        per_trial = [r.learn_times[method] for r in results]
        sample_ratios = np.asarray(ratios[1:])
        rows.append(MethodComparison(
            method=method, order=designs[method].order, design_time_s=build[method] + float(np.mean(per_trial)),
            rmse_nominal=rmses[0], ratio_nominal=ratios[0], rmse_worst=float(max(rmses[1:])),
            ratio_worst=float(sample_ratios.max()), ratio_median=float(np.median(sample_ratios)),
            improved_share=float(np.mean(sample_ratios < 1.0)), ratios=ratios))
    return Comparison(scenario=scenario_id, source=source, target=target, samples=opts.samples,
                      delta_set=deltas[source].source, rmse_without_nominal=results[0].rmse_without,
                      rmse_without_worst=float(max(r.rmse_without for r in results[1:])), methods=rows,
                      law=opts.law)
