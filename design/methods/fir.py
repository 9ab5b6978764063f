"""Implementable learning filters: fixed-order non-causal FIRs, a convex fit under robust convergence.

The closed-form filters of the Theorem (docs/theory.md section 2, :mod:`ilcdob.design.maps.closed_form`)
are rational, improper and partly anti-causal. Here each of them is replaced by a FIR with a
fixed non-causal advance ``a`` (samples)::

    output(k) = sum_{i=0}^{n-1} h[i] * input(k + a - i)        H(z) = z^a * sum_i h[i] z^-i

whose coefficients solve a weighted least-squares fit to the ideal response ``L(e^{jw Ts})`` on the
design grid ``w_min <= w <= w_max`` (default: Nyquist; :meth:`FIROptions.grid`)::

    minimise    sum_w  q(w) weight(w) |H(e^{jw Ts}) - L(e^{jw Ts})|^2 / |L(e^{jw Ts})|^2
              + ridge * ||h / s||^2                          (s = max |L|, conditioning)
    subject to  |Te1_k(e^{jw Ts})| <= r_k(w)    for every model k and check-grid frequency w   (L1 only)
    with        Te1_k = Gd_j^k / Gd_{j-1}^k - Gf_j^k H        (the k-th sampled true loops of
                                                               both systems, paired)

and ``r_k(w) = 1 - margin``: robust monotone convergence of the error map of the Theorem over
the Delta set (docs/theory.md section 3). The relative (``1/|L|^2``) weighting makes the fit
scale-free: ``|L1|`` spans five decades between ``w_min`` and Nyquist (an inverse plant at high
frequency). ``weight(w)`` is ``band_weight`` inside ``weight_band`` and 1 elsewhere; ``q(w)``
makes the sum an integral over ``log w`` (``1/n_grid`` on a log grid).

Grids. The design grid is ``n_grid`` log-spaced frequencies plus :data:`POINTS_PER_RIPPLE` linear
points per ``2 pi / (n_taps Ts)``: on the log grid alone an 80-tap FIR had fewer than two points per
ripple near Nyquist, and a fit held to the margin there swung to 1.5 times it between them. The
constraint is a continuum of frequencies; it is checked on the design grid refined
:data:`CHECK_REFINE` times and held there by exchange: solve with the constraint at some
(model, frequency) pairs, add the violated ones (the peak of each run between design-grid
frequencies), solve again (a handful of rounds).

Solving. Each constraint ``|c - b h| <= r`` is a second-order cone and the objective a convex
quadratic, so the problem is a convex second-order cone program. It is solved in orthonormal
coordinates ``z`` of the fit (an SVD of the weighted least-squares matrix, ridge included): the
objective becomes ``||z - z0||^2`` (``z0``: the unconstrained fit) and every design-grid constraint
row is of order one, where in the coefficients ``h`` the fit matrix has a condition number of 1e7.
The default solver is Clarabel (interior point, with a certificate when there is no solution);
IPOPT through CasADi (exact Hessian, warm-started at ``z0``) remains selectable. docs/fir.md
compares them.

When the margin cannot be met. Per frequency, the smallest ``max_k |Te1_k|`` that *any* filter
reaches (whatever its order or structure) is a small cone program over one complex number
(:func:`attainable_te1`). Where it exceeds ``1 - margin`` the sampled models disagree too much
for monotone convergence, and no choice of taps, advance or solver changes that. With
``unattainable="no-harm"`` (default) the design then keeps, for every model and frequency, the
weaker promise ``r_k(w) = max(1 - margin, |Gd_j^k / Gd_{j-1}^k|)``: the error of system j with
learning is at most ``1 - margin`` times system j-1's error, or at most its own error without
learning (no harm). It gives up the margin only where it must: a first cone program finds the
least total excess of ``|Te1|`` over ``1 - margin`` on the design grid (within the no-harm
promise), and the fit then keeps ``1 - margin`` at every (model, check-grid frequency) where that
least-excess point keeps it, and the no-harm bound elsewhere. The bands where the
margin is given up are stated (:attr:`FIRDesign.relaxed_bands`, ``filters.json``) and a
:class:`FIRGuaranteeWarning` says so. ``unattainable="refuse"`` raises instead (on the command
line: ``ilcdob design --method fir --fir-unattainable refuse``).

DC and the integrator of L1. ``L1 = -(1 - Q_j) Gd_{j-1}^{-1}`` keeps the PID integrator of
system j-1 (a pole at z = 1, visible below about ``ki/kp`` rad/s), which a FIR, with its
finite DC gain, cannot reproduce. The fit and the constraint therefore start at
``w_min > 0`` (choose it below the lowest disturbance frequency of interest). Below
``w_min`` nothing is promised: as ``w -> 0``, ``Gf_j H -> 0`` and ``Te1 -> lim Gd_j/Gd_{j-1}
= ki_{j-1}/ki_j`` (same Q), which exceeds 1 when system j-1 has the larger integral gain.
The design reports ``|Te1|`` below the band (:attr:`FIRDesign.te1_below_band`) so the user
sees it; in practice slow drifts are left to each system's own integrator and DOB.

L2 (``L1 Gf_{j-1}``, finite at DC and at Nyquist) is fitted the same way without constraint
(a linear least-squares problem, solved directly).
"""

from __future__ import annotations

import functools
import time
import warnings
from dataclasses import dataclass, field

import clarabel
import numpy as np
import scipy.sparse as sp
from threadpoolctl import ThreadpoolController

from ilcdob.errors import IlcdobError, NumericalError, SpecError
from ilcdob.interrupts import honour_interrupts
from ilcdob.loop import LoopSystem, freqresp
from ilcdob.response import fir_matrix, fir_response
from ilcdob.signals import as_signal, extend_smoothly

from ..maps.closed_form import LearningFilters, closed_form_filters
from ..sets.delta import DeltaSet
from ..filters.frequency_grid import FitWeighting, check_advance, check_count, check_w_min, log_linear_grid

__all__ = ["FIROptions", "FIRFilter", "FIRFit", "FIRDesign", "FIRDesignError", "FIRSolverError",
           "FIRGuaranteeWarning", "SOLVERS", "UNATTAINABLE", "POINTS_PER_RIPPLE", "CHECK_REFINE", "attainable_te1",
           "design_fir", "fit_fir"]

#: Solvers of the constrained fit (module docstring, "Solving").
SOLVERS = ("clarabel", "ipopt")
#: What :func:`design_fir` does where ``|Te1| <= 1 - margin`` cannot be met (module docstring).
UNATTAINABLE = ("no-harm", "refuse")
#: Points of the linear part of the design grid per ``2 pi / (n_taps Ts)`` (:meth:`FIROptions.grid`).
POINTS_PER_RIPPLE = 4
#: The constraint is checked on the design grid refined this many times (log spacing), and held there.
CHECK_REFINE = 8
#: Rounds of adding the check grid's violated frequencies to the constraint (module docstring, "Solving").
_ROUNDS = 12
#: Relative tolerance on every bound when a returned point is judged.
_TOL = 1e-6
_CLARABEL_OK = ("Solved", "AlmostSolved")
_IPOPT_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
_INFEASIBLE = ("PrimalInfeasible", "AlmostPrimalInfeasible", "Infeasible_Problem_Detected")


