"""Output-error fits of continuous-time transfer functions with delay, for real flight logs.

The criterion is the simulation error (output error, MATLAB's ``tfest`` with
``Focus='simulation'``)::

    minimise  sum_e sum_k ( y_e[k] - yhat_e[k] )^2,
    yhat_e = G(theta, delay){u_e} + free response(beta_e) + trend_e

with ``G(s) = B(s)/(s^K A(s)) e^{-s delay}`` sampled exactly under a zero-order hold
(:mod:`.oe`), and per experiment ``e`` an initial condition ``beta_e`` (one coefficient per
pole) and a polynomial output trend (offset by default; slope for slow drift). The trend
degrees that the free response already spans (a constant with one integrator, a ramp with
two) are left out.

Engine (chosen by measurement against the CasADi/IPOPT formulation it replaced: 1.28 s ->
0.03 s on ``benchmarks/bench_tfest.py``, 3,900 -> 200 bytes per sample; the design and its
reasons are in ``docs/identification.md``):

* variable projection: numerator, initial conditions and trends are solved exactly at every
  step (Gram matrices, per-experiment Schur elimination); Levenberg-Marquardt runs on the
  free denominator coefficients and the delay only, with Kaufman's Jacobian;
* exact sensitivities computed by filtering (:mod:`.oe`): O(N) per parameter, in C;
* starts from SRIVC (:mod:`.srivc`) and a grid of pole locations, ranked together on a record
  decimated to the band the response lives in (:func:`_ranking_decimation`; long logs only) with
  their filtering batched (:func:`_ranked`), the best few re-solved on the full record; LM runs
  from the best and from the next distinct start within :data:`SECONDARY_START_RATIO` of it;
  unstable trial models (a free pole with Re >= 0) are rejected when ``stable``;
* ``delay="auto"``: the delay is a continuous parameter of the same LM (the fractional-delay
  ZOH is smooth in it), started from a profile over :data:`DELAY_SWEEP_POINTS` delays, each a
  single LM step warm-started from its neighbour (no fit from scratch per point);
* an iteration or time limit returns the best iterate with a ``RuntimeWarning`` and its
  status in ``solver``;
* memory: a few signal-length arrays per parameter (about 200 bytes per sample for a
  2-pole model); ranking records beyond :data:`RANKING_SAMPLES` samples (after decimation)
  are represented by evenly spaced chunks while the starts are chosen.

Closed-loop data: the direct output-error fit is consistent when the output disturbance
is white measurement noise and the plant is strictly proper (Ljung, System Identification,
2nd ed., sec. 13.4); it is biased by coloured disturbances that are fed back, in
proportion to their power relative to the external excitation. Fly closed-loop experiments
in calm air with a strong external excitation and check ``input_correlation``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import signal as sps
from scipy.linalg import expm
from threadpoolctl import ThreadpoolController

from ilcdob.errors import IlcdobError, SignalError, SpecError
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure

from .held import held_runs, held_segments
from .oe import Discretisation, allpole_sos, delay_split, delayed_input, discretise, response, zoh_inputs
from .results import TFEstimate, trend_basis
from .srivc import srivc

__all__ = ["FitOptions", "tfest", "Progress", "min_samples"]

#: ``progress(done, total, what)``: how :func:`tfest` reports as it advances.
Progress = Callable[[int, int, str], None]


#: A converged fit with its offset estimated that explains less than this share of the output
#: (fit, %) means the output does not respond to the input: :func:`tfest` refuses it instead
#: of returning a model of noise (a weak but real response, e.g. 20 dB SNR, fits above 50 %).
MIN_RESPONSE_FIT = 1.0


def _silent(done: int, total: int, what: str) -> None:
    """The default ``progress``: reports nothing."""


def min_samples(structure: ModelStructure) -> int:
    """Fewest samples :func:`tfest` fits an experiment (or a piece between gaps) with.

    Parameters
    ----------
    structure : ModelStructure
        The model orders.

    Returns
    -------
    int
        ``10 (n_params + n_poles)``: ten samples per estimated parameter and initial state.
    """
    return 10 * (structure.n_params + structure.n_poles)


@dataclass(frozen=True)
class FitOptions:
    """Settings of :func:`tfest`.

    Attributes
    ----------
    delay : float or "auto"
        Input delay in s (fixed), or ``"auto"`` to estimate it in ``[0, max_delay]``.
    max_delay : float or None
        Upper bound of the delay search, s (``delay="auto"`` only: refused with a fixed delay).
        Must be below half the shortest experiment's duration. None (default):
        :data:`DEFAULT_DELAY_SHARE` of the shortest experiment, so that a slow process sampled
        every few seconds is searched as far as a fast vehicle's log is, relative to its record.
    estimate_x0 : bool
        Estimate each experiment's initial condition (else: the system starts at rest).
    trend : int or None
        Degree (0-5) of a polynomial output trend estimated per experiment (Legendre basis
        over the record): ``0`` an offset (default), ``1`` offset and slope, higher degrees
        for a slow, smooth drift (sensor bias, estimator drift); ``None`` none. A drift that
        wanders faster than the record's few slowest polynomials is coloured noise to the
        fit: cut such logs into shorter segments.
    stable : bool
        Reject models with a free pole in the closed right half plane (default True).
    starts : int
        Number of initial estimates the LM runs from (default 2).
    max_iter : int
        LM iteration limit per start (default 100).
    time_limit : float or None
        Wall-time limit of the whole fit, s; the best iterate so far is returned.
    tol : float
        Relative tolerance on the predicted decrease of the criterion and on the step.
    outlier_sigmas : float or None
        Gross-error threshold: after the fit, samples whose residual lies more than this many
        robust standard deviations (1.4826 x the median absolute deviation of all residuals)
        off the model, and by more than :data:`GROSS_ERROR_FLOOR` of the output's standard
        deviation, are left out, the record cut there into pieces with their own initial
        conditions, and the fit rerun (at most :data:`OUTLIER_ROUNDS` times, and only while the
        samples left out stay below :data:`MAX_OUTLIER_SHARE` of the data); every sample left
        out is named in the diagnostics. Default 10 (Gaussian noise exceeds it with probability
        about 1e-23). None keeps every sample.
    initial : array or None
        An initial model ``theta`` (the parameter order of :class:`ModelStructure`), e.g. the
        vehicle's previous identification: the LM starts from its denominator (numerator,
        initial conditions and trends are solved anyway) and the SRIVC/pole-grid search is
        skipped.
    verbose : bool
        Report every LM iteration through ``progress`` (``done``: the iteration, ``total``:
        the iteration limit).
    """

    delay: float | str = 0.0
    max_delay: float | None = None
    estimate_x0: bool = True
    trend: int | None = 0
    stable: bool = True
    starts: int = 2
    max_iter: int = 100
    time_limit: float | None = None
    tol: float = 1e-8
    outlier_sigmas: float | None = 10.0
    initial: tuple[float, ...] | None = None
    verbose: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.delay, str):
            if self.delay != "auto":
                raise SpecError(f"`delay`: got {self.delay!r}, expected a number of seconds >= 0 or 'auto'")
        elif not (isinstance(self.delay, (int, float)) and math.isfinite(self.delay) and self.delay >= 0):
            raise SpecError(f"`delay`: got {self.delay!r}, expected a number of seconds >= 0 or 'auto'")
        if self.max_delay is not None and not (isinstance(self.max_delay, (int, float)) and not isinstance(
                self.max_delay, bool) and math.isfinite(self.max_delay) and self.max_delay >= 0):
            raise SpecError(f"`max_delay`: got {self.max_delay!r}, expected None or a number >= 0 (s)")
        if self.max_delay is not None and self.delay != "auto":
            raise SpecError(f"`max_delay`: got {self.max_delay!r} with a fixed delay ({self.delay!r} s); it bounds "
                            "the search of delay='auto' (--delay auto): give both, or neither")
        if self.trend is not None and (isinstance(self.trend, bool) or self.trend not in range(6)):
            raise SpecError(f"`trend`: got {self.trend!r}, expected None (no trend) or a polynomial degree 0-5 "
                            "(0: offset, 1: offset + slope)")
        for name in ("starts", "max_iter"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise SpecError(f"`{name}`: got {v!r}, expected an integer >= 1")
        if self.time_limit is not None and not (math.isfinite(self.time_limit) and self.time_limit > 0):
            raise SpecError(f"`time_limit`: got {self.time_limit!r}, expected None or a number of seconds > 0")
        if self.outlier_sigmas is not None and not (
                isinstance(self.outlier_sigmas, (int, float)) and not isinstance(self.outlier_sigmas, bool)
                and math.isfinite(self.outlier_sigmas) and self.outlier_sigmas >= 3):
            raise SpecError(f"`outlier_sigmas`: got {self.outlier_sigmas!r}, expected None (keep every sample) or "
                            "a number >= 3 (robust standard deviations)")
        if not (math.isfinite(self.tol) and 0 < self.tol < 1):
            raise SpecError(f"`tol`: got {self.tol!r}, expected a number in (0, 1)")
        if self.initial is not None:
            try:
                init = tuple(float(v) for v in np.asarray(self.initial, dtype=float).ravel())
            except (TypeError, ValueError):
                raise SpecError(f"`initial`: got {self.initial!r}, expected a sequence of numbers (theta)") from None
            if not all(math.isfinite(v) for v in init):
                raise SpecError(f"`initial`: got {self.initial!r}, expected finite numbers")
            object.__setattr__(self, "initial", init)


# ---------------------------------------------------------------- experiments and model evaluation

@dataclass
class _Exp:
    u: np.ndarray
    y: np.ndarray
    trend: np.ndarray        # N x n_trend Legendre basis (trend degrees the free response does not span)
    source: str

    @property
    def n(self) -> int:
        return self.u.size


def _trend_basis(n: int, structure: ModelStructure, opts: FitOptions) -> np.ndarray:
    covered = structure.n_integrators if opts.estimate_x0 else 0
    if opts.trend is None or opts.trend < covered:
        return np.zeros((n, 0))
    return trend_basis(n, opts.trend)[:, covered:]


def _gram(blocks: list[np.ndarray]) -> np.ndarray:
    """``R R'`` of the rows ``R`` stacked from ``blocks`` (each ``(k_i, n)``), block by block: a record-long
    signal is never copied into a stacked matrix (memory per sample, docs/identification.md, "Measured")."""
    return np.block([[a @ b.T for b in blocks] for a in blocks])


def _scaled_pinv(g: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of a Gram matrix after Jacobi scaling (columns of any magnitude)."""
    if g.size == 0:
        return g
    sc = np.sqrt(np.maximum(np.abs(np.diag(g)), 1e-300))
    return np.linalg.pinv(g / np.outer(sc, sc), rcond=1e-13, hermitian=True) / np.outer(sc, sc)


def _eliminate(grams: list[np.ndarray], nb: int, n_local: list[int]):
    """Least squares on Gram matrices with a shared block and per-experiment blocks.

    Each ``grams[e]`` is the Gram matrix of the columns ``[X | L_e | W]``: ``X`` (``nb``
    columns) with coefficients shared by every experiment, ``L_e`` (``n_local[e]``) with
    coefficients of its own, ``W`` the right-hand sides. The per-experiment blocks are
    eliminated first (Schur complements), then the shared one. Returns ``(coef_x, coef_l,
    m)``: coefficients per right-hand side and ``m = W' P W``, with ``P`` the projection
    onto the complement of all the columns.
    """
    s_xx = s_xw = s_ww = 0.0
    elim = []
    for g, nl in zip(grams, n_local):
        x, l, w = slice(0, nb), slice(nb, nb + nl), slice(nb + nl, None)
        inv = _scaled_pinv(g[l, l])
        glx, glw = g[l, x], g[l, w]
        s_xx = s_xx + g[x, x] - glx.T @ inv @ glx
        s_xw = s_xw + g[x, w] - glx.T @ inv @ glw
        s_ww = s_ww + g[w, w] - glw.T @ inv @ glw
        elim.append((inv, glx, glw))
    coef_x = _scaled_pinv(np.atleast_2d(s_xx)) @ s_xw
    m = s_ww - s_xw.T @ coef_x
    coef_l = [inv @ (glw - glx @ coef_x) for inv, glx, glw in elim]
    return coef_x, coef_l, m


