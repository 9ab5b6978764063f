"""One learning design for a pair of systems (j-1 -> j), by method, and its outputs.

This is the API behind ``ilcdob design``: it builds the design, the ``filters.json``
content (discrete filters applied to the previous system's error and learning signal:
second-order sections or FIR taps with a non-causal ``advance``, see :mod:`.export`; the C
code of :mod:`.c_export` runs them), the lifted matrices
for the lifted methods, and the learning signal for a given trial of the previous system.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet

from .closed_form import closed_form_filters
from .delta import DeltaSet, delta_set
from .export import zpk_to_coefficients
from .fir import FIROptions, design_fir
from .norm_optimal import NormOptimalDesigner, NormOptimalOptions, norm_optimal_learning
from .robust import RobustOptions, RobustPairDesigner

__all__ = ["PairDesign", "design_pair", "fleet_delta_sets", "METHODS"]

METHODS = ("closed-form", "fir", "norm-optimal", "robust")


@dataclass(frozen=True)
class PairDesign:
    """A learning design for system ``target`` learning from ``source``.

    Attributes
    ----------
    method : str
    filters : dict
        ``filters.json`` content.
    lifted : dict of str -> array, or None
        ``L1``, ``L2`` (N x N) for the norm-optimal method.
    learn : callable (e_prev, df_prev) -> d_f
        Learning signal of the target from a trial of the source (m, m/s^2 -> m/s^2).
    robust : RobustPairDesigner or None
        For the robust method: the per-trial SOCP (its ``design`` gives ratios per model).
    """

    method: str
    filters: dict[str, Any]
    learn: Callable[[np.ndarray, np.ndarray], np.ndarray]
    lifted: dict[str, np.ndarray] | None = field(default=None)
    robust: RobustPairDesigner | None = field(default=None, repr=False)

    @property
    def order(self) -> str:
        """Implementation size: filter orders (zpk/FIR), lifted matrix size, or SOCP models."""
        f = self.filters
        if self.method == "norm-optimal":
            return f"lifted {f['n']}x{f['n']}"
        if self.method == "robust":
            return f"per-trial SOCP, {f['models']} models"
        return ", ".join(f"{k}: {_filter_size(f[k])}" for k in ("L1", "L2"))


def _filter_size(coeffs: dict[str, Any]) -> str:
    """``"17 SOS, advance 24"`` for sections, ``"79/0"`` (numerator/denominator degree) otherwise."""
    if coeffs.get("sos"):
        return f"{len(coeffs['sos'])} SOS, advance {coeffs['advance']}"
    return f"{len(coeffs['num']) - 1}/{len(coeffs['den']) - 1}"


def fleet_delta_sets(fleet: Fleet, names: list[str], k: int = 8, bound: float | None = None,
                     scale: float = 1.0, seed: int = 0) -> dict[str, DeltaSet]:
    """Delta sets of the named systems: from each identification (scaled), or a common ``bound``."""
    rng = np.random.default_rng(seed)
    return {name: delta_set(next(s for s in fleet.systems if s.name == name), fleet.sample_time, k, rng,
                            scale=scale, bound=bound) for name in names}


def design_pair(fleet: Fleet, source: str, target: str, method: str = "closed-form", n: int | None = None,
                norm_optimal: NormOptimalOptions | None = None, fir: FIROptions | None = None,
                deltas: dict[str, DeltaSet] | None = None, robust: RobustOptions | None = None,
                relax: bool = False, lifted: bool = True) -> PairDesign:
    """Design the learning filters of ``target`` from ``source`` with ``method``.

    Parameters
    ----------
    fleet : Fleet
    source, target : str
        System names (j-1 and j).
    method : {"closed-form", "fir", "norm-optimal", "robust"}
    n : int, optional
        Trial length in samples for the lifted matrices of the lifted methods (default 500).
    norm_optimal : NormOptimalOptions, optional
    fir : FIROptions, optional
    deltas : dict name -> DeltaSet, optional
        Sampled true loops of ``source`` and ``target`` for the robust constraint of the FIR
        design and the models of the robust design (default: :func:`fleet_delta_sets` with
        K = 8 from the identifications).
    robust : RobustOptions, optional
        Options of the robust SOCP; its models are the nominal pair plus the paired samples.
    relax : bool
        Robust method: design at the smallest feasible rho (with a warning) when ``rho`` is
        infeasible for a trial, instead of raising.
    lifted : bool
        Norm-optimal: build the N x N matrices L1, L2 (O(N^2) memory; not needed to learn).
    """
    if method not in METHODS:
        raise SpecError(f"`method`: got {method!r}, valid methods are {list(METHODS)}")
    src, tgt = fleet.loop(source), fleet.loop(target)
    head = {"method": method, "from": source, "to": target, "sample_time": fleet.sample_time}
    if method == "closed-form":
        lf = closed_form_filters(src, tgt)
        filters = {**head, "L1": zpk_to_coefficients(lf.L1), "L2": zpk_to_coefficients(lf.L2),
                   "units": {"L1": "(m/s^2)/m", "L2": "1"}}
        return PairDesign(method, filters, lf.apply)
    if method in ("fir", "robust"):
        deltas = deltas or fleet_delta_sets(fleet, [source, target])
    if method == "robust":
        opts = robust or RobustOptions()
        designer = RobustPairDesigner([src, *deltas[source].loops], [tgt, *deltas[target].loops], opts, relax)
        filters = {**head, "models": len(designer.sources),
                   "delta_set": {source: deltas[source].source, target: deltas[target].source},
                   "options": {"rho": opts.rho, "lam": opts.lam, "mu": opts.mu, "reduction_tol": opts.reduction_tol},
                   "learning": "per trial (SOCP over the models): learning_signal.csv and lifted.npz"}
        return PairDesign(method, filters, designer.learn, robust=designer)
    if method == "fir":
        fd = design_fir(src, tgt, deltas[source], deltas[target], fir)
        info = fd.to_dict()
        filters = {**head, "L1": info.pop("L1"), "L2": info.pop("L2"),
                   "units": {"L1": "(m/s^2)/m", "L2": "1"},
                   "robustness": {k: v for k, v in info.items() if k not in ("source", "target")}}
        return PairDesign(method, filters, fd.apply)
    opts = norm_optimal or NormOptimalOptions()
    n = 500 if n is None else int(n)
    if n < 2:
        raise SpecError(f"`n`: got {n}, expected a trial length >= 2 samples")
    matrices = None
    if lifted:
        l1, l2 = NormOptimalDesigner(tgt, n, opts).lifted_matrices(src)
        matrices = {"L1": l1, "L2": l2}
    filters = {**head, "options": {"lam": opts.lam, "mu": opts.mu, "weight": opts.weight}, "n": n,
               "lifted": "lifted.npz (L1, L2: d_f,j = L1 e_{j-1} + L2 d_f,{j-1})"}
    return PairDesign(method, filters, lambda e, df: norm_optimal_learning(src, tgt, e, df, opts),
                      matrices)