class FIRDesignError(IlcdobError, ValueError):
    """The robust convergence constraint cannot be met (by any filter, or by the FIR of the given order)."""


class FIRSolverError(NumericalError):
    """A cone program of the FIR design that has a solution was not solved (a numerical failure)."""


class FIRGuaranteeWarning(UserWarning):
    """The FIR design gave up ``|Te1| <= 1 - margin`` in some band and keeps only the no-harm promise there."""


@dataclass(frozen=True)
class FIROptions(FitWeighting):
    """Options of :func:`design_fir` (module docstring gives the optimisation problem).

    Attributes
    ----------
    n_taps : int
        FIR length ``n`` (>= 2).
    advance : int
        Non-causal lead ``a`` in samples, ``0 <= a <= n_taps - 1``.
    w_min : float
        Lowest grid frequency, rad/s (> 0; the integrator of L1 is not fitted below it).
    w_max : float or None
        Highest grid frequency, rad/s (default ``0.999 * pi / Ts``, just below Nyquist).
    n_grid : int
        Number of log-spaced grid frequencies (>= 10).
    margin : float
        Robust monotone convergence margin: ``|Te1| <= 1 - margin``, ``0 <= margin < 1``.
    weight_band : tuple of float
        Frequencies ``(lo, hi)`` rad/s where the fit is emphasised by ``band_weight``.
    band_weight : float
        Multiplier (> 0) of the relative fit weight inside ``weight_band``.
    ridge : float
        Tikhonov weight (>= 0) on the scaled coefficients; tames the huge cancelling
        coefficients of a long FIR fitting an inverse plant (at least 1e-14 is used, so that
        the fit has one solution).
    max_iter : int
        Iteration limit of the solver of the constrained fit.
    solver : {"clarabel", "ipopt"}
        Solver of the constrained fit (:data:`SOLVERS`; module docstring, "Solving").
    unattainable : {"no-harm", "refuse"}
        Where ``|Te1| <= 1 - margin`` cannot be met for every model: keep the no-harm promise
        there, with a :class:`FIRGuaranteeWarning` (default), or raise :class:`FIRDesignError`.
    """

    n_taps: int = 80
    advance: int = 8
    w_min: float = 0.3
    w_max: float | None = None
    n_grid: int = 200
    margin: float = 0.1
    weight_band: tuple[float, float] = (0.3, 5.0)
    band_weight: float = 10.0
    ridge: float = 1e-8
    max_iter: int = 300
    solver: str = "clarabel"
    unattainable: str = "no-harm"

    def __post_init__(self) -> None:
        check_count("n_taps", self.n_taps, 2)
        check_advance(self.advance, self.n_taps)
        check_w_min(self.w_min, " (a FIR cannot match the integrator of L1 at DC)")
        if self.w_max is not None and not (np.isfinite(self.w_max) and self.w_max > self.w_min):
            raise SpecError(f"`w_max`: got {self.w_max!r}, expected > w_min = {self.w_min} rad/s or None")
        check_count("n_grid", self.n_grid, 10)
        if not (np.isfinite(self.margin) and 0 <= self.margin < 1):
            raise SpecError(f"`margin`: got {self.margin!r}, expected 0 <= margin < 1")
        self._check_weighting()
        check_count("max_iter", self.max_iter, 1)
        if self.solver not in SOLVERS:
            raise SpecError(f"`solver`: got {self.solver!r}, expected one of {list(SOLVERS)}")
        if self.unattainable not in UNATTAINABLE:
            raise SpecError(f"`unattainable`: got {self.unattainable!r}, expected one of {list(UNATTAINABLE)} "
                            "(no-harm: keep only the no-harm promise where the margin cannot be met; refuse: raise)")

    def grid(self, ts: float) -> np.ndarray:
        """Design grid from ``w_min`` to ``w_max``: ``n_grid`` log-spaced frequencies and a linear grid.

        The linear grid has :data:`POINTS_PER_RIPPLE` points per ``2 pi / (n_taps Ts)``, the
        frequency resolution of the FIR: on the log grid alone an 80-tap FIR has fewer than two
        points per ripple near Nyquist and can swing between them unseen by the fit and the constraint.

        Parameters
        ----------
        ts : float
            Sample time, s (gives the default ``w_max``, just below Nyquist).

        Returns
        -------
        numpy.ndarray
            The sorted frequencies, rad/s.

        Raises
        ------
        SpecError
            ``w_max`` above Nyquist or not above ``w_min``.
        """
        nyq = 0.999 * np.pi / ts
        w_max = nyq if self.w_max is None else float(self.w_max)
        if w_max > np.pi / ts or self.w_min >= w_max:
            raise SpecError(f"`w_min`/`w_max`: need w_min = {self.w_min} < w_max = {w_max} <= Nyquist "
                            f"{np.pi / ts:.4g} rad/s; lower w_min or raise w_max")
        step = 2 * np.pi / (self.n_taps * ts) / POINTS_PER_RIPPLE
        grid = log_linear_grid(self.w_min, w_max, self.n_grid, np.arange(self.w_min + step, w_max, step))
        keep = np.concatenate([[True], np.diff(np.log(grid)) > 1e-3 * np.log(w_max / self.w_min) / self.n_grid])
        return grid[keep]  # no near-duplicates (they would only repeat a row of the fit)