@dataclass
class _Point:
    """The model at one point of its nonlinear parameters, the linear ones solved."""

    alpha: np.ndarray                 # free denominator coefficients (and the delay, when estimated)
    theta: np.ndarray                 # alpha's denominator + the solved numerator
    delay: float
    locals_: list[np.ndarray]         # per experiment: initial condition, trend coefficients
    sse: float
    cols: list | None = None          # per experiment: numerator rows, local rows (None: recompute)


class _Model:
    """The output-error criterion as a separable least-squares problem (variable projection).

    Nonlinear parameters ``alpha``: the free denominator coefficients and, when estimated,
    the delay. Linear ones, solved exactly at every ``alpha``: the numerator (shared by every
    experiment) and, per experiment, the initial condition and the trend. LM runs on
    ``alpha`` only, with Kaufman's Jacobian of the projected residual (Golub and Pereyra,
    2003): the linear parameters follow every step exactly, which removes the strong
    coupling between a denominator change and the initial conditions that stalls a joint
    Gauss-Newton iteration on integrating plants.
    """

    def __init__(self, structure: ModelStructure, exps: list[_Exp], ts: float, opts: FitOptions,
                 estimate_delay: bool):
        self.s, self.exps, self.ts, self.opts = structure, exps, ts, opts
        self.estimate_delay = estimate_delay
        self.n = structure.n_poles
        self.nf = structure.n_free_poles
        self.nb = structure.n_zeros + 1
        self.n_beta = self.n if opts.estimate_x0 else 0
        self.n_alpha = self.nf + (1 if estimate_delay else 0)
        self.n_local = [self.n_beta + e.trend.shape[1] for e in exps]
        self.e1 = np.eye(1, self.n)[0]

    def split(self, alpha: np.ndarray, delay_fixed: float) -> tuple[np.ndarray, float]:
        return alpha[: self.nf], (float(alpha[self.nf]) if self.estimate_delay else delay_fixed)

    def stable(self, a: np.ndarray) -> bool:
        if self.nf == 0 or not self.opts.stable:
            return True
        return bool(np.all(np.roots(np.concatenate([[1.0], a])).real < 0))

    def columns(self, d: Discretisation, e: _Exp) -> tuple[np.ndarray, np.ndarray]:
        """Linear-parameter signals of one experiment as rows: numerator (theta order), locals."""
        eye = np.eye(self.n)
        num_rows = np.atleast_2d(response(d.phi, eye[self.nb - 1::-1], d.sos, d.den, e.n, zoh_inputs(d, e.u)))
        if not self.n_beta:
            return num_rows, e.trend.T
        # e_1' Phi^k e_i = e_i' (Phi')^k e_1: every free-response signal in one pass, computed
        # only while it lasts (stable modes below 1e-14 of their start are zero)
        radius = float(np.max(np.abs(d.poles)))
        span = e.n if radius >= 1.0 else min(e.n, int(math.ceil(math.log(1e-14) / math.log(radius))) + self.n)
        free = np.zeros((self.n, e.n))
        free[:, :span] = response(d.phi.T, eye, d.sos, d.den, span, (), self.e1)
        return num_rows, (np.vstack([free, e.trend.T]) if e.trend.shape[1] else free)

    def evaluate(self, alpha: np.ndarray, delay_fixed: float) -> _Point:
        """Solve the linear parameters at ``alpha``; ``sse`` is inf for an unusable model."""
        a, delay = self.split(alpha, delay_fixed)
        bad = _Point(alpha, np.concatenate([a, np.zeros(self.nb)]), delay, [], math.inf)
        if not (np.all(np.isfinite(alpha)) and self.stable(a)):
            return bad
        theta0 = np.concatenate([a, np.zeros(self.nb - 1), [1.0]])
        with np.errstate(over="ignore", invalid="ignore"):
            try:
                d = discretise(self.s, theta0, self.ts, delay, derivatives=False)
                cols = [self.columns(d, e) for e in self.exps]
                grams = [_gram([xr, lr, e.y[None, :]]) for (xr, lr), e in zip(cols, self.exps)]
                if not all(np.all(np.isfinite(g)) for g in grams):
                    return bad
                coef_x, coef_l, _ = _eliminate(grams, self.nb, self.n_local)
            except (ValueError, np.linalg.LinAlgError):
                return bad
            b = coef_x[:, 0]
            locs = [c[:, 0] for c in coef_l]
            sse = 0.0
            for (xr, lr), e, loc in zip(cols, self.exps, locs):
                r = e.y - b @ xr - loc @ lr
                sse += float(r @ r)
        theta = np.concatenate([a, b])
        if not (np.all(np.isfinite(theta)) and math.isfinite(sse)):
            return bad
        return _Point(alpha, theta, delay, locs, sse, cols)

    def sensitivities(self, p: _Point, d: Discretisation, e: _Exp, loc: np.ndarray) -> np.ndarray:
        """Rows ``d yhat / d alpha`` of one experiment, linear parameters held (:mod:`.oe`)."""
        n = self.n
        ins = zoh_inputs(d, e.u)
        rows = np.empty((self.n_alpha, e.n))
        z = np.zeros((n, n))
        c2 = np.concatenate([np.zeros(n), d.c[0]])
        cf2 = np.concatenate([np.zeros(n), self.e1])
        x0 = np.concatenate([loc[: self.n_beta], np.zeros(n)]) if self.n_beta else None
        for i in range(self.nf):
            phi2 = np.block([[d.phi, z], [d.dphi[i], d.phi]])
            ins2 = [(np.vstack([d.g0, d.dg0[i]]), ins[0][1])]
            if d.f > 0:
                ins2.append((np.vstack([d.g1, d.dg1[i]]), ins[1][1]))
            rows[i] = response(phi2, c2, d.sos2, d.den2, e.n, ins2, x0, cf2)
        if self.estimate_delay:
            ud, gd = ins[0][1], d.g_delay
            rows[-1] = response(d.phi, d.c[0], d.sos, d.den, e.n, [(-gd, ud), (gd, delayed_input(ud, 1))])
        return rows

    def _cols(self, p: _Point, d: Discretisation | None = None) -> list:
        """The point's linear-parameter signals, recomputed (with ``d`` when given) if dropped."""
        if p.cols is not None:
            return p.cols
        d = d or discretise(self.s, p.theta, self.ts, p.delay, derivatives=False)
        return [self.columns(d, e) for e in self.exps]

    def reduced_normal(self, p: _Point) -> tuple[np.ndarray, np.ndarray]:
        """``(J'J, -J'r)`` of the projected residual in ``alpha`` (Kaufman's Jacobian)."""
        d = discretise(self.s, p.theta, self.ts, p.delay)
        grams = [_gram([xr, lr, e.y[None, :], self.sensitivities(p, d, e, loc)])
                 for (xr, lr), e, loc in zip(self._cols(p, d), self.exps, p.locals_)]
        _, _, m = _eliminate(grams, self.nb, self.n_local)
        return m[1:, 1:], m[1:, 0]

    def full_normal(self, p: _Point) -> np.ndarray:
        """Normal matrix of the joint problem in ``(theta[, delay], locals)`` (for the covariance)."""
        d = discretise(self.s, p.theta, self.ts, p.delay)
        ng = self.s.n_params + (1 if self.estimate_delay else 0)
        size = ng + sum(self.n_local)
        h = np.zeros((size, size))
        k = ng
        for (xr, lr), e, loc, nl in zip(self._cols(p, d), self.exps, p.locals_, self.n_local):
            sens = self.sensitivities(p, d, e, loc)
            g = _gram([sens[: self.nf], xr, sens[self.nf:], lr])
            h[:ng, :ng] += g[:ng, :ng]
            h[:ng, k:k + nl] = g[:ng, ng:]
            h[k:k + nl, :ng] = g[ng:, :ng]
            h[k:k + nl, k:k + nl] = g[ng:, ng:]
            k += nl
        return h


# ---------------------------------------------------------------- Levenberg-Marquardt

