"""Reproduce the paper's validation: no DOB, only DOB, and learning passed around the fleet.

Learning chain (cyclic, paper Sec. IV): every system first flies without DOB and with DOB
only. The first system of the order flies the DOB-only trial that starts the chain; then
each flight learns from the flight before it in the chain::

    order = [A, B, C]:  B <- A(DOB only), C <- B, A <- C, B <- A, C <- B, A <- C, ...

until every system has flown ``iterations`` learning trials; ``rmse_learning[i]`` is a
system's (i+1)-th learning trial. Each learning signal comes from the learning law ``law``
(:mod:`ilcdob.design.laws`), always built from the systems' *models*:

* ``"paper"`` (default): the closed-form filters of the Theorem (paper Sec. III,
  :func:`ilcdob.design.closed_form_filters`) on the previous flight;
* ``"exact-reference"``: the same filters with the reference term ``(1 - G_r) r`` kept
  (:mod:`ilcdob.design.reference`), from the scenario's reference and its acceleration;
* ``"multi-source"``: from the latest flight of every system that has flown in the chain so
  far (the first system's DOB-only trial included), confidence-weighted by each system's
  Delta set (identification or fleet ``uncertainty`` bound, 8 samples, seed 0; systems with
  neither count as exact models) (:mod:`ilcdob.design.multi_source`).

With one earlier flight (each scenario's first learning flight) ``multi-source`` is the
paper's law; with a hover (no reference motion) ``exact-reference`` is.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Callable


import numpy as np

from ilcdob.design import LearningFilters, closed_form_filters
from ilcdob.design.delta import DeltaSet, delta_set
from ilcdob.design.laws import DEFAULT_LAW, check_law, reference_terms
from ilcdob.design.multi_source import SourceTrial, multi_source_learning
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet

from .scenarios import Scenario, scenario
from .simulate import Flight, simulate_flight

__all__ = ["SystemResult", "ScenarioResult", "ReproductionResult", "learning_chain", "law_delta_sets", "run_scenario",
           "reproduce"]


@dataclass(frozen=True)
class SystemResult:
    """Flights of one system in one scenario."""

    no_dob: Flight
    dob: Flight
    learning: tuple[Flight, ...]

    def metrics(self) -> dict[str, object]:
        """RMSE figures for results.json (m, and m/s^2 for ``rmse_dhat_*``)."""
        return {
            "rmse_no_dob": self.no_dob.rmse,
            "rmse_dob": self.dob.rmse,
            "rmse_learning": [f.rmse for f in self.learning],
            "rmse_dhat_dob": self.dob.rmse_dhat,
            "rmse_dhat_learning": [f.rmse_dhat for f in self.learning],
        }


@dataclass(frozen=True)
class ScenarioResult:
    """All flights of one scenario; ``chain`` lists (source, target) of each learning flight."""

    scenario: Scenario
    order: list[str]
    systems: dict[str, SystemResult]
    chain: list[tuple[str, str]] = field(default_factory=list)

    def to_dict(self) -> dict[str, object]:
        return {
            "id": self.scenario.id,
            "title": self.scenario.title,
            "duration_s": self.scenario.duration,
            "order": self.order,
            "chain": [list(p) for p in self.chain],
            "systems": {name: self.systems[name].metrics() for name in self.order},
        }


@dataclass(frozen=True)
class ReproductionResult:
    """Every scenario run, plus the fleet, the filters used and the learning law.

    ``filters`` holds the Theorem's pair (L1, L2) of every pair flown with the ``paper`` or
    ``exact-reference`` law; it is empty for ``multi-source`` (no single pair's filters).
    """

    fleet: Fleet
    scenarios: list[ScenarioResult]
    iterations: int
    filters: dict[tuple[str, str], LearningFilters]
    elapsed_s: float
    law: str = DEFAULT_LAW

    def to_dict(self) -> dict[str, object]:
        return {
            "plant": "linear",
            "law": self.law,
            "fleet": self.fleet.source,
            "sample_time": self.fleet.sample_time,
            "iterations": self.iterations,
            "units": {"rmse": "m", "rmse_dhat": "m/s^2"},
            "scenarios": [s.to_dict() for s in self.scenarios],
        }


def _filters_for(fleet: Fleet, cache: dict, src: str, tgt: str) -> LearningFilters:
    if (src, tgt) not in cache:
        cache[(src, tgt)] = closed_form_filters(fleet.loop(src), fleet.loop(tgt))
    return cache[(src, tgt)]


def learning_chain(order: list[str], iterations: int, first: Flight,
                   step: Callable[[str, str, Flight], Flight]) -> tuple[dict[str, list[Flight]], list[tuple[str, str]]]:
    """Pass learning around ``order`` cyclically (module docstring), starting from ``first``.

    ``step(source, target, previous_flight)`` designs the target's learning signal from the
    previous flight and flies it; returns each system's learning flights and the (source,
    target) of every step.
    """
    learning: dict[str, list[Flight]] = {name: [] for name in order}
    chain = []
    prev = first
    n = len(order)
    for k in range(iterations * n):
        src, tgt = order[k % n], order[(k + 1) % n]
        if n == 1:
            src = tgt = order[0]
        prev = step(src, tgt, prev)
        learning[tgt].append(prev)
        chain.append((src, tgt))
    return learning, chain


def law_delta_sets(fleet: Fleet, k: int = 8, seed: int = 0) -> dict[str, DeltaSet]:
    """Delta sets of the ``multi-source`` law: every system with an identification or a fleet bound.

    Systems with neither are left out (their models count as exact: the error-power floor).
    """
    rng = np.random.default_rng(seed)
    return {s.name: delta_set(s, fleet.sample_time, k, rng) for s in fleet.systems
            if s.identification is not None or s.uncertainty is not None}


def run_scenario(fleet: Fleet, sc: Scenario, iterations: int = 3,
                 filters: dict | None = None, law: str = DEFAULT_LAW,
                 deltas: dict[str, DeltaSet] | None = None) -> ScenarioResult:
    """Fly one scenario for every system: no DOB, only DOB, ``iterations`` learning trials.

    Parameters
    ----------
    fleet : Fleet
    sc : Scenario
    iterations : int
        Learning trials per system (>= 1).
    filters : dict, optional
        Cache of closed-form filters per (source, target), filled as pairs are flown.
    law : {"paper", "exact-reference", "multi-source"}
        Learning law (module docstring, :mod:`ilcdob.design.laws`).
    deltas : dict name -> DeltaSet, optional
        ``multi-source``: the confidence weights' Delta sets (default :func:`law_delta_sets`).

    Raises
    ------
    SpecError
        ``iterations`` or ``law`` invalid.
    """
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise SpecError(f"`iterations`: got {iterations!r}, expected an integer >= 1")
    law = check_law(law)
    filters = {} if filters is None else filters
    ts = fleet.sample_time
    t = sc.time(ts)
    r = sc.reference(t)
    a_ref = sc.acceleration(t)
    wind = sc.disturbance(t)
    order = sc.order(fleet.names)
    specs = {s.name: s for s in fleet.systems}
    dist = {name: wind + specs[name].noise(t) for name in order}
    base = {}
    for name in order:
        lp = fleet.loop(name)
        base[name] = (simulate_flight(lp, r, dist[name], mode="no_dob", a_ref=a_ref),
                      simulate_flight(lp, r, dist[name], mode="dob", a_ref=a_ref))
    latest: dict[str, Flight] = {order[0]: base[order[0]][1]}  # multi-source: each system's last trial
    if law == "multi-source" and deltas is None:
        deltas = law_delta_sets(fleet)
    refs: dict[tuple[str, str], object] = {}
    powers: dict = {}  # multi-source: error powers of the Delta sets, computed once per system

    def step(src: str, tgt: str, prev: Flight) -> Flight:
        if law == "multi-source":
            trials = [SourceTrial(fleet.loop(name), f.e, f.d_f, deltas.get(name)) for name, f in latest.items()]
            df = multi_source_learning(fleet.loop(tgt), trials, power_cache=powers)
        elif law == "exact-reference":
            if (src, tgt) not in refs:
                refs[(src, tgt)] = reference_terms(fleet.loop(src), fleet.loop(tgt), r, a_ref)
            df = refs[(src, tgt)].wrap(_filters_for(fleet, filters, src, tgt).apply)(prev.e, prev.d_f)
        else:
            df = _filters_for(fleet, filters, src, tgt).apply(prev.e, prev.d_f)
        flight = simulate_flight(fleet.loop(tgt), r, dist[tgt], d_f=df, a_ref=a_ref)
        latest[tgt] = flight
        return flight

    learning, chain = learning_chain(order, iterations, base[order[0]][1], step)
    systems = {name: SystemResult(base[name][0], base[name][1], tuple(learning[name]))
               for name in order}
    return ScenarioResult(scenario=sc, order=order, systems=systems, chain=chain)


def reproduce(fleet: Fleet, scenario_ids: list[int] = (1, 2, 3, 4), iterations: int = 3,
              progress: Callable[[str], None] | None = None, law: str = DEFAULT_LAW) -> ReproductionResult:
    """Run the listed scenarios on ``fleet`` (see module docstring).

    Parameters
    ----------
    fleet : Fleet
    scenario_ids : list of int
        Scenarios 1-4 (:mod:`ilcdob.validation.scenarios`).
    iterations : int
        Learning trials per system (>= 1).
    progress : callable, optional
        Receives one line per scenario (default: printed to stderr).
    law : {"paper", "exact-reference", "multi-source"}
        Learning law (module docstring); recorded in the result.

    Raises
    ------
    SpecError
        Bad scenario id, ``iterations`` or ``law``.
    """
    law = check_law(law)
    say = progress if progress is not None else (lambda msg: print(msg, file=sys.stderr, flush=True))
    start = time.perf_counter()
    filters: dict = {}
    deltas = law_delta_sets(fleet) if law == "multi-source" else None
    results = []
    for i, sid in enumerate(scenario_ids, 1):
        sc = scenario(sid)
        t0 = time.perf_counter()
        results.append(run_scenario(fleet, sc, iterations, filters, law, deltas))
        say(f"[{i}/{len(scenario_ids)}] scenario {sid} ({sc.title}, law {law}): "
            f"{time.perf_counter() - t0:.1f} s")
    return ReproductionResult(fleet=fleet, scenarios=results, iterations=iterations,
                              filters=filters, elapsed_s=time.perf_counter() - start, law=law)
