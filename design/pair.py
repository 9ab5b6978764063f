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
from ilcdob.lifted import check_lifted_size
from ilcdob.display import html_table

from .closed_form import closed_form_filters
from .delta import DeltaSet, delta_set
from .export import zpk_to_coefficients
from .fir import FIROptions, design_fir
from .laws import DEFAULT_LAW, LAW_DESCRIPTIONS, ReferenceTerms, check_law, reference_terms
from .norm_optimal import NormOptimalDesigner, NormOptimalOptions, norm_optimal_learning
from .robust import RobustOptions, RobustPairDesigner
from .robust_set import RobustSetOptions, design_robust_set

__all__ = ["PairDesign", "design_pair", "with_law", "fleet_delta_sets", "METHODS", "DEFAULT_METHODS"]

METHODS = ("closed-form", "fir", "norm-optimal", "robust", "robust-set")
#: The designs that comparisons and campaigns run unless told otherwise (robust-set takes a
#: minute or more per source vehicle: on request).
DEFAULT_METHODS = ("closed-form", "fir", "norm-optimal", "robust")


@dataclass(frozen=True)
class PairDesign:
    """A learning design for system ``target`` learning from ``source``.

    Attributes
    ----------
    method : str
        Design method (one of :data:`METHODS`).
    filters : dict
        ``filters.json`` content.
    lifted : dict of str -> array, or None
        ``L1``, ``L2`` (N x N) for the norm-optimal method.
    learn : callable (e_prev, df_prev) -> d_f
        Learning signal of the target from a trial of the source (m, m/s^2 -> m/s^2).
    robust : RobustPairDesigner or None
        For the robust method: the per-trial SOCP (its ``design`` gives ratios per model).
    law : str
        Learning law (:mod:`ilcdob.design.laws`): ``"paper"`` or ``"exact-reference"``.
    reference : ReferenceTerms or None
        ``exact-reference``: the pair's reference terms, already applied by ``learn`` (callers of
        ``robust.design`` apply ``reference.error_in`` / ``reference.signal_out`` themselves).
    """

    method: str
    filters: dict[str, Any]
    learn: Callable[[np.ndarray, np.ndarray], np.ndarray]
    lifted: dict[str, np.ndarray] | None = field(default=None)
    robust: RobustPairDesigner | None = field(default=None, repr=False)
    law: str = DEFAULT_LAW
    reference: ReferenceTerms | None = field(default=None, repr=False)

    def __repr__(self) -> str:
        pair = f"{self.filters.get('from', '?')} -> {self.filters.get('to', '?')}"
        return f"<PairDesign {self.method} {pair}, law {self.law}: {self.order}>"

    def _repr_html_(self) -> str:
        rows = [[k, v] for k, v in self.filters.items() if isinstance(v, (str, int, float, bool))]
        return html_table(f"{self.method} design {self.filters.get('from', '?')} -> {self.filters.get('to', '?')}",
                          ["", "value"], [*rows, ["order", self.order]])

    @property
    def order(self) -> str:
        """Implementation size: filter orders (zpk/FIR), lifted matrix size, or SOCP models."""
        f = self.filters
        if self.method == "norm-optimal":
            return f"lifted {f['n']}x{f['n']}"
        if self.method == "robust-set":
            return f"closed form + {len(f['F']['num'])}-tap FIR"
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
    """Delta sets of the named systems: from each identification (scaled), or a common ``bound``.

    Parameters
    ----------
    fleet : Fleet
        The fleet.
    names : list of str
        Systems to draw Delta sets for, in this order (one generator serves them all).
    k : int
        Sampled true plants per system.
    bound : float, optional
        A common multiplicative bound for every system (default: each system's own stated
        bound or identification, see :func:`~ilcdob.design.delta.delta_set`).
    scale : float
        Multiplier of the identified standard deviations.
    seed : int
        Seed of the random generator.

    Returns
    -------
    dict of str to DeltaSet
        Name -> Delta set.
    """
    rng = np.random.default_rng(seed)
    return {name: delta_set(next(s for s in fleet.systems if s.name == name), fleet.sample_time, k, rng,
                            scale=scale, bound=bound) for name in names}


