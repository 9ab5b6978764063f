"""Nominal norm-optimal learning design (docs/theory.md section 3), solved in O(N).

For system j learning from system j-1 with the predicted error without learning ``e0``
(from j-1's flight: ``e0 = -Gd_j {d_rec}``, ``d_rec`` the disturbance reconstructed from
j-1's data with its model), choose the learning signal ``d_f`` to minimise::

    J = sum_t  w (e0_t - y_t)^2 + lam d_f,t^2 + mu (d_f,t - d_f,t-1)^2,    y = Gf_j {d_f}

This is a finite-horizon linear-quadratic tracking problem. With the state of ``Gf_j``
augmented by the previous input (for the difference penalty), the backward Riccati
recursion gives time-varying gains once per system, and each trial costs one backward pass
for the affine term and one forward pass: no N x N matrix is formed. The same optimum,
written as the linear system ``(Gf' W Gf + lam I + mu Diff' Diff) d_f = Gf' W e0``, is what a
dense QP would solve in O(N^3). Its solution map, composed with the reconstruction, is the
pair of lifted learning matrices (:meth:`NormOptimalDesigner.lifted_matrices`); as
``lam, mu -> 0`` with exact models it reproduces the closed-form filters of the Theorem.

How it is computed (measurements in docs/performance.md, "Norm-optimal ILC"):

* The gains come from the Chandrasekhar form of the Riccati recursion. The state weight has
  rank 2 (the error and the input difference), so every change ``P_t - P_{t+1}`` of the
  Riccati matrix has rank <= 2 and is carried as ``Y_t M_t Y_t'`` (``Y_t`` n x 2): O(n^2) per
  sample instead of O(n^3), and ``P_t`` itself is never formed. It is the same recursion
  (an algebraic identity), to rounding; its two running sums are compensated (:func:`_base`).
* The recursions (gains, the affine backward pass, the forward pass, plain simulation) run as
  CasADi SX functions of a few samples each (``_UNROLL``), chained over blocks of samples by
  ``mapaccum``. They are compiled to native code where a C compiler runs (:mod:`ilcdob.native`:
  once per machine and sparsity pattern, for trials of ``_NATIVE_MIN_SAMPLES`` samples or more,
  about 8 times as fast) and otherwise evaluated in CasADi's virtual machine, with the same
  results bit for bit. The system's
  nonzero entries travel in the accumulated state, so one function serves every system with the
  same zero entries (the fleet's maps share them), and its zeros cost no instructions: the
  products with them are left out, which changes no sum, so the results are those of dense
  matrices bit for bit, 1.5 times as fast for the built-in fleet.
* Accuracy: the gains are within a few units of rounding of the exact ones (80-bit arithmetic);
  the learning signal carries their rounding amplified by the problem's conditioning. At the
  default weights (a closed-loop pole at 1 - 1e-8) storing the exact gains as float64 alone
  moves it by 7e-13 to 8e-13 of its peak, and the design is 3e-12 to 4.4e-12 from the exact
  optimum (N = 1500 to 300,000), as was the per-sample loop it replaced; with better conditioned
  weights, within 1e-12 (tests/test_norm_optimal.py, benchmarks/bench_norm_optimal.py).
* :meth:`NormOptimalDesigner.law` gives the learning law of the lifted matrices,
  ``d_f,j = L1 e_{j-1} + L2 d_f,{j-1}``, without them (:class:`NormOptimalLaw`, O(N n)
  memory): ``L1 = F Gd_j Gd_{j-1}^+`` and ``L2 = L1 Gf_{j-1}``, where the Tikhonov inverse
  ``Gd_{j-1}^+`` of :func:`~ilcdob.design.maps.lifted_filters.regularised_inverse` is itself a
  regularised least-squares problem over the trial, solved by the same recursion. Its weight
  ``alpha = regularisation * sigma_max^2`` needs the largest singular value of the lifted
  ``Gd_{j-1}``: Lanczos on ``(sigma I - T'T)^{-1}`` with ``sigma`` the squared peak gain of
  ``Gd_{j-1}`` (an upper bound, checked by the signs of the recursion's pivots), each step one
  more solve (:func:`_top_eigenvalue`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from ilcdob.errors import NumericalError, SpecError
from ilcdob.lifted import lifted_operator, markov_parameters, relative_degree
from ilcdob.loop import LoopSystem
from ilcdob.native import NativeFunction
from ilcdob.signals import as_signal

from ..maps.closed_form import reconstruct_disturbance, simulate_map

__all__ = ["NormOptimalOptions", "NormOptimalDesigner", "NormOptimalLaw", "norm_optimal_learning",
           "MAX_NORM_OPTIMAL_BYTES", "LIFTED_PEAK_MATRICES", "norm_optimal_bytes", "check_norm_optimal_size"]

#: Memory one norm-optimal design may take, bytes (what two 20,000-sample lifted matrices took).
MAX_NORM_OPTIMAL_BYTES = 6.4e9

#: Peak memory of :meth:`NormOptimalDesigner.lifted_matrices`, in N x N float64 matrices, a bound above
#: the tracemalloc peak; two of them are kept (measured: docs/performance.md, "Measured figures behind
#: the design's choices").
LIFTED_PEAK_MATRICES = 8

#: Peak memory of the compact design per sample, in float64 numbers: ``_COMPACT_ROWS`` rows of
#: ``order + 2`` (the gains and pivot of a recursion: the design's, the inverse's, the shifted
#: problem of :func:`_top_eigenvalue` and a copy while one is reordered) plus ``_COMPACT_SIGNALS``
#: signals. 64 at order 11, a bound above the tracemalloc peak (measured: docs/performance.md,
#: "Measured figures behind the design's choices").
_COMPACT_ROWS = 4
_COMPACT_SIGNALS = 12

#: Samples per call of each compiled recursion (its SX function is unrolled over them), chosen by
#: measurement: the gains run fastest in short functions, the passes, which read and write a row per
#: sample, in longer ones (measured: docs/performance.md, "Measured figures behind the design's
#: choices"). The results do not depend on it, bit for bit.
_UNROLL = {"gains": 4, "backward": 16, "forward": 16, "simulate": 16}

#: Trials of at least this many samples build a recursion's native library (:mod:`ilcdob.native`)
#: when none is on disk; shorter ones use a built one or the virtual machine. A build costs compiler
#: time once per machine and sparsity pattern, which only long trials repay: shorter ones run fast
#: enough in the virtual machine (measured: docs/performance.md, "Measured figures behind the design's
#: choices").
_NATIVE_MIN_SAMPLES = 20_000

#: Calls per ``mapaccum`` block, largest first (a trial is run in blocks of these sizes).
_BLOCKS = (512, 64, 8, 1)

#: Lanczos for ``sigma_max`` (:func:`_top_eigenvalue`): accept the Ritz value when its residual
#: bound is below this (relative), and give up after this many steps (it takes about 8).
_EIG_RTOL = 1e-14
_EIG_MAX_STEPS = 100


@dataclass(frozen=True)
class NormOptimalOptions:
    """Weights of the norm-optimal cost.

    Attributes
    ----------
    lam : float
        Weight of ``||d_f||^2`` (>= 0), (m/(m/s^2))^2.
    mu : float
        Weight of ``||Diff d_f||^2`` (>= 0); ``lam + mu`` must be > 0 unless Gf has a
        direct feedthrough.
    weight : float
        Error weight ``w`` (> 0).
    """

    lam: float = 1e-8
    mu: float = 1e-8
    weight: float = 1.0

    def __post_init__(self) -> None:
        for name in ("lam", "mu"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise SpecError(f"`{name}`: got {v!r}, expected a finite number >= 0")
        if not (math.isfinite(self.weight) and self.weight > 0):
            raise SpecError(f"`weight`: got {self.weight!r}, expected a number > 0")


# ----------------------------------------------------------------------------- compiled recursions

_System = tuple[np.ndarray, np.ndarray, np.ndarray, float]  # (A, B as a vector, C as a vector, D)


def _state_space(sys: Any) -> _System:
    """``(A, b, c, d)`` of a discrete SISO state-space system, as float arrays."""
    a = np.array(sys.A, dtype=float, ndmin=2)
    nx = a.shape[0]
    b = np.asarray(sys.B, dtype=float).reshape(nx)
    c = np.asarray(sys.C, dtype=float).reshape(nx)
    return a, b, c, float(np.asarray(sys.D, dtype=float).ravel()[0])


#: Where a system's entries are nonzero: ``(nx, A, b, c, d)`` with the indices of the nonzero entries of
#: ``A`` (column-major), ``b`` and ``c``, and whether ``d`` is nonzero (the key of :func:`_base`).
_Pattern = tuple[int, tuple[int, ...], tuple[int, ...], tuple[int, ...], bool]


def _pattern(sys: _System) -> _Pattern:
    """The sparsity pattern of ``(A, b, c, d)``: the recursions are built for it (:func:`_base`)."""
    a, b, c, d = sys

    def nonzero(v: np.ndarray) -> tuple[int, ...]:
        return tuple(int(i) for i in np.flatnonzero(v))

    return a.shape[0], nonzero(a.ravel(order="F")), nonzero(b), nonzero(c), d != 0.0


def _params(sys: _System) -> np.ndarray:
    """The system's nonzero entries (:func:`_pattern`) as the leading entries of every recursion's
    accumulated state, then a 1 (see :func:`_base`)."""
    a, b, c, d = sys
    _, ia, ib, ic, has_d = _pattern(sys)
    return np.concatenate([a.ravel(order="F")[list(ia)], b[list(ib)], c[list(ic)], [d] if has_d else [], [1.0]])


#: Sparsity patterns whose compiled recursions are kept (the fleet's maps have three or four).
_CACHED_PATTERNS = 16


@lru_cache(maxsize=4 * _CACHED_PATTERNS)
def _base(kind: str, pattern: _Pattern, unroll: int) -> Any:
    """CasADi SX function running ``unroll`` samples of recursion ``kind`` for systems of ``pattern``.

    Its first input and output are the accumulated state ``[A, b, c, d, 1, state]`` (the system's
    nonzero entries, :func:`_params`, passed through unchanged); the second input (if any) holds one
    column per sample, the last output one column per sample. ``nz = nx + 1`` (the state augmented by
    the previous input). The system's zero entries are structural zeros of the SX matrices, so no
    instruction multiplies by them (a third to a half fewer instructions for the built-in fleet, whose
    ``A`` has 65 nonzero entries of 121 and ``c`` one of 11); leaving out a product with zero leaves
    every sum as it was.

    * ``gains``: state ``[Y0, Y1, G, M11, M12, M22, Re, dG, dRe]`` of the Chandrasekhar recursion,
      run backward in time; outputs ``[K_t; Re_t]`` (the gain and the pivot ``R + B'P_{t+1}B``).
      ``G = S + A'P_{t+1}B`` and ``Re`` are sums of one increment per sample: summed plainly they
      drift (the Riccati form corrects itself, this one does not), so they are summed with
      compensation (``TwoSum``; ``dG``, ``dRe`` hold the rounding errors; measured: docs/performance.md,
      "Measured figures behind the design's choices").
      The symbolic 1 keeps CasADi from simplifying ``(a + b) - a`` to ``b``.
    * ``backward``: state ``p`` (affine term of the value function); inputs ``[K_t; Re_t; q_t;
      r_t]`` with the linear cost ``2 (q_t Cz' z + r_t u)``; output ``kff_t``.
    * ``forward``: state ``z``; inputs ``[K_t; kff_t]``; output ``u_t = -K_t z - kff_t``.
    * ``simulate``: state ``x`` of ``(A, b, c, d)`` from rest; input ``u_t``; output ``y_t``.
    """
    import casadi as cs  # only here: CasADi takes a while to load

    nx, ia, ib, ic, has_d = pattern
    nz = nx + 1
    npar = len(ia) + len(ib) + len(ic) + int(has_d) + 1
    nstate = {"gains": 4 * nz + 5, "backward": nz, "forward": nz, "simulate": nx}[kind]
    nin = {"gains": 0, "backward": nz + 3, "forward": nz + 1, "simulate": 1}[kind]
    acc = cs.SX.sym("acc", npar + nstate)
    ends = np.cumsum([len(ia), len(ib), len(ic)])
    a = cs.SX(cs.Sparsity.triplet(nx, nx, [i % nx for i in ia], [i // nx for i in ia]), acc[: ends[0]])
    b = cs.SX(cs.Sparsity.triplet(nx, 1, list(ib), [0] * len(ib)), acc[ends[0]: ends[1]])
    c = cs.SX(cs.Sparsity.triplet(nx, 1, list(ic), [0] * len(ic)), acc[ends[1]: ends[2]])
    d, one = (acc[npar - 2] if has_d else cs.SX(0.0)), acc[npar - 1]
    at = a.T

    def two_sum(x: Any, y: Any) -> tuple[Any, Any]:  # x + y = s + e exactly (Knuth)
        s = x + y
        yv = s * one - x
        return s, (x - (s - yv)) + (y - yv)

    def a_aug(v: Any) -> Any:  # Abar v, Abar = [[A, 0], [0, 0]]
        return cs.vertcat(cs.mtimes(a, v[:nx]), 0)

    def at_aug(v: Any) -> Any:  # Abar' v
        return cs.vertcat(cs.mtimes(at, v[:nx]), 0)

    def b_dot(v: Any) -> Any:  # Bbar' v, Bbar = [b; 1]
        return cs.dot(b, v[:nx]) + v[nx]

    state = acc[npar:]
    inputs = cs.SX.sym("in", nin, unroll) if nin else None
    outs = []
    for k in range(unroll):
        if kind == "gains":
            y0, y1, g = state[:nz], state[nz: 2 * nz], state[2 * nz: 3 * nz]
            m11, m12, m22, re = state[3 * nz], state[3 * nz + 1], state[3 * nz + 2], state[3 * nz + 3]
            dg, dre = state[3 * nz + 4: 4 * nz + 4], state[4 * nz + 4]
            pivot = re + dre
            gain = (g + dg) / pivot
            by0, by1 = b_dot(y0), b_dot(y1)
            mb0, mb1 = m11 * by0 + m12 * by1, m12 * by0 + m22 * by1
            re_next, e_re = two_sum(re, by0 * mb0 + by1 * mb1)
            dre = dre + e_re
            ay0, ay1 = at_aug(y0), at_aug(y1)
            g_next, e_g = two_sum(g, ay0 * mb0 + ay1 * mb1)
            pivot_next = re_next + dre
            state = cs.vertcat(ay0 - gain * by0, ay1 - gain * by1, g_next, m11 - mb0 * mb0 / pivot_next,
                               m12 - mb0 * mb1 / pivot_next, m22 - mb1 * mb1 / pivot_next, re_next, dg + e_g, dre)
            outs.append(cs.vertcat(gain, pivot))
        elif kind == "backward":
            col = inputs[:, k]
            gain, re, q, r = col[:nz], col[nz], col[nz + 1], col[nz + 2]
            h_u = r + b_dot(state)
            state = at_aug(state) + q * cs.vertcat(c, 0) - gain * h_u
            outs.append(h_u / re)
        elif kind == "forward":
            col = inputs[:, k]
            u = -cs.dot(col[:nz], state) - col[nz]
            state = a_aug(state) + cs.vertcat(b, 1) * u
            outs.append(u)
        else:
            u = inputs[0, k]
            outs.append(cs.dot(c, state) + d * u)
            state = cs.mtimes(a, state) + b * u
    args = [acc] if inputs is None else [acc, inputs]
    results = [cs.densify(cs.vertcat(acc[:npar], state)), cs.densify(cs.horzcat(*outs))]
    return cs.Function(f"norm_optimal_{kind}_{nx}", args, results)


@lru_cache(maxsize=4 * _CACHED_PATTERNS)
def _native(kind: str, pattern: _Pattern, unroll: int) -> NativeFunction:
    """:func:`_base` and its build in native code (:mod:`ilcdob.native`)."""
    return NativeFunction(_base(kind, pattern, unroll))


@lru_cache(maxsize=8 * len(_BLOCKS) * _CACHED_PATTERNS)
def _block(kind: str, pattern: _Pattern, unroll: int, calls: int, native: bool) -> Any:
    """``calls`` chained evaluations of :func:`_base` (``calls * unroll`` samples), native or not."""
    handle = _native(kind, pattern, unroll)
    return (handle.loaded if native else handle.function).mapaccum(calls)


def _run(kind: str, sys: _System, state: np.ndarray, steps: int,
         fill: Callable[[np.ndarray, int, int], None] | None = None) -> np.ndarray:
    """Run recursion ``kind`` of :func:`_base` for ``steps`` samples from ``state``.

    ``fill(rows, start, count)`` writes the inputs of samples ``start .. start + count - 1`` into
    ``rows`` (one row per sample; rows past ``steps`` are padding and must keep the recursion
    finite). CasADi reads and writes the numpy arrays in place (``Function.buffer``): its
    column-major ``k x count`` matrices are C-ordered ``count x k`` arrays.

    Returns
    -------
    numpy.ndarray
        One row of outputs per sample (``steps x outputs``).
    """
    pattern = _pattern(sys)
    acc = np.concatenate([_params(sys), state])
    unroll = _UNROLL[kind]
    handle = _native(kind, pattern, unroll)
    base = handle.get(build=steps >= _NATIVE_MIN_SAMPLES)
    native = base is not handle.function
    n_in = base.size1_in(1) if base.n_in() > 1 else 0
    padded = -(-steps // unroll) * unroll
    out = np.empty((padded, base.size1_out(1)))
    rows = np.empty((min(padded, _BLOCKS[0] * unroll), n_in))
    evaluators: dict[int, tuple[Any, Any, np.ndarray]] = {}
    done = 0
    while done < padded:
        calls = next(c for c in _BLOCKS if c * unroll <= padded - done)
        if calls not in evaluators:
            buf, run = _block(kind, pattern, unroll, calls, native).buffer()
            evaluators[calls] = (buf, run, np.empty((calls, acc.size)))
        buf, run, accs = evaluators[calls]
        count = calls * unroll
        buf.set_arg(0, memoryview(acc))
        if n_in:
            fill(rows[:count], done, count)
            buf.set_arg(1, memoryview(rows[:count]))
        buf.set_res(0, memoryview(accs))
        buf.set_res(1, memoryview(out[done: done + count]))
        run()
        acc = accs[-1].copy()
        done += count
    return out[:steps]


def _lq_gains(sys: _System, w: float, lam: float, mu: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gains ``K_t`` (n x nz) and pivots ``Re_t`` (n) of ``sum w y^2 + lam u^2 + mu (du)^2`` over ``n`` samples.

    The Riccati recursion ``P_t = Q + A'P A - G G'/Re``, ``P_n = 0``, in Chandrasekhar form
    (module docstring): ``P_{n-1} - P_n = Q - S S'/R = Y M Y'`` with ``Y = [Cz, e_u]``.
    """
    a, b, c, d = sys
    nz = b.size + 1
    cz, sel = np.append(c, 0.0), np.zeros(nz)
    sel[-1] = 1.0
    r = w * d * d + lam + mu
    s = w * d * cz - mu * sel
    st = np.array([w * d, -mu])
    m0 = np.diag([w, mu]) - np.outer(st, st) / r
    state = np.concatenate([cz, sel, s, [m0[0, 0], m0[0, 1], m0[1, 1], r], np.zeros(nz + 1)])
    out = _run("gains", sys, state, n)[::-1]  # run backward in time: row k was sample n - 1 - k
    return np.ascontiguousarray(out[:, :nz]), np.ascontiguousarray(out[:, nz])


def _lq_solve(sys: _System, gains: np.ndarray, pivots: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Minimiser ``u`` of the problem of :func:`_lq_gains` plus the linear cost ``2 sum q_t Cz'z_t + r_t u_t``.

    Tracking ``e0`` with weight ``w`` is ``q = -w e0``, ``r = -w d e0``.
    """
    n, nz = gains.shape

    def backward(rows: np.ndarray, start: int, count: int) -> None:
        rows[:] = 0.0
        rows[:, nz] = 1.0  # padding pivots
        lo, hi = max(n - start - count, 0), n - start  # samples hi - 1 down to lo
        m = hi - lo
        if m > 0:
            rows[:m, :nz] = gains[lo:hi][::-1]
            rows[:m, nz] = pivots[lo:hi][::-1]
            rows[:m, nz + 1] = q[lo:hi][::-1]
            rows[:m, nz + 2] = r[lo:hi][::-1]

    kff = _run("backward", sys, np.zeros(nz), n, backward)[::-1, 0].copy()

    def forward(rows: np.ndarray, start: int, count: int) -> None:
        m = max(min(count, n - start), 0)
        rows[m:] = 0.0
        rows[:m, :nz] = gains[start: start + m]
        rows[:m, nz] = kff[start: start + m]

    return _run("forward", sys, np.zeros(nz), n, forward)[:, 0].copy()


def _simulate(sys: _System, u: np.ndarray) -> np.ndarray:
    """Response of ``(A, b, c, d)`` from rest to ``u`` (compiled; the same map as ``simulate_map``)."""
    n = u.size

    def inputs(rows: np.ndarray, start: int, count: int) -> None:
        m = max(min(count, n - start), 0)
        rows[m:] = 0.0
        rows[:m, 0] = u[start: start + m]

    return _run("simulate", sys, np.zeros(sys[0].shape[0]), n, inputs)[:, 0].copy()


def _top_eigenvalue(sys: _System, h: np.ndarray) -> float:
    """Largest eigenvalue ``lambda_1`` of ``T'T``, ``T`` the lifted map of ``sys`` (Markov parameters ``h``).

    Lanczos on ``(sigma I - T'T)^{-1}``, ``sigma`` the squared peak gain of ``sys``: an upper
    bound (a finite section of a causal map is no larger than the map), checked by the pivots
    of ``sigma I - T'T`` (all positive if and only if it is positive definite). Each step is
    one solve of the recursion; the largest eigenvalue ``1 / (sigma - lambda_1)`` of the
    inverse stands well apart from the rest, and the Ritz value is accepted when its residual
    bound moves ``lambda_1`` by less than ``_EIG_RTOL`` (relative): about 8 steps.

    Raises
    ------
    NumericalError
        No shift above the spectrum found, or no convergence.
    """
    import control as ct
    from scipy.linalg import eigh_tridiagonal

    n = h.size
    a, b, c, d = sys
    bound = float(np.sum(np.abs(h))) ** 2  # ||T||_2^2 <= ||h||_1^2
    try:
        peak, omega = ct.linfnorm(ct.ss(a, b.reshape(-1, 1), c.reshape(1, -1), [[d]], True), tol=1e-12)
        sigma, omega = min(float(peak) ** 2 * (1 + 1e-10), bound * (1 + 1e-12)), float(omega)
    except Exception:  # noqa: BLE001 - any failure of the peak search falls back to the bound
        sigma, omega = bound * (1 + 1e-12), 0.0
    if not (math.isfinite(sigma) and sigma > 0):
        raise NumericalError(f"the peak gain of the map to invert is {sigma!r}: not a finite number > 0")
    step = sigma * 1e-9
    for _ in range(40):
        gains, pivots = _lq_gains(sys, -1.0, sigma, 0.0, n)
        if np.all(pivots > 0):
            break
        sigma, step = min(sigma + step, bound * (1 + 1e-12)), step * 10.0
    else:
        raise NumericalError("no upper bound of the largest singular value of the lifted map to invert "
                             f"was found (last tried {sigma:.6g}); its regularisation weight is undefined")
    k = np.arange(n)
    v = np.sin(np.pi * (k + 1) / (n + 1)) * (np.cos(omega * k) + np.sin(omega * k)) + 1e-3
    v /= np.linalg.norm(v)
    v_prev, beta, zeros = np.zeros(n), 0.0, np.zeros(n)
    diag: list[float] = []
    off: list[float] = []
    for _ in range(_EIG_MAX_STEPS):
        w = _lq_solve(sys, gains, pivots, zeros, -v)  # (sigma I - T'T)^{-1} v
        diag.append(float(v @ w))
        w -= diag[-1] * v + beta * v_prev
        w -= float(v @ w) * v  # keep it orthogonal to v (rounding)
        beta = float(np.linalg.norm(w))
        theta, s = eigh_tridiagonal(np.array(diag), np.array(off), select="i",
                                    select_range=(len(diag) - 1, len(diag) - 1))
        theta = float(theta[0])
        lam1 = sigma - 1.0 / theta
        if beta * abs(s[-1, 0]) / theta**2 <= _EIG_RTOL * lam1 or beta == 0.0:
            return lam1
        off.append(beta)
        v_prev, v = v, w / beta
    raise NumericalError(f"the largest singular value of the lifted map to invert did not settle in "
                         f"{_EIG_MAX_STEPS} Lanczos steps (last {math.sqrt(max(lam1, 0.0)):.12g})")


# ----------------------------------------------------------------------------- size of a design

def norm_optimal_bytes(n: int, order: int, lifted: bool = False) -> float:
    """Peak memory of a norm-optimal design of ``n`` samples, bytes.

    Parameters
    ----------
    n : int
        Trial length, samples.
    order : int
        Largest state order of the maps involved (``G_f`` of the target, ``G_d`` of the source).
    lifted : bool
        Whether the N x N lifted matrices are built as well (their peak,
        :data:`LIFTED_PEAK_MATRICES` matrices, dominates).

    Returns
    -------
    float
        Bytes.
    """
    compact = 8.0 * n * (_COMPACT_SIGNALS + _COMPACT_ROWS * (order + 2))
    return compact + (8.0 * LIFTED_PEAK_MATRICES * float(n) ** 2 if lifted else 0.0)


def _size(nbytes: float) -> str:
    return f"{nbytes / 1e9:.3g} GB" if nbytes >= 1e9 else f"{nbytes / 1e6:.3g} MB"


def check_norm_optimal_size(n: int, order: int | None, lifted: bool = False, name: str = "n",
                            option: str = "lifted=True") -> None:
    """Refuse, before any work, a norm-optimal design that would take more than :data:`MAX_NORM_OPTIMAL_BYTES`.

    Parameters
    ----------
    n : int
        Trial length, samples.
    order : int or None
        Largest state order of the maps involved (:func:`norm_optimal_bytes`); None before
        the models are known: then only the lifted matrices (if asked for) are counted.
    lifted : bool
        Whether the N x N lifted matrices were asked for.
    name, option : str
        The argument that gave ``n`` and the one that asks for the lifted matrices, for the message.

    Raises
    ------
    SpecError
        The design would exceed the limit; the message states the memory it would take.
    """
    matrices = 8.0 * LIFTED_PEAK_MATRICES * float(n) ** 2 if lifted else 0.0
    need = norm_optimal_bytes(n, order, lifted) if order is not None else matrices
    if need <= MAX_NORM_OPTIMAL_BYTES:
        return
    cap = _size(MAX_NORM_OPTIMAL_BYTES)
    if lifted:
        longest = int(math.sqrt(MAX_NORM_OPTIMAL_BYTES / (8.0 * LIFTED_PEAK_MATRICES)))
        compact = f"{_size(norm_optimal_bytes(n, order))}" if order is not None else "O(N) memory"
        raise SpecError(f"`{name}`: got {n} samples; the lifted {n} x {n} matrices L1, L2 ({option}) take "
                        f"{_size(need)} of memory to build (about {LIFTED_PEAK_MATRICES} such matrices at once); "
                        f"the limit is {cap} ({longest} samples): omit {option} (the design's compact form, "
                        f"Riccati gains, takes {compact}), or use a shorter trial")
    per_sample = norm_optimal_bytes(1, order)
    raise SpecError(f"`{name}`: got {n} samples; the norm-optimal design (Riccati gains, {order} states) would "
                    f"take {_size(need)} of memory; the limit is {cap} ({int(MAX_NORM_OPTIMAL_BYTES // per_sample)} "
                    "samples): use a shorter trial")


# ----------------------------------------------------------------------------- the design

class NormOptimalDesigner:
    """Riccati solution of the nominal norm-optimal problem for one target loop.

    Parameters
    ----------
    target : LoopSystem
        System j; its nominal (model) ``G_f`` is used.
    n : int
        Trial length, samples (>= 2).
    options : NormOptimalOptions, optional
        Weights of the cost (default ``NormOptimalOptions()``).

    Attributes
    ----------
    gains : numpy.ndarray
        Time-varying feedback gains ``K_t`` (n x (order + 1)) on the state of ``G_f``
        augmented by the previous input.
    pivots : numpy.ndarray
        ``R + B'P_{t+1}B`` (n), the divisor of each step's optimum.

    Notes
    -----
    The backward recursion for the gains runs once, here (O(N n^2), Chandrasekhar form); each
    :meth:`solve` then costs O(N n^2) (module docstring; docs/theory.md section 3).
    """

    def __init__(self, target: LoopSystem, n: int, options: NormOptimalOptions | None = None) -> None:
        if n < 2:
            raise SpecError(f"`n`: got {n}, expected a trial length >= 2 samples")
        self.target, self.n = target, int(n)
        self.options = opts = options or NormOptimalOptions()
        self._system = _state_space(target.nominal.G_f)
        d = self._system[3]
        if opts.weight * d**2 + opts.lam + opts.mu <= 0:
            raise SpecError("`lam` + `mu` must be > 0 (Gf has no direct feedthrough)")
        self.gains, self.pivots = _lq_gains(self._system, opts.weight, opts.lam, opts.mu, self.n)

    def solve(self, e0: object) -> np.ndarray:
        """Optimal learning signal for a predicted error without learning.

        Parameters
        ----------
        e0 : array_like
            Predicted error of system j without learning, m, ``n`` samples.

        Returns
        -------
        numpy.ndarray
            The minimiser ``d_f`` of ``J`` (module docstring), m/s^2, ``n`` samples.
        """
        e0 = as_signal(e0, "e0", self.n)
        w = self.options.weight
        return _lq_solve(self._system, self.gains, self.pivots, -w * e0, -w * self._system[3] * e0)

    def cost(self, e0: np.ndarray, d_f: np.ndarray) -> float:
        """Value of the cost ``J`` for a given learning signal (for checks).

        Parameters
        ----------
        e0 : numpy.ndarray
            Predicted error without learning, m.
        d_f : numpy.ndarray
            Learning signal, m/s^2, same length.

        Returns
        -------
        float
            ``J`` (module docstring).
        """
        o = self.options
        y = simulate_map(self.target.nominal.G_f, d_f)
        du = np.diff(np.concatenate([[0.0], d_f]))
        return float(o.weight * np.sum((e0 - y) ** 2) + o.lam * np.sum(d_f**2) + o.mu * np.sum(du**2))

    def solution_matrix(self) -> np.ndarray:
        """The N x N map ``e0 -> d_f``: ``(Gf' W Gf + lam I + mu Diff' Diff)^{-1} Gf' W`` (dense, O(N^3))."""
        o = self.options
        gf = lifted_operator(markov_parameters(self.target.nominal.G_f, self.n))
        diff = np.eye(self.n) - np.eye(self.n, k=-1)
        h = o.weight * gf.T @ gf + o.lam * np.eye(self.n) + o.mu * diff.T @ diff
        return np.linalg.solve(h, o.weight * gf.T)

    def lifted_matrices(self, source: LoopSystem, regularisation: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
        """Lifted learning matrices ``(L1, L2)``: ``d_f,j = L1 e_{j-1} + L2 d_f,{j-1}``.

        ``L1 = F Gd_j Gd_{j-1}^+`` (``e0 = -Gd_j d_rec``, ``d_rec = -Gd_{j-1}^+ e'``) with ``F`` the
        solution matrix and ``Gd_{j-1}^+`` the
        regularised inverse of :func:`~ilcdob.design.maps.lifted_filters.regularised_inverse`;
        ``L2 = L1 Gf_{j-1}``. Dense, O(N^3) time and about :data:`LIFTED_PEAK_MATRICES` N x N
        matrices of memory: for export and checks at moderate N (:meth:`law` is the same map
        in O(N)).

        Parameters
        ----------
        source : LoopSystem
            System j-1 (its model is used).
        regularisation : float
            Relative Tikhonov weight of the inverse of ``Gd_{j-1}``, > 0.

        Returns
        -------
        L1, L2 : numpy.ndarray
            N x N learning matrices.
        """
        from ..maps.lifted_filters import regularised_inverse

        src = source.nominal
        n = self.n
        gd_prev_inv, _, _ = regularised_inverse(markov_parameters(src.G_d, n), regularisation)
        gd_j = lifted_operator(markov_parameters(self.target.nominal.G_d, n))
        l1 = self.solution_matrix() @ (gd_j @ gd_prev_inv)
        l2 = l1 @ lifted_operator(markov_parameters(src.G_f, n))
        return l1, l2

    def law(self, source: LoopSystem, regularisation: float = 1e-12) -> NormOptimalLaw:
        """The learning law of :meth:`lifted_matrices` in compact form (O(N n) memory and time).

        Parameters
        ----------
        source : LoopSystem
            System j-1 (its model is used).
        regularisation : float
            Relative Tikhonov weight of the inverse of ``Gd_{j-1}``, > 0 (as in
            :meth:`lifted_matrices`).

        Returns
        -------
        NormOptimalLaw
            ``law.apply(e, d_f)`` equals ``L1 @ e + L2 @ d_f`` to rounding.

        Raises
        ------
        SpecError
            ``regularisation`` not > 0.
        NumericalError
            The largest singular value of the lifted ``Gd_{j-1}`` could not be found.
        """
        if isinstance(regularisation, bool) or not (isinstance(regularisation, (int, float)) and regularisation > 0
                                                    and math.isfinite(regularisation)):
            raise SpecError(f"`regularisation`: got {regularisation!r}, expected a number > 0")
        src = source.nominal
        n = self.n
        gd_prev = _state_space(src.G_d)
        a, b, c, _ = gd_prev
        impulse = np.zeros(n)
        impulse[0] = 1.0
        h = _simulate(gd_prev, impulse)  # Markov parameters of Gd_{j-1} over the trial
        m = relative_degree(h)
        # the shifted map h[m], h[m+1], ...: (A, b, c A^m, h[m])
        inverse = (a, b, c @ np.linalg.matrix_power(a, m), float(h[m]))
        alpha = float(regularisation) * _top_eigenvalue(inverse, h[m:])
        inv_gains, inv_pivots = _lq_gains(inverse, 1.0, alpha, 0.0, n - m)
        o = self.options
        return NormOptimalLaw(n=n, shift=m, regularisation=float(regularisation), alpha=alpha,
                              source_gf=_state_space(src.G_f), inverse=inverse, inverse_gains=inv_gains,
                              inverse_pivots=inv_pivots, target_gd=_state_space(self.target.nominal.G_d),
                              target_gf=self._system, weight=o.weight, lam=o.lam, mu=o.mu,
                              gains=self.gains, pivots=self.pivots)


#: Names of the arrays of :meth:`NormOptimalLaw.to_arrays` (besides the four matrices of each map).
_MAPS = ("source_gf", "inverse", "target_gd", "target_gf")
_SCALARS = ("n", "shift", "regularisation", "alpha", "weight", "lam", "mu")
_GAINS = ("inverse_gains", "inverse_pivots", "gains", "pivots")


@dataclass(frozen=True)
class NormOptimalLaw:
    """The norm-optimal learning law ``d_f,j = L1 e_{j-1} + L2 d_f,{j-1}`` without N x N matrices.

    Made by :meth:`NormOptimalDesigner.law`; written to ``lifted.npz`` by ``ilcdob design
    --method norm-optimal`` (:meth:`to_arrays`) and read back with :meth:`from_arrays`.
    :meth:`apply` runs, in O(N n)::

        e'  = e + Gf_{j-1}{d_f,{j-1}}                       (error without learning)
        x   = argmin ||Hs x - e'[m:]||^2 + alpha ||x||^2     (Gd_{j-1}^+ e', then m zeros)
        e0  = Gd_j{x}
        d_f = argmin J(d_f; e0)                              (module docstring)

    where ``Hs`` is the lifted ``Gd_{j-1}`` with its relative degree ``m`` shifted out (the map
    ``inverse``); both minimisations are the LQ recursion with the stored gains and pivots.
    Each map is ``(A, b, c, d)``: ``x+ = A x + b u``, ``y = c x + d u``, from rest.

    Attributes
    ----------
    n : int
        Trial length, samples.
    shift : int
        Relative degree ``m`` of ``Gd_{j-1}``, samples.
    regularisation, alpha : float
        Relative Tikhonov weight and ``alpha = regularisation * sigma_max(Hs)^2``.
    source_gf, inverse, target_gd, target_gf : tuple
        ``(A, b, c, d)`` of ``Gf_{j-1}``, the shifted ``Gd_{j-1}``, ``Gd_j`` and ``Gf_j``.
    weight, lam, mu : float
        Weights of the norm-optimal cost.
    inverse_gains, inverse_pivots : numpy.ndarray
        Gains ((n - m) x (order + 1)) and pivots of the regularised inverse.
    gains, pivots : numpy.ndarray
        Gains (n x (order + 1)) and pivots of the norm-optimal problem.
    """

    n: int
    shift: int
    regularisation: float
    alpha: float
    source_gf: _System
    inverse: _System
    inverse_gains: np.ndarray
    inverse_pivots: np.ndarray
    target_gd: _System
    target_gf: _System
    weight: float
    lam: float
    mu: float
    gains: np.ndarray
    pivots: np.ndarray

    def __repr__(self) -> str:
        return (f"<NormOptimalLaw {self.n} samples, shift {self.shift}, {self.gains.shape[1]} + "
                f"{self.inverse_gains.shape[1]} gains per sample, {self.nbytes / 1e6:.3g} MB>")

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays."""
        return sum(int(np.asarray(v).nbytes) for v in self.to_arrays().values())

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """The learning signal of system j from a trial of system j-1.

        Parameters
        ----------
        e_prev : array_like
            Tracking error of system j-1, m, ``n`` samples.
        df_prev : array_like
            Learning signal system j-1 flew with, m/s^2, ``n`` samples.

        Returns
        -------
        numpy.ndarray
            ``d_f,j = L1 e_{j-1} + L2 d_f,{j-1}``, m/s^2.
        """
        e = as_signal(e_prev, "e_prev", self.n)
        df = as_signal(df_prev, "df_prev", self.n)
        e_no = e + _simulate(self.source_gf, df)
        m = self.shift
        x = np.zeros(self.n)
        x[: self.n - m] = _lq_solve(self.inverse, self.inverse_gains, self.inverse_pivots,
                                    -e_no[m:], -self.inverse[3] * e_no[m:])
        e0 = _simulate(self.target_gd, x)
        w = self.weight
        return _lq_solve(self.target_gf, self.gains, self.pivots, -w * e0, -w * self.target_gf[3] * e0)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Its content as named arrays (``numpy.savez``): scalars, ``<map>_A/_B/_C/_D`` and the gains."""
        out: dict[str, np.ndarray] = {k: np.asarray(getattr(self, k)) for k in _SCALARS}
        for name in _MAPS:
            for key, value in zip("ABCD", getattr(self, name)):
                out[f"{name}_{key}"] = np.asarray(value, dtype=float)
        out.update({k: getattr(self, k) for k in _GAINS})
        return out

    @classmethod
    def from_arrays(cls, arrays: Any, what: str = "lifted.npz") -> NormOptimalLaw:
        """Read a law written by :meth:`to_arrays` (e.g. ``numpy.load("lifted.npz")``).

        Parameters
        ----------
        arrays : mapping of str -> array
            The arrays.
        what : str
            Where they come from, for messages.

        Returns
        -------
        NormOptimalLaw

        Raises
        ------
        SpecError
            A missing array, one of the wrong shape, or values that are not finite numbers.
        """
        names = [*_SCALARS, *(f"{m}_{k}" for m in _MAPS for k in "ABCD"), *_GAINS]
        missing = [k for k in names if k not in arrays]
        if missing:
            raise SpecError(f"{what}: no norm-optimal law in it (missing {missing[:4]}); write it with "
                            "`ilcdob design --method norm-optimal` or NormOptimalLaw.to_arrays")
        got = {}
        for k in names:
            try:
                got[k] = np.asarray(arrays[k], dtype=float)
            except (TypeError, ValueError) as exc:
                raise SpecError(f"{what}: `{k}` is not numeric ({exc})") from None
            if not np.all(np.isfinite(got[k])):
                raise SpecError(f"{what}: `{k}` holds values that are not finite numbers")
        bad = [k for k in _SCALARS if got[k].shape != ()]
        if bad:
            raise SpecError(f"{what}: {bad} must be single numbers; got shapes {[got[k].shape for k in bad]}")
        scal = {k: float(got[k]) for k in _SCALARS}
        n, m = int(scal["n"]), int(scal["shift"])
        if n != scal["n"] or m != scal["shift"] or n < 2 or not 0 <= m < n:
            raise SpecError(f"{what}: `n` {scal['n']!r} and `shift` {scal['shift']!r}: expected whole numbers "
                            "with n >= 2 and 0 <= shift < n")
        maps = {}
        for name in _MAPS:
            a, b, c, d = (got[f"{name}_{k}"] for k in "ABCD")
            nx = a.shape[0] if a.ndim == 2 else -1
            if a.shape != (nx, nx) or b.shape != (nx,) or c.shape != (nx,) or d.shape != ():
                raise SpecError(f"{what}: `{name}` has A {a.shape}, B {b.shape}, C {c.shape}, D {d.shape}; "
                                "expected n x n, n, n and a scalar")
            maps[name] = (a, b, c, float(d))
        for prefix, rows, sys in (("inverse_", n - m, maps["inverse"]), ("", n, maps["target_gf"])):
            g, p = got[f"{prefix}gains"], got[f"{prefix}pivots"]
            if g.shape != (rows, sys[0].shape[0] + 1) or p.shape != (rows,):
                raise SpecError(f"{what}: `{prefix}gains` {g.shape} and `{prefix}pivots` {p.shape}; expected "
                                f"({rows}, {sys[0].shape[0] + 1}) and ({rows},) for {n} samples, shift {m}")
            if np.any(p <= 0):
                raise SpecError(f"{what}: `{prefix}pivots` must be > 0 (they divide each step's optimum); "
                                f"got {float(np.min(p))!r}")
        return cls(n=n, shift=m, regularisation=scal["regularisation"], alpha=scal["alpha"], weight=scal["weight"],
                   lam=scal["lam"], mu=scal["mu"], inverse_gains=got["inverse_gains"],
                   inverse_pivots=got["inverse_pivots"], gains=got["gains"], pivots=got["pivots"], **maps)


def norm_optimal_learning(source: LoopSystem, target: LoopSystem, e_prev: object, df_prev: object,
                          options: NormOptimalOptions | None = None) -> np.ndarray:
    """Learning signal of ``target`` from a flight of ``source`` (nominal norm-optimal design).

    ``e0 = -Gd_j{d_rec}``, ``d_rec = reconstruct_disturbance(source, e_prev, df_prev)``; then the
    Riccati solution of :class:`NormOptimalDesigner`.

    Parameters
    ----------
    source : LoopSystem
        System j-1, which flew (its model is used for the reconstruction).
    target : LoopSystem
        System j, the learning system (its model's ``G_d`` and ``G_f`` are used).
    e_prev : array_like
        Tracking error of system j-1 over the trial, m.
    df_prev : array_like
        Learning signal system j-1 flew with, m/s^2 (zeros if none), same length.
    options : NormOptimalOptions, optional
        Weights of the cost.

    Returns
    -------
    numpy.ndarray
        ``d_f,j``, m/s^2, same length as ``e_prev``.
    """
    e_prev = as_signal(e_prev, "e_prev")
    d_rec = reconstruct_disturbance(source, e_prev, df_prev)
    e0 = -simulate_map(target.nominal.G_d, d_rec)
    return NormOptimalDesigner(target, e_prev.size, options).solve(e0)