@dataclass(frozen=True)
class FIRFilter:
    """A non-causal FIR ``output(k) = sum_i h[i] input(k + advance - i)``.

    Attributes
    ----------
    h : numpy.ndarray
        Coefficients ``h[0..n-1]`` (``h[0]`` multiplies ``input(k + advance)``).
    advance : int
        Non-causal lead, samples.
    ts : float
        Sample time, s.
    fit_error : float
        Weighted relative RMS fit error on the design grid (``nan`` if not fitted).
    max_rel_error : float
        Largest ``|H - L| / |L|`` on the design grid.
    """

    h: np.ndarray
    advance: int
    ts: float
    fit_error: float = float("nan")
    max_rel_error: float = float("nan")

    def __post_init__(self) -> None:
        h = np.asarray(self.h, dtype=float)
        if h.ndim != 1 or h.size < 1 or not np.all(np.isfinite(h)):
            raise SpecError(f"`h`: expected a 1-D finite array of coefficients, got shape {h.shape}")
        if not (0 <= int(self.advance)):
            raise SpecError(f"`advance`: got {self.advance!r}, expected >= 0 samples")
        if not (np.isfinite(self.ts) and self.ts > 0):
            raise SpecError(f"`ts`: got {self.ts!r}, expected a sample time > 0 s")
        object.__setattr__(self, "h", h)
        object.__setattr__(self, "advance", int(self.advance))

    def __repr__(self) -> str:
        return (f"<FIRFilter {self.n_taps} taps, advance {self.advance}, Ts {self.ts:g} s, fit error "
                f"{self.fit_error:.3g}, max relative error {self.max_rel_error:.3g}>")

    @property
    def n_taps(self) -> int:
        """Number of coefficients ``n``."""
        return int(self.h.size)

    def freqresp(self, w: np.ndarray) -> np.ndarray:
        """Frequency response ``H(e^{jw Ts}) = e^{jw Ts a} sum_i h[i] e^{-jw Ts i}``.

        Computed by :func:`ilcdob.response.fir_response`.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex response, the shape of ``w``.
        """
        return fir_response(self.h, w, self.ts, self.advance)

    def apply(self, x: object, name: str = "x") -> np.ndarray:
        """Apply non-causally over a whole trial.

        Before the trial the input is taken as zero (the system starts at rest); the
        ``advance`` samples needed past its end continue the input by a cubic fitted to the
        last samples (:func:`ilcdob.signals.extend_smoothly`), never by zeros (a step into a
        differentiating filter would spike).

        Parameters
        ----------
        x : array_like
            The trial, one sample per sample time.
        name : str
            The signal's name, for error messages.

        Returns
        -------
        numpy.ndarray
            The filtered trial, same length.
        """
        x = as_signal(x, name)
        n, m = x.size, self.n_taps
        z = np.concatenate([np.zeros(m - 1), extend_smoothly(x, self.advance)])
        full = np.convolve(z, self.h)
        start = m - 1 + self.advance
        return full[start:start + n]

    def to_dict(self) -> dict:
        """The filter in the coefficient form of ``filters.json`` (:mod:`..filters.coefficients`).

        ``num`` lists the coefficients of ``z^0, z^-1, ...`` (highest power first), so
        ``output(k) = sum_i num[i] * input(k + advance - i)``.

        Returns
        -------
        dict
            ``{"num": [...], "den": [1.0], "advance": a, "ts": Ts}``:
            ``H(z) = z^a sum_i num[i] z^-i``.
        """
        return {"num": [float(v) for v in self.h], "den": [1.0], "advance": int(self.advance),
                "ts": float(self.ts)}


@dataclass(frozen=True)
class FIRFit:
    """One FIR fitted by :func:`fit_fir`.

    Attributes
    ----------
    filter : FIRFilter
        The fitted FIR.
    te : numpy.ndarray
        ``|te_const - te_gain * H|`` on the grid (K x len(w); 0 x len(w) without constraint).
    status : str
        The solver's status (``"least squares"`` for an unconstrained fit).
    success : bool
        The solver reports an optimum (callers judge the point by the constraint as well).
    objective : float
        Weighted least-squares objective of the module docstring at the returned point.
    solve_time_s : float
        Wall time of the solver call, s (0 for an unconstrained fit).
    iterations : int
        Solver iterations (0 for an unconstrained fit).
    solver : str
        ``"clarabel"``, ``"ipopt"`` or ``"lstsq"``.
    """

    filter: FIRFilter
    te: np.ndarray
    status: str
    success: bool
    objective: float
    solve_time_s: float = 0.0
    iterations: int = 0
    solver: str = "lstsq"


@dataclass(frozen=True)
class FIRDesign:
    """The FIR pair replacing the closed-form (L1, L2) of one learning step j-1 -> j.

    Attributes
    ----------
    source, target : str
        Names of systems j-1 and j.
    L1, L2 : FIRFilter
        The filters replacing the closed-form ``L1`` and ``L2``.
    w : numpy.ndarray
        Design grid, rad/s (:meth:`FIROptions.grid`): the fit and :attr:`attainable`.
    te1 : numpy.ndarray
        ``|Te1_k|`` (K x len(check_w)) with the FIR L1 and the sampled true loops, on the check grid.
    worst_te1 : float
        ``max |Te1|`` on the check grid (<= 1 - margin unless :attr:`relaxed_bands` is not empty).
    worst_w : float
        Frequency of ``worst_te1``, rad/s.
    worst_model : int
        Index k of the sampled model pair attaining it.
    te1_below_band : float
        ``max |Te1|`` over models on a check grid from 1e-3 rad/s to ``w_min`` (not
        constrained, see module docstring: the FIR has no integrator).
    options : FIROptions
        The options of the design.
    solver_status : str
        The solver's status for the last fit of L1.
    limit : numpy.ndarray
        The bound ``r_k(w)`` each ``|Te1_k(w)|`` is held to on the check grid (K x len(check_w)):
        ``1 - margin``, or the no-harm bound ``max(1 - margin, |Gd_j^k / Gd_{j-1}^k|)`` where the
        margin is given up.
    attainable : numpy.ndarray
        Per design-grid frequency, the smallest ``max_k |Te1_k|`` any filter reaches
        (:func:`attainable_te1`).
    unattainable_bands : tuple of (float, float)
        Bands of the design grid (rad/s, first and last frequency) where ``attainable > 1 - margin``:
        no filter of any order meets the margin for every model there.
    relaxed_bands : tuple of (float, float)
        Bands of the check grid (rad/s) where this design exceeds ``1 - margin`` for some model (and
        keeps the no-harm promise); empty when the margin holds on the whole check grid.
    check_w : numpy.ndarray
        The check grid, rad/s: the design grid with :data:`CHECK_REFINE` - 1 log-spaced
        frequencies inserted in each interval. Every bound holds on it.
    """

    source: str
    target: str
    L1: FIRFilter
    L2: FIRFilter
    w: np.ndarray
    te1: np.ndarray
    worst_te1: float
    worst_w: float
    worst_model: int
    te1_below_band: float
    options: FIROptions
    solver_status: str = field(default="")
    limit: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    attainable: np.ndarray = field(default_factory=lambda: np.zeros(0))
    unattainable_bands: tuple[tuple[float, float], ...] = ()
    relaxed_bands: tuple[tuple[float, float], ...] = ()
    check_w: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __repr__(self) -> str:
        taps = f"{self.L1.n_taps} taps" if self.L1.n_taps == self.L2.n_taps else \
            f"L1 {self.L1.n_taps} taps, L2 {self.L2.n_taps} taps"
        status = self.solver_status or "no status"
        return (f"<FIRDesign {self.source!r} -> {self.target!r}: {taps}; worst |Te1| {self.worst_te1:.3g} at "
                f"{self.worst_w:.3g} rad/s (limit {1.0 - self.options.margin:.3g}); {status}; "
                f"{len(self.unattainable_bands)} unattainable, {len(self.relaxed_bands)} relaxed band(s)>")

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """Learning signal of system j: ``L1{e_{j-1}} + L2{d_f,{j-1}}`` (the Theorem, paper Sec. III).

        Parameters
        ----------
        e_prev : array_like
            Tracking error of system j-1 over the trial, m.
        df_prev : array_like
            Learning signal system j-1 flew with, m/s^2 (zeros if none), same length.

        Returns
        -------
        numpy.ndarray
            ``d_f,j``, m/s^2, same length.
        """
        e = as_signal(e_prev, "e_prev")
        df = as_signal(df_prev, "df_prev", e.size)
        out = self.L1.apply(e, "e_prev")
        return out + self.L2.apply(df, "df_prev") if np.any(df) else out

    @property
    def guarantee(self) -> str:
        """What the design promises on its grid, in words."""
        lim = 1.0 - self.options.margin
        band = f"{self.w[0]:.4g} to {self.w[-1]:.4g} rad/s ({self.check_w.size} frequencies)"
        if not self.relaxed_bands:
            return f"|Te1| <= {lim:.3g} for every sampled model from {band} (robust monotone convergence)"
        return (f"|Te1| <= {lim:.3g} for every sampled model from {band} except at {_format_bands(self.relaxed_bands)} "
                f"rad/s, where each model's error with learning is at most {lim:.3g} times system j-1's or at most "
                "its own error without learning (no harm)")

    def to_dict(self) -> dict:
        """The design as a JSON-ready dict.

        Returns
        -------
        dict
            ``source``, ``target``, both filters (:meth:`FIRFilter.to_dict`), the worst
            ``|Te1|`` with its frequency and model, ``te1_below_band``, both fit errors, the
            promise (``limit``, ``guarantee``, ``relaxed_bands``, ``unattainable_bands``,
            ``best_attainable_worst_te1``) and the solver's status.
        """
        return {"source": self.source, "target": self.target, "L1": self.L1.to_dict(),
                "L2": self.L2.to_dict(), "worst_te1": self.worst_te1, "worst_w": self.worst_w,
                "worst_model": self.worst_model, "te1_below_band": self.te1_below_band,
                "fit_error_L1": self.L1.fit_error, "fit_error_L2": self.L2.fit_error,
                "limit": 1.0 - self.options.margin, "guarantee": self.guarantee,
                "relaxed_bands": [list(b) for b in self.relaxed_bands],
                "unattainable_bands": [list(b) for b in self.unattainable_bands],
                "best_attainable_worst_te1": float(np.max(self.attainable)) if self.attainable.size else 0.0,
                "solver": self.options.solver, "solver_status": self.solver_status}