def design_pair(fleet: Fleet, source: str, target: str, method: str = "closed-form", n: int | None = None,
                norm_optimal: NormOptimalOptions | None = None, fir: FIROptions | None = None,
                deltas: dict[str, DeltaSet] | None = None, robust: RobustOptions | None = None,
                relax: bool = False, lifted: bool = True, law: str = DEFAULT_LAW,
                reference: np.ndarray | None = None, acceleration: np.ndarray | None = None,
                robust_set: RobustSetOptions | None = None) -> PairDesign:
    """Design the learning filters of ``target`` from ``source`` with ``method``.

    Parameters
    ----------
    fleet : Fleet
    source, target : str
        System names (j-1 and j).
    method : {"closed-form", "fir", "norm-optimal", "robust", "robust-set"}
        ``robust-set``: closed form followed by a FIR whose improvement is guaranteed for every
        multiplicative error of the source within its Delta set's bound (:mod:`.robust_set`).
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
    law : {"paper", "exact-reference"}
        Learning law (:mod:`ilcdob.design.laws`). ``exact-reference`` wraps the method's learning
        (its filters act on the disturbance part of the source's error) with the reference terms
        of ``reference``; ``multi-source`` learns from several trials and is refused here.
    reference : array, m, optional
        ``exact-reference``: reference position of the trial (required).
    acceleration : array, m/s^2, optional
        ``exact-reference``: reference acceleration, for controllers that feed it forward.
    robust_set : RobustSetOptions, optional
        Options of the robust-set design (default: ``rho`` of ``robust``, capped at 1, else 0.95);
        its bound is ``deltas[source].bound``.

    Raises
    ------
    SpecError
        Unknown method or law, ``multi-source``, ``exact-reference`` without ``reference``.
    """
    if check_law(law) != DEFAULT_LAW:  # every other argument forwarded as given (locals() holds only them here)
        given = {k: v for k, v in locals().items() if k not in ("law", "reference", "acceleration")}
        return with_law(design_pair(**given), fleet, source, target, law, reference, acceleration)
    if reference is not None or acceleration is not None:
        raise SpecError("`reference`/`acceleration`: only the exact-reference law uses the reference trajectory; "
                        "got one with law 'paper' (pass law='exact-reference')")
    if method not in METHODS:
        raise SpecError(f"`method`: got {method!r}, valid methods are {list(METHODS)}")
    src, tgt = fleet.loop(source), fleet.loop(target)
    head = {"method": method, "law": DEFAULT_LAW, "from": source, "to": target, "sample_time": fleet.sample_time}
    if method == "closed-form":
        lf = closed_form_filters(src, tgt)
        filters = {**head, "L1": zpk_to_coefficients(lf.L1), "L2": zpk_to_coefficients(lf.L2),
                   "units": {"L1": "(m/s^2)/m", "L2": "1"}}
        return PairDesign(method, filters, lf.apply)
    if method in ("fir", "robust", "robust-set"):
        deltas = deltas or fleet_delta_sets(fleet, [source, target])
    if method == "robust-set":
        rs_opts = robust_set or RobustSetOptions(rho=min(1.0, robust.rho) if robust is not None else 0.95)
        rs = design_robust_set(src, tgt, deltas[source].w, deltas[source].bound, rs_opts)
        filters = {**head, "closed_form": {"L1": zpk_to_coefficients(rs.filters.L1),
                                           "L2": zpk_to_coefficients(rs.filters.L2)},
                   "units": {"L1": "(m/s^2)/m", "L2": "1", "F": "1"},
                   "learning": "d_f,j = F{L1{e_{j-1}} + L2{d_f,{j-1}}}, computed on a trial as (1 - Q_j){F{d_hat}} "
                               "with d_hat the disturbance reconstructed by the model (F: FIR, output(k) = "
                               "sum_i num[i] input(k + advance - i)); no C code",
                   "delta_set": {source: deltas[source].source}, **rs.to_dict()}
        return PairDesign(method, filters, rs.apply)
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
        check_lifted_size(n, "n")
        l1, l2 = NormOptimalDesigner(tgt, n, opts).lifted_matrices(src)
        matrices = {"L1": l1, "L2": l2}
    filters = {**head, "options": {"lam": opts.lam, "mu": opts.mu, "weight": opts.weight}, "n": n,
               "lifted": "lifted.npz (L1, L2: d_f,j = L1 e_{j-1} + L2 d_f,{j-1})"}
    return PairDesign(method, filters, lambda e, df: norm_optimal_learning(src, tgt, e, df, opts),
                      matrices)


def with_law(design: PairDesign, fleet: Fleet, source: str, target: str, law: str,
             reference: np.ndarray | None = None, acceleration: np.ndarray | None = None) -> PairDesign:
    """``design`` (made for the paper's law) learning with ``law`` instead (see :func:`design_pair`).

    Parameters
    ----------
    design : PairDesign
        A design of ``source`` -> ``target`` with the paper's law.
    fleet : Fleet
    source, target : str
        Systems j-1 and j.
    law : {"exact-reference"}
        ``multi-source`` is refused (it needs every earlier trial); ``paper`` returns ``design``.
    reference, acceleration : array, optional
        Reference position (m) and acceleration (m/s^2) of the trial.

    Raises
    ------
    SpecError
        Unknown law, ``multi-source``, a design that already has a law other than the paper's,
        no ``reference``, or no ``acceleration`` for a pair with acceleration feed-forward.
    """
    if check_law(law) == DEFAULT_LAW:
        return design
    if design.law != DEFAULT_LAW:
        raise SpecError(f"`design`: already learns with law {design.law!r}; give a design made with the paper's law")
    if law == "multi-source":
        raise SpecError("`law`: 'multi-source' learns from the trials of every earlier system at once, and a pair "
                        f"design ({source} -> {target}) learns from one trial of {source}; use "
                        "ilcdob.design.multi_source.multi_source_learning with every trial, or "
                        "reproduce(..., law='multi-source') for a learning chain")
    if reference is None:
        raise SpecError(f"`reference`: the exact-reference law needs the reference trajectory of the trial "
                        f"(m, sampled every {fleet.sample_time} s); got none")
    terms = reference_terms(fleet.loop(source), fleet.loop(target), reference, acceleration)
    filters = {**design.filters, "law": law,
               "reference_terms": {**terms.to_dict(),
                                   "rule": "d_f,j = learning{e_{j-1} - e_ref,{j-1}, d_f,{j-1}} + correction "
                                           "(reference_terms.csv: e_ref_source in m, correction in m/s^2)",
                                   "law": LAW_DESCRIPTIONS[law]}}
    return PairDesign(design.method, filters, terms.wrap(design.learn), design.lifted, design.robust, law, terms)
