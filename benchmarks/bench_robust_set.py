"""Benchmark: the robust-set design (:func:`ilcdob.design.methods.robust_set.design_robust_set`), before and after.

Per pair, the whole design (the FIR ``F``, its verification, the closed form and the whole-trial figure
``rho_N``) is timed in one process with

* ``before``: the formulation as it was (the pieces that differ, ``_old_*`` below, swapped into today's
  design for the run): the structured set's polygon and sagitta built from every value of its grid on
  all 20,199 verification frequencies, the 60 worst violations per exchange round, ``F`` on the
  verification grid as a dense ``20,199 x n_taps`` matrix;
* ``after``: the current :mod:`ilcdob.design.methods.robust_set` / :mod:`ilcdob.design.sets.value_set` (the
  set's boundary values where they decide the polygon, runs of violations in the exchange, ``F`` by
  Horner's rule).

The design cache is cleared before every design; the two are interleaved (before, after, before,
after, ...) and the median CPU time (``time.process_time``: every thread of the process, Clarabel's
included) of ``--repeat`` designs is reported with their ratio. The figures of each design (rho_best,
rho_guaranteed, nominal_worst) are printed for both, and the largest tap difference.

Pairs: the built-in fleet's default design (``ilcdob design --method robust-set``: the source's Delta
set from its identification, guaranteed over its parameter ellipsoid) for UAV1->UAV2, UAV2->UAV3 and
UAV1->UAV3; ``delta_set="structured"`` (for an identified source: the same ellipsoid); the README's
example (UAV2->UAV3, rho 0.8, disc of bound 0.3). ``--extra`` adds the fleet-bound sets of
reports/robust_set (UAV1->UAV2 at bound 0.5 and 0.9: disc, and the structured gain/high-pass family at
margins 0.5, 0.2 and 0), which take 14-70 s each before.

Run:  python benchmarks/bench_robust_set.py [--repeat 3] [--extra] [--only NAME,...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings
from dataclasses import dataclass

import numpy as np

import ilcdob
from ilcdob.design.methods import robust_set as rs
from ilcdob.design.sets import value_set as vs
from ilcdob.design.pair import fleet_delta_sets
from ilcdob.design.methods.robust_set import RobustSetDesign, RobustSetOptions, structured_set
from ilcdob.design.sets.value_set import EllipseFamily, ValueSet


# ---------------------------------------------------------------------------------------------------------------
# Before: only what the formulation did differently (design/methods/robust_set.py and design/sets/value_set.py as
# they were).
# ``before`` runs today's ``_design_filter`` (and SOCP, verification, polygon and image, unchanged since) with these
# four pieces swapped in: the set's rows from every value of its grid (its values by ``einsum``), the sagitta as the
# distance to the chord of the images, the 60 worst violations per exchange round, and ``F`` on the verification
# grid as a dense ``n_verify x n_taps`` matrix, built once per design.
# ---------------------------------------------------------------------------------------------------------------

def _old_values(family, source, w, margin):
    """``family.values`` as it was: the ellipse's grid by ``einsum``."""
    if isinstance(family, EllipseFamily):
        a = family.axes(source.ts, w)
        phi = np.linspace(0, 2 * np.pi, 2 * family.n_phi + 1)
        rho = np.linspace(0, 1, 2 * family.n_rad - 1)
        u = rho[:, None, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)[None]
        xy = np.einsum("wij,rpj->wrpi", a, u)
        return ValueSet(w, (xy[..., 0] + 1j * xy[..., 1],), family.describe())
    return family.values(source, w, margin)


def _old_sagitta(values, t0, keep, g):
    """``_sagitta`` as it was: the distance of each odd image point from the chord of its even neighbours."""
    out = np.zeros(g.shape[0])
    for arr in (g, np.swapaxes(g, 1, 2)):
        a, m, b = arr[:, 0:-2:2], arr[:, 1:-1:2], arr[:, 2::2]
        chord = b - a
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(np.real((m - a) * np.conj(chord)) / np.abs(chord) ** 2, 0, 1)
            d = np.abs(m - (a + np.where(np.abs(chord) > 0, t, 0) * chord))
        d = np.where(np.isfinite(d), d, 0.0).reshape(g.shape[0], -1)
        if d.shape[1]:
            out = np.maximum(out, d.max(axis=1))
    return out


def _old_family_rows(source, family, w, t0, margin, directions):
    """``_family_rows`` as it was: the rows of the whole grid, never the boundary's."""
    return vs._cone_rows(_old_values(family, source, w, margin), t0, margin, directions)


def _old_exchange_points(worst, bad, n_max=60):
    """``_exchange_points`` as it was: the ``n_max`` worst violations."""
    idx = np.flatnonzero(bad)
    return idx[np.argsort(-np.nan_to_num(worst[idx], posinf=1e12))][:n_max]


_DENSE: dict = {}  # the dense matrix of the design in progress (cleared before every design)


def _old_fir_response(h, w, ts, lead):
    """``_fir_response`` as it was: ``F`` on ``w`` through the dense matrix ``exp(-j w Ts (i - lead))``."""
    key = (id(w), w.size, ts, lead, h.size)
    if key not in _DENSE:
        _DENSE[key] = np.exp(-1j * np.outer(w * ts, np.arange(h.size) - lead))
    return _DENSE[key] @ h