def _realify(a: np.ndarray) -> np.ndarray:
    return np.concatenate([a.real, a.imag], axis=0)


def _bands(w: np.ndarray, mask: np.ndarray) -> tuple[tuple[float, float], ...]:
    """Runs of consecutive grid points where ``mask`` holds, as (first, last) frequency."""
    return tuple((float(w[lo]), float(w[hi])) for lo, hi in _runs(mask))


def _quadrature(w: np.ndarray) -> np.ndarray:
    """Weights of a sum over ``w`` that approximates an integral over ``log w`` (sum 1; ``1/len(w)``
    on a log-spaced grid), so that the linear part of the design grid does not weigh high frequencies more."""
    d = np.gradient(np.log(w)) if w.size > 1 else np.ones(1)
    return d / np.sum(d)


def _format_bands(bands: tuple[tuple[float, float], ...]) -> str:
    return ", ".join(f"{lo:.3g}" if lo == hi else f"{lo:.3g}-{hi:.3g}" for lo, hi in bands)


@dataclass(frozen=True)
class _Whitened:
    """The weighted least-squares fit in orthonormal coordinates ``z`` (module docstring, "Solving"):
    objective ``||z - z0||^2 + residual``, response ``H(w_i) = resp[i] @ z``, coefficients ``h = to_h @ z``."""

    resp: np.ndarray
    z0: np.ndarray
    residual: float
    to_h: np.ndarray


def _whiten(target: np.ndarray, w: np.ndarray, ts: float, options: FIROptions) -> _Whitened:
    n, m = int(options.n_taps), w.size
    e_mat = fir_matrix(w, n, int(options.advance), ts)
    wt = np.sqrt(options.weights(w) * _quadrature(w)) / np.abs(target)
    scale = float(np.max(np.abs(target)))
    a_aug = np.vstack([_realify(e_mat * wt[:, None]), np.sqrt(max(options.ridge, 1e-14)) / scale * np.eye(n)])
    y_aug = np.concatenate([_realify(target * wt), np.zeros(n)])
    u, sv, vt = np.linalg.svd(a_aug, full_matrices=False)
    z0 = u.T @ y_aug
    return _Whitened(resp=(u[:m] + 1j * u[m:2 * m]) / wt[:, None], z0=z0,
                     residual=max(float(y_aug @ y_aug - z0 @ z0), 0.0), to_h=vt.T / sv[None, :])


def _clarabel(p_mat: sp.csc_matrix, q: np.ndarray, a_mat: sp.csc_matrix, b: np.ndarray, cones: list,
              max_iter: int = 200) -> tuple[np.ndarray, str, int, float]:
    """Solve ``min 1/2 x'Px + q'x`` s.t. ``b - A x`` in ``cones``; (x, status, iterations, seconds)."""
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_iter = int(max_iter)
    settings.direct_solve_method = "faer"  # a quarter faster than qdldl on these dense-column problems
    settings.max_threads = 1  # small factorisations: threads only cost wake-ups (see design_fir)
    t0 = time.perf_counter()
    try:
        with honour_interrupts():
            sol = clarabel.DefaultSolver(p_mat, q, a_mat, b, cones, settings).solve()
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # Clarabel raises on malformed data or internal failures
        raise FIRSolverError(f"FIR design: Clarabel failed ({exc}); next step: solver='ipopt' in FIROptions") from exc
    return np.asarray(sol.x, float), str(sol.status), int(sol.iterations), time.perf_counter() - t0


