"""Where the two extensions beyond the paper help, and by how much, scenario by scenario.

* **Exact reference term** (:mod:`ilcdob.design.reference`): the chain's first pair
  (j-1 -> j) with the fleet's models exact and each vehicle's noise; the learning flight's
  error with the paper's filters against the filters that keep ``(1 - G_r) r``.
* **Learning from every earlier system** (:mod:`ilcdob.design.multi_source`): the third
  system of the order learns after the first two have flown (the first DOB-only, the second
  with its learning signal from the first). Case II: the second system's true plant is
  ``P_hat (1 + a tau s / (tau s + 1))`` (a model its fleet bound ``|Delta| <= a`` covers), the
  first system's model is good (bound 0.05). Compared: the paper (from the second only), the
  joint reconstruction with equal weights, and with confidence weights.

Figures are ratios ``||e_j|| / ||e'_j||`` (learning flight over DOB-only flight, same
vehicle, same noise): smaller is better.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ilcdob.design import closed_form_filters, delta_set
from ilcdob.design.multi_source import SourceTrial, multi_source_learning
from ilcdob.design.reference import ExactReferenceLearning
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet
from ilcdob.loop import build_loop
from ilcdob.specs import PlantSpec

from .scenarios import scenario
from .simulate import simulate_flight

__all__ = ["ExtensionRow", "extensions_study", "format_extensions"]


@dataclass(frozen=True)
class ExtensionRow:
    """Ratios ``||e_j|| / ||e'_j||`` of one scenario (see module docstring)."""

    scenario: int
    title: str
    reference_pair: str
    paper_reference_dropped: float
    exact_reference: float
    multi_target: str
    paper_last_only: float
    joint_equal: float
    joint_confidence: float


def _high_pass_plant(model: PlantSpec, gain: float, tau: float) -> PlantSpec:
    return PlantSpec(tuple(np.polymul(model.num, [(1 + gain) * tau, 1.0])),
                     tuple(np.polymul(model.den, [tau, 1.0])), model.delay)


def extensions_study(fleet: Fleet, scenario_ids=(1, 2, 3, 4), error_gain: float = 0.8, error_tau: float = 1.0,
                     seed: int = 0) -> list[ExtensionRow]:
    """Run both comparisons on each scenario (module docstring); needs >= 3 systems."""
    if len(fleet.systems) < 3:
        raise SpecError(f"fleet {fleet.source}: the multi-source study needs >= 3 systems, got {len(fleet.systems)}")
    if not (0 < abs(error_gain) < 1 and error_tau > 0):
        raise SpecError(f"`error_gain`, `error_tau`: got {error_gain!r}, {error_tau!r}; expected 0 < |gain| < 1 "
                        "(inside a fleet bound) and tau > 0 s")
    ts = fleet.sample_time
    specs = {s.name: s for s in fleet.systems}
    rows = []
    for sid in scenario_ids:
        sc = scenario(sid)
        t = sc.time(ts)
        r, a_ref, wind = sc.reference(t), sc.acceleration(t), sc.disturbance(t)
        first, second, third = sc.order(fleet.names)[:3]
        dist = {n: wind + specs[n].noise(t) for n in (first, second, third)}

        def fly(lp, name, d_f=None):
            return simulate_flight(lp, r, dist[name], d_f=d_f, a_ref=a_ref)

        l1, l2, l3 = (fleet.loop(n) for n in (first, second, third))
        without = {name: float(np.linalg.norm(fly(lp, name).e)) for lp, name in ((l2, second), (l3, third))}

        def ratio(lp, name, d_f):  # lp is the fleet's loop of `name`: its DOB-only flight is `without`
            return float(np.linalg.norm(fly(lp, name, d_f).e) / without[name])

        f1 = fly(l1, first)
        cf12 = closed_form_filters(l1, l2)
        df12 = cf12.apply(f1.e, f1.d_f)
        paper_ref = ratio(l2, second, df12)
        exact_ref = ratio(l2, second, ExactReferenceLearning(cf12, r, a_ref).apply(f1.e, f1.d_f))

        rng = np.random.default_rng(seed)
        spec2 = specs[second]
        true2 = build_loop(replace(spec2, plant=_high_pass_plant(spec2.nominal_plant, error_gain, error_tau),
                                   model=spec2.nominal_plant), ts)
        f2 = fly(true2, second, df12)
        trials = [SourceTrial(l1, f1.e, f1.d_f, delta_set(specs[first], ts, 8, rng, bound=0.05)),
                  SourceTrial(l2, f2.e, f2.d_f, delta_set(spec2, ts, 8, rng, bound=abs(error_gain)))]
        rows.append(ExtensionRow(
            scenario=sid, title=sc.title, reference_pair=f"{first} -> {second}",
            paper_reference_dropped=paper_ref, exact_reference=exact_ref,
            multi_target=f"{third} after {first}, {second}",
            paper_last_only=ratio(l3, third, closed_form_filters(l2, l3).apply(f2.e, f2.d_f)),
            joint_equal=ratio(l3, third, multi_source_learning(l3, trials, "equal")),
            joint_confidence=ratio(l3, third, multi_source_learning(l3, trials))))
    return rows


def format_extensions(rows: list[ExtensionRow], error_gain: float = 0.8, error_tau: float = 1.0) -> str:
    """Markdown tables of :func:`extensions_study`."""
    out = ["## Exact reference term (exact models, each vehicle's noise)", "",
           "| scenario | pair | paper (reference dropped) | reference kept | gain |", "|---|---|---|---|---|"]
    out += [f"| {r.scenario} {r.title} | {r.reference_pair} | {r.paper_reference_dropped:.5f} | "
            f"{r.exact_reference:.5f} | {r.paper_reference_dropped / r.exact_reference:.1f}x |" for r in rows]
    out += ["", f"## Learning from every earlier system (Case II: second system's true plant "
                f"P_hat (1 + {error_gain:g} {error_tau:g}s/({error_tau:g}s + 1)))", "",
            "| scenario | learner | paper (last system only) | joint, equal weights | joint, confidence weights "
            "| gain |", "|---|---|---|---|---|---|"]
    out += [f"| {r.scenario} {r.title} | {r.multi_target} | {r.paper_last_only:.5f} | {r.joint_equal:.5f} | "
            f"{r.joint_confidence:.5f} | {r.paper_last_only / r.joint_confidence:.1f}x |" for r in rows]
    out += ["", "Ratios ||e_j|| / ||e'_j|| (learning flight over the same vehicle's DOB-only flight); smaller is "
                "better."]
    return "\n".join(out) + "\n"