class _Sections:
    """LM coordinates of the free denominator: the coefficients of its second-order sections
    ``s^2 + c1 s + c0`` (and one ``s + c`` for an odd count), not of the expanded polynomial.

    The expanded coefficients of a high-order, lightly damped denominator are badly conditioned:
    a small coefficient change moves every pole, and LM creeps along a narrow valley (a three-mass
    flexible system, 6 poles: 100 iterations at 18 % above the optimum's criterion). Per section,
    a coefficient moves one pole pair. The map is exact (``alpha = coefficients of the product``)
    and its Jacobian carries the normal equations over (``J_z = J_alpha T``); real roots are paired
    in order of magnitude, so sections pass smoothly between two real poles and a complex pair.
    """

    def __init__(self, nf: int):
        self.nf = nf

    def from_alpha(self, a: np.ndarray) -> np.ndarray:
        roots = np.roots(np.concatenate([[1.0], a]))
        cplx = sorted((r for r in roots if r.imag > 1e-12 * max(1.0, abs(r))), key=abs)
        real = sorted((float(r.real) for r in roots if abs(r.imag) <= 1e-12 * max(1.0, abs(r))), key=abs)
        z = [c for r in cplx for c in (-2.0 * r.real, abs(r) ** 2)]
        for i in range(0, len(real) - 1, 2):
            z += [-(real[i] + real[i + 1]), real[i] * real[i + 1]]
        if len(real) % 2:
            z.append(-real[-1])
        return np.array(z)

    def _factors(self, z: np.ndarray) -> list[np.ndarray]:
        quads = [np.array([1.0, z[i], z[i + 1]]) for i in range(0, 2 * (self.nf // 2), 2)]
        return quads + ([np.array([1.0, z[-1]])] if self.nf % 2 else [])

    def to_alpha(self, z: np.ndarray) -> np.ndarray:
        prod = np.array([1.0])
        for f in self._factors(z):
            prod = np.polymul(prod, f)
        return prod[1:]

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """``d alpha / d z`` (``nf x nf``)."""
        facs = self._factors(z)
        cols = []
        for i, f in enumerate(facs):
            rest = np.array([1.0])
            for j, g in enumerate(facs):
                if j != i:
                    rest = np.polymul(rest, g)
            for k in range(1, f.size):  # the coefficient of s^(deg f - k)
                unit = np.zeros(f.size)
                unit[k] = 1.0
                col = np.polymul(rest, unit)
                cols.append(np.concatenate([np.zeros(self.nf + 1 - col.size), col])[1:])
        return np.column_stack(cols)


@dataclass
class _LMResult:
    point: _Point
    status: str
    iterations: int


def _levenberg_marquardt(model: _Model, start: _Point, delay_fixed: float, opts: FitOptions, deadline: float,
                         say: Progress, max_iter: int | None = None) -> _LMResult:
    """LM (Nielsen's damping update) in the nonlinear parameters on Jacobi-scaled normal
    equations, the denominator in second-order sections from three free poles on
    (:class:`_Sections`); the delay, when estimated, is kept in ``[0, max_delay]`` by holding it while it
    sits on a bound that the step pushes against."""
    p = start
    if model.n_alpha == 0:
        return _LMResult(p, "converged", 0)
    nf = model.nf
    sec = _Sections(nf) if nf >= 3 else None

    def coords(q: _Point) -> np.ndarray:
        return np.concatenate([sec.from_alpha(q.alpha[:nf]), q.alpha[nf:]]) if sec else q.alpha

    def normal(q: _Point, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(over="ignore", invalid="ignore"):  # overflow ends the search as "numerical"
            hq, gq = model.reduced_normal(q)
        q.cols = None  # not needed again (a rejected step reuses hq, gq): one record's worth less while a trial is held
        if sec is None:
            return hq, gq
        t = np.eye(hq.shape[0])
        t[:nf, :nf] = sec.jacobian(x[:nf])
        return t.T @ hq @ t, t.T @ gq

    def to_alpha(x: np.ndarray) -> np.ndarray:
        return np.concatenate([sec.to_alpha(x[:nf]), x[nf:]]) if sec else x

    x = coords(p)
    h, grad = normal(p, x)
    if not (np.all(np.isfinite(h)) and np.all(np.isfinite(grad))):
        return _LMResult(p, "numerical", 0)
    mu, nu = None, 2.0
    lo, hi = 0.0, opts.max_delay
    n_obs = sum(e.n for e in model.exps)
    k_delay = model.n_alpha - 1 if model.estimate_delay else -1
    limit = max_iter or opts.max_iter
    it = 0
    for it in range(1, limit + 1):
        if time.perf_counter() > deadline:
            return _LMResult(p, "time_limit", it - 1)
        dg = np.sqrt(np.maximum(np.diag(h), 1e-300))
        with np.errstate(over="ignore", invalid="ignore"):
            hs = h / np.outer(dg, dg)
            gs = grad / dg
        if not (np.all(np.isfinite(hs)) and np.all(np.isfinite(gs))):
            return _LMResult(p, "numerical", it - 1)
        if mu is None:
            mu = 1e-3 * float(np.max(np.diag(hs)))
        free = np.ones(hs.shape[0], dtype=bool)
        while True:
            step = np.zeros_like(gs)
            try:
                step[free] = np.linalg.solve(hs[np.ix_(free, free)] + mu * np.eye(int(free.sum())), gs[free])
            except np.linalg.LinAlgError:
                mu, nu = mu * nu, nu * 2.0
                continue
            step = step / dg
            if k_delay >= 0 and free[k_delay]:
                tau, new = x[k_delay], x[k_delay] + step[k_delay]
                if (tau <= lo and new < lo) or (tau >= hi and new > hi):
                    free[k_delay] = False         # on the bound, pushed outwards: hold it there
                    continue
                step[k_delay] = min(max(new, lo), hi) - tau
            pred = float(step @ grad - 0.5 * step @ h @ step)
            trial = model.evaluate(to_alpha(x + step), delay_fixed)
            rho = 0.5 * (p.sse - trial.sse) / pred if pred > 0 else -1.0
            small = np.linalg.norm(step * dg) <= opts.tol * (np.linalg.norm(x * dg) + opts.tol)
            if rho > 0:
                decrease = min(pred, 0.5 * (p.sse - trial.sse))
                converged = decrease <= max(opts.tol, STATISTICAL_TOL / n_obs) * 0.5 * p.sse or small
                p, x = trial, x + step
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                if opts.verbose:
                    say(it, limit, f"  LM {it:3d}: SSE {p.sse:.10g}, mu {mu:.3g}"
                        + (f", delay {p.delay:.5g} s" if model.estimate_delay else ""))
                if converged:
                    return _LMResult(p, "converged", it)
                if it == limit:                   # no further step: its normal equations are not needed
                    return _LMResult(p, "max_iter", it)
                h, grad = normal(p, x)
                if not (np.all(np.isfinite(h)) and np.all(np.isfinite(grad))):
                    return _LMResult(p, "numerical", it)
                break
            mu, nu = mu * nu, nu * 2.0
            if small or mu > 1e16 * max(1.0, float(np.max(np.diag(hs)))):
                return _LMResult(p, "converged", it)
            if time.perf_counter() > deadline:
                return _LMResult(p, "time_limit", it)
    return _LMResult(p, "max_iter", it)


# ---------------------------------------------------------------- initialisation

#: The pole grid's slowest real pole and slowest pair, in rad per sample (``p Ts``, ``w_n Ts``): the grid is in
#: the data's units, so a fit does not depend on the unit of time (0.3 and 1 rad/s at the built-in Ts = 20 ms).
GRID_LOWEST_POLE = 0.006
GRID_LOWEST_PAIR = 0.02


def _grid_denominators(structure: ModelStructure, ts: float) -> list[np.ndarray]:
    return list(_pole_grid(structure.n_free_poles, ts))


@functools.lru_cache(maxsize=32)
def _pole_grid(nf: int, ts: float) -> tuple[np.ndarray, ...]:
    """The grid of :func:`_grid_denominators` (read-only arrays, computed once per order and sample time)."""
    if nf == 0:
        return (np.zeros(0),)
    nyq = np.pi / ts
    out = [np.real(np.poly(np.full(nf, -p)))[1:] for p in np.geomspace(GRID_LOWEST_POLE / ts, 0.5 * nyq, 7)]
    if nf >= 2:  # lightly damped pairs
        for wn in np.geomspace(GRID_LOWEST_PAIR / ts, 0.3 * nyq, 4):
            rest = np.real(np.poly(np.full(nf - 2, -wn)))
            out.append(np.polymul([1.0, 0.6 * wn, wn**2], rest)[1:])
    for a in out:
        a.flags.writeable = False
    return tuple(out)


def _empirical_response(exps: list[_Exp], ts: float, nper: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The frequency response ``H = P_yu / P_uu`` (Welch with ``nper``-sample segments, the longest
    experiment) at the bins where the input is excited (within 20 dB of its peak power), the
    coherence exceeds 0.8 and the frequency is below half the Nyquist frequency: ``(w rad/s, H)``,
    or None with fewer than 8."""
    from scipy import signal as sps

    e = max(exps, key=lambda x: x.n)
    nper = int(min(e.n, nper))
    if nper < 64:
        return None
    f, puu = sps.welch(e.u, fs=1.0 / ts, nperseg=nper)
    _, pyy = sps.welch(e.y, fs=1.0 / ts, nperseg=nper)
    _, pyu = sps.csd(e.u, e.y, fs=1.0 / ts, nperseg=nper)
    with np.errstate(divide="ignore", invalid="ignore"):
        coh = np.abs(pyu) ** 2 / (puu * pyy)  # scipy.signal.coherence's own formula, on spectra already at hand
    ok = (puu > 1e-2 * puu.max()) & (f > 0) & (f < 0.25 / ts) & (coh > 0.8)
    if ok.sum() < 8:
        return None
    return 2 * np.pi * f[ok], pyu[ok] / puu[ok]


def _frequency_domain_denominators(structure: ModelStructure, exps: list[_Exp], ts: float,
                                   delay: float) -> list[np.ndarray]:
    """Starts for lightly damped structures: the model fitted to the empirical frequency response.

    Sanathanan-Koerner iterations (Pintelon and Schoukens, System Identification: A Frequency
    Domain Approach, 2nd ed., sec. 9.8) of ``(jw)^K A(jw) H(jw) e^{jw delay} = B(jw)``, linear in
    the coefficients, each weighted by ``1/(|A_prev| sqrt|H|)`` (half-way to a relative error: the
    resonances far below the response's peak count too, while the noisy bins where ``|H|`` is tiny
    do not take over), on a frequency axis scaled to the data's band; unstable roots reflected into
    the left half plane. A pole grid cannot place several sharp resonances at once, and a
    least-squares fit started away from them stays in a local minimum between them (a three-mass
    flexible system, 6 poles and 5 zeros, fitted 57 % held out from the grid).
    """
    nf, nz, k = structure.n_free_poles, structure.n_zeros, structure.n_integrators
    if nf < 4:  # one pair the grid and the retune after convergence place (:func:`_retune_resonances`)
        return []
    out = []
    for nper in (512, 1024, 2048, 4096):  # resolution against variance: a start from each
        frf = _empirical_response(exps, ts, nper)
        if frf is not None:
            out += _sanathanan_koerner(*frf, nf, nz, k, delay)
    return out


def _sanathanan_koerner(w: np.ndarray, h: np.ndarray, nf: int, nz: int, k: int, delay: float) -> list[np.ndarray]:
    """The free denominator fitted to ``H`` at ``w`` (rad/s) for :func:`_frequency_domain_denominators`."""
    w0 = float(np.exp(np.mean(np.log(w))))
    s = 1j * w / w0
    g = h * np.exp(1j * w * delay) * (1j * w) ** k * w0 ** (-k)  # B/A in the scaled variable
    rel = 1.0 / np.sqrt(np.maximum(np.abs(g), 1e-300))
    weight = rel
    a = np.zeros(nf)
    for _ in range(8):
        # unknowns: a_1..a_nf (A monic in s, highest power first), b_0..b_nz
        cols = [g * s ** (nf - 1 - i) for i in range(nf)] + [-(s ** (nz - i)) for i in range(nz + 1)]
        m = np.column_stack(cols) * weight[:, None]
        rhs = -g * s**nf * weight
        sol, *_ = np.linalg.lstsq(np.vstack([m.real, m.imag]), np.concatenate([rhs.real, rhs.imag]), rcond=None)
        if not np.all(np.isfinite(sol)):
            return []
        a = sol[:nf]
        weight = rel / np.maximum(np.abs(np.polyval(np.concatenate([[1.0], a]), s)), 1e-12)
    roots = np.roots(np.concatenate([[1.0], a]))
    roots = np.where(roots.real > 0, -roots.real + 1j * roots.imag, roots) * w0  # reflect, unscale
    roots = np.where(roots.real == 0, roots - 1e-3 * w0, roots)
    return [np.real(np.poly(roots))[1:]]


#: Samples used to rank the initial estimates: longer records are represented by evenly
#: spaced chunks (each with its own initial condition), which keeps the start-up cost of a
#: fit on a long log bounded while every part of the record has a say.
RANKING_SAMPLES = 100_000
#: Default upper bound of the delay search as a share of the shortest experiment's duration.
DEFAULT_DELAY_SHARE = 0.1
#: Delays visited by the profile sweep of ``delay="auto"`` (evenly spaced over
#: ``[0, max_delay]``, at most one per sample); the LM refines the delay continuously from
#: the best of them.
DELAY_SWEEP_POINTS = 7
#: A profile point whose criterion, warm-started from its neighbour, is this many times the best of the profile
#: so far is not polished by its LM step: it cannot become the profile's minimum (measured on the 6000-sample
#: closed-loop log: the coarse points beyond the first lie 6,000-190,000 times above the best).
HOPELESS_DELAY = 100.0
#: LM stops when a step lowers the criterion by less than this fraction of one sample's
#: residual variance (the parameters then move by about sqrt(1e-3) = 3 % of their standard
#: deviation), or by less than ``FitOptions.tol`` relative.
STATISTICAL_TOL = 1e-3
#: A further start runs only when its criterion is within this factor of the best start's.
SECONDARY_START_RATIO = 4.0
_CHUNK = 10_000
#: The band the response lives in holds this share of the output power that the input
#: explains (:func:`_ranking_decimation`).
BAND_SHARE = 0.999
#: The starts are ranked on a record decimated so that its Nyquist frequency stays at least
#: this factor above that band.
BAND_MARGIN = 1.0
#: Largest decimation of the ranking record.
MAX_DECIMATION = 32
#: Fewest samples the decimated ranking record keeps in all (each experiment at least twice
#: :func:`min_samples`): below about twice this a log is ranked whole, where the per-candidate
#: overhead, not the filtering, is the cost of the search.
MIN_RANKING_SAMPLES = 5_000
_BAND_SEGMENTS = 64            # at most this many segments in all (evenly spaced over long logs)
_RANKING_BYTES = 64e6          # signals kept at once while the candidates are ranked


def _chunked(model: _Model) -> _Model:
    """The model on evenly spaced :data:`_CHUNK`-sample chunks of its experiments when they hold more
    than :data:`RANKING_SAMPLES` samples in all (each chunk with its own initial condition and trend);
    else the model itself."""
    total = sum(e.n for e in model.exps)
    if total <= RANKING_SAMPLES:
        return model
    chunks = []
    for e in model.exps:
        share = max(1, round(RANKING_SAMPLES * e.n / total / _CHUNK))
        if e.n <= 2 * _CHUNK or share * _CHUNK >= e.n:
            chunks.append(e)
            continue
        for start in np.linspace(0, e.n - _CHUNK, share).astype(int):
            sl = slice(start, start + _CHUNK)
            chunks.append(_Exp(e.u[sl], e.y[sl], _trend_basis(_CHUNK, model.s, model.opts), e.source))
    return _Model(model.s, chunks, model.ts, model.opts, model.estimate_delay)


def _explained_power(exps: list[_Exp], nseg: int) -> np.ndarray | None:
    """Cumulative output power that the input explains, ``|S_yu|^2 / S_uu`` over the frequency bins above
    DC of ``nseg``-sample Hann segments (at most :data:`_BAND_SEGMENTS`, evenly spaced, from every
    experiment), normalised to end at 1; None without a segment or explained power."""
    total = sum(e.n // nseg for e in exps)
    if total == 0:
        return None
    keep = min(1.0, _BAND_SEGMENTS / total)
    win = np.hanning(nseg)
    s_uu = np.zeros(nseg // 2 + 1)
    s_yu = np.zeros(nseg // 2 + 1, complex)
    for e in exps:
        k = e.n // nseg
        if k == 0:
            continue
        rows = np.unique(np.linspace(0, k - 1, max(1, round(k * keep))).astype(int))
        fu, fy = (np.fft.rfft((seg - seg.mean(axis=1, keepdims=True)) * win, axis=1)
                  for seg in (x[: k * nseg].reshape(k, nseg)[rows] for x in (e.u, e.y)))
        s_uu += np.sum(fu.real**2 + fu.imag**2, axis=0)
        s_yu += np.sum(np.conj(fu) * fy, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        cum = np.cumsum(np.where(s_uu[1:] > 0, np.abs(s_yu[1:]) ** 2 / s_uu[1:], 0.0))
    if not (math.isfinite(cum[-1]) and cum[-1] > 0):
        return None
    return cum / cum[-1]


def _ranking_decimation(model: _Model) -> int:
    """How far the record can be decimated for ranking the starts without losing the band its response
    lives in.

    The band: the lowest frequency below which :data:`BAND_SHARE` of the output power that the input
    explains lies (:func:`_explained_power`: noise that the input does not explain, white or coloured,
    hardly counts). The segments are a sixteenth of the longest experiment (a power of two, 256 to 4096
    samples): a slow response is resolved on a long log, and a segment shorter than the response's memory
    spreads explained power over the spectrum (which only makes the factor smaller). The decimated Nyquist
    frequency stays :data:`BAND_MARGIN` times above the band; the factor is capped by
    :data:`MAX_DECIMATION`, by :data:`MIN_RANKING_SAMPLES` and by twice :func:`min_samples` per
    experiment; 1 (no decimation) when the input explains nothing.
    """
    n_total = sum(e.n for e in model.exps)
    cap = min(MAX_DECIMATION, n_total // MIN_RANKING_SAMPLES,
              min(e.n for e in model.exps) // (2 * min_samples(model.s)))
    if cap < 2:
        return 1
    nseg = int(2 ** np.clip(math.floor(math.log2(max(e.n for e in model.exps) / 16)), 8, 12))
    cum = _explained_power(model.exps, nseg)
    if cum is None:
        return 1
    edge = int(np.searchsorted(cum, BAND_SHARE)) + 2     # upper edge of the band's last bin, in bins
    return max(1, min(int(nseg / (2.0 * BAND_MARGIN * edge)), cap))


def _decimated(model: _Model, factor: int) -> _Model:
    """The model on its experiments decimated by ``factor`` (sample time ``factor ts``): the input
    averaged over each block of ``factor`` samples (the mean of the held input over the block, so the
    coarse zero-order hold carries the same area), the output sampled at each block's first instant."""
    if factor <= 1:
        return model
    exps = []
    for e in model.exps:
        m = e.n // factor
        exps.append(_Exp(e.u[: m * factor].reshape(m, factor).mean(axis=1), e.y[: m * factor: factor].copy(),
                         _trend_basis(m, model.s, model.opts), e.source))
    return _Model(model.s, exps, model.ts * factor, model.opts, model.estimate_delay)


def _stacked_pinv(g: np.ndarray) -> np.ndarray:
    """:func:`_scaled_pinv` of a stack of Gram matrices (``... x k x k``)."""
    if g.shape[-1] == 0:
        return g
    sc = np.sqrt(np.maximum(np.abs(np.diagonal(g, axis1=-2, axis2=-1)), 1e-300))
    outer = sc[..., :, None] * sc[..., None, :]
    return np.linalg.pinv(g / outer, rcond=1e-13, hermitian=True) / outer


def _stacked_eliminate(grams: list[np.ndarray], nb: int, n_local: list[int]):
    """:func:`_eliminate` for a stack of candidates with one right-hand side (the output): ``grams[e]`` is
    ``candidates x k x k`` per experiment. Returns ``(coef_x, coef_l)``: ``candidates x nb`` and, per
    experiment, ``candidates x n_local[e]``."""
    s_xx = s_xw = 0.0
    elim = []
    for g, nl in zip(grams, n_local):
        x, l, w = slice(0, nb), slice(nb, nb + nl), slice(nb + nl, None)
        inv = _stacked_pinv(g[:, l, l])
        glx, glw = g[:, l, x], g[:, l, w]
        glx_t = np.swapaxes(glx, -1, -2)
        s_xx = s_xx + g[:, x, x] - glx_t @ inv @ glx
        s_xw = s_xw + g[:, x, w] - glx_t @ inv @ glw
        elim.append((inv, glx, glw))
    coef_x = _stacked_pinv(s_xx) @ s_xw
    coef_l = [(inv @ (glw - glx @ coef_x))[:, :, 0] for inv, glx, glw in elim]
    return coef_x[:, :, 0], coef_l


def _allpole(sections: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``x`` (rows) through the all-pole sections ``[1, 0, 0, 1, a1, a2]`` of :func:`.oe.allpole_sos`, one
    ``lfilter`` per section (a tenth of ``sosfilt``'s call overhead, which dominates on short rows)."""
    for sec in sections:
        x = sps.lfilter(_ONE, sec[3:], x, axis=-1)
    return x


_ONE = np.ones(1)


def _ranked(model: _Model, dens: list[np.ndarray], delay: float) -> list[_Point]:
    """The criterion of each candidate free denominator on ``model`` at ``delay``, best first, unusable
    candidates (non-finite, unstable under ``stable``, diverging) left out.

    The criterion and signals are those of :meth:`_Model.evaluate` (numerator and free-response rows by
    filtering, the trends; the linear parameters eliminated; the residual computed explicitly), computed
    for all the candidates together where that is cheaper than one at a time: one batched matrix
    exponential, the Markov parameters of every candidate in one recursion, each candidate's FIR pass as
    one product with the shifted input, the linear parameters eliminated for the whole stack
    (:func:`_stacked_eliminate`). Only the all-pole passes (:func:`_allpole`) and the residuals run per
    candidate. The points carry the numerator but no initial conditions or signals: re-solve the ones
    used (:meth:`_Model.evaluate`).
    """
    s, n, nf, nb = model.s, model.n, model.nf, model.nb
    given = [a for a in (np.asarray(d, dtype=float).reshape(-1) for d in dens)
             if a.size == nf and np.all(np.isfinite(a))]
    if not given:
        return []
    all_roots = np.zeros((len(given), 0))
    if nf:                                      # the roots as np.roots finds them: companion eigenvalues
        comp = np.zeros((len(given), nf, nf))
        comp[:, 1:, :-1] = np.eye(nf - 1)
        comp[:, 0, :] = -np.array(given)
        all_roots = np.linalg.eigvals(comp)
    keep = np.all(all_roots.real < 0, axis=1) if model.opts.stable and nf else np.ones(len(given), dtype=bool)
    usable = [a for a, k in zip(given, keep) if k]
    roots = [r for r, k in zip(all_roots, keep) if k]
    if not usable:
        return []
    count, ts = len(usable), model.ts
    nd, f = delay_split(delay, ts)
    den = np.concatenate([np.ones((count, 1)), np.array(usable).reshape(count, nf),
                          np.zeros((count, s.n_integrators))], axis=1)
    big = np.zeros((count, n + 1, n + 1))          # [[A_c, e_n], [0, 0]] (companion form, :func:`.oe.discretise`)
    big[:, : n - 1, 1:n] = np.eye(n - 1)
    big[:, n - 1, :n] = -den[:, :0:-1]
    big[:, n - 1, n] = 1.0
    with np.errstate(over="ignore", invalid="ignore"):
        e_r = expm(big * (ts - f))
        phi, gains = e_r[:, :n, :n], [e_r[:, :n, n]]
        if f > 0:
            e_f = expm(big * f)
            gains.append(np.einsum("cij,cj->ci", phi, e_f[:, :n, n]))
            phi = phi @ e_f[:, :n, :n]
    sections, zden, radius = [], np.empty((count, n + 1)), np.empty(count)
    for c, r in enumerate(roots):
        poles = np.concatenate([np.exp(r * ts), np.ones(s.n_integrators)])
        sos_c, zden[c] = allpole_sos(poles)
        sections.append(sos_c)
        radius[c] = float(np.max(np.abs(poles)))
    # Toeplitz of each discrete denominator: (conv(den, h))[:n + 1] = toe @ h
    toe = np.zeros((count, n + 1, n + 1))
    for j in range(n + 1):
        toe[:, j:, j] = zden[:, : n + 1 - j]

    def markov(vec: np.ndarray, pick: np.ndarray, mat: np.ndarray, steps: int) -> np.ndarray:
        """``[vec, mat vec, mat^2 vec, ...]`` of every candidate, the states ``pick`` (``count x pick x steps``)."""
        out = np.empty((count, pick.size, steps))
        for k in range(steps):
            out[:, :, k] = vec[:, pick]
            vec = np.einsum("cij,cj->ci", mat, vec)
        return out

    num_rows = np.arange(nb - 1, -1, -1)
    coef = np.zeros((count, nb, n + 2))            # FIR on u[k-nd-j], j = 0 .. n + 1
    with np.errstate(over="ignore", invalid="ignore"):
        for i, g in enumerate(gains):
            h = np.concatenate([np.zeros((count, nb, 1)), markov(g, num_rows, phi, n)], axis=2)
            coef[:, :, i:i + n + 1] += np.einsum("cji,cri->crj", toe, h)
        free = None
        if model.n_beta:
            h = markov(np.tile(model.e1, (count, 1)), np.arange(n), np.swapaxes(phi, 1, 2), n + 1)
            free = np.einsum("cji,cri->crj", toe, h)
    ok = np.all(np.isfinite(coef.reshape(count, -1)), axis=1) & np.all(np.isfinite(phi.reshape(count, -1)), axis=1)
    if free is not None:
        ok &= np.all(np.isfinite(free.reshape(count, -1)), axis=1)
    extra = [delay] if model.estimate_delay else []
    n_sig = nb + model.n_beta
    group = max(1, int(_RANKING_BYTES // (8 * n_sig * sum(e.n for e in model.exps) + 1)))
    live = np.flatnonzero(ok)
    points = []
    for first in range(0, live.size, group):
        batch = live[first:first + group]
        grams, signals = [], []
        for e, nl in zip(model.exps, model.n_local):
            m = e.n
            ud = delayed_input(e.u, nd)
            shifted = np.zeros((n + 2, m))
            for j in range(n + 2):
                shifted[j, j:] = ud[: m - j]
            rows = np.zeros((nb + nl + 1, m))
            rows[n_sig: nb + nl] = e.trend.T
            rows[-1] = e.y
            g_e = np.zeros((batch.size, rows.shape[0], rows.shape[0]))
            s_e = []
            for i, c in enumerate(batch):
                with np.errstate(over="ignore", invalid="ignore"):
                    rows[:nb] = _allpole(sections[c], coef[c] @ shifted)
                    if model.n_beta:
                        span = m if radius[c] >= 1.0 else min(
                            m, int(math.ceil(math.log(1e-14) / math.log(max(radius[c], 1e-300)))) + n)
                        drive = np.zeros((n, span))
                        k = min(n + 1, span)
                        drive[:, :k] = free[c][:, :k]
                        rows[nb:n_sig] = 0.0
                        rows[nb:n_sig, :span] = _allpole(sections[c], drive)
                    g_e[i] = rows @ rows.T
                s_e.append(rows[:n_sig].copy())
            grams.append(g_e)
            signals.append(s_e)
        good = np.ones(batch.size, dtype=bool)
        for g_e in grams:
            good &= np.all(np.isfinite(g_e.reshape(batch.size, -1)), axis=1)
        sel = np.flatnonzero(good)
        if sel.size == 0:
            continue
        try:
            solved = [(sel, _stacked_eliminate([g[sel] for g in grams], nb, model.n_local))]
        except np.linalg.LinAlgError:
            solved = []
            for i in sel:
                try:
                    solved.append((np.array([i]), _stacked_eliminate([g[i:i + 1] for g in grams], nb, model.n_local)))
                except np.linalg.LinAlgError:
                    pass
        for which, (coef_x, coef_l) in solved:
            for j, i in enumerate(which):
                sse = 0.0
                with np.errstate(over="ignore", invalid="ignore"):
                    for e, sig, loc in zip(model.exps, signals, coef_l):
                        r = e.y - coef_x[j] @ sig[i][:nb] - loc[j][: model.n_beta] @ sig[i][nb:] \
                            - loc[j][model.n_beta:] @ e.trend.T
                        sse += float(r @ r)
                if math.isfinite(sse):
                    a = usable[batch[i]]
                    points.append(_Point(np.concatenate([a, extra]), np.concatenate([a, coef_x[j]]), delay, [], sse))
    return sorted(points, key=lambda p: p.sse)


#: Starts whose criterion on the ranking record exceeds the best one's by more than this factor times
#: :data:`SECONDARY_START_RATIO` are not re-solved on the full record (they would not run).
RANKING_SLACK = 2.0
#: Starts ranked within this relative distance of the previous one are re-solved too, and the order
#: settled on the full record (the ranking criterion is approximate: decimation, rounding).
RANKING_TIE = 1e-2


def _candidates(model: _Model, delay: float, say: Progress) -> tuple[list[_Point], dict]:
    """Initial estimates at ``delay``, best first, and how they were ranked (``decimation``: the
    factor; ``samples``: the ranking record's length). SRIVC and the pole grid (and, from four free poles,
    fits to the empirical frequency response), ranked together (:func:`_ranked`) on the record
    decimated to the band its response lives in (:func:`_ranking_decimation`) and, beyond
    :data:`RANKING_SAMPLES` samples, on evenly spaced chunks of it. The best ``FitOptions.starts``
    distinct ones within ``RANKING_SLACK * SECONDARY_START_RATIO`` of the best (and those within
    :data:`RANKING_TIE` of the one before) are re-solved on all the data and returned in the order of
    their criterion there. SRIVC and the frequency-domain fits use the full-rate record (its chunks
    beyond :data:`RANKING_SAMPLES`), the grid its sample time: an instrumental-variable estimate of sharp
    resonances suffers from a coarse hold far more than the ranking does (a three-mass system, 6 poles, on
    a record decimated 7x: SRIVC unstable)."""
    full = model
    factor = _ranking_decimation(full)
    model = _chunked(_decimated(full, factor))
    s = model.s
    dens = []
    whole = _chunked(full)
    try:  # a diverging instrumental-variable pass overflows: its estimate is then not finite and left out
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            th = srivc(s, [(e.u, e.y) for e in whole.exps], whole.ts, delay=delay, iterations=4, tol=1e-4)
        if np.all(np.isfinite(th)):
            dens.append(th[: s.n_free_poles])
    except (np.linalg.LinAlgError, ValueError):
        say(0, 0, "SRIVC gave no estimate; starting from the pole grid only")
    dens += _grid_denominators(s, full.ts) + _frequency_domain_denominators(s, whole.exps, full.ts, delay)
    want = max(full.opts.starts, 1)
    solved: list[_Point] = []
    ranked: list[_Point] = []            # distinct so far (:func:`_distinct`, taken one at a time)
    for p in _ranked(model, dens, delay):
        if not _differs(p, ranked):
            continue
        tie = bool(ranked) and p.sse <= (1.0 + RANKING_TIE) * ranked[-1].sse
        far = bool(ranked) and p.sse > RANKING_SLACK * SECONDARY_START_RATIO * ranked[0].sse
        ranked.append(p)
        if solved and not tie and (len(solved) >= want or far):
            break
        q = full.evaluate(p.alpha, delay)
        if math.isfinite(q.sse):
            if model is full:
                # ranked whole: the LM recomputes the start's signals with the derivatives' discretisation,
                # as the exhaustive search did, so that the fit stays bit-identical to it
                q.cols = None
            solved.append(q)
    return (_distinct(sorted(solved, key=lambda p: p.sse), want),
            {"decimation": factor, "samples": sum(e.n for e in model.exps)})


#: Damping ratio below which a converged pole pair is searched in frequency (:func:`_retune_resonances`).
RESONANCE_DAMPING = 0.2


def _retune_resonances(model: _Model, p: _Point, delay_fixed: float) -> _Point:
    """The converged point with each lightly damped pole pair moved, one at a time, to the natural
    frequency (within +-20 %, damping kept) and then the damping (x 1/4 to 4) where the criterion
    is lowest.

    The output-error criterion of a pair with damping ``zeta`` at ``w`` has a basin about
    ``zeta w`` wide in frequency: a start further off converges to a local minimum with the pair
    misplaced (a 12.9 rad/s mode with damping 0.014 started at 11.6 rad/s). A profile over the
    frequency finds the right basin for the next LM run; the damping has such basins too (a
    0.014 mode converged at 0.0044). It costs 58 criterion evaluations per pair and nothing for
    structures without such pairs.
    """
    nf = model.nf
    roots = np.roots(np.concatenate([[1.0], p.alpha[:nf]])) if nf >= 2 else np.zeros(0)
    pairs = [r for r in roots if r.imag > 0 and -r.real / abs(r) < RESONANCE_DAMPING]
    best = p

    def scan(rest: np.ndarray, pairs_wz) -> None:
        nonlocal best
        for w, z in pairs_wz:
            trial = model.evaluate(np.concatenate([np.polymul(rest, [1.0, 2 * z * w, w * w])[1:], best.alpha[nf:]]),
                                   delay_fixed)
            if trial.sse < best.sse:
                best = trial

    for r in pairs:
        others = [q for q in np.roots(np.concatenate([[1.0], best.alpha[:nf]]))
                  if abs(q - r) > 1e-9 * abs(r) and abs(q - np.conj(r)) > 1e-9 * abs(r)]
        if len(others) != nf - 2:
            continue  # the pair moved or merged in an earlier retune
        rest = np.real(np.poly(others)) if others else np.array([1.0])
        wn, zeta = abs(r), -r.real / abs(r)
        scan(rest, ((f * wn, zeta) for f in np.linspace(0.8, 1.2, 41)))             # the frequency, then
        w_best = _pair_frequency(best.alpha[:nf], r, wn)                             # the damping there
        scan(rest, ((w_best, g * zeta) for g in np.geomspace(0.25, 4.0, 17) if g * zeta < 1.0))
    return best


#: At most this many refits after leaving gross errors out (:attr:`FitOptions.outlier_sigmas`).
OUTLIER_ROUNDS = 3
#: Gross errors are left out only while they stay below this share of the samples: beyond it the residuals
#: are heavy-tailed (a structure that misses dynamics, a disturbance), not a few corrupt samples.
MAX_OUTLIER_SHARE = 0.02
#: ... and only residuals beyond this share of the output's standard deviation count (nearly noise-free data have
#: a tiny robust scale, against which rounding structure would stand out).
GROSS_ERROR_FLOOR = 0.05


def _fitted(model: _Model, p: _Point) -> list[np.ndarray]:
    """The model output per experiment at ``p`` (forced response, free response and trend)."""
    return [p.theta[model.nf:] @ xr + loc @ lr for (xr, lr), loc in zip(model._cols(p), p.locals_)]


def _smooth_start(r: np.ndarray, flags: np.ndarray, guard: int) -> int:
    """How many leading samples of a residual ``r`` form a start-up transient rather than a glitch: a run of
    flagged samples beginning within ``guard`` samples of the start (gaps up to ``guard`` joined) along which the
    residual moves smoothly, no step between samples above half its peak (a glitch jumps; a start the model
    misses, a climb from a state not at rest, does not). 0 when there is none."""
    idx = np.flatnonzero(flags)
    if idx.size < 2 or idx[0] > guard:
        return 0
    breaks = np.flatnonzero(np.diff(idx) > guard + 1)
    k = int(idx[breaks[0]] if breaks.size else idx[-1]) + 1
    seg = r[: min(k + 1, r.size)]
    return k if k >= 2 and np.max(np.abs(np.diff(seg))) <= 0.5 * np.max(np.abs(seg)) else 0


def _without_gross_errors(model: _Model, p: _Point, sigmas: float) -> tuple[list[_Exp], list[dict], list[dict]]:
    """The experiments cut around samples whose residual at ``p`` lies more than ``sigmas`` robust
    standard deviations off, and what was left out (``source``, ``first``/``last`` sample of the
    experiment, ``samples``); unchanged experiments and no record when none is found or when the
    outliers exceed :data:`MAX_OUTLIER_SHARE`. Residuals below :data:`GROSS_ERROR_FLOOR` of the output's
    standard deviation never count, nor below half the largest one (each round takes the worst cluster: the
    smaller errors a glitch spreads through a distorted fit go with the refit). Each flagged sample is widened by
    the model order on both sides (the samples around a glitch carry its transient); good runs shorter than
    :func:`min_samples` are left out with it. A smooth run at an experiment's start (:func:`_smooth_start`) is a
    start-up transient, not a glitch: kept, and returned third (``source``, ``samples``)."""
    resid = [e.y - f for e, f in zip(model.exps, _fitted(model, p))]
    flat = np.concatenate(resid)
    centre = float(np.median(flat))
    scale = 1.4826 * float(np.median(np.abs(flat - centre)))
    spread = float(np.sqrt(np.mean([np.var(e.y) for e in model.exps])))
    worst = float(np.max(np.abs(flat - centre)))
    # the worst cluster first: a fit distorted by a glitch spreads smaller errors that the refit removes
    limit = max(sigmas * scale, GROSS_ERROR_FLOOR * spread, 0.5 * worst)
    flags = [np.abs(r - centre) > limit for r in resid]
    guard = model.n
    startup = []
    for e, r, f in zip(model.exps, resid, flags):
        k = _smooth_start(r - centre, f, guard)
        if k:
            f[:k] = False
            startup.append({"source": e.source, "samples": k})
    if not any(f.any() for f in flags):
        return model.exps, [], startup
    pieces, left = [], []
    for e, f in zip(model.exps, flags):
        if not f.any():
            pieces.append(e)
            continue
        kept, record = _cut(model, e, np.convolve(f, np.ones(2 * guard + 1), mode="same") > 0)
        pieces += kept
        left.append({**record, **_held_within(e, f)})
    if sum(d["samples"] for d in left) > MAX_OUTLIER_SHARE * flat.size or not pieces:
        return model.exps, [], startup
    return pieces, left, startup


def _cut(model: _Model, e: _Exp, bad: np.ndarray) -> tuple[list[_Exp], dict]:
    """``e`` without its ``bad`` samples: the good runs of at least :func:`min_samples` samples as experiments of
    their own (named ``source [a:b]``), and the record of what was left out (``source``, ``first``/``last``
    sample, ``samples``)."""
    need = min_samples(model.s)
    edges = np.flatnonzero(np.diff(np.concatenate([[True], bad, [True]]).astype(int)))
    keep = [(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= need]
    dropped = np.ones(e.n, bool)
    pieces = []
    for a, b in keep:
        dropped[a:b] = False
        pieces.append(_Exp(e.u[a:b], e.y[a:b], _trend_basis(b - a, model.s, model.opts),
                           e.source if (a, b) == (0, e.n) else f"{e.source} [{a}:{b}]"))
    idx = np.flatnonzero(dropped)
    return pieces, {"source": e.source, "first": int(idx[0]), "last": int(idx[-1]), "samples": int(idx.size)}


def _held_within(e: _Exp, flags: np.ndarray) -> dict:
    """``{"held": {"value", "extreme"}}`` when a held-input run (:func:`.held.held_runs`) covers most of the
    flagged samples of ``e`` (a landed or saturated segment, not a glitch), else empty."""
    for a, b, value, extreme in held_runs(e.u, e.y):
        if 2 * np.count_nonzero(flags[a:b]) > np.count_nonzero(flags):
            return {"held": {"value": value, "extreme": extreme}}
    return {}


def _pair_frequency(a: np.ndarray, near: complex, default: float) -> float:
    """Natural frequency of the pole pair of ``[1, a]`` nearest to ``near``."""
    roots = [q for q in np.roots(np.concatenate([[1.0], a])) if q.imag > 0]
    return abs(min(roots, key=lambda q: abs(q - near))) if roots else default


def _differs(c: _Point, chosen: list[_Point]) -> bool:
    """Whether ``c``'s denominator differs by more than 1 % from every one in ``chosen``."""
    return all(np.linalg.norm(c.alpha - o.alpha) > 1e-2 * (np.linalg.norm(o.alpha) + 1e-12) for o in chosen)


def _distinct(cands: list[_Point], k: int) -> list[_Point]:
    """The ``k`` best candidates whose denominators differ by more than 1 %."""
    chosen: list[_Point] = []
    for c in cands:
        if _differs(c, chosen):
            chosen.append(c)
        if len(chosen) == k:
            break
    return chosen


def _delay_sweep(structure: ModelStructure, exps: list[_Exp], ts: float, opts: FitOptions, start: _Point,
                 deadline: float, say: Progress, refine: bool = True) -> list[_Point]:
    """The criterion minimised over the model at each delay of a grid on ``[0, max_delay]``,
    each point a short LM warm-started from its neighbour's solution (never a fit from
    scratch per point; none where the warm start lies :data:`HOPELESS_DELAY` times above the best so far),
    then (``refine``) coarse to fine around the best minimum: the delays half a step to either side, the step halved until it is one sample. Returns the points at the local minima (the best one
    refined), best first, with the delay as their last parameter (docs/identification.md, "The search")."""
    fixed = _Model(structure, exps, ts, opts, estimate_delay=False)
    count = int(np.clip(round(opts.max_delay / ts) + 1, 2, DELAY_SWEEP_POINTS))
    done, total = 0, count

    floor = math.inf  # the profile's best criterion so far

    def sweep(delays: list[float], a: np.ndarray) -> list[_Point]:
        nonlocal done, floor
        out = []
        for d in delays:
            done += 1
            p0 = fixed.evaluate(a, float(d))
            if not math.isfinite(p0.sse):
                say(done, total, f"delay sweep: {d:.3g} s, model diverges")
                continue
            hopeless = p0.sse > HOPELESS_DELAY * floor
            p = p0 if hopeless else _levenberg_marquardt(fixed, p0, float(d), opts, deadline, say, max_iter=1).point
            floor = min(floor, p.sse)
            a = p.alpha
            p.cols = None                # keep the profile light: signals are recomputed for the starts
            out.append(p)
            say(done, total, f"delay sweep: {p.delay:.3g} s, SSE {p.sse:.4g}")
        return out

    prof = sweep(list(np.linspace(0.0, opts.max_delay, count)), start.alpha[: structure.n_free_poles])
    if not prof:
        return [start]
    sse = [p.sse for p in prof]
    found = [prof[i] for i in range(len(prof))
             if (i == 0 or sse[i] <= sse[i - 1]) and (i == len(prof) - 1 or sse[i] <= sse[i + 1])]
    coarse = best = min(found, key=lambda p: p.sse)
    step = opts.max_delay / max(count - 1, 1)
    while refine and step > ts * (1 + 1e-9):  # bisect around the best minimum: half a step to each side
        step *= 0.5
        grid = [d for d in (best.delay - step, best.delay + step) if 0.0 <= d <= opts.max_delay]
        total += len(grid)
        best = min([best, *sweep(grid, best.alpha)], key=lambda p: p.sse)
    found = [best, *(p for p in found if p is not coarse)]
    return [_Point(np.concatenate([p.alpha, [p.delay]]), p.theta, p.delay, p.locals_, p.sse, p.cols)
            for p in sorted(found, key=lambda p: p.sse)]


# ---------------------------------------------------------------- public entry

def _experiments(data, input: str, output: str, structure: ModelStructure, opts: FitOptions,
                 say: Progress) -> tuple[list[_Exp], float]:
    if isinstance(data, FlightData):
        data = [data]
    data = list(data)
    if not data:
        raise SignalError("`data`: no experiments given")
    ts = data[0].ts
    need = min_samples(structure)
    exps = []
    for fd in data:
        if abs(fd.ts - ts) > 1e-9 * ts:
            raise SignalError(f"{fd.source}: sample time {fd.ts} s differs from {data[0].source} ({ts} s); "
                              "resample to one grid first")
        pieces = fd.pieces()
        for piece in pieces:
            u, y = piece[input], piece[output]
            if u.size < need:
                if len(pieces) > 1:
                    say(0, 0, f"{piece.source}: piece of {u.size} samples between gaps skipped "
                              f"(fewer than {need})")
                    continue
                raise SignalError(f"{fd.source}: {u.size} samples are too few for a model with "
                                  f"{structure.n_params} parameters (need at least {need})")
            if np.std(u) == 0:
                raise SignalError(f"{fd.source}: input `{input}` is constant: it does not excite the system")
            if np.std(y) == 0:
                raise SignalError(f"{fd.source}: output `{output}` is constant ({y[0]:g}): there is no response "
                                  "to fit; check the signal name and the log")
            exps.append(_Exp(u, y, _trend_basis(u.size, structure, opts), piece.source))
    if not exps:
        raise SignalError(f"`data`: no piece of at least {need} samples between the gaps of the logs")
    if opts.delay == "auto" and opts.max_delay is None:
        pass  # DEFAULT_DELAY_SHARE of the shortest experiment (:func:`_fit_problem`): within half of it
    elif opts.delay == "auto" or opts.delay > 0:
        shortest = min(e.n for e in exps) * ts
        limit = opts.max_delay if opts.delay == "auto" else float(opts.delay)
        if limit >= 0.5 * shortest:
            name = "max_delay" if opts.delay == "auto" else "delay"
            raise SpecError(f"`{name}`: got {limit:g} s, but the shortest experiment lasts {shortest:g} s; "
                            f"a delay must stay below half of it ({0.5 * shortest:g} s)")
    return exps, ts


def tfest(data: FlightData | list[FlightData], input: str, output: str, structure: ModelStructure,
          options: FitOptions | None = None, validation: FlightData | list[FlightData] | None = None,
          progress: Progress | None = None) -> TFEstimate:
    """Fit a continuous-time transfer function to one or several experiments.

    Parameters
    ----------
    data : FlightData or list of FlightData
        Estimation experiments (same sample time); fitted jointly. Logs with gaps
        (``FlightData.metadata["gaps"]``) are split there, each piece with its own initial
        condition and trend.
    input, output : str
        Signal names of the plant input (e.g. commanded acceleration, m/s^2) and output
        (e.g. position, m).
    structure : ModelStructure
        Poles (incl. fixed integrators), zeros, integrators.
    options : FitOptions, optional
        Fit settings (default ``FitOptions()``: no delay, offset trend, two starts).
    validation : FlightData or list of FlightData, optional
        Held-out experiments: their fit percent is reported (initial condition and trend
        estimated there too, by linear least squares, as MATLAB's ``compare`` does).
    progress : callable, optional
        ``progress(done, total, what)``, called as the fit advances: after each point of the
        delay sweep (``delay="auto"``; ``done`` of ``total`` sweep points), once the starts are
        chosen (``0`` of the number of starts) and after the LM run from each start; with
        ``FitOptions.verbose`` after every LM iteration too (``done`` of the iteration limit).
        Remarks outside a counted stage (a piece between gaps skipped, SRIVC failing) come with
        ``done = total = 0``. None (default): silent.

    Returns
    -------
    TFEstimate
        With ``solver`` holding the status (``converged``, ``max_iter``, ``time_limit``),
        iterations, starts, wall time and, when the starts were searched, how they were ranked
        (``ranking``: ``decimation`` factor and ``samples`` of the ranking record).

    Warns
    -----
    RuntimeWarning
        When the iteration or time limit stopped the search (the best iterate is returned).
    """
    opts = options or FitOptions()
    say: Progress = progress if progress is not None else _silent
    # every matrix here is tiny or tall-and-thin: BLAS threads only cost wake-ups (milliseconds
    # per call on a loaded machine), so the fit runs single-threaded
    _keep_freed_memory()
    with _blas_controller().limit(limits=1, user_api="blas"):
        return _tfest(data, input, output, structure, opts, validation, say)


@functools.lru_cache(maxsize=1)
def _blas_controller() -> ThreadpoolController:
    return ThreadpoolController()


@functools.lru_cache(maxsize=1)
def _keep_freed_memory() -> None:
    """Free one 16 MiB block, once per process.

    glibc's malloc serves blocks above its mmap threshold (128 kiB at start) with fresh
    mappings and trims the heap after each free, so every signal-sized temporary of the fit
    costs page faults again (measured: a 30,000-sample fit 58 ms in a fresh process, 31 ms once
    a large block had been freed). Freeing a large block raises both thresholds to its size
    (mallopt(3), dynamic mmap threshold), after which temporaries reuse heap memory. Elsewhere
    this is one allocation and nothing more.
    """
    block = np.ones(2 * 1024 * 1024)         # below glibc's 32 MiB cap of the dynamic threshold
    del block


def _tfest(data: FlightData | list[FlightData], input: str, output: str, structure: ModelStructure,
           opts: FitOptions, validation: FlightData | list[FlightData] | None, say: Progress) -> TFEstimate:
    """The fit of :func:`tfest` (its BLAS limited by the caller), step by step.

    The steps are those of docs/identification.md, "The search": the criterion
    (:func:`_fit_problem`), the starts (:func:`_initial_points`, :func:`_lm_starts`; step 1 and the
    delay profile of step 2), Levenberg-Marquardt and the resonances retuned (:func:`_search`;
    steps 3-4), the gross errors (:func:`_refit_without_gross_errors`; step 5), the limits
    (:func:`_warn_if_stopped`; step 6) and the result with its covariance (:func:`_result`; step 7).

    Parameters
    ----------
    data : FlightData or list of FlightData
        Estimation experiments (one sample time), as given to :func:`tfest`.
    input, output : str
        Signal names of the plant input and output.
    structure : ModelStructure
        The model orders.
    opts : FitOptions
        Fit settings; a ``max_delay`` of None is replaced by its default (:func:`_fit_problem`).
    validation : FlightData or list of FlightData or None
        Held-out experiments (their fit percent is reported).
    say : Progress
        Where the fit reports as it advances.

    Returns
    -------
    TFEstimate
        The fitted model, its covariance, fits and the solver's report (``solver["seconds"]``:
        wall time of this call, s).

    Raises
    ------
    SignalError
        Data unfit for the structure (:func:`_experiments`), or a converged fit of an output that
        does not respond to the input (:func:`_result`).
    SpecError
        An unusable ``FitOptions.initial`` or delay bound.
    IlcdobError
        No start could be formed.

    Warns
    -----
    RuntimeWarning
        The search stopped at a limit (:func:`_warn_if_stopped`).
    """
    t_start = time.perf_counter()
    deadline = t_start + (opts.time_limit if opts.time_limit is not None else math.inf)
    model, delay0 = _fit_problem(data, input, output, structure, opts, say)
    cands, ranking = _initial_points(model, delay0, say)
    runs: list[dict] = []
    starts = _lm_starts(model, cands, deadline, say)
    del cands  # each holds a record's worth of signals (memory per sample: docs/identification.md, "Measured")
    best = _search(model, starts, delay0, deadline, say, runs)
    del starts
    model, best, left_out, startup = _refit_without_gross_errors(model, best, delay0, deadline, say, runs)
    model, best, held = _refit_without_held_inputs(model, best, delay0, deadline, say, runs)
    _warn_if_stopped(best)
    return _result(model, best, input, output, validation, runs, ranking, left_out + held, t_start, startup)


def _fit_problem(data: FlightData | list[FlightData], input: str, output: str, structure: ModelStructure,
                 opts: FitOptions, say: Progress) -> tuple[_Model, float]:
    """The experiments and the criterion to minimise over them (docs/identification.md, "The model of one log").

    Parameters
    ----------
    data : FlightData or list of FlightData
        Estimation experiments (one sample time); split at their gaps (:func:`_experiments`).
    input, output : str
        Signal names of the plant input and output.
    structure : ModelStructure
        The model orders.
    opts : FitOptions
        Fit settings. With ``delay="auto"`` and ``max_delay=None``, the criterion's options get
        ``max_delay`` = :data:`DEFAULT_DELAY_SHARE` of the shortest experiment, s.
    say : Progress
        Told of pieces between gaps too short to fit.

    Returns
    -------
    model : _Model
        The criterion; ``model.opts`` are the settings the fit runs with (``max_delay`` set).
    delay0 : float
        The delay held fixed in the criterion, s: ``opts.delay``, or 0 when the delay is estimated
        (it is then the last nonlinear parameter).

    Raises
    ------
    SignalError, SpecError
        As :func:`_experiments`: too few samples, a constant signal, mixed sample times, a delay
        bound of half the shortest experiment or more.
    """
    exps, ts = _experiments(data, input, output, structure, opts, say)
    if opts.max_delay is None and opts.delay == "auto":
        opts = dataclasses.replace(opts, max_delay=DEFAULT_DELAY_SHARE * min(e.n for e in exps) * ts)
    estimate_delay = opts.delay == "auto"
    return _Model(structure, exps, ts, opts, estimate_delay), 0.0 if estimate_delay else float(opts.delay)


def _initial_points(model: _Model, delay0: float, say: Progress) -> tuple[list[_Point], dict]:
    """The candidate starts: ``FitOptions.initial`` alone, else those of :func:`_candidates`.

    docs/identification.md, "The search", step 1.

    Parameters
    ----------
    model : _Model
        The criterion (its ``opts`` and structure say which starts).
    delay0 : float
        The fixed delay, s (0 when estimated: the start's delay parameter is then 0 as well).
    say : Progress
        Told when SRIVC gives no estimate.

    Returns
    -------
    cands : list of _Point
        The starts with their linear parameters solved, best criterion first (at least one).
    ranking : dict
        How :func:`_candidates` ranked them (``decimation``, ``samples``); empty for ``initial``.

    Raises
    ------
    SpecError
        ``initial`` not of ``n_params`` values, or a model whose criterion is not finite.
    IlcdobError
        Every candidate model diverged.
    """
    opts, structure = model.opts, model.s
    if opts.initial is not None:
        if len(opts.initial) != structure.n_params:
            raise SpecError(f"`initial`: got {len(opts.initial)} values, the structure has {structure.n_params} "
                            f"parameters (free denominator, then numerator)")
        a0 = np.asarray(opts.initial[: structure.n_free_poles])
        start = model.evaluate(np.concatenate([a0, [delay0] if model.estimate_delay else []]), delay0)
        if not math.isfinite(start.sse):
            raise SpecError(f"`initial`: the model {list(opts.initial)} cannot start the fit (unstable or "
                            "diverging on these data)")
        cands, ranking = [start], {}
    else:
        cands, ranking = _candidates(model, delay0, say)
    if not cands:
        raise IlcdobError("no initial estimate could be formed (every candidate model diverged); check that "
                          "the input excites the system and that the structure suits the data")
    return cands, ranking


def _competitive(points: list[_Point]) -> list[_Point]:
    """The points within :data:`SECONDARY_START_RATIO` of the first one's criterion (``points`` best first).

    A start whose criterion is several times the best start's lies in a region the first run never needed
    to search.

    Parameters
    ----------
    points : list of _Point
        Starts, best first (not empty).

    Returns
    -------
    list of _Point
        Those with ``sse <= SECONDARY_START_RATIO * points[0].sse``, in their order.
    """
    return [p0 for p0 in points if p0.sse <= SECONDARY_START_RATIO * points[0].sse]


def _lm_starts(model: _Model, cands: list[_Point], deadline: float, say: Progress) -> list[_Point]:
    """The points Levenberg-Marquardt runs from (docs/identification.md, "The search", steps 1-2).

    ``FitOptions.starts`` distinct candidates; with ``delay="auto"`` every competitive one profiles
    the delay (:func:`_delay_sweep`: the best denominator at delay 0 need not be the best at the
    true delay) and the distinct profile minima replace them. The starts are reported through
    ``say`` (``0`` of the number of runs).

    Parameters
    ----------
    model : _Model
        The criterion.
    cands : list of _Point
        Candidate starts, best first (:func:`_initial_points`).
    deadline : float
        ``time.perf_counter()`` value at which the delay sweep stops, s.
    say : Progress
        Told after each sweep point and of the starts chosen.

    Returns
    -------
    list of _Point
        The competitive starts (:func:`_competitive`), best first; with the delay as their last
        parameter when it is estimated.
    """
    opts = model.opts
    starts = _distinct(cands, opts.starts)
    if model.estimate_delay:
        swept = [q for i, p0 in enumerate(_competitive(starts))  # the best start's profile refined
                 for q in _delay_sweep(model.s, model.exps, model.ts, opts, p0, deadline, say, refine=i == 0)]
        starts = _distinct(sorted(swept, key=lambda q: q.sse), opts.starts)
    runs_from = _competitive(starts)
    say(0, len(runs_from), "initial estimate(s): " + ", ".join(
        f"SSE {p.sse:.6g}" + (f" at delay {p.delay:.4g} s" if model.estimate_delay else "") for p in starts))
    return runs_from


def _lm_run(model: _Model, start: _Point, delay0: float, deadline: float, say: Progress, runs: list[dict],
            note: str | None = None) -> _LMResult:
    """One Levenberg-Marquardt run (:func:`_levenberg_marquardt`), recorded in ``runs``.

    Parameters
    ----------
    model : _Model
        The criterion.
    start : _Point
        Where the run starts.
    delay0 : float
        The fixed delay, s (0 when estimated).
    deadline : float
        ``time.perf_counter()`` value at which the run stops with status ``time_limit``, s.
    say : Progress
        Told after every iteration with ``FitOptions.verbose``.
    runs : list of dict
        Appended to: ``{"start_sse", "sse", "status", "iterations"}`` and, with ``note``, ``"start"``
        (the record of ``solver["starts"]``).
    note : str, optional
        What the start was, when not a start of the search.

    Returns
    -------
    _LMResult
        The run's best point, status and iterations.
    """
    res = _levenberg_marquardt(model, start, delay0, model.opts, deadline, say)
    runs.append({"start_sse": start.sse, "sse": res.point.sse, "status": res.status, "iterations": res.iterations,
                 **({"start": note} if note is not None else {})})
    return res


def _search(model: _Model, runs_from: list[_Point], delay0: float, deadline: float, say: Progress,
            runs: list[dict]) -> _LMResult:
    """Levenberg-Marquardt from each start, then the resonances of a converged best retuned.

    docs/identification.md, "The search", steps 3-4: the runs stop early at the time limit; after a
    converged best, :func:`_retune_resonances` moves its lightly damped pole pairs and, from a lower
    criterion, one more run replaces the best if it ends lower.

    Parameters
    ----------
    model : _Model
        The criterion.
    runs_from : list of _Point
        The starts, best first (:func:`_lm_starts`; not empty).
    delay0 : float
        The fixed delay, s (0 when estimated).
    deadline : float
        ``time.perf_counter()`` value at which the search stops, s.
    say : Progress
        Told after each run (``done`` of ``len(runs_from)``).
    runs : list of dict
        Appended to, a record per run (:func:`_lm_run`).

    Returns
    -------
    _LMResult
        The run with the lowest criterion.
    """
    best: _LMResult | None = None
    for i, p0 in enumerate(runs_from):
        res = _lm_run(model, p0, delay0, deadline, say, runs)
        say(i + 1, len(runs_from),
            f"LM: {res.status} after {res.iterations} iterations, SSE {p0.sse:.6g} -> {res.point.sse:.6g}")
        if best is None or res.point.sse < best.point.sse:
            best = res
        if res.status == "time_limit":
            break
    assert best is not None
    ran = len(runs)
    if best.status == "converged":  # a lightly damped pair converged in a neighbouring basin: move it and refit
        moved = _retune_resonances(model, best.point, delay0)
        if moved.sse < best.point.sse:
            res = _lm_run(model, moved, delay0, deadline, say, runs, "resonances retuned")
            if res.point.sse < best.point.sse:
                best = res
    if len(runs_from) > 1 or len(runs) > ran:  # the last line printed is the model returned
        say(len(runs_from), len(runs_from), f"LM: kept the best of {len(runs_from) + len(runs) - ran} runs, "
            f"SSE {best.point.sse:.6g}")
    return best


def _refit_without_gross_errors(model: _Model, best: _LMResult, delay0: float, deadline: float, say: Progress,
                                runs: list[dict]) -> tuple[_Model, _LMResult, list[dict], list[dict]]:
    """Up to :data:`OUTLIER_ROUNDS` refits with the worst cluster of gross errors left out.

    docs/identification.md, "The search", step 5. Only after a converged fit and with
    ``FitOptions.outlier_sigmas`` set; a round that finds no gross error
    (:func:`_without_gross_errors`), or whose cut record the current point cannot start, ends them.

    Parameters
    ----------
    model : _Model
        The criterion the fit converged on.
    best : _LMResult
        That fit.
    delay0 : float
        The fixed delay, s (0 when estimated).
    deadline : float
        ``time.perf_counter()`` value at which a refit stops, s.
    say : Progress
        Told of each round (``done = total = 0``).
    runs : list of dict
        Appended to, a record per refit (:func:`_lm_run`).

    Returns
    -------
    model : _Model
        The criterion on the experiments as last cut (``model`` itself without a round).
    best : _LMResult
        The last refit (``best`` itself without a round).
    left_out : list of dict
        What every round left out (``source``, ``first``, ``last``, ``samples``).
    startup : list of dict
        The start-up transients the first round kept (``source``, ``samples``; :func:`_smooth_start`).
    """
    opts = model.opts
    left_out: list[dict] = []
    startup: list[dict] | None = None
    for _ in range(OUTLIER_ROUNDS if opts.outlier_sigmas is not None and best.status == "converged" else 0):
        pieces, left, kept = _without_gross_errors(model, best.point, opts.outlier_sigmas)
        startup = kept if startup is None else startup
        cut = _Model(model.s, pieces, model.ts, opts, model.estimate_delay) if left else None
        p0 = cut.evaluate(best.point.alpha, delay0) if cut is not None else None
        if p0 is None or not math.isfinite(p0.sse):
            break
        samples = sum(d["samples"] for d in left)
        best = _lm_run(cut, p0, delay0, deadline, say, runs, f"{samples} gross-error samples left out")
        model = cut
        left_out += left
        say(0, 0, f"gross errors: {samples} samples left out, LM {best.status}, SSE {best.point.sse:.6g}")
    return model, best, left_out, startup or []


def _refit_without_held_inputs(model: _Model, best: _LMResult, delay0: float, deadline: float, say: Progress,
                               runs: list[dict]) -> tuple[_Model, _LMResult, list[dict]]:
    """The fit again without the landed or saturated segments the fit shows (:func:`.held.held_segments`).

    docs/identification.md, "Scores and notes". Such a segment can ruin the fit it is found by, so the refit
    searches afresh (its starts from the cut record). Without ``FitOptions.outlier_sigmas``, or where the cut
    would leave fewer samples than the structure needs, nothing is cut (the segments are then noted as kept).

    Returns
    -------
    model, best
        The criterion and fit on the cut record (unchanged without a cut).
    left_out : list of dict
        What was left out (``source``, ``first``, ``last``, ``samples``, ``held``: ``value`` and ``extreme``).
    """
    if model.opts.outlier_sigmas is None or not any(held_runs(e.u, e.y) for e in model.exps):
        return model, best, []  # the model's output (a record's worth of columns) only where a run is held
    held = held_segments([(e.u, e.y) for e in model.exps], _fitted(model, best.point),
                         [e.source for e in model.exps], model.ts)
    pieces, left = [], []
    for e in model.exps:
        runs_of = [d for d in held if d["source"] == e.source]
        if not runs_of:
            pieces.append(e)
            continue
        bad = np.zeros(e.n, bool)
        for d in runs_of:
            bad[d["first"]:d["last"] + 1] = True
        kept, record = _cut(model, e, bad)
        pieces += kept
        left.append({**record, "held": {"value": runs_of[0]["value"], "extreme": runs_of[0]["extreme"]}})
    if not left or not pieces:
        return model, best, []
    cut = _Model(model.s, pieces, model.ts, model.opts, model.estimate_delay)
    samples = sum(d["samples"] for d in left)
    say(0, 0, f"held input: {samples} samples of a landed or saturated segment left out; fitting again")
    cands, _ = _initial_points(cut, delay0, say)
    return cut, _search(cut, _lm_starts(cut, cands, deadline, say), delay0, deadline, say, runs), left


#: Why a search that did not converge stopped, by its status (:func:`_warn_if_stopped`).
_STOPPED = {"max_iter": "at its iteration limit", "time_limit": "at its time limit",
            "numerical": "where the sensitivities overflowed (the model order may exceed what the data support)"}


def _warn_if_stopped(best: _LMResult) -> None:
    """Warn that the search stopped before converging (docs/identification.md, "The search", step 6).

    Parameters
    ----------
    best : _LMResult
        The fit returned.

    Warns
    -----
    RuntimeWarning
        ``best.status`` is not ``converged``: why it stopped, its criterion and the advice. The
        warning points at the caller of :func:`tfest`.
    """
    if best.status == "converged":
        return
    advice = ("raise FitOptions.max_iter/time_limit (--max-iter/--time-limit) or check the model structure"
              if best.status != "numerical" else "check the model structure; an open-loop unstable plant needs "
              "FitOptions(stable=False) (--allow-unstable)")
    warnings.warn(f"tfest stopped {_STOPPED[best.status]} ({best.status}); the best iterate is returned (SSE "
                  f"{best.point.sse:.6g}); {advice}", RuntimeWarning, stacklevel=4)


def _delay_pull(model: _Model, p: _Point) -> dict:
    """Evidence that a negative delay would fit better, for the diagnostics.

    Parameters
    ----------
    model : _Model
        The criterion.
    p : _Point
        The fit.

    Returns
    -------
    dict
        With the delay estimated and on its lower bound (``<= 1e-12`` s),
        ``{"delay_lower_bound_gain": g}``: the decrease of the criterion that a Gauss-Newton step
        of the delay alone predicts (``g_r^2 / h_r`` from the delay's entries of the reduced normal
        equations; 0 unless that step points below 0 s), divided by the residual variance
        ``SSE / samples``. Else empty.
    """
    if not (model.estimate_delay and p.delay <= 1e-12):
        return {}
    with np.errstate(over="ignore", invalid="ignore"):
        h_r, g_r = model.reduced_normal(p)
    gain = g_r[-1] ** 2 / h_r[-1, -1] if g_r[-1] < 0 and h_r[-1, -1] > 0 else 0.0
    return {"delay_lower_bound_gain": float(gain / max(p.sse / sum(e.n for e in model.exps), 1e-300))}


def _covariance(model: _Model, p: _Point) -> tuple[float, np.ndarray]:
    """Residual variance and covariance of the fit (docs/identification.md, "The search", step 7).

    Parameters
    ----------
    model : _Model
        The criterion.
    p : _Point
        The fit.

    Returns
    -------
    sigma2 : float
        ``SSE / (samples - parameters)``, in the output's unit squared (all linear and nonlinear
        parameters counted; at least 1 in the denominator).
    cov : numpy.ndarray
        Covariance of the structure's parameters (and of the delay, last, when estimated) from the
        joint normal matrix of every parameter: inf, not a warning, for a diverging model.
    """
    n_obs = sum(e.n for e in model.exps)
    with np.errstate(over="ignore", invalid="ignore"):  # a diverging model's covariance is inf, not a warning
        h = model.full_normal(p)
    sigma2 = p.sse / max(n_obs - h.shape[0], 1)
    n_global = model.s.n_params + (1 if model.estimate_delay else 0)
    return sigma2, sigma2 * _scaled_pinv(h)[:n_global, :n_global]


def _result(model: _Model, best: _LMResult, input: str, output: str, validation: FlightData | list[FlightData] | None,
            runs: list[dict], ranking: dict, left_out: list[dict], t_start: float,
            startup: list[dict] | None = None) -> TFEstimate:
    """The fit as a :class:`TFEstimate`, refused when the output shows no response.

    Parameters
    ----------
    model : _Model
        The criterion of the fit (experiments as last cut).
    best : _LMResult
        The fit.
    input, output : str
        Signal names of the plant input and output.
    validation : FlightData or list of FlightData or None
        Held-out experiments.
    runs : list of dict
        The record of every LM run (:func:`_lm_run`): ``solver["starts"]``.
    ranking : dict
        How the starts were ranked (:func:`_initial_points`; may be empty).
    left_out : list of dict
        The gross errors left out (:func:`_refit_without_gross_errors`; may be empty).
    t_start : float
        ``time.perf_counter()`` value at the start of the fit, s.
    startup : list of dict, optional
        Start-up transients kept in the fit (:func:`_refit_without_gross_errors`).

    Returns
    -------
    TFEstimate
        With ``solver``: engine, status, iterations, starts, then ``ranking``, ``max_delay``
        (delay estimated), ``delay_lower_bound_gain`` (:func:`_delay_pull`), ``gross_errors`` (with ``held``
        where a held input explains them), ``startup_transients`` and ``held_inputs``
        (:func:`.held.held_segments`: a landed or saturated segment left in the fit) where they apply, and
        ``seconds``, the wall time since ``t_start``.

    Raises
    ------
    SignalError
        A converged fit with a trend that explains less than :data:`MIN_RESPONSE_FIT` % of the output.
    """
    p, opts, exps = best.point, model.opts, model.exps
    p.cols = model._cols(p)  # once for the delay's pull, the covariance and the fitted output
    pull = _delay_pull(model, p)
    sigma2, cov = _covariance(model, p)
    fitted = _fitted(model, p)
    held = held_segments([(e.u, e.y) for e in exps], fitted, [e.source for e in exps], model.ts)
    est = TFEstimate.from_fit(structure=model.s, theta=p.theta, delay=p.delay, covariance=cov,
                              delay_estimated=model.estimate_delay, sigma2=sigma2,
                              experiments=[(e.u, e.y) for e in exps], ts=model.ts, validation=validation,
                              input=input, output=output, trend=opts.trend, fitted=fitted,
                              solver={"engine": "variable projection + Levenberg-Marquardt, filtered sensitivities",
                                      "status": best.status, "iterations": best.iterations,
                                      "starts": runs, **({"ranking": ranking} if ranking else {}),
                                      **({"max_delay": opts.max_delay} if model.estimate_delay else {}), **pull,
                                      **({"gross_errors": left_out} if left_out else {}),
                                      **({"startup_transients": startup} if startup else {}),
                                      **({"held_inputs": held} if held else {}),
                                      "seconds": time.perf_counter() - t_start})
    if best.status == "converged" and opts.trend is not None and not est.fit_estimation >= MIN_RESPONSE_FIT:
        raise SignalError(f"{exps[0].source}: output `{output}` shows no response to input `{input}`: the best "
                          f"model explains {est.fit_estimation:.2g} % of it beyond its offset (below "
                          f"{MIN_RESPONSE_FIT:g} %); check the signal names, the units and that the excitation "
                          "reached the vehicle")
    return est