def _te_rows(fit: _Whitened, te_const: np.ndarray, te_gain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Te1`` as ``c - B z`` (rows ordered model-major, like ``te_const.reshape(-1)``)."""
    n = fit.z0.size
    return te_const.reshape(-1), (te_gain[:, :, None] * fit.resp[None, :, :]).reshape(-1, n)


def _soc_rows(b_rows: np.ndarray, n_vars: int) -> sp.csc_matrix:
    """Rows ``[0; Re B_i; Im B_i]`` of one 3-dimensional cone per row ``B_i`` (z the first variables)."""
    p, n = b_rows.shape
    a3 = np.zeros((p, 3, n_vars))
    a3[:, 1, :n] = b_rows.real
    a3[:, 2, :n] = b_rows.imag
    return sp.csc_matrix(a3.reshape(3 * p, n_vars))


def _solve_conic(fit: _Whitened, c: np.ndarray, b_rows: np.ndarray, bound: np.ndarray,
                 max_iter: int) -> tuple[np.ndarray, str, int, float]:
    n = fit.z0.size
    cones = [clarabel.SecondOrderConeT(3) for _ in range(c.size)]
    rhs = np.stack([bound, c.real, c.imag], axis=1).reshape(-1)
    return _clarabel(sp.csc_matrix(2.0 * sp.identity(n)), -2.0 * fit.z0, _soc_rows(b_rows, n), rhs, cones, max_iter)


def _solve_ipopt(fit: _Whitened, c: np.ndarray, b_rows: np.ndarray, bound: np.ndarray,
                 max_iter: int) -> tuple[np.ndarray, str, int, float]:
    import casadi as cs  # only for this solver: CasADi takes a while to load

    n = fit.z0.size
    z = cs.MX.sym("z", n)
    re = cs.DM(c.real) - cs.mtimes(cs.DM(b_rows.real), z)
    im = cs.DM(c.imag) - cs.mtimes(cs.DM(b_rows.imag), z)
    nlp = {"x": z, "f": cs.sumsqr(z - cs.DM(fit.z0)), "g": re**2 + im**2}
    solver = cs.nlpsol("fir_fit", "ipopt", nlp, {
        "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": int(max_iter),
        "ipopt.tol": 1e-8, "ipopt.acceptable_tol": 1e-6, "ipopt.acceptable_iter": 5,
        "ipopt.hessian_approximation": "exact"})
    t0 = time.perf_counter()
    with honour_interrupts():  # CasADi turns a Ctrl-C into a failed solve
        sol = solver(x0=fit.z0, lbg=-np.inf * np.ones(c.size), ubg=bound**2)
    elapsed = time.perf_counter() - t0
    stats = solver.stats()
    return (np.asarray(sol["x"], float).reshape(-1), str(stats.get("return_status", "")),
            int(stats.get("iter_count", 0)), elapsed)


def fit_fir(target: np.ndarray, w: np.ndarray, ts: float, options: FIROptions,
            te_const: np.ndarray | None = None, te_gain: np.ndarray | None = None,
            te_limit: np.ndarray | float | None = None) -> FIRFit:
    """Fit a FIR to the response ``target`` on ``w`` (module docstring), optionally constrained.

    Parameters
    ----------
    target : complex array
        Ideal response on ``w`` (no zeros).
    w : array
        Grid, rad/s.
    ts : float
        Sample time, s.
    options : FIROptions
        Taps, advance, weights, ridge, solver and its iteration limit.
    te_const, te_gain : complex arrays (K x len(w)), optional
        Constraint ``|te_const - te_gain * H| <= te_limit`` (Te1 of the module docstring);
        omitted: the unconstrained fit, a linear least-squares solve.
    te_limit : float or array (K x len(w)), optional
        The bound (default ``1 - margin``).

    Returns
    -------
    FIRFit
        The filter, ``|Te|`` at it and the solver's report. An infeasible problem returns the
        solver's last point with ``success`` False.

    Raises
    ------
    SpecError
        A target with zeros or non-finite values on the grid; mismatched constraint arrays.
    FIRSolverError
        Clarabel raised.
    """
    w = np.asarray(w, float)
    target = np.asarray(target, complex)
    if target.shape != w.shape or np.any(target == 0) or not np.all(np.isfinite(target)):
        raise SpecError("`target`: the ideal response has zeros or non-finite values on the grid, or not one value "
                        "per grid frequency; move w_min/w_max away from them")
    const = gain = None
    if te_const is not None:
        const, gain = np.asarray(te_const, complex), np.asarray(te_gain, complex)
        if const.ndim != 2 or const.shape != gain.shape or const.shape[1] != w.size:
            raise SpecError(f"`te_const`/`te_gain`: got shapes {const.shape} and {np.shape(te_gain)}, expected "
                            f"both (K, {w.size})")
    fit = _whiten(target, w, ts, options)
    z, status, iters, elapsed, ok, solver = fit.z0, "least squares", 0, 0.0, True, "lstsq"
    te = np.zeros((0, w.size))
    if const is not None:
        limit = 1.0 - options.margin if te_limit is None else te_limit
        bound = np.broadcast_to(np.asarray(limit, float), const.shape).reshape(-1)
        c, b_rows = _te_rows(fit, const, gain)
        solve = _solve_conic if options.solver == "clarabel" else _solve_ipopt
        z, status, iters, elapsed = solve(fit, c, b_rows, bound, int(options.max_iter))
        ok, solver = status in (_CLARABEL_OK + _IPOPT_OK), options.solver
        te = np.abs(c - b_rows @ z).reshape(const.shape)
    h = fit.to_h @ z
    resp = fir_matrix(w, int(options.n_taps), int(options.advance), ts) @ h
    rel = np.abs(resp - target) / np.abs(target)
    wts = options.weights(w) * _quadrature(w)
    filt = FIRFilter(h, int(options.advance), ts, float(np.sqrt(np.sum(wts * rel**2) / np.sum(wts))),
                     float(np.max(rel)))
    objective = float(np.sum((z - fit.z0) ** 2) + fit.residual)
    return FIRFit(filt, te, status, ok, objective, elapsed, iters, solver)


def attainable_te1(te_const: np.ndarray, te_gain: np.ndarray) -> np.ndarray:
    """Per frequency, the smallest ``max_k |te_const[k] - te_gain[k] * H|`` over every complex ``H``.

    It is what the best filter of any order and structure reaches at that frequency (one
    complex value per frequency is all a filter contributes there), so no design does better.
    Solved as one cone program (a minimax over K discs per frequency), with ``H`` scaled per
    frequency by ``max_k |te_gain[k]|``.

    Parameters
    ----------
    te_const, te_gain : complex arrays (K x M)
        ``Te1_k = te_const[k] - te_gain[k] * H`` (module docstring).

    Returns
    -------
    numpy.ndarray
        The M smallest worst-case magnitudes.

    Raises
    ------
    SpecError
        Arrays of different or non-2-D shapes, non-finite values, or a zero gain column.
    FIRSolverError
        The cone program was not solved.
    """
    return _attainable(np.asarray(te_const, complex), np.asarray(te_gain, complex))[0]


def _attainable(c: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`attainable_te1` and the minimising ``H`` per frequency."""
    if c.ndim != 2 or c.shape != g.shape or not (np.all(np.isfinite(c)) and np.all(np.isfinite(g))):
        raise SpecError(f"`te_const`/`te_gain`: got shapes {c.shape} and {g.shape}, expected two finite (K, M) arrays")
    k_models, m = c.shape
    sig = np.max(np.abs(g), axis=0)
    if np.any(sig == 0):
        raise SpecError("`te_gain`: zero at some frequency for every model; the filter has no effect there")
    if k_models == 1:
        return np.zeros(m), c[0] / g[0]
    gs = g / sig
    cone = np.arange(k_models * m)
    i = np.tile(np.arange(m), k_models)
    gr, gi = gs.real.reshape(-1), gs.imag.reshape(-1)
    rows = np.concatenate([3 * cone, 3 * cone + 1, 3 * cone + 1, 3 * cone + 2, 3 * cone + 2])
    cols = np.concatenate([2 * m + i, i, m + i, i, m + i])
    vals = np.concatenate([-np.ones(cone.size), gr, -gi, gi, gr])
    a_mat = sp.csc_matrix((vals, (rows, cols)), shape=(3 * cone.size, 3 * m))
    rhs = np.stack([np.zeros(cone.size), c.real.reshape(-1), c.imag.reshape(-1)], axis=1).reshape(-1)
    q = np.concatenate([np.zeros(2 * m), np.ones(m)])
    x, status, _, _ = _clarabel(sp.csc_matrix((3 * m, 3 * m)), q, a_mat, rhs,
                                [clarabel.SecondOrderConeT(3) for _ in range(cone.size)])
    if status not in _CLARABEL_OK:
        raise FIRSolverError(f"FIR design: the attainable |Te1| (a cone program with a solution) was not solved "
                             f"(Clarabel: {status}); next step: fewer Delta samples or a coarser grid (n_grid)")
    h_best = (x[:m] + 1j * x[m:2 * m]) / sig
    return np.max(np.abs(c - g * h_best[None, :]), axis=0), h_best


def _least_excess(fit: _Whitened, c: np.ndarray, b_rows: np.ndarray, limit: float,
                  no_harm: np.ndarray) -> np.ndarray:
    """``z`` of the least total excess ``sum v`` with ``|Te1| <= limit + v`` and ``0 <= v <= no_harm - limit``
    at the given rows (module docstring, "When the margin cannot be met")."""
    n, p = fit.z0.size, c.size
    free = np.flatnonzero(no_harm > limit)
    nv = free.size
    a_soc = _soc_rows(b_rows, n + nv).tolil()
    a_soc[3 * free, n + np.arange(nv)] = -1.0
    box = sp.hstack([sp.csc_matrix((2 * nv, n)), sp.vstack([-sp.identity(nv), sp.identity(nv)])])
    a_mat = sp.vstack([a_soc.tocsc(), box], format="csc")
    rhs = np.concatenate([np.stack([np.full(p, limit), c.real, c.imag], axis=1).reshape(-1),
                          np.zeros(nv), no_harm[free] - limit])
    cones = [clarabel.SecondOrderConeT(3) for _ in range(p)] + [clarabel.NonnegativeConeT(2 * nv)]
    q = np.concatenate([np.zeros(n), np.ones(nv)])
    x, status, _, _ = _clarabel(sp.csc_matrix((n + nv, n + nv)), q, a_mat, rhs, cones)
    if status not in _CLARABEL_OK:  # feasible by construction: H = 0 meets the no-harm bound
        raise FIRSolverError(f"FIR design: the least excess over the margin (a cone program with a solution) was "
                             f"not solved (Clarabel: {status}); next step: unattainable='refuse' to see where the "
                             "margin fails, or fewer Delta samples")
    return x[:n]


def _models(loop: LoopSystem, delta: DeltaSet | None, which: str) -> tuple[LoopSystem, ...]:
    if delta is None:
        return (loop,)
    if not isinstance(delta, DeltaSet):
        raise SpecError(f"`{which}`: expected a DeltaSet (ilcdob.design.delta_set) or None, "
                        f"got {type(delta).__name__}")
    if delta.system != loop.name:
        raise SpecError(f"`{which}`: Delta set of system {delta.system!r} given for loop {loop.name!r}; "
                        "pass the Delta set of the same system")
    return tuple(delta.loops)


def _worst(te: np.ndarray, w: np.ndarray) -> tuple[float, int, int, str]:
    """Largest ``|Te1|``, its model and grid index, and which models are within 1e-6 of it there."""
    k, i = np.unravel_index(int(np.argmax(te)), te.shape)
    worst = float(te[k, i])
    tied = np.flatnonzero(te[:, i] >= worst * (1 - 1e-6))
    which = f"sampled model {k}" if tied.size == 1 else "sampled models " + ", ".join(map(str, tied))
    return worst, int(k), int(i), which


def _check_grid(w: np.ndarray) -> np.ndarray:
    """The design grid with :data:`CHECK_REFINE` - 1 log-spaced points inserted in each interval
    (``check[::CHECK_REFINE] == w``)."""
    m = w.size
    check = np.exp(np.interp(np.arange((m - 1) * CHECK_REFINE + 1) / CHECK_REFINE, np.arange(m), np.log(w)))
    check[::CHECK_REFINE] = w
    return check


def _peaks(ratio: np.ndarray, over: np.ndarray) -> np.ndarray:
    """Per model (row), the largest ``ratio`` of each run of consecutive ``over`` points."""
    out = np.zeros_like(over)
    for k in range(over.shape[0]):
        for lo, hi in _runs(over[k]):
            out[k, lo + int(np.argmax(ratio[k, lo:hi + 1]))] = True
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(idx) > 1)
    return list(zip(idx[np.concatenate([[0], cuts + 1])], idx[np.concatenate([cuts, [idx.size - 1]])]))


