"""FIR learning filters with the learning system's Q-filter bandwidth chosen jointly.

System j's DOB low-pass ``Q_j(s) = 1/(tau s + 1)^n`` shapes both its own disturbance
rejection and what learning can still do (``Te1 = Gd_j/Gd_{j-1} - Gf_j L1``, docs/theory.md
sections 2-3). Where asked, ``tau`` is chosen together with the FIR coefficients: an outer
bounded scalar search over ``log10 tau`` (scipy ``minimize_scalar``, method ``"bounded"``)
around the CasADi/IPOPT FIR design of :func:`~ilcdob.design.fir.design_fir`, minimising the
robust residual of learning::

    J(tau) = max_k  mean_{w in band} |Te1_k(e^{jw Ts}; tau)|^2

over the paired Delta samples k (band: ``FIROptions.weight_band``; the fleet's own ``tau`` is
evaluated first, so the result is never worse than it), subject to the FIR
design's own constraint ``|Te1_k| <= 1 - margin``; a ``tau`` for which that fails, or whose
loop is unstable, counts as infeasible. The search is bilevel (``tau`` enters the loop maps
through the ZOH/Tustin discretisation, which CasADi would have to differentiate through), and
each evaluation is one FIR design (about 1-2 s).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize_scalar

from ilcdob.errors import IlcdobError, SpecError
from ilcdob.loop import LoopSystem, build_loop

from .delta import DeltaSet
from .fir import FIRDesign, FIRDesignError, FIROptions, design_fir

__all__ = ["JointQDesign", "design_fir_joint_q"]


@dataclass(frozen=True)
class JointQDesign:
    """FIR design at the chosen Q time constant of system j.

    Attributes
    ----------
    q_time_constant : float
        Chosen ``tau`` of system j's Q, s.
    design : FIRDesign
        The FIR pair at that ``tau`` (with ``next_loop`` rebuilt with it).
    objective : float
        ``J(tau)`` (module docstring).
    evaluations : list of (tau, J or None)
        Every ``tau`` tried (None: infeasible).
    """

    q_time_constant: float
    design: FIRDesign
    objective: float
    evaluations: list[tuple[float, float | None]]


def _with_tau(loop: LoopSystem, tau: float) -> LoopSystem:
    spec = loop.spec
    return build_loop(replace(spec, dob=replace(spec.dob, q_time_constant=tau)), loop.ts)


def design_fir_joint_q(prev_loop: LoopSystem, next_loop: LoopSystem, delta_prev: DeltaSet, delta_next: DeltaSet,
                       options: FIROptions | None = None, tau_bounds: tuple[float, float] = (0.05, 0.5),
                       max_evaluations: int = 12) -> JointQDesign:
    """Choose system j's Q time constant and its FIR learning filters together (module docstring).

    Raises
    ------
    SpecError
        Bad ``tau_bounds`` or ``max_evaluations``.
    FIRDesignError
        No ``tau`` tried gave a feasible design.
    """
    lo, hi = (float(v) for v in tau_bounds)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
        raise SpecError(f"`tau_bounds`: got {tau_bounds!r}, expected (lo, hi) with 0 < lo < hi, in s")
    if max_evaluations < 3:
        raise SpecError(f"`max_evaluations`: got {max_evaluations!r}, expected >= 3")
    options = options or FIROptions()
    band = options.weight_band
    evaluations: list[tuple[float, float | None]] = []
    designs: dict[float, tuple[float, FIRDesign]] = {}

    def objective(log_tau: float) -> float:
        tau = float(10.0 ** log_tau)
        try:
            nxt = _with_tau(next_loop, tau)
            dn = replace(delta_next, nominal=nxt, loops=tuple(_with_tau(lp, tau) for lp in delta_next.loops))
            design = design_fir(prev_loop, nxt, delta_prev, dn, options)
        except IlcdobError:
            evaluations.append((tau, None))
            return 1e6 * (1 + abs(log_tau - np.log10(next_loop.spec.dob.q_time_constant)))
        inside = (design.w >= band[0]) & (design.w <= band[1])
        j = float(np.max(np.mean(design.te1[:, inside] ** 2, axis=1)))
        evaluations.append((tau, j))
        designs[tau] = (j, design)
        return j

    current = next_loop.spec.dob.q_time_constant
    if lo <= current <= hi:  # the fleet's own tau is a candidate: the result is never worse than it
        objective(float(np.log10(current)))
    minimize_scalar(objective, bounds=(np.log10(lo), np.log10(hi)), method="bounded",
                    options={"maxiter": max_evaluations, "xatol": 0.01})
    if not designs:
        raise FIRDesignError(f"FIR learning filter {prev_loop.name!r} -> {next_loop.name!r}: no Q time constant in "
                             f"[{lo:g}, {hi:g}] s gave a feasible design ({len(evaluations)} tried); widen "
                             "tau_bounds, reduce the margin or the uncertainty, or add taps")
    tau = min(designs, key=lambda k: designs[k][0])
    return JointQDesign(q_time_constant=tau, design=designs[tau][1], objective=designs[tau][0],
                        evaluations=evaluations)