#: (module, name, the piece as it was) swapped in for a ``before`` design.
_BEFORE = ((vs, "_family_rows", _old_family_rows), (vs, "_sagitta", _old_sagitta),
           (rs, "_exchange_points", _old_exchange_points), (rs, "_fir_response", _old_fir_response))


# ---------------------------------------------------------------------------------------------------------------
# The pairs and the timing
# ---------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Case:
    """One design: source, target, a common bound (None: the fleet's own Delta sets) and options."""

    name: str
    source: str
    target: str
    bound: float | None
    options: RobustSetOptions


CASES = [
    Case("UAV1->UAV2 default", "UAV1", "UAV2", None, RobustSetOptions()),
    Case("UAV2->UAV3 default", "UAV2", "UAV3", None, RobustSetOptions()),
    Case("UAV1->UAV3 default", "UAV1", "UAV3", None, RobustSetOptions()),
    Case("UAV1->UAV2 structured", "UAV1", "UAV2", None, RobustSetOptions(delta_set="structured")),
    Case("UAV2->UAV3 disc 0.3", "UAV2", "UAV3", 0.3, RobustSetOptions(rho=0.8, delta_set="disc")),
]
EXTRA = [
    Case("UAV1->UAV2 disc 0.5", "UAV1", "UAV2", 0.5, RobustSetOptions(rho=0.8, delta_set="disc")),
    Case("UAV1->UAV2 disc 0.9", "UAV1", "UAV2", 0.9, RobustSetOptions(rho=0.8, delta_set="disc")),
    Case("UAV1->UAV2 family 0.9", "UAV1", "UAV2", 0.9, RobustSetOptions(delta_set="structured")),
    Case("UAV1->UAV2 family 0.9 m0.2", "UAV1", "UAV2", 0.9, RobustSetOptions(delta_set="structured", margin=0.2)),
    Case("UAV1->UAV2 family 0.9 m0", "UAV1", "UAV2", 0.9, RobustSetOptions(delta_set="structured", margin=0.0)),
    Case("UAV1->UAV2 family 0.5", "UAV1", "UAV2", 0.5, RobustSetOptions(rho=0.8, delta_set="structured")),
]


def _design(fleet, case: Case, before: bool) -> tuple[float, RobustSetDesign]:
    """One whole design (cache cleared), its CPU time and result; ``before`` swaps in the pieces as they were."""
    ds = fleet_delta_sets(fleet, [case.source, case.target], bound=case.bound)[case.source]
    spec = next(s for s in fleet.systems if s.name == case.source)
    structure = structured_set(spec, ds.source, ds.bound, case.options.delta_set)
    rs._CACHE.clear()
    _DENSE.clear()
    today = [(module, name, getattr(module, name)) for module, name, _ in _BEFORE]
    if before:
        for module, name, old in _BEFORE:
            setattr(module, name, old)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            t0 = time.process_time()
            d = rs.design_robust_set(fleet.loop(case.source), fleet.loop(case.target), ds.w, ds.bound,
                                     case.options, structure)
            return time.process_time() - t0, d
    finally:
        for module, name, fn in today:
            setattr(module, name, fn)


def run(cases: list[Case], repeat: int = 3) -> list[dict]:
    """Interleaved before/after designs of every case; medians of the CPU times and both designs' figures."""
    fleet = ilcdob.default_fleet()
    for case in cases[:1]:  # warm caches shared by both (sampled blocks, admissible ranges, imports)
        _design(fleet, case, False)
    out = []
    for case in cases:
        times = {True: [], False: []}
        result = {}
        for _ in range(repeat):
            for before in (True, False):
                t, d = _design(fleet, case, before)
                times[before].append(t)
                result[before] = d
        b, a = result[True], result[False]
        out.append({"case": case.name, "before_s": statistics.median(times[True]),
                    "after_s": statistics.median(times[False]),
                    **{f"{k}_{tag}": getattr(d, k) for tag, d in (("before", b), ("after", a))
                       for k in ("rho_best", "rho_guaranteed", "nominal_worst", "rho_design", "exchanges")},
                    "taps_diff": float(np.max(np.abs(a.F.h - b.F.h)))})
        r = out[-1]
        print(f"{r['case']:28s} {r['before_s']:7.2f} {r['after_s']:6.2f} {r['before_s'] / r['after_s']:6.1f}x  "
              f"{r['rho_best_before']:.6f} {r['rho_best_after']:.6f}  {r['rho_guaranteed_before']:.6f} "
              f"{r['rho_guaranteed_after']:.6f}  {r['nominal_worst_before']:.3e} {r['nominal_worst_after']:.3e}  "
              f"{r['exchanges_before']}/{r['exchanges_after']}  {r['taps_diff']:.1e}", flush=True)
    return out


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="designs per method and case (median)")
    parser.add_argument("--extra", action="store_true", help="add the fleet-bound sets of reports/robust_set")
    parser.add_argument("--only", default="", help="comma-separated case names (substrings) to run")
    args = parser.parse_args()
    chosen = CASES + (EXTRA if args.extra else [])
    if args.only:
        keys = [k.strip() for k in args.only.split(",")]
        chosen = [c for c in CASES + EXTRA if any(k in c.name for k in keys)]
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}; "
          f"CPU time = time.process_time (all threads), median of {args.repeat}")
    print(f"{'case':28s} {'before':>7s} {'after':>6s} {'ratio':>7s}  {'rho_best before/after':21s}  "
          f"{'rho_guaranteed before/after':27s}  {'nominal_worst before/after':21s}  exch  max|dh|")
    run(chosen, args.repeat)
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