@dataclass
class _Exchange:
    """Result of :func:`_hold` and :func:`_least_hold`: the point, ``|Te1|`` there on the check grid, the
    solver's last status, whether the bound holds on the check grid, and the constrained (model, frequency) pairs."""

    z: np.ndarray
    te: np.ndarray
    status: str
    held: bool
    active: np.ndarray
    rounds: int


class _Checked:
    """The constraint data on the check grid: ``Te1 = const - gain * (resp @ z)`` (K x len(check))."""

    def __init__(self, fit: _Whitened, resp: np.ndarray, const: np.ndarray, gain: np.ndarray):
        self.fit, self.resp, self.const, self.gain = fit, resp, const, gain

    def rows(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(c, B)`` of the active pairs (model-major), ``Te1 = c - B z``."""
        k, i = np.nonzero(active)
        return self.const[k, i], self.gain[k, i][:, None] * self.resp[i]

    def te(self, z: np.ndarray) -> np.ndarray:
        """``|Te1|`` on the check grid at ``z``."""
        return np.abs(self.const - self.gain * (self.resp @ z)[None, :])


def _add(te: np.ndarray, bound: np.ndarray, active: np.ndarray, on_w: np.ndarray, every: bool = False) -> np.ndarray:
    """Pairs to constrain next (the exchange step): every violated pair on the design grid, and the peak of every
    run of violations on the check grid (``every``: all of its violated pairs)."""
    over = te > bound * (1 + _TOL / 2)
    add = over.copy() if every else _peaks(te / bound, over)
    add[:, on_w] |= over[:, on_w]
    return add & ~active


def _hold(data: _Checked, bound: np.ndarray, active: np.ndarray, on_w: np.ndarray,
          options: FIROptions) -> _Exchange:
    """Minimise the fit with ``|Te1| <= bound`` at the ``active`` pairs of the check grid, add the violated pairs
    (:func:`_add`) and solve again, until the bound holds on the whole check grid (an exchange method for the
    continuum of frequencies; module docstring, "Solving")."""
    active = active | _add(data.te(data.fit.z0), bound, active, on_w)
    solve = _solve_conic if options.solver == "clarabel" else _solve_ipopt
    z, status = data.fit.z0, "unconstrained optimum"
    for rounds in range(1, _ROUNDS + 1):
        if active.any():
            c, b_rows = data.rows(active)
            k, i = np.nonzero(active)
            z, status, _, _ = solve(data.fit, c, b_rows, bound[k, i], int(options.max_iter))
        te = data.te(z)
        if status in _INFEASIBLE:
            return _Exchange(z, te, status, False, active, rounds)
        add = _add(te, bound, active, on_w)
        held = bool(np.all(te <= bound * (1 + _TOL / 2)))
        if held or not add.any():  # held, or broken where it was imposed (the solver's accuracy)
            return _Exchange(z, te, status, held, active, rounds)
        active |= add
    return _Exchange(z, te, status, False, active, _ROUNDS)


def _least_hold(data: _Checked, limit: float, no_harm: np.ndarray, on_w: np.ndarray, active: np.ndarray,
                rounds: int) -> _Exchange:
    """:func:`_least_excess` at the ``active`` pairs, with up to ``rounds`` exchange steps against the no-harm
    bound on the check grid (so that its point meets the no-harm bound there)."""
    for done in range(1, rounds + 1):
        c, b_rows = data.rows(active)
        z = _least_excess(data.fit, c, b_rows, limit, no_harm[active])
        te = data.te(z)
        add = _add(te, no_harm, active, on_w, every=True)  # each round re-solves the whole design grid: few rounds
        held = bool(np.all(te <= no_harm * (1 + _TOL / 2)))
        if held or not add.any() or done == rounds:
            return _Exchange(z, te, "Solved", held, active, done)
        active = active | add
    raise AssertionError("unreachable: rounds >= 1")


def _give_up(data: _Checked, limit: float, no_harm: np.ndarray, least: _Exchange, on_w: np.ndarray,
             options: FIROptions) -> tuple[_Exchange, np.ndarray]:
    """The fit that keeps the margin wherever the least-excess point ``least`` keeps it and the no-harm bound
    elsewhere; (result, the bound it holds)."""
    give_up = least.te > limit * (1 + _TOL / 4)
    bound = np.where(give_up, no_harm, limit)
    return _hold(data, bound * (1 + _TOL / 4), least.active & give_up, on_w, options), bound


def design_fir(prev_loop: LoopSystem, next_loop: LoopSystem, delta_prev: DeltaSet | None = None,
               delta_next: DeltaSet | None = None, options: FIROptions | None = None) -> FIRDesign:
    """FIR learning filters for system ``next_loop`` (j) learning from ``prev_loop`` (j-1).

    L1 is fitted to ``closed_form_filters(prev_loop, next_loop).l1_response`` subject to
    robust monotone convergence ``|Te1_k| <= 1 - margin`` for every pair ``k`` of sampled
    true loops (``delta_prev.loops[k]``, ``delta_next.loops[k]``) on the grid; where no filter
    meets it, as ``options.unattainable`` says; L2 is fitted to ``l2_response`` without
    constraint (module docstring; docs/theory.md sections 2-3; docs/fir.md).

    Parameters
    ----------
    prev_loop, next_loop : LoopSystem
        Loops of systems j-1 and j (their models).
    delta_prev, delta_next : DeltaSet or None
        Sampled true loops of both systems, the same number K of each (None: the model only).
    options : FIROptions, optional
        Taps, grid, margin, solver and the policy where the margin is unattainable.

    Returns
    -------
    FIRDesign
        Both filters, ``|Te1|`` on the grid and the promise they keep.

    Raises
    ------
    SpecError
        Bad options, mismatched Delta sets or sample times.
    FIRDesignError
        ``unattainable="refuse"`` and the margin cannot be met; the message says whether any
        filter could, names the worst frequency and models, and the next step.
    FIRSolverError
        A cone program with a solution was not solved, or the returned point breaks its bound.

    Warns
    -----
    FIRGuaranteeWarning
        ``unattainable="no-harm"`` gave up the margin in some band (named in the message).
    """
    # every matrix here is small (80 columns): BLAS threads only cost wake-ups, up to a second per
    # SVD on a loaded machine, so the design runs single-threaded
    with _blas_controller().limit(limits=1, user_api="blas"):
        return _design_fir(prev_loop, next_loop, delta_prev, delta_next, options)


@functools.lru_cache(maxsize=1)
def _blas_controller() -> ThreadpoolController:
    return ThreadpoolController()


def _design_fir(prev_loop: LoopSystem, next_loop: LoopSystem, delta_prev: DeltaSet | None,
                delta_next: DeltaSet | None, options: FIROptions | None) -> FIRDesign:
    options = FIROptions() if options is None else options
    if not isinstance(options, FIROptions):
        raise SpecError(f"`options`: expected FIROptions, got {type(options).__name__}")
    filters: LearningFilters = closed_form_filters(prev_loop, next_loop)
    ts = prev_loop.ts
    w = options.grid(ts)
    src_models = _models(prev_loop, delta_prev, "delta_prev")
    tgt_models = _models(next_loop, delta_next, "delta_next")
    if delta_prev is None and delta_next is not None:
        src_models = (prev_loop,) * len(tgt_models)
    if delta_next is None and delta_prev is not None:
        tgt_models = (next_loop,) * len(src_models)
    if len(src_models) != len(tgt_models):
        raise SpecError(f"`delta_prev`/`delta_next`: {len(src_models)} and {len(tgt_models)} samples; the "
                        "k-th samples are paired, draw both Delta sets with the same k")
    check = _check_grid(w)
    const_c = np.array([freqresp(t.G_d, check) / freqresp(s.G_d, check) for s, t in zip(src_models, tgt_models)])
    gain_c = np.array([freqresp(t.G_f, check) for t in tgt_models])
    on_w = np.arange(0, check.size, CHECK_REFINE)  # check[on_w] == w
    const, gain = const_c[:, on_w], gain_c[:, on_w]
    target = filters.l1_response(w)
    limit = 1.0 - options.margin
    name = f"FIR learning filter {prev_loop.name!r} -> {next_loop.name!r}"
    best, h_best = _attainable(const, gain)
    unattainable = best > limit * (1 + _TOL)
    if unattainable.any() and options.unattainable == "refuse":
        raise FIRDesignError(_refusal(name, options, w, unattainable, best, const, gain, h_best, None))
    fit = _whiten(target, w, ts, options)
    data = _Checked(fit, fir_matrix(check, int(options.n_taps), int(options.advance), ts) @ fit.to_h, const_c, gain_c)
    none = np.zeros(const_c.shape, bool)
    no_harm = np.maximum(limit, np.abs(const_c))
    bound = np.full(const_c.shape, limit)
    result = None
    if not unattainable.any():
        result = _hold(data, bound, none, on_w, options)
        result = result if result.held else None  # no FIR of this order meets the margin everywhere
    if result is None:
        on_grid = np.zeros(const_c.shape, bool)
        on_grid[:, on_w] = True
        least = _least_hold(data, limit, no_harm, on_w, on_grid, 1)
        if options.unattainable == "refuse":
            raise FIRDesignError(_refusal(name, options, w, unattainable, best, const, gain, h_best,
                                          least.te[:, on_w]))
        result, bound = _give_up(data, limit, no_harm, least, on_w, options)
        if not result.held:
            # the least-excess point broke the no-harm bound between grid frequencies and the fit found no point
            # within its pattern: hold the least-excess point to the no-harm bound on the check grid, then refit
            least = _least_hold(data, limit, no_harm, on_w, least.active, _ROUNDS)
            if not least.held:
                raise _not_held(name, options, check, least, no_harm)
            result, bound = _give_up(data, limit, no_harm, least, on_w, options)
        if not result.held:
            raise _not_held(name, options, check, result, bound)
    h = fit.to_h @ result.z
    te = np.abs(const_c - gain_c * (fir_matrix(check, int(options.n_taps), int(options.advance), ts) @ h)[None, :])
    rel = np.abs(fir_matrix(w, int(options.n_taps), int(options.advance), ts) @ h - target) / np.abs(target)
    wts = options.weights(w) * _quadrature(w)
    l1_fir = FIRFilter(h, int(options.advance), ts, float(np.sqrt(np.sum(wts * rel**2) / np.sum(wts))),
                       float(np.max(rel)))
    worst, k, i, _ = _worst(te, check)
    relaxed = np.max(te, axis=0) > limit * (1 + _TOL)
    if relaxed.any():
        peak = int(np.argmax(best))
        cause = (f"no filter of any order meets it for every sampled model at {_format_bands(_bands(w, unattainable))} "
                 f"rad/s (the best any filter reaches there is |Te1| = {best[peak]:.3g} at {w[peak]:.3g} rad/s)"
                 if unattainable.any() else
                 f"no FIR of {options.n_taps} taps with advance {options.advance} meets it on the whole grid")
        warnings.warn(f"{name}: robust monotone convergence |Te1| <= {limit:.3g} given up at "
                      f"{_format_bands(_bands(check, relaxed))} rad/s: {cause}. There the design keeps the no-harm "
                      "promise (for every sampled model, the error with learning is at most the margin times system "
                      "j-1's or at most its own error without learning). Next step: a smaller uncertainty to keep the "
                      "margin, or FIROptions(unattainable='refuse') (command line: --fir-unattainable refuse) to stop "
                      "instead", FIRGuaranteeWarning,
                      stacklevel=3)
    w_low = np.logspace(-3, np.log10(options.w_min), 40)
    const_low = np.array([freqresp(t.G_d, w_low) / freqresp(s.G_d, w_low)
                          for s, t in zip(src_models, tgt_models)])
    gain_low = np.array([freqresp(t.G_f, w_low) for t in tgt_models])
    te_low = float(np.max(np.abs(const_low - gain_low * l1_fir.freqresp(w_low)[None, :])))
    l2_fir = fit_fir(filters.l2_response(w), w, ts, options).filter
    return FIRDesign(source=prev_loop.name, target=next_loop.name, L1=l1_fir, L2=l2_fir, w=w, te1=te,
                     worst_te1=worst, worst_w=float(check[i]), worst_model=k, te1_below_band=te_low,
                     options=options, solver_status=result.status, limit=bound, attainable=best,
                     unattainable_bands=_bands(w, unattainable), relaxed_bands=_bands(check, relaxed),
                     check_w=check)


def _not_held(name: str, options: FIROptions, check: np.ndarray, result: _Exchange,
              bound: np.ndarray) -> FIRSolverError:
    """The error when the exchange stopped with the bound broken on the check grid although it has a solution."""
    k, i = np.unravel_index(int(np.argmax(result.te / bound)), bound.shape)
    other = "solver='clarabel'" if options.solver == "ipopt" else "solver='ipopt'"
    return FIRSolverError(
        f"{name}: the fit has a solution but {options.solver} ({result.status}, {result.rounds} rounds) returned a "
        f"point with |Te1| = {result.te[k, i]:.4g} > {bound[k, i]:.4g} at w = {check[i]:.4g} rad/s for sampled model "
        f"{k}; next step: a larger max_iter ({options.max_iter}), {other}, or fewer Delta samples")


def _refusal(name: str, options: FIROptions, w: np.ndarray, unattainable: np.ndarray, best: np.ndarray,
             const: np.ndarray, gain: np.ndarray, h_best: np.ndarray, te_least: np.ndarray | None) -> str:
    """The message of :class:`FIRDesignError` for ``unattainable="refuse"``."""
    limit = 1.0 - options.margin
    head = f"{name}: robust monotone convergence |Te1| <= {limit:.3g} not met"
    if unattainable.any():
        te_best = np.abs(const - gain * h_best[None, :])
        worst, _, i, which = _worst(te_best, w)
        margin = f", a margin below {1 - worst:.3g}" if worst < 1 else ""
        return (f"{head} by any filter: at {_format_bands(_bands(w, unattainable))} rad/s the sampled models "
                f"disagree too much; even the best response there leaves worst |Te1| = {worst:.4g} at w = "
                f"{w[i]:.4g} rad/s for {which}, and no FIR does better whatever its taps or advance. Next step: a "
                f"smaller uncertainty (the Delta sets' bound or scale){margin}, or FIROptions(unattainable='no-harm') "
                "(command line: --fir-unattainable no-harm, the default) to keep the margin where it can be met "
                "and only the no-harm promise elsewhere")
    worst, _, i, which = _worst(te_least, w)
    return (f"{head} ({options.solver}); some filter meets it at every grid frequency, but no FIR of n_taps = "
            f"{options.n_taps} with advance {options.advance} does: at the least excess, worst |Te1| = {worst:.4g} "
            f"at w = {w[i]:.4g} rad/s for {which}. Next step: more taps (n_taps = {options.n_taps}), a "
            f"larger advance ({options.advance}), a larger w_min ({options.w_min} rad/s), a smaller margin "
            f"({options.margin}), or FIROptions(unattainable='no-harm') (command line: --fir-unattainable no-harm)")
