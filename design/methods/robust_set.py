"""Robust learning whose improvement guarantee holds over the whole Delta set (paper Secs. II-III).

The learning law of the Theorem (paper Sec. III) gives system j the signal
``d_f,j = L1{e'_{j-1}}`` with ``e'_{j-1} = e_{j-1} + Gf_{j-1}{d_f,j-1}`` and the closed-form
``L1 = -(1 - Q_j) Gd_{j-1}^{-1}`` built from system j-1's *model* (:mod:`..maps.closed_form`). Here
a robustness filter ``F`` (a non-causal FIR) is added to it::

    d_f,j = F{ L1{e'_{j-1}} } = (1 - Q_j){ F{ d_hat } },    d_hat = -Gd_{j-1}^{-1}{e'_{j-1}}

(the second form is how a trial is filtered, :meth:`RobustSetDesign.apply`), and ``F`` is chosen
so that the improvement holds for *every* true plant of system j-1 in the Delta set
``P_{j-1} = (1 + Delta) P_hat_{j-1}``, ``|Delta(e^{jw Ts})| <= W(w)`` (the multiplicative model
error of the Theorem, paper Sec. III), robustly over the set rather than on samples of it. The
ratio below is exact in Delta, where the Theorem's condition (:mod:`..checks.theorem`) rests on a
first-order expansion.

Error map. With the loop maps of the paper (Sec. II; :mod:`ilcdob.loop`)
``D = 1 - Q + P (M + C)``, ``Gd = P (1 - Q)/D``, ``Gf = -P/D``, a trial of system j-1 without
learning under disturbance ``d`` gives ``e'_{j-1} = -Gd_{j-1}{d}`` and system j's error with and
without the learning signal are ``e_j = -Gd_j{d} - Gf_j{d_f,j}`` and ``e'_j = -Gd_j{d}``. Since
``Gf_j / Gd_j = -1/(1 - Q_j)`` holds for *any* plant of system j (its Q is software, known
exactly), the ratio of the two errors frequency by frequency is::

    T(w) = e_j / e'_j = 1 - F(w) * Gd_{j-1}(w) / Gd_hat_{j-1}(w)

independent of system j's plant. With ``P = (1 + Delta) P_hat`` and the nominal
``D_hat = 1 - Q + P_hat (M + C)``, ``D = D_hat + Delta P_hat (M + C)``, so::

    Gd / Gd_hat = (1 + Delta) / (1 + T0 Delta),     T0 = P_hat (M + C) / D_hat

(``T0``: complementary sensitivity of system j-1's nominal DOB loop), a Moebius map of
``Delta``. It maps the disc ``|Delta| <= W`` onto the disc with centre ``c`` and radius ``r``::

    c = (1 - conj(T0) W^2) / s,    r = |1 - T0| W / s,     s = 1 - |T0|^2 W^2

when ``s > 0``; when ``s <= 0`` the disc contains the pole ``Delta = -1/T0`` (an admissible
error that brings system j-1's loop to the stability boundary) and its image is unbounded.
The worst case over the disc is therefore *exactly*::

    max_{|Delta| <= W} |T(w)| = |1 - c F(w)| + r |F(w)|          (s > 0)

Multiplying by ``s > 0`` gives the homogeneous second-order-cone constraint used in the design,
well conditioned as ``s -> 0``::

    |s - (1 - conj(T0) W^2) F| + |1 - T0| W |F|  <=  rho s

Where ``W |T0| >= 1`` the worst case over the whole disc is unbounded for any ``F(w) != 0``, and a
FIR (or any rational filter) vanishing on a band vanishes everywhere: over the whole disc only
"no learning" would be guaranteed. There the design guarantees the improvement for the Deltas
that keep system j-1's true loop a stability margin ``m`` (``margin``), ``|1 + T0 Delta| >= m``:
``(1 + Delta)/(1 + T0 Delta) = 1/T0 + (1 - 1/T0)/(1 + T0 Delta)`` lies in the disc of centre
``1/T0`` and radius ``|1 - 1/T0|/m`` (a sound, conservative outer bound), used wherever
``W |T0| > 1 - m`` and it is the tighter of the two; where ``W |T0| <= 1 - m`` every Delta of the
disc has that margin, so nothing is excluded (:func:`uncertainty_cones`). With the built-in fleet
this matters: UAV1's DOB loop has ``|T0|`` up to 2.05 at 2.8 rad/s, so ``|Delta| <= 0.5`` already
reaches its stability boundary; ``F`` is then held near 0 over about 1.5-6 rad/s (no learning
where the source's true loop may resonate) and the guaranteed factor is 1 (never worse).

Design (an SOCP in the FIR taps ``h``, ``F(w) = e^{jw Ts a} sum_i h_i e^{-jw Ts i}``, solved by
Clarabel through cvxpy)::

    minimise    sum_w  weight(w) |1 - F(w)|^2  +  ridge ||h||^2          (nominal: T = 1 - F)
    subject to  the cone constraint above at every grid frequency, with rho_design

1. The asked rho first (with the exchange of step 3). A feasible rho whose verified worst case ends above
   it (the exchange stops within ``tol``) is designed again at ``rho - tol``; a design is feasible only
   where the verified ``rho_guaranteed <= rho``. ``rho_best``, the smallest rho an FIR of this order
   guarantees (same cones, minimise rho), is then only reported: one solve on the grid the design ended
   on, verified (an upper bound on the best; converging its own exchange took 7 solves, 15 s, at 2 ms).
   Where a frequency's set reaches its centre's distance (``R >= |b|``, or its image is unbounded) every
   ``F`` has a worst case of at least 1 there (``|a - b F| + R |F| >= a``): ``rho_best = 1`` without a solve.
2. Where the asked rho is not feasible (the SOCP infeasible, or not solved within
   :data:`_FIRST_TRY_ITERATIONS`, and the min-max filter with its exchange above rho),
   ``rho_design = min(1, rho_best + slack)``: the design says so (warning, or
   :class:`RobustSetInfeasibleError` with ``relax=False``) and guarantees the best it can. It never
   exceeds 1: no admissible plant is made worse than without learning.
3. Exchange: the worst case is evaluated on a dense verification grid (``n_verify`` points,
   linear to Nyquist, plus a log grid below ``w_min``); frequencies where it exceeds
   ``rho_design`` are added to the design grid and the SOCP is solved again (per round at most 60:
   the peak and the two ends of every run of violations, the runs taken in the order of their
   peaks, :func:`_exchange_points`).

What is guaranteed. For every ``Delta`` (stable, any phase) with ``|Delta| <= W`` at each
frequency (and, only where ``W |T0| > 1 - m``, ``|1 + T0 Delta| >= m``) and every disturbance,
``|T(w)| <= rho_guaranteed`` on the verification grid, hence (Parseval)
``||e_j|| <= rho_guaranteed ||e'_j||`` for signals over an infinite horizon. The bound is exact
for the disc where it is used (no conservatism from the Delta dependence) and conservative where
the margin disc is used; the remaining gaps are: (a) between verification-grid points the bound
is checked, not proved (spacing ``pi/(Ts n_verify)``, 0.008 rad/s by default; a structured set's
polygon is checked at every one of them, built from the set's boundary values where they decide it,
:func:`~..sets.value_set.family_cones`), and the exchange
stops within ``tol`` (2e-3) of the imposed rho, so ``rho_guaranteed <= rho_design + tol`` (it is
reported; where ``F`` must vanish on a band a FIR can only come within ``tol`` of it, hence e.g.
1.0013 for "never worse"); (b) a trial is finite: the bound is per frequency, i.e. for signals
over an infinite horizon, and a non-causal ``F`` at the ends of a trial acts on samples it does
not have (:meth:`RobustSetDesign.apply` says how they are treated). Every design flies whole trials of
its law for the stated set's extreme plants and the disturbances that meet a trial's ends
(:attr:`RobustSetDesign.whole_trial`, :mod:`..maps.whole_trial`) and says where one exceeds its
guarantee (:func:`check_whole_trial`). The whole-trial figure
``rho_N = max_d ||e_j|| / ||e'_j||`` of the lifted ``N``-sample map (:mod:`..maps.finite_horizon`) is
reported on request (:attr:`RobustSetDesign.finite`, exact models, ``finite_trial_s``). It exceeds 1
for every zero-phase ``F`` (1.5-2.1 on the built-in fleet at |Delta| <= 0.3 and 0.5, 60 s): the
worst disturbance sits in the trial's last half second, where ``F``'s look-ahead spreads it back
to times at which the error without learning has nothing. A causal ``F`` (``advance = 0``) keeps
the frequency-domain bound on every finite trial (``rho_N`` at most its nominal ``max |1 - F|``
plus the closed form's own end term, 0.002-0.014: causal lifted maps commute, so
``e_j = (1 - F R) e'_j`` exactly on the trial up to the stable inversion's last samples), but on
the built-in fleet at |Delta| <= 0.5 it learns nothing from UAV1 and UAV3 (``|1 - F| ~ 0.9-1`` in
the band, against 0.05-0.07 zero-phase); (c) the guarantee concerns the disturbance part: system
j-1's own learning signal (``d_f,j-1 != 0``, modelled by its nominal ``Gf``), the reference terms
``(1 - G_r) r`` and noise that differs between the two systems are outside it. The frequency-wise
disc is a superset of any structured Delta (real gains, fixed-order high-pass errors), so the
design is conservative for those: given a structured set (``structure``, :mod:`..sets.value_set`: the
fleet bound's gain/high-pass family, an identification's parameter ellipsoid) the same SOCP takes
several cone rows per frequency, the vertices of a polygon containing that set's image, and the
guarantee holds for every plant of the set that keeps the margin.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Callable

import control as ct
import cvxpy as cp
import numpy as np
from scipy.signal import fftconvolve

from ilcdob.errors import IlcdobError, SpecError
from ilcdob.lifted import markov_parameters
from ilcdob.loop import LoopSystem, freqresp
from ilcdob.signals import as_signal, check_grid

from ..maps.closed_form import (LearningFilters, closed_form_filters, inverse_gd_filter, one_minus,
                                reconstruct_disturbance, simulate_map)
from .fir import FIRFilter
from ..filters.frequency_grid import FitWeighting, check_advance, check_count, check_w_min, log_linear_grid
from ..filters.noncausal import lookahead
from ..filters.trial_edges import StartMatch, fir_on_trial
from ..filters.trial_inverse import MAX_TRIAL_SAMPLES, TrialInverse, trial_inverse
from ..sets.delta import disturbance_peak
from ..sets.value_set import TAU_RANGE, BoundFamily, EllipseFamily, admissible_range, family_cones, worst_over_set
from ..sets.worst_case import mask_intervals, uncertainty_cones
from ..maps.whole_trial import WholeTrialFigure, family_members, whole_trial_figure

#: A structured Delta set of the source (:mod:`..sets.value_set`).
StructuredSet = BoundFamily | EllipseFamily

if TYPE_CHECKING:
    from ..maps.finite_horizon import FiniteHorizonRatio, LinearMap

__all__ = ["RobustSetOptions", "RobustSetDesign", "RobustSetInfeasibleError", "RobustSetSolverError",
           "design_robust_set", "check_whole_trial", "bound_on_grid", "admissible", "admissibility", "structured_set", "DELTA_SETS", "TRIAL_LAWS", "START_LAWS", "choose_start"]

_OK = ("optimal", "optimal_inaccurate")
_INFEASIBLE = ("infeasible", "infeasible_inaccurate", "user_limit")  # user_limit: no certificate either way
#: Interior-point iterations of a first try at the asked rho: feasible ones took 10-25 on the fleets measured, an
#: infeasible one ran to Clarabel's 200 (7 s) without a certificate. Past it the min-max filter decides, and a rho it
#: shows feasible is solved again without the cap.
_FIRST_TRY_ITERATIONS = 60
_ITERATIONS = 200  # Clarabel's default
#: Choices of :attr:`RobustSetOptions.delta_set`.
DELTA_SETS = ("auto", "disc", "structured")
#: Choices of :attr:`RobustSetOptions.trial`.
TRIAL_LAWS = ("extended", "projected")
#: Choices of :attr:`RobustSetOptions.start`.
START_LAWS = ("auto", "matched", "fold")
#: Supporting directions of a structured set's polygon in the SOCP: a coarser polygon than the verification's
#: (:data:`~..sets.value_set.DIRECTIONS`), containing it, so fewer and better conditioned cones (64 per frequency
#: made Clarabel stall) and a design that the verification rarely sends back.
_DESIGN_DIRECTIONS = 16
_DIRECT_METHOD = "faer"  # supernodal, multithreaded: the dense tap columns make qdldl slow
#: Threads of Clarabel's KKT solver (0: its own choice, every core); campaigns set 1 on their workers, which
#: share the cores with each other.
CLARABEL_THREADS = 0
#: Clarabel's static regularisation, tried in turn when a solve ends in NumericalError: its default first, then
#: stronger ones (a structured set near the stability boundary, margin 0.1 and below, needed 1e-7 at the third
#: exchange round; the result is verified on the dense grid either way).
_STATIC_REGULARISATION = (1e-8, 1e-7, 1e-6)


class RobustSetInfeasibleError(IlcdobError, ValueError):
    """The asked rho cannot be guaranteed over the Delta set by any FIR of the given order.

    Parameters
    ----------
    message : str
        The error message.
    rho : float
        The asked improvement factor.
    rho_best : float
        The smallest factor an FIR of this order guarantees (minimised directly).

    Attributes
    ----------
    rho : float
        The asked improvement factor.
    rho_best : float
        The smallest factor an FIR of this order guarantees.
    """

    def __init__(self, message: str, rho: float, rho_best: float):
        super().__init__(message)
        self.rho = rho
        self.rho_best = rho_best


class RobustSetSolverError(IlcdobError, RuntimeError):
    """The conic solver failed on the robust-set SOCP (no solution, no infeasibility certificate)."""


@dataclass(frozen=True)
class RobustSetOptions(FitWeighting):
    """Options of :func:`design_robust_set` (module docstring gives the problem).

    Attributes
    ----------
    rho : float
        Asked guaranteed improvement, ``|T(w)| <= rho`` for every admissible Delta; in (0, 1].
    relax : bool
        If ``rho`` cannot be guaranteed, design at the best guaranteed rho (with a
        ``RuntimeWarning``) instead of raising :class:`RobustSetInfeasibleError`.
    n_taps : int
        FIR length of the robustness filter ``F`` (>= 3). Its frequency resolution is about
        ``2 pi / (n_taps Ts)`` rad/s (1.04 rad/s for 301 taps at 50 Hz).
    advance : int or None
        Non-causal lead of ``F`` in samples, in ``[0, n_taps - 1]`` (default ``n_taps // 2``,
        a centred filter).
    n_grid : int
        Log-spaced design frequencies from ``w_min`` to Nyquist (>= 20).
    w_min : float
        Lowest design frequency, rad/s (> 0).
    n_verify : int
        Points of the linear verification grid up to Nyquist (>= n_grid).
    weight_band : tuple of float
        ``(lo, hi)`` rad/s where the nominal criterion is emphasised by ``band_weight``.
    band_weight : float
        Weight (> 0) of ``|1 - F|^2`` inside ``weight_band`` (1 elsewhere).
    ridge : float
        Weight (>= 0) of ``||h||^2``.
    slack : float
        Margin (in [0, 0.1]) added to ``rho_best`` when the asked rho is infeasible, leaving the
        nominal criterion room to act.
    max_exchange : int
        Rounds of the exchange step (>= 0).
    margin : float
        Stability margin ``m`` in [0, 1) of system j-1's true loop, ``|1 + T0 Delta| >= m``
        (its true ``D`` at least ``m`` times its model's), assumed only at frequencies where
        ``W |T0| > 1 - m`` (:func:`uncertainty_cones`); 0 keeps the whole disc everywhere: where the
        disc then reaches the stability boundary (``W |T0| >= 1``) no FIR has a finite worst case
        (it would have to vanish on a band) and :func:`design_robust_set` refuses with a ``SpecError``.
    tol : float
        Verification tolerance (in [0, 0.01]): the worst case on the verification grid may exceed
        the imposed rho by this much before the exchange step adds frequencies; where the bound
        forces ``F = 0`` on a band a FIR can only approach it.
    finite_trial_s : float
        Length (s, >= 0) of the trial on which ``rho_N``, the largest whole-trial ratio over *every*
        disturbance with exact models, is computed (:attr:`RobustSetDesign.finite`,
        :mod:`..maps.finite_horizon`); 0 (default) skips it: a Lanczos iteration whose inner solves did not
        converge at 2 ms (a 5 s trial took 455 s of CPU), and for a zero-phase ``F`` it is above 1 anyway.
    whole_trial_s : float
        Length (s, >= 0) of the whole trials flown for the stated set's extreme plants and the disturbances
        that meet a trial's ends (:attr:`RobustSetDesign.whole_trial`, :mod:`..maps.whole_trial`); 0 skips
        them. A design whose worst trial exceeds what it guarantees per frequency says so (a RuntimeWarning;
        with ``relax=False`` a :class:`RobustSetInfeasibleError`).
    trial : {"extended", "projected"}
        How the law treats a finite trial (:meth:`RobustSetDesign.apply`): ``"extended"`` (default)
        filters the reconstructed disturbance continued past the trial's end; ``"projected"`` asks
        the target for the error ``F`` gives its predicted error and inverts its learning map over
        the trial by least squares (:mod:`..filters.trial_inverse`): with exact models every disturbance of
        the whole trial keeps ``sqrt(2) max |1 - F|``, but the learning signal spikes at the trial's
        ends. Trials longer than :data:`~..filters.trial_inverse.MAX_TRIAL_SAMPLES` samples are extended
        (with a warning).
    delta_set : {"auto", "disc", "structured"}
        The Delta set guaranteed over when a design is made from a fleet (:func:`structured_set`):
        ``"disc"`` the frequency-wise disc ``|Delta| <= W``; ``"structured"`` the set the bound or the
        identification stands for (:mod:`..sets.value_set`); ``"auto"`` the identification's parameter
        ellipsoid when the source carries one, else the disc.
    start : {"auto", "matched", "fold"}
        The extended law's treatment of ``F``'s output before ``t = 0`` (:attr:`RobustSetDesign.start`):
        ``"fold"`` adds it time-reversed to the first samples, exact for a disturbance that steps on at ``t = 0``
        and keeps on (a constant wind from the start) but up to 1.16 times the error without learning for one that
        switches on abruptly; ``"matched"`` continues it into the first second by its effect on the target model,
        which keeps those trials at the price of the step's (docs/theory.md section 6, "The trial's start");
        ``"auto"`` (default) the fold unless its whole trials exceed the claim, then the continuation
        (:func:`choose_start`; without whole trials, the fold).
    """

    rho: float = 0.95
    relax: bool = True
    n_taps: int = 301
    advance: int | None = None
    n_grid: int = 150
    w_min: float = 0.01
    n_verify: int = 20000
    weight_band: tuple[float, float] = (0.1, 20.0)
    band_weight: float = 10.0
    ridge: float = 1e-6
    slack: float = 0.01
    max_exchange: int = 6
    margin: float = 0.5
    tol: float = 2e-3
    finite_trial_s: float = 0.0
    whole_trial_s: float = 60.0
    trial: str = "extended"
    delta_set: str = "auto"
    start: str = "auto"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rho) and 0 < self.rho <= 1):
            raise SpecError(f"`rho`: got {self.rho!r}, expected a guaranteed improvement factor in (0, 1] "
                            "(1: never worse than without learning)")
        check_count("n_taps", self.n_taps, 3)
        check_advance(self.advance, self.n_taps, optional=True)
        check_count("n_grid", self.n_grid, 20)
        check_w_min(self.w_min)
        check_count("n_verify", self.n_verify, self.n_grid, f"n_grid = {self.n_grid}")
        self._check_weighting(" rad/s")
        if not (np.isfinite(self.slack) and 0 <= self.slack <= 0.1):
            raise SpecError(f"`slack`: got {self.slack!r}, expected a margin in [0, 0.1]")
        check_count("max_exchange", self.max_exchange, 0)
        if not (np.isfinite(self.margin) and 0 <= self.margin < 1):
            raise SpecError(f"`margin`: got {self.margin!r}, expected a stability margin in [0, 1)")
        if not (np.isfinite(self.tol) and 0 <= self.tol <= 0.01):
            raise SpecError(f"`tol`: got {self.tol!r}, expected a tolerance in [0, 0.01]")
        if self.delta_set not in DELTA_SETS:
            raise SpecError(f"`delta_set`: got {self.delta_set!r}, expected one of {list(DELTA_SETS)}")
        if self.trial not in TRIAL_LAWS:
            raise SpecError(f"`trial`: got {self.trial!r}, expected one of {list(TRIAL_LAWS)}")
        if self.start not in START_LAWS:
            raise SpecError(f"`start`: got {self.start!r}, expected one of {list(START_LAWS)}")
        for name in ("finite_trial_s", "whole_trial_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise SpecError(f"`{name}`: got {value!r}, expected a trial length >= 0 s (0: no whole-trial figure)")

    @property
    def lead(self) -> int:
        """The advance actually used, samples."""
        return self.n_taps // 2 if self.advance is None else int(self.advance)

    def grid(self, ts: float) -> np.ndarray:
        """Design grid: ``n_grid`` log-spaced from ``w_min`` to Nyquist, joined with a linear grid.

        The linear grid has ``n_taps`` points to Nyquist (spacing half the FIR's resolution
        ``2 pi/(n_taps Ts)``); the exchange step adds what it misses.

        Parameters
        ----------
        ts : float
            Sample time, s.

        Returns
        -------
        numpy.ndarray
            Sorted frequencies, rad/s.

        Raises
        ------
        SpecError
            ``w_min`` at or above Nyquist.
        """
        nyq = np.pi / ts
        if self.w_min >= nyq:
            raise SpecError(f"`w_min`: got {self.w_min} rad/s, expected below Nyquist {nyq:.4g} rad/s")
        return log_linear_grid(self.w_min, nyq, self.n_grid, np.linspace(nyq / self.n_taps, nyq, self.n_taps))

    def verify_grid(self, ts: float) -> np.ndarray:
        """Dense verification grid: log from 1e-4 rad/s to ``w_min``, then linear to Nyquist.

        Parameters
        ----------
        ts : float
            Sample time, s.

        Returns
        -------
        numpy.ndarray
            Sorted frequencies, rad/s (200 log-spaced plus ``n_verify`` linearly spaced).
        """
        return log_linear_grid(1e-4, self.w_min, 200, np.linspace(self.w_min, np.pi / ts, self.n_verify))


def bound_on_grid(w_bound: np.ndarray, bound: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``W(w)`` on ``w``: linear interpolation in log frequency, held constant beyond the ends.

    Parameters
    ----------
    w_bound : array_like
        Frequencies of the bound, rad/s (> 0, any order).
    bound : array_like
        Multiplicative bound ``|Delta|`` on ``w_bound`` (>= 0); one value is a constant bound.
    w : array_like
        Frequencies wanted, rad/s.

    Returns
    -------
    numpy.ndarray
        ``W`` on ``w``.

    Raises
    ------
    SpecError
        Non-finite, negative or mismatched bound arrays.
    """
    wb, b = np.asarray(w_bound, float).reshape(-1), np.asarray(bound, float).reshape(-1)
    if wb.size != b.size or wb.size < 1 or not np.all(np.isfinite(b)) or np.any(b < 0) or np.any(wb <= 0):
        raise SpecError(f"`bound`: got {b.size} values on {wb.size} frequencies, expected equal-length arrays of "
                        "finite bounds >= 0 on frequencies > 0 rad/s")
    if wb.size == 1:
        return np.full(np.shape(w), float(b[0]))
    order = np.argsort(wb)
    return np.interp(np.log(np.asarray(w, float)), np.log(wb[order]), b[order])


def structured_set(spec, source: str, bound: np.ndarray, choice: str = "auto") -> StructuredSet | None:
    """The structured Delta set a robust-set design guarantees over, or None for the disc (:attr:`RobustSetOptions.delta_set`).

    Parameters
    ----------
    spec : SystemSpec
        System j-1.
    source : str
        Where its Delta set comes from (``DeltaSet.source``): ``"identification"`` or ``"fleet bound"``.
    bound : array_like
        Its bound ``W`` (a constant for a fleet bound).
    choice : {"auto", "disc", "structured"}

    Returns
    -------
    BoundFamily, EllipseFamily or None
    """
    if choice == "disc" or (choice == "auto" and source != "identification"):
        return None
    if source == "identification":
        return EllipseFamily.from_spec(spec)
    return BoundFamily(float(np.min(bound)))  # the stated bound: the sampled radius at low frequency (1 + 1e-12)


def admissible(source: LoopSystem, source_true: LoopSystem, w_bound: np.ndarray, bound: np.ndarray,
               margin: float = 0.5, n: int = 3000) -> tuple[bool, str]:
    """Whether a true plant of system j-1 lies in the set the design guarantees (module docstring).

    ``Delta = P/P_hat - 1`` must satisfy ``|Delta| <= W`` (to 1e-6 relative) at every frequency and
    ``|1 + T0 Delta| >= margin`` wherever ``W |T0| > 1 - margin`` (:func:`uncertainty_cones`),
    checked on ``n`` log-spaced frequencies from 1e-3 rad/s to Nyquist.

    Parameters
    ----------
    source : LoopSystem
        System j-1 (its model is used).
    source_true : LoopSystem
        The loop with the true plant.
    w_bound, bound : array
        The Delta set's bound ``W`` (:func:`bound_on_grid`).
    margin : float
        The design's stability margin (``RobustSetOptions.margin``).
    n : int
        Frequencies checked.

    Returns
    -------
    ok : bool
    why : str
        Empty when admissible, else what fails and where.
    """
    why = admissibility(source, w_bound, bound, margin, n)(source_true)
    return not why, why


def admissibility(source: LoopSystem, w_bound: np.ndarray, bound: np.ndarray, margin: float = 0.5,
                  n: int = 3000) -> Callable[[LoopSystem], str]:
    """:func:`admissible` for many true plants of one source: the model's frequency responses computed once.

    Parameters
    ----------
    source : LoopSystem
        System j-1 (its model is used).
    w_bound, bound : array
        The Delta set's bound ``W`` (:func:`bound_on_grid`).
    margin : float
        The design's stability margin.
    n : int
        Frequencies checked.

    Returns
    -------
    callable
        ``true loop -> why``: empty when admissible, else what fails and where.
    """
    nyq = np.pi / source.ts
    w = np.logspace(-3, np.log10(nyq * (1 - 1e-9)), n)
    p_hat = freqresp(source.nominal.P, w)
    W = bound_on_grid(w_bound, bound, w)
    _, _, _, t0, _ = uncertainty_cones(source, w, W, margin)
    zone = W * np.abs(t0) > 1 - margin

    def why(source_true: LoopSystem) -> str:
        delta = freqresp(source_true.P, w) / p_hat - 1
        over = np.abs(delta) > W * (1 + 1e-6) + 1e-12
        if np.any(over):
            i = int(np.argmax(np.abs(delta) - W))
            return f"|Delta| = {abs(delta[i]):.4g} > W = {W[i]:.4g} at {w[i]:.4g} rad/s"
        close = zone & (np.abs(1 + t0 * delta) < margin)
        if np.any(close):
            i = int(np.flatnonzero(close)[np.argmin(np.abs(1 + t0 * delta)[close])])
            return f"|1 + T0 Delta| = {abs(1 + t0[i] * delta[i]):.4g} < margin {margin:g} at {w[i]:.4g} rad/s"
        return ""

    return why


@dataclass(frozen=True)
class RobustSetDesign:
    """A learning design whose improvement is guaranteed over the whole Delta set.

    Attributes
    ----------
    filters : LearningFilters or None
        Closed-form ``L1``, ``L2`` (system j-1's model); set by :func:`design_robust_set`.
    F : FIRFilter
        Robustness filter applied after them.
    rho : float
        The asked factor.
    rho_best : float
        Smallest factor an FIR of this order guarantees (verification grid; where the asked rho is
        feasible, the verified worst case of one min-max solve: an upper bound, module docstring step 1).
    rho_design : float
        Factor imposed: ``rho`` (or ``rho - tol``, step 2 of the module docstring) if feasible, else
        ``min(1, rho_best + slack)``.
    rho_guaranteed : float
        ``max_w max_{|Delta|<=W} |T(w)|`` of the result on the verification grid
        (<= ``rho_design + tol``; the exchange step stops within ``tol``).
    feasible : bool
        Whether the asked ``rho`` is guaranteed: ``rho_guaranteed <= rho`` on the verification grid.
    nominal_worst : float
        ``max_w |1 - F(w)|``: the ratio bound for the nominal plant.
    margin_bands : list of (float, float)
        Frequency intervals (rad/s) where the set reaches system j-1's stability boundary: there the
        guarantee covers the Deltas with ``|1 + T0 Delta| >= margin`` only (the disc: where its margin
        bound is used, :func:`uncertainty_cones`; a structured set: where some of its values are left
        out, :mod:`..sets.value_set`), and ``F`` is near 0 where even those allow no learning.
    w, worst : numpy.ndarray
        Verification grid (rad/s) and the worst-case ratio on it.
    exchanges : int
        Exchange rounds used.
    solve_time : float
        Total solver wall-clock time, s.
    delta_set : str
        The Delta set guaranteed over: ``"disc |Delta| <= W"`` or a structured set's description.
    trial : str
        How a finite trial is treated, :attr:`RobustSetOptions.trial`.
    whole_trial : WholeTrialFigure or None
        Whole trials of the law for the stated set's extreme plants and the disturbances that meet a trial's ends
        (:mod:`..maps.whole_trial`; :attr:`RobustSetOptions.whole_trial_s`); :attr:`trial_guaranteed` compares them
        with :attr:`claimed`.
    finite : FiniteHorizonRatio or None
        The whole-trial figure ``rho_N = max_d ||e_j|| / ||e'_j||`` over a trial of
        ``options.finite_trial_s`` with exact models (:mod:`..maps.finite_horizon`), the law of
        :meth:`apply` without a band; set by :func:`design_robust_set` (None: not computed).
        ``rho_guaranteed`` holds per frequency (an infinite horizon); ``rho_N`` is what a whole
        trial can reach for its worst disturbance, which for this zero-phase ``F`` lies at an end
        of the trial (module docstring, gap (b)).
    start : StartMatch or None
        The extended law's continuation of ``F``'s output before ``t = 0`` over the trial's first samples,
        matched to its effect on the target model (:class:`~..filters.trial_edges.StartMatch`); set by
        :func:`design_robust_set`; None (a causal ``F``, the projected law, or a design without it) folds.
    fold_worst : float or None
        Where :attr:`RobustSetOptions.start` ``"auto"`` chose the continuation: the worst whole trial of the fold,
        which exceeded the claim; None otherwise.
    """

    filters: LearningFilters | None
    F: FIRFilter
    rho: float
    rho_best: float
    rho_design: float
    rho_guaranteed: float
    feasible: bool
    nominal_worst: float
    margin_bands: list[tuple[float, float]]
    w: np.ndarray = field(repr=False)
    worst: np.ndarray = field(repr=False)
    exchanges: int = 0
    solve_time: float = 0.0
    delta_set: str = "disc |Delta| <= W"
    finite: FiniteHorizonRatio | None = None
    trial: str = "extended"
    whole_trial: WholeTrialFigure | None = None
    start: StartMatch | None = None
    fold_worst: float | None = None

    @property
    def claimed(self) -> float:
        """What the design guarantees per frequency: the asked ``rho`` where feasible, else ``rho_guaranteed``."""
        return self.rho if self.feasible else self.rho_guaranteed

    @property
    def trial_guaranteed(self) -> bool | None:
        """Whether every whole trial flown (:attr:`whole_trial`) keeps :attr:`claimed`; None if none was flown."""
        if self.whole_trial is None or not self.whole_trial.plants:
            return None
        return bool(self.whole_trial.ratio <= self.claimed)

    def trial_map(self, n: int) -> "LinearMap":
        """The law on a trial of ``n`` samples, the source flying without learning, as a linear map
        (``e'_{j-1} -> d_f,j``, :mod:`..maps.finite_horizon`): what :meth:`apply` computes.

        Parameters
        ----------
        n : int
            Samples of the trial.
        """
        from ..maps.finite_horizon import LinearMap, causal_map, fir_map, odd_start_map, trend_map, zpk_map

        inv = zpk_map(inverse_gd_filter(self.filters.source, model=True), n)
        a = self.F.advance
        if self.projected(n):  # -P F_N Gd_hat_j {d_hat}, P the least-squares inverse of Gf_hat_j
            ti = self.trial_inverse(n)
            proj = LinearMap(n, n, ti.solve, ti.adjoint, "Gf_j^+")
            gd_t = causal_map(self.filters.target.nominal.G_d, n, "Gd_hat_j")
            m = min(a, n)
            fn = fir_map(self.F.h, a + m, n, fold=False, n_in=n + m) @ odd_start_map(n, m)
            return proj @ fn @ gd_t @ inv
        steps = [-inv]
        if a:
            steps.append(trend_map(n, a, self.end_fade))
        steps.append(fir_map(self.F.h, a, n, n_in=n + a, start=self.start))
        steps.append(causal_map(one_minus(self.filters.target.Q), n, "1 - Q_j"))
        out = steps[0]
        for s in steps[1:]:
            out = s @ out
        return out

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """Learning signal of system j, ``(1 - Q_j){F{d_hat}}`` with ``d_hat = -Gd_{j-1}^{-1}{e'_{j-1}}``.

        Over an infinite horizon this is ``F{L1{e'_{j-1}}}`` (``L1 = -(1 - Q_j) Gd_{j-1}^{-1}``, paper
        Sec. III). How a finite trial is treated follows :attr:`trial`.

        ``"projected"``: with ``y = Gd_hat_j{d_hat}`` the target's predicted error without learning
        and ``F_N`` the FIR over the trial (``y`` extended before ``t = 0`` as an odd function, zero
        after the end), ``d_f`` is the least-squares solution of ``Gf_hat_j{d_f} = -F_N{y}`` over the
        trial (:mod:`..filters.trial_inverse`). Over an infinite horizon it is the same law
        (``Gf_j (1 - Q_j) = -Gd_j``); on the trial, with exact models, ``e_j = P (I - F_N) e'_j`` with
        ``P`` a projection, so ``||e_j|| <= sqrt(2) max |1 - F| ||e'_j||`` for every disturbance
        (the odd extension at most doubles the energy ``F`` sees). The price: to give the trial's first
        and last samples their error exactly, ``d_f`` has spikes there, far larger than the extended
        law's, which an acceleration limit clips, and a clipped law keeps no guarantee (measured:
        docs/performance.md, "Measured figures behind the design's choices"). Trials longer than
        :data:`~..filters.trial_inverse.MAX_TRIAL_SAMPLES` are extended, with a warning.

        ``"extended"`` (default): ``F`` acts on the reconstructed disturbance ``d_hat``
        (:func:`~ilcdob.design.reconstruct_disturbance`, the model's maps), a smooth signal; this left
        smaller error ratios than ``F`` after or before ``L1`` (measured: docs/performance.md, "Measured
        figures behind the design's choices").

        Trial ends. ``F`` looks ``F.advance`` samples (1.5 s for 301 taps at 10 ms) past every sample.
        Before the trial ``d_hat`` is zero (the vehicle at rest); what ``F`` puts before ``t = 0`` would
        have set the target going before the trial. It is folded onto the trial's first samples, exact for
        a wind that steps on at ``t = 0``, or, where the design's whole trials show the fold exceeding its
        claim (a disturbance switching on abruptly at the start reached 1.16 times the error without
        learning), replaced by the signal over the first samples whose effect on the target model's error
        matches that one's (:attr:`start`, :class:`~..filters.trial_edges.StartMatch`,
        :attr:`RobustSetOptions.start`, docs/theory.md section 6). After it ``d_hat``
        continues along its trend (:func:`end_continuation`): the line fitted (Hann-weighted least
        squares) to the ``2 F.advance`` samples before its last :attr:`end_fade` ones (those the
        stable inversion built from the error continued past the end), blended into over them. A line is what the
        loops cannot see (``Gd`` has a double zero at ``z = 1``: constant and ramp disturbances
        leave only a start transient in the error), so continuing it costs nothing where learning
        has least to gain, and averaging over ``2 F.advance`` samples leaves oscillations out. Holding
        ``d_hat`` at its last value made trials much worse than no learning near the end, and zeros
        after the end made a ramp disturbance worse; the trend keeps the trials checked below their
        ``rho_guaranteed`` and 1 (``tests/test_finite_horizon.py``; measured: docs/performance.md,
        "Measured figures behind the design's choices"). A zero-phase ``F`` still cannot keep
        ``rho_guaranteed`` for every disturbance of a finite trial (:attr:`finite`,
        :mod:`..maps.finite_horizon`); a causal one (``advance = 0``, no continuation needed) does, at
        the price of learning where the set reaches the source's stability boundary.

        Parameters
        ----------
        e_prev : array_like
            Tracking error of system j-1, m.
        df_prev : array_like
            Learning signal system j-1 flew with, m/s^2 (zeros if none), same length.

        Returns
        -------
        numpy.ndarray
            ``d_f,j``, m/s^2, same length.
        """
        e = as_signal(e_prev, "e_prev")
        df = as_signal(df_prev, "df_prev", e.size)
        d_hat = reconstruct_disturbance(self.filters.source, e, df, model=True)
        h, a, n = self.F.h, self.F.advance, e.size
        if self.projected(n):
            y = fftconvolve(markov_parameters(self.filters.target.nominal.G_d, n), d_hat)[:n]  # as the lifted map
            m = min(a, n)  # F on y extended as an odd function before t = 0 (its output starts near 0)
            return -self.trial_inverse(n).solve(np.convolve(np.concatenate([-y[:m][::-1], y]), h)[a + m:a + m + n])
        return simulate_map(one_minus(self.filters.target.Q), fir_on_trial(d_hat, h, a, self.end_fade, self.start))

    def projected(self, n: int) -> bool:
        """Whether a trial of ``n`` samples is treated by least squares (:meth:`apply`); warns when it is too long.

        Parameters
        ----------
        n : int
            Samples of the trial.

        Returns
        -------
        bool
            ``trial == "projected"`` and ``n <= MAX_TRIAL_SAMPLES``.
        """
        if self.trial != "projected":
            return False
        if n > MAX_TRIAL_SAMPLES:
            warnings.warn(f"robust-set learning: a trial of {n} samples is longer than {MAX_TRIAL_SAMPLES}, the "
                          "longest the least-squares trial inverse is built for; the reconstructed disturbance is "
                          "extended past the trial's end instead (no whole-trial bound for every disturbance)",
                          RuntimeWarning, stacklevel=3)
            return False
        return True

    def trial_inverse(self, n: int) -> TrialInverse:
        """The target model's ``Gf`` inverted over ``n`` samples by least squares (:mod:`..filters.trial_inverse`).

        Parameters
        ----------
        n : int
            Samples of the trial.

        Returns
        -------
        TrialInverse
            Built once per target and length.
        """
        tgt = self.filters.target.nominal
        return trial_inverse(tgt.G_f, n, (repr(tgt.spec), tgt.ts))

    @cached_property
    def end_fade(self) -> int:
        """Samples at the end of a trial over which ``F``'s input ``d_hat`` is blended into its trend (:meth:`apply`).

        With a look-ahead (``F.advance > 0``): the samples of ``d_hat`` that the stable inversion
        built from the error continued past the trial's end (its anti-causal look-ahead to
        ``LOOKAHEAD_TOL`` plus its advance, :mod:`..filters.noncausal`; 24 on the built-in fleet). A causal
        ``F`` (``advance = 0``) needs nothing past the end and uses ``d_hat`` as reconstructed: 0.
        """
        if self.F.advance == 0 or self.filters is None:
            return 0
        inv = inverse_gd_filter(self.filters.source, model=True).realised
        pu = inv.anticausal_poles
        return int(max((lookahead(p) for p in pu), default=0) + inv.advance)

    def response(self, w: np.ndarray) -> np.ndarray:
        """Frequency response of the robustness filter ``F``.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            ``F(e^{j w Ts})``, complex.
        """
        return self.F.freqresp(w)

    def to_dict(self) -> dict:
        """Summary for ``filters.json`` (the FIR taps under ``F``)."""
        return {"F": self.F.to_dict(), "rho": self.rho, "rho_best": self.rho_best, "rho_design": self.rho_design,
                "rho_guaranteed": self.rho_guaranteed, "feasible": self.feasible,
                "nominal_worst": self.nominal_worst, "guaranteed_over": self.delta_set, "margin_bands_rad_s": [list(b) for b in self.margin_bands],
                "exchanges": self.exchanges,
                "trial_ends": {"law": "projected", "max_samples": MAX_TRIAL_SAMPLES,
                               "rule": "y = Gd_hat_j{d_hat} (the target's predicted error, causal from rest), "
                                       "extended before t = 0 as an odd function (y(-1-k) = -y(k)) for F's advance "
                                       "and zero after the end; d_f = argmin ||Gf_hat_j{d_f} + F{y}||^2 + lam "
                                       "||d_f||^2 over the trial's samples (lifted maps, lam = 1e-12 x the mean "
                                       "diagonal of Gf^T Gf, design/filters/trial_inverse.py); longer trials are "
                                       "extended"}
                if self.trial == "projected" else
                {"fade_samples": self.end_fade, "fit_samples": 2 * self.F.advance,
                               "rule": "F acts on the reconstructed disturbance d_hat, zero before the trial; with "
                                       "m = fade_samples, L = fit_samples (fewer on short trials) and l(k) the "
                                       "least-squares line through d_hat[n-m-L .. n-m-1] with the weights "
                                       "numpy.hanning(L + 2)[1:-1] on the squared residuals, d_hat[n-m+k] becomes "
                                       "l + w_k (d_hat - l) with w_k = 0.5 (1 + cos(pi (k + 1)/(m + 1))), "
                                       "k = 0..m-1, and l continues it for F's advance past the end; F's output "
                                       "before t = 0, p, is replaced by gain x0 added to the first samples (as "
                                       "many as gain has rows), x0 the state of target_map (Gf_hat_j (1 - Q_j)) "
                                       "run from rest over p (design/filters/trial_edges.py StartMatch); "
                                       "without start, p is added time-reversed to the first samples",
                               "start_law": "fold" if self.start is None else "matched",
                               **({} if self.fold_worst is None else {"fold_worst_trial": self.fold_worst}),
                               **({} if self.start is None else {"start": self.start.to_dict()})},
                "whole_trial": None if self.whole_trial is None else
                {**self.whole_trial.to_dict(), "guaranteed": self.trial_guaranteed, "claimed": self.claimed,
                 "meaning": "largest ||e_j|| / ||e'_j|| over whole trials of the stated set's extreme plants "
                            "(the disc: gains and all-pass errors at the bound; a structured family: its members at the ends "
                            "of their admissible range; an ellipsoid: the ends of its principal axes) and "
                            "disturbances meeting the trial's ends (design/maps/whole_trial.py); guaranteed: "
                            "at most what the design claims per frequency"},
                "finite_trial": None if self.finite is None else
                {**self.finite.to_dict(), "models": "exact (true plants = models)",
                 "meaning": "largest ||e_j|| / ||e'_j|| over every disturbance of a whole trial (design/"
                            "finite_horizon.py); rho_guaranteed bounds it per frequency, i.e. over an "
                            "infinite horizon, for every admissible Delta"}}


def _exchange_points(worst: np.ndarray, bad: np.ndarray, n_max: int = 60) -> np.ndarray:
    """Verification-grid indices that join the design grid in an exchange round (at most ``n_max``).

    Per run of adjacent violations (``bad``), its peak and its two ends, the runs taken in the order of
    their peaks' violation: every band the filter's ripple exceeds the level in gets frequencies in the
    same round (the ``n_max`` worst violations alone tend to lie in a few bands and took up to 5 rounds).
    """
    idx = np.flatnonzero(bad)
    key = np.nan_to_num(worst[idx], posinf=1e12)
    cuts = np.flatnonzero(np.diff(idx) > 1) + 1
    starts, ends = np.concatenate([[0], cuts]), np.concatenate([cuts - 1, [idx.size - 1]])
    peaks = starts + np.array([np.argmax(run) for run in np.split(key, cuts)], dtype=int)
    order = np.argsort(-key[peaks], kind="stable")
    picked = np.stack([peaks[order], starts[order], ends[order]], axis=1).reshape(-1)
    _, first = np.unique(picked, return_index=True)
    return idx[np.sort(picked[np.sort(first)][:n_max])]


def _fir_response(h: np.ndarray, w: np.ndarray, ts: float, lead: int) -> np.ndarray:
    """``F(w) = e^{jw Ts lead} sum_i h_i e^{-jw Ts i}`` by Horner's rule (no ``len(w) x len(h)`` matrix)."""
    x = np.exp(-1j * w * ts)
    out = np.zeros(w.size, complex)
    for c in h[::-1]:
        out = out * x + c
    return out * np.exp(1j * w * ts * lead)


def _set_rows(source: LoopSystem, w: np.ndarray, w_bound: np.ndarray, bound: np.ndarray,
              structure: StructuredSet | None, margin: float, directions: int = 0) -> tuple[np.ndarray, ...]:
    """Cone rows ``(index, a, b, R)`` of the Delta set on ``w`` and where values were left out for the margin:
    one disc row per frequency (:func:`uncertainty_cones`), or a structured set's polygon of ``directions``
    supporting lines (:func:`~..sets.value_set.family_cones`)."""
    if structure is not None:
        return family_cones(source, structure, w, margin, directions)
    a, b, r, _, kind = uncertainty_cones(source, w, bound_on_grid(w_bound, bound, w), margin)
    return np.arange(w.size), a, b, r, kind == 1


class _Problem:
    """The SOCP on one grid; ``rho=None`` minimises rho instead of the nominal criterion.

    ``F`` on the grid is a pair of variables tied to the taps (``F = Phi h``), so a frequency's many
    cone rows (a structured set) each cost a 3-dimensional cone, not a dense row in the taps.
    """

    def __init__(self, ts: float, w: np.ndarray, rows: tuple[np.ndarray, ...], opts: RobustSetOptions,
                 structured: bool = False):
        idx, a, b, r = rows[:4]
        self.structured = structured
        scale = np.maximum.reduce([np.abs(a), np.abs(b), r])  # rows are homogeneous: normalise each
        self.idx, self.a, self.b, self.r = idx, a / scale, b / scale, r / scale
        self.w, self.opts = w, opts
        self.phi = np.exp(-1j * np.outer(w * ts, np.arange(opts.n_taps) - opts.lead))

    def solve(self, rho: float | None, first_try: bool = False) -> tuple[np.ndarray, float] | None:
        """Taps ``h`` and the imposed (or minimised) rho; None where the imposed rho is infeasible on this grid, or on
        a ``first_try`` (:data:`_FIRST_TRY_ITERATIONS`) not solved."""
        o = self.opts
        h = cp.Variable(o.n_taps)
        fr, fi = cp.Variable(self.w.size), cp.Variable(self.w.size)
        # no F != 0 keeps the worst case <= 1 where the set's radius reaches its centre's distance (R >= |b|)
        # or the image is unbounded (a <= 0): there |F| <= cap, with cap (|b| + R)/a = tol/2 (F = 0 exactly,
        # as equalities, leaves the cones without interior and the equality rows rank deficient)
        hard = (self.a <= 1e-9) | (self.r >= np.abs(self.b) * (1 - 1e-9))
        ok, zero = np.flatnonzero(~hard), np.flatnonzero(hard)
        if not ok.size:  # the set reaches its centre's distance everywhere: only F = 0 (no learning) keeps 1
            return np.zeros(o.n_taps), 1.0 if rho is None else float(rho)
        i_ok = self.idx[ok]
        br, bi = self.b[ok].real, self.b[ok].imag
        u, v = cp.Variable(ok.size), cp.Variable(self.w.size)
        cons = [fr == self.phi.real @ h, fi == self.phi.imag @ h,
                cp.SOC(u, cp.vstack([self.a[ok] - (cp.multiply(br, fr[i_ok]) - cp.multiply(bi, fi[i_ok])),
                                     -(cp.multiply(br, fi[i_ok]) + cp.multiply(bi, fr[i_ok]))]), axis=0),
                cp.SOC(v, cp.vstack([fr, fi]), axis=0)]
        if zero.size:
            az = np.maximum(self.a[zero], 0.0)
            cap = 0.5 * o.tol * az / (np.abs(self.b[zero]) + self.r[zero])
            iz = self.idx[zero]
            cons.append(cp.SOC(cap, cp.vstack([fr[iz], fi[iz]]), axis=0))
        # a structured set's rows all pass through F = 0 at rho = 1: imposing rho + tol/2 there keeps F = 0 strictly
        # inside (Clarabel stalls on a feasible set without interior); the verification allows tol anyway
        t = cp.Variable() if rho is None else rho + (0.5 * o.tol if self.structured and rho >= 1 else 0.0)
        cons.append(u + cp.multiply(self.r[ok], v[i_ok]) <= t * self.a[ok])
        if rho is None:
            obj = t + 1e-6 * cp.sum_squares(h)
        else:
            sw = np.sqrt(o.weights(self.w) / self.w.size)
            obj = (cp.sum_squares(cp.multiply(sw, 1 - fr)) + cp.sum_squares(cp.multiply(sw, fi))
                   + o.ridge * cp.sum_squares(h))
        prob = cp.Problem(cp.Minimize(obj), cons)
        for k, reg in enumerate(_STATIC_REGULARISATION):
            try:
                with warnings.catch_warnings():  # "optimal_inaccurate" is accepted: the result is verified afterwards
                    warnings.filterwarnings("ignore", message="Solution may be inaccurate", category=UserWarning)
                    prob.solve(solver="CLARABEL", direct_solve_method=_DIRECT_METHOD, max_threads=CLARABEL_THREADS,
                               static_regularization_constant=reg,
                               max_iter=_FIRST_TRY_ITERATIONS if first_try else _ITERATIONS)
                break
            except cp.error.SolverError as exc:
                if first_try:
                    return None
                if k + 1 == len(_STATIC_REGULARISATION):
                    raise RobustSetSolverError(f"robust-set design: Clarabel failed ({exc}); try fewer taps "
                                               "(`n_taps`) or a coarser grid (`n_grid`)") from exc
        if rho is not None and prob.status in _INFEASIBLE:
            return None
        if prob.status not in _OK or h.value is None:
            raise RobustSetSolverError(f"robust-set design: solver status {prob.status!r} at rho = {rho}; try fewer "
                                       "taps (`n_taps`), a coarser grid (`n_grid`) or a larger `ridge`")
        return np.asarray(h.value, float), float(t.value) if rho is None else float(rho)


def design_robust_set(source: LoopSystem, target: LoopSystem, w_bound: np.ndarray, bound: np.ndarray,
                      options: RobustSetOptions | None = None,
                      structure: StructuredSet | None = None) -> RobustSetDesign:
    """Design the closed-form filters with a robustness FIR guaranteed over the Delta set.

    Parameters
    ----------
    source, target : LoopSystem
        Systems j-1 and j (their models are used; system j's plant does not enter the ratio).
    w_bound, bound : array
        System j-1's multiplicative bound ``W`` on frequencies ``w_bound`` (rad/s), e.g.
        ``DeltaSet.w`` and ``DeltaSet.bound`` (:mod:`..sets.delta`); a single value is a constant bound.
    options : RobustSetOptions, optional
    structure : BoundFamily or EllipseFamily, optional
        A structured Delta set of system j-1 (:mod:`..sets.value_set`) to guarantee over instead of the
        disc ``|Delta| <= W``: the fleet bound's gain/high-pass family or an identification's
        parameter ellipsoid. ``w_bound`` and ``bound`` are then only reported.

    Returns
    -------
    RobustSetDesign

    Raises
    ------
    RobustSetInfeasibleError
        ``options.relax`` is False and ``options.rho`` cannot be guaranteed; carries ``rho_best``.
    RobustSetSolverError
        The SOCP solver failed.
    SpecError
        ``margin = 0`` over the disc (``structure`` None) where the disc reaches system j-1's stability
        boundary: no FIR has a finite worst case there; or ``options.finite_trial_s`` longer than
        :data:`ilcdob.signals.MAX_GRID_SAMPLES` samples.
    """
    o = options or RobustSetOptions()
    check_grid(o.finite_trial_s, source.ts, "robust-set design: `finite_trial_s`, the whole-trial figure's trial")
    check_grid(o.whole_trial_s, source.ts, "robust-set design: `whole_trial_s`, the whole trials' length")
    lf = closed_form_filters(source, target)
    # F depends on system j-1 and its bound only: designs of several targets from one source share it
    key = (repr(source.nominal.spec), source.ts, np.asarray(w_bound, float).tobytes(),
           np.asarray(bound, float).tobytes(), o, structure)
    if key not in _CACHE:
        _CACHE[key] = _design_filter(source, target, w_bound, bound, o, structure)
    design = _CACHE[key]
    check_feasible(design, source, target, o)
    flies = int(round(o.whole_trial_s / source.ts)) >= 10
    design = choose_start(replace(design, filters=lf), _start_match(design, lf), o,
                          lambda d: _whole_trial(d, source, target, w_bound, bound, o, structure) if flies else None)
    n_trial = int(round(o.finite_trial_s / source.ts))
    if n_trial >= 2:
        from ..maps.finite_horizon import finite_horizon_ratio, law_map

        design = replace(design, finite=finite_horizon_ratio(law_map(design, n_trial), source.nominal, target.nominal))
    check_whole_trial(design, source, target, o)
    return design


def choose_start(design: RobustSetDesign, start: StartMatch | None, o: RobustSetOptions,
                 fly: Callable[[RobustSetDesign], WholeTrialFigure | None]) -> RobustSetDesign:
    """``design`` with the start law of ``o.start`` (:attr:`RobustSetOptions.start`) and its whole trials.

    ``"auto"``: the fold, unless its whole trials exceed the claim and a continuation exists; then the matched
    continuation, the fold's worst trial kept in :attr:`RobustSetDesign.fold_worst`.

    Parameters
    ----------
    design : RobustSetDesign
        With its filters.
    start : StartMatch or None
        The matched continuation (None: a causal ``F`` or the projected law).
    o : RobustSetOptions
    fly : callable
        ``design -> WholeTrialFigure`` of its law, or None where no whole trials are flown.

    Returns
    -------
    RobustSetDesign
    """
    first = replace(design, start=start if o.start == "matched" else None)
    first = replace(first, whole_trial=fly(first))
    if o.start != "auto" or start is None or first.trial_guaranteed is not False:
        return first
    matched = replace(design, start=start, fold_worst=first.whole_trial.ratio)
    return replace(matched, whole_trial=fly(matched))


def _start_match(design: RobustSetDesign, lf: LearningFilters) -> StartMatch | None:
    """The extended law's continuation of ``F``'s output before ``t = 0`` into the target model
    (:class:`~..filters.trial_edges.StartMatch`); None for the projected law or a causal ``F``."""
    if design.trial != "extended" or not design.F.advance:
        return None
    return StartMatch.design(ct.series(one_minus(lf.target.Q), lf.target.nominal.G_f), design.F.advance)


def _whole_trial(design: RobustSetDesign, source: LoopSystem, target: LoopSystem, w_bound: np.ndarray,
                 bound: np.ndarray, o: RobustSetOptions, structure: StructuredSet | None) -> WholeTrialFigure:
    """Whole trials of the design's law for the set's extreme plants that keep the margin (:mod:`..maps.whole_trial`):
    the disc's gains and all-pass errors at the bound; the fleet-bound family's gains and high-pass errors at the
    ends of their admissible range (:func:`~..maps.whole_trial.family_members`, time constants at the ends and the
    middle of :data:`~..sets.value_set.TAU_RANGE`); an identification's ellipsoid, the model and the ends of its
    principal axes (:meth:`~..sets.value_set.EllipseFamily.members`) that keep the margin."""
    from ..maps.finite_horizon import law_map

    law = law_map(design, int(round(o.whole_trial_s / source.ts)))
    w_worst = [float(design.w[np.nanargmax(design.worst)])]
    if isinstance(structure, BoundFamily):
        taus = [TAU_RANGE[0], float(np.sqrt(TAU_RANGE[0] * TAU_RANGE[1])), TAU_RANGE[1]]
        lo, hi = admissible_range(source, tuple(taus), o.margin)
        spec = source.nominal.spec
        members = family_members(spec.model or spec.plant, structure.bound, taus, lo, hi)
        return whole_trial_figure(law, source, target, structure.bound, w_worst, o.whole_trial_s, members=members)
    if isinstance(structure, EllipseFamily):  # the margin is the set's only cut (value by value, module docstring)
        spec = source.nominal.spec

        def keep(loop: LoopSystem) -> str:
            peak = disturbance_peak(loop, source.nominal) if o.margin > 0 else 0.0
            return f"|Gd/Gd_hat| peaks at {peak:.4g} > 1/margin {1 / o.margin:.4g}" if peak * o.margin > 1 else ""

        return whole_trial_figure(law, source, target, 0.0, w_worst, o.whole_trial_s, keep,
                                  members=[("model", spec.model or spec.plant), *structure.members()])
    # the disc: its sampled radius at low frequency
    return whole_trial_figure(law, source, target, float(np.min(bound)), w_worst, o.whole_trial_s,
                              admissibility(source, w_bound, bound, o.margin))


def check_whole_trial(design: RobustSetDesign, source: object, target: object, o: RobustSetOptions) -> None:
    """Warn (or, with ``o.relax`` False, raise) where a whole trial exceeds what ``design`` claims per frequency.

    Parameters
    ----------
    design : RobustSetDesign
        With its :attr:`~RobustSetDesign.whole_trial`.
    source, target : LoopSystem or ChannelLoop
        The pair, for the message.
    o : RobustSetOptions

    Raises
    ------
    RobustSetInfeasibleError
        ``o.relax`` is False and a whole trial exceeds the claim.
    """
    if design.trial_guaranteed is not False:
        return
    f = design.whole_trial
    msg = (f"robust-set design {source.name!r} -> {target.name!r}: not guaranteed on a whole trial of "
           f"{f.duration_s:g} s: {f.disturbance} with the source's plant {f.plant} gives ||e_j|| / ||e'_j|| = "
           f"{f.ratio:.4g}, above the {design.claimed:.4g} guaranteed per frequency (an infinite horizon); the "
           "trial's ends decide it")
    if not o.relax:
        raise RobustSetInfeasibleError(msg, rho=o.rho, rho_best=design.rho_best)
    warnings.warn(msg, RuntimeWarning, stacklevel=3)


_CACHE: dict[tuple, RobustSetDesign] = {}


def check_feasible(design: RobustSetDesign, source: object, target: object, o: RobustSetOptions) -> None:
    """Raise or warn where ``design`` (its FIR) cannot guarantee the asked ``o.rho``.

    Parameters
    ----------
    design : RobustSetDesign
    source, target : LoopSystem or ChannelLoop
        The pair, for the message.
    o : RobustSetOptions

    Raises
    ------
    RobustSetInfeasibleError
        ``o.relax`` is False and ``o.rho`` is not guaranteed; with ``relax`` a RuntimeWarning instead.
    """
    if design.feasible:
        return
    verified = design.rho_best <= o.rho  # the asked rho was imposed, and the verification found it exceeded
    msg = (f"robust-set design {source.name!r} -> {target.name!r}: rho = {o.rho:g} cannot be guaranteed over "
           f"the Delta set; the best an FIR of {o.n_taps} taps guarantees is rho = "
           f"{design.rho_guaranteed if verified else design.rho_best:.4g}"
           + (" (verified on the dense grid, within the exchange's tolerance of the asked rho)" if verified else ""))
    if not o.relax:
        raise RobustSetInfeasibleError(msg + f". Next step: ask rho >= {design.rho_best:.4g}, lower the bound, "
                                       "or allow more taps (`n_taps`).", rho=o.rho, rho_best=design.rho_best)
    warnings.warn(msg + f"; designed at rho = {design.rho_design:.4g}", RuntimeWarning, stacklevel=3)


def _design_filter(source: LoopSystem, target: LoopSystem, w_bound: np.ndarray, bound: np.ndarray,
                   o: RobustSetOptions, structure: StructuredSet | None) -> RobustSetDesign:
    """The robustness FIR of :func:`design_robust_set` (steps 1-3 of the module docstring)."""
    ts = source.ts
    t_start = time.perf_counter()
    wv = o.verify_grid(ts)
    rows_v = _set_rows(source, wv, w_bound, bound, structure, o.margin)
    excluded_v = rows_v[4]
    if structure is None and not np.all(rows_v[1] > 0):
        # margin 0 keeps the whole disc, and where it reaches the stability boundary (W |T0| >= 1) its image is
        # unbounded: only F = 0 there keeps the worst case finite, and a FIR vanishing on a band vanishes everywhere
        reach = mask_intervals(wv, ~(rows_v[1] > 0))
        raise SpecError(f"`margin`: got {o.margin!r}; over the whole disc |Delta| <= W system {source.name}'s "
                        f"loop reaches its stability boundary (W |T0| >= 1 at {reach[0][0]:.3g}-{reach[-1][1]:.3g} "
                        "rad/s), where no learning filter has a finite worst case. Expected a margin in (0, 1) "
                        "(default 0.5: the guarantee then covers the plants keeping it), a smaller bound, or "
                        "`delta_set = \"structured\"`")
    described = "disc |Delta| <= W" if structure is None else structure.describe()

    def phi_v_at(h: np.ndarray) -> np.ndarray:  # F on the verification grid
        return _fir_response(h, wv, ts, o.lead)

    def _result(h: np.ndarray, worst: np.ndarray, rho_design: float, rho_best: float, feasible: bool,
                rounds: int) -> RobustSetDesign:
        guaranteed = float(np.max(worst))
        if not guaranteed <= 1.0 + o.tol:
            raise RobustSetSolverError(f"robust-set design {source.name!r} -> {target.name!r}: worst-case ratio "
                                       f"{guaranteed:.4g} > 1 on the verification grid after {rounds} exchange "
                                       "rounds; raise `max_exchange` or `n_grid`, or use fewer taps")
        return RobustSetDesign(filters=None, F=FIRFilter(h, o.lead, ts), rho=o.rho, rho_best=rho_best,
                               rho_design=rho_design, rho_guaranteed=guaranteed,
                               feasible=feasible and guaranteed <= o.rho,  # the asked rho as verified, not as imposed
                               nominal_worst=float(np.max(np.abs(1 - phi_v_at(h)))),
                               margin_bands=mask_intervals(wv, excluded_v), w=wv, worst=worst, exchanges=rounds,
                               solve_time=time.perf_counter() - t_start, delta_set=described, trial=o.trial)

    def _refused(h: np.ndarray, worst: np.ndarray, best: float) -> RobustSetDesign:  # relax=False: the best, unused
        return RobustSetDesign(None, FIRFilter(h, o.lead, ts), o.rho, best, best, best, False,
                               float(np.max(np.abs(1 - phi_v_at(h)))), mask_intervals(wv, excluded_v), wv, worst, 0,
                               time.perf_counter() - t_start, described, trial=o.trial)

    def run(rho: float | None, grid: np.ndarray, max_rounds: int = o.max_exchange, first_try: bool = False
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
        """Taps, worst case on the verification grid, final design grid and rounds; None if ``rho`` is infeasible."""
        rounds = 0
        while True:
            rows = _set_rows(source, grid, w_bound, bound, structure, o.margin, _DESIGN_DIRECTIONS)
            solved = _Problem(ts, grid, rows, o, structure is not None).solve(rho, first_try)
            if solved is None:
                return None
            h, level = solved
            worst = worst_over_set(phi_v_at(h), *rows_v[:4], wv.size)
            bad = worst > level + o.tol
            if not np.any(bad) or rounds >= max_rounds:
                return h, worst, grid, rounds
            grid = np.unique(np.concatenate([grid, wv[_exchange_points(worst, bad)]]))
            rounds += 1

    _, a_v, b_v, r_v = rows_v[:4]
    forced = (a_v <= 1e-9) | (r_v >= np.abs(b_v) * (1 - 1e-9))  # rows every F keeps at a worst case >= 1 (_Problem)
    if o.rho < 1 and np.any(forced):
        # |a - b F| + R |F| >= a - |b| |F| + R |F| >= a there: no FIR guarantees rho < 1, and the best is "never worse"
        if not o.relax:
            return _refused(np.zeros(o.n_taps), np.ones(wv.size), 1.0)
        made = run(1.0, o.grid(ts))
        h, worst, _, rounds = made if made is not None else (np.zeros(o.n_taps), np.ones(wv.size), None, 0)
        return _result(h, worst, 1.0, 1.0, False, rounds)
    # the asked rho first; where it holds, rho_best is reported only: the min-max filter of one solve on the grid the
    # design ended on, verified (the exchange to convergence took 7 solves, 15 s, at 2 ms)
    rho_design, made = o.rho, run(o.rho, o.grid(ts), first_try=True)
    if made is not None and np.max(made[1]) > o.rho:  # the exchange stops within `tol` of what it imposes
        lower = run(o.rho - o.tol, made[2]) if o.rho - o.tol > 0 else None
        if lower is not None:
            rho_design, made = o.rho - o.tol, lower
    start = made[2] if made is not None else o.grid(ts)
    h_best, worst_best, _, _ = run(None, start, 0 if made is not None else o.max_exchange)
    rho_best = float(np.max(worst_best))
    if made is None and rho_best <= o.rho:  # feasible after all: the design's SOCP without the first try's cap,
        made = run(o.rho, start) or (h_best, worst_best, start, 0)  # else the min-max filter itself
    feasible = made is not None
    if feasible:
        h, worst, _, rounds = made
    else:  # the asked rho is not guaranteed: design at the best guaranteed one
        rho_design = float(min(1.0, rho_best + o.slack))
        if not o.relax:
            return _refused(h_best, worst_best, rho_best)
        made = run(rho_design, start)
        h, worst, _, rounds = made if made is not None else (h_best, worst_best, start, 0)
    if float(np.max(worst)) > max(rho_design + o.tol, rho_best):  # the exchange did not converge: the min-max filter
        h, worst = h_best, worst_best
    rho_best = min(rho_best, float(np.max(worst)))  # the min-max exchange may stop short of what the design reaches
    return _result(h, worst, rho_design, rho_best, feasible, rounds)
