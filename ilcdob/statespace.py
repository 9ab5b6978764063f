"""Simulating a discrete LTI state-space system over a trial, in compiled code.

The recursion of a realisation ``(A, B, C, D)`` from a state ``x[0]`` (rest by default)::

    y[k]     = C x[k] + D u[k]
    x[k + 1] = A x[k] + B u[k]

is what :func:`simulate` computes, to the accuracy of that recursion evaluated sample by sample
in double precision, without a Python loop over the samples:

1. **Schur solve.** ``A = Z T Z^T`` with ``T`` quasi upper triangular (real Schur form,
   orthogonal ``Z``: backward stable, and well defined for repeated or clustered poles, such as
   the ``q_order``-fold pole of a DOB's Q filter, where a diagonalisation is not). In the
   coordinates ``Z^T x`` the states are computed from the last up, each driven by the input and
   by the later states, already known (one matrix product over the trial): a 1 x 1 block of
   ``T`` is a first-order recursion, a 2 x 2 block (a complex pole pair) a second-order one on
   its characteristic polynomial, one ``scipy.signal.lfilter`` call each. O(n^2 N) operations,
   all in BLAS and lfilter.
2. **Refinement.** The Schur solve is exact for a matrix within rounding of ``A``, which is not
   enough at fast sampling: the nearly defective cluster of a high-order Q filter about
   ``Ts/tau`` from ``z = 1`` turns that backward error into output errors of ~1e-9 of the peak
   (``Ts`` = 1 ms, ``q_order`` 8; a second-order section's coefficients lose as much for a pole
   pair near 1). The defect ``r[k] = A x[k] + B u[k] - x[k + 1]`` of the computed states is
   therefore evaluated in the realisation's own coordinates, and the correction, which obeys the
   same recursion driven by ``r``, is solved for and added (iterative refinement). A pass
   multiplies the error by the solve's relative error (~1e-9 on the hardest loops measured),
   so one pass leaves only the rounding of the defect itself: the accuracy of the plain
   recursion (on the built-in fleet and the stress loops, trials up to 3e5 samples, as close
   to an 80-bit recursion as the plain double one: docs/performance.md). Passes repeat while the correction exceeds
   :data:`REFINE_RTOL` of the largest state, at most :data:`MAX_REFINE` times; if it has not
   settled then (never seen on a stable system), the chunk is computed by the plain recursion,
   a Python loop: slow, but the same result.

When the matrices are products of a model's blocks (an interconnection: a plant closed by a
controller), their rounding makes a slightly different system than the blocks stepped one by
one, and a signal that is a small difference of large ones (a DOB's estimate ``M{y} - Q{u2}``)
shows it (1.5e-12 of its peak, measured at 1 ms). The caller then passes the model's own step
(``evaluate``): the defects and the outputs are computed by it, and the refinement converges to
the trajectory of the model as stepped; the matrices only serve the solve.

Above :data:`DENSE_MAX_STATES` states (long delay lines at fast sampling) the O(n^2) work per
sample of the solve exceeds that of the plain recursion, which then runs instead (a loop over
the samples, one matrix-vector product each: the sample-by-sample result itself); not with a
model's own step, which costs more per sample in Python than the solve.

Long trials run in chunks of about :data:`CHUNK_ENTRIES` state samples, the state carried
from one chunk to the next exactly (the chunks stay in cache; memory O(n L)), with BLAS on one
thread (its threads only add wake-ups to products of n rows). The Schur forms of the last few
realisations are kept: a design simulates the same map many times.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Callable

import numpy as np
from scipy.linalg import schur
from scipy.signal import lfilter
from threadpoolctl import ThreadpoolController

from .errors import SignalError, SpecError

__all__ = ["simulate", "Evaluate", "REFINE_RTOL", "MAX_REFINE", "DENSE_MAX_STATES", "CHUNK_ENTRIES"]

#: A refinement pass is repeated while its correction exceeds this fraction of the largest state
#: (the error left after a pass is about the square of the relative correction).
REFINE_RTOL = 1e-7
#: Most refinement passes on one chunk before the plain recursion takes over.
MAX_REFINE = 4
#: Largest state dimension for the Schur solve: its O(n^2) work per sample exceeds the plain recursion's
#: per-sample cost above about this size (measured, benchmarks/bench_loops.py), which then runs instead.
DENSE_MAX_STATES = 50
#: State samples (states x samples) per chunk of a long trial, and the fewest samples per chunk.
CHUNK_ENTRIES = 1 << 16
MIN_CHUNK = 4096
#: Rows of T per group of the Schur solve: the coupling from later groups is one matrix product.
_GROUP = 16
_ONE = np.ones(1)


class _Schur:
    """Real Schur form of ``A`` and the solve of module docstring step 1."""

    def __init__(self, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> None:
        self.t, self.z = schur(a, output="real")
        self.zt = np.ascontiguousarray(self.z.T)
        self.bz = self.zt @ b  # B and C in Schur coordinates
        self.cz = c @ self.z
        n = a.shape[0]
        #: (first row, 2 x 2?) of each diagonal block of T, last first
        self.blocks: list[tuple[int, bool]] = []
        i = n - 1
        while i >= 0:
            pair = i > 0 and self.t[i, i - 1] != 0.0
            self.blocks.append((i - 1, True) if pair else (i, False))
            i -= 2 if pair else 1
        #: the blocks in groups of about _GROUP rows (last first): (first row, end row, blocks), each block
        #: (first row, None) for 1 x 1, or (first row, FIR map) for 2 x 2, with its lfilter denominator
        self.groups: list[tuple[int, int, list[tuple[int, np.ndarray | None, np.ndarray]]]] = []
        for i, pair in self.blocks:
            if pair:
                (t11, t12), (t21, t22) = self.t[i:i + 2, i:i + 2]
                block = (i, np.array([[-t22, t12], [t21, -t11]]), np.array([1.0, -(t11 + t22), t11 * t22 - t12 * t21]))
            else:
                block = (i, None, np.array([1.0, -self.t[i, i]]))
            if not self.groups or self.groups[-1][1] - i > _GROUP:
                self.groups.append((i, i + 2 if pair else i + 1, []))
            self.groups[-1] = (i, self.groups[-1][1], self.groups[-1][2] + [block])

    def solve(self, drive: np.ndarray) -> np.ndarray:
        """``s[1..L]`` (n x L) of ``s[k + 1] = T s[k] + drive[:, k]`` from ``s[0] = 0`` (Schur coordinates;
        ``drive`` is overwritten)."""
        t = self.t
        n = drive.shape[0]
        s = np.empty_like(drive)
        for g0, g1, members in self.groups:
            if g1 < n:  # the later groups, known, drive this one one sample later (one matrix product)
                drive[g0:g1, 1:] += (t[g0:g1, g1:] @ s[g1:])[:, :-1]
            for i, fir, den in members:
                if fir is None:
                    dr = drive[i]
                    if i + 1 < g1:  # and the later states of the group
                        dr[1:] += (t[i, i + 1:g1] @ s[i + 1:g1])[:-1]
                    s[i] = lfilter(_ONE, den, dr)
                    continue
                dr = drive[i:i + 2]
                if i + 2 < g1:
                    dr[:, 1:] += (t[i:i + 2, i + 2:g1] @ s[i + 2:g1])[:, :-1]
                # (z - T_b) S = W: S_1 = ((z - t22) W_1 + t12 W_2)/det, S_2 = (t21 W_1 + (z - t11) W_2)/det
                v = dr.copy()
                v[:, 1:] += fir @ dr[:, :-1]
                s[i:i + 2] = lfilter(_ONE, den, v, axis=1)
        return s


@lru_cache(maxsize=1)
def _blas_controller() -> ThreadpoolController:
    return ThreadpoolController()


@lru_cache(maxsize=32)
def _schur_cached(a: bytes, b: bytes, c: bytes, n: int, m: int, p: int) -> _Schur:
    return _Schur(np.frombuffer(a).reshape(n, n), np.frombuffer(b).reshape(n, m), np.frombuffer(c).reshape(p, n))


def _schur(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> _Schur:
    """The Schur form of a realisation, kept for the last few (a design simulates the same map many times)."""
    a, b, c = (np.ascontiguousarray(x, dtype=float) for x in (a, b, c))
    return _schur_cached(a.tobytes(), b.tobytes(), c.tobytes(), a.shape[0], b.shape[1], c.shape[0])


def _product(b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``b @ u`` (for one input a broadcast product: a matrix product of inner size 1 is several times slower)."""
    return b * u if b.shape[1] == 1 else b @ u


#: ``evaluate(x, u) -> (x_next, y)`` for a run of samples (columns): the model's own arithmetic.
Evaluate = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def _plain(a: np.ndarray, b: np.ndarray, u: np.ndarray, x0: np.ndarray, evaluate: Evaluate | None) -> np.ndarray:
    """``x[1..L]`` by the recursion sample by sample (the large-``n`` path and the last resort)."""
    x = np.empty((a.shape[0], u.shape[1]))
    prev = x0
    if evaluate is None:
        w = _product(b, u)
        for k in range(u.shape[1]):
            prev = x[:, k] = a @ prev + w[:, k]
    else:
        for k in range(u.shape[1]):
            prev = x[:, k] = evaluate(prev[:, None], u[:, k:k + 1])[0][:, 0]
    return x


def _previous(x: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """``x[0..L-1]`` from ``x[1..L]`` and ``x[0]``."""
    prev = np.empty_like(x)
    prev[:, 0] = x0
    prev[:, 1:] = x[:, :-1]
    return prev


def _outputs(c: np.ndarray, d: np.ndarray, u: np.ndarray, x: np.ndarray, x0: np.ndarray,
             evaluate: Evaluate | None) -> np.ndarray:
    """``y[0..L-1]`` from the states ``x[1..L]`` and ``x[0]``."""
    if evaluate is not None:
        return evaluate(_previous(x, x0), u)[1]
    y = _product(d, u)
    y[:, 0] += c @ x0
    y[:, 1:] += (c @ x)[:, :-1]
    return y


def _chunk(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, form: _Schur, u: np.ndarray,
           x0: np.ndarray, evaluate: Evaluate | None) -> tuple[np.ndarray, np.ndarray]:
    """``y[0..L-1]`` (p x L) and ``x[L]`` of one chunk from ``x[0] = x0`` (module docstring)."""
    at_rest = not np.any(x0)
    if at_rest:
        x = form.z @ form.solve(_product(form.bz, u))
    else:  # the initial state as an impulse one sample earlier
        x = form.z @ form.solve(np.hstack([(form.zt @ x0)[:, None], _product(form.bz, u)]))[:, 1:]
    w = _product(b, u) if evaluate is None else None
    for _ in range(MAX_REFINE):
        # r[k] = A x[k] + B u[k] - x[k + 1], with x[0] = x0 exactly
        if evaluate is None:
            ax = a @ x
            defect = w - x
            defect[:, 1:] += ax[:, :-1]
            if not at_rest:
                defect[:, 0] += a @ x0
        else:
            defect = evaluate(_previous(x, x0), u)[0] - x
        corr = form.solve(form.zt @ defect)  # Schur coordinates
        size = float(np.max(np.abs(corr)))
        if size <= REFINE_RTOL * float(np.max(np.abs(x))):
            if evaluate is None:  # C (x + Z corr) without forming x + Z corr
                cx = c @ x + form.cz @ corr
                y = _product(d, u)
                y[:, 0] += c @ x0
                y[:, 1:] += cx[:, :-1]
                return y, x[:, -1] + form.z @ corr[:, -1]
            x += form.z @ corr
            return _outputs(c, d, u, x, x0, evaluate), x[:, -1]
        if not np.isfinite(size):
            break
        x += form.z @ corr
    x = _plain(a, b, u, x0, evaluate)
    return _outputs(c, d, u, x, x0, evaluate), x[:, -1]


def _matrix(value: object, name: str, shape: tuple[int, int], what: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim < 2 and arr.size == shape[0] * shape[1] and 1 in shape:  # a vector (a number) for one input/output
        arr = arr.reshape(shape)
    if arr.shape != shape:
        raise SpecError(f"`{name}`: got shape {arr.shape}, expected {shape} ({what}); give A (n x n), "
                        "B (n x m), C (p x n), D (p x m) for n states, m inputs, p outputs")
    if not np.all(np.isfinite(arr)):
        raise SpecError(f"`{name}`: has non-finite entries; give a realisation with finite matrices")
    return arr


def simulate(a: object, b: object, c: object, d: object, u: object, x0: object | None = None,
             evaluate: Evaluate | None = None) -> np.ndarray:
    """Outputs of a discrete LTI system over a trial: ``y[k] = C x[k] + D u[k]``, ``x[k+1] = A x[k] + B u[k]``.

    Compiled: a Schur solve with a refinement pass (module docstring); the result is that of
    the sample-by-sample recursion to its own rounding (about 1e-14 of the peak).

    Parameters
    ----------
    a, b, c, d : array_like
        The realisation: ``A`` (n x n), ``B`` (n x m), ``C`` (p x n), ``D`` (p x m). With one
        input, ``b`` may be a vector of n entries; with one output, ``c`` and ``d`` may be vectors
        (``d`` a number with one input too).
    u : array_like
        Inputs, ``m x N`` (one row per input, one column per sample); a 1-D array of ``N``
        samples for a single input.
    x0 : array_like, optional
        State at sample 0, n entries (default: rest, all zero).
    evaluate : callable, optional
        ``evaluate(x, u) -> (x_next, y)``: the step and the outputs for a run of samples
        (``x`` n x L, ``u`` m x L; ``x_next`` n x L, ``y`` p x L) computed by the model's own
        equations, when the matrices are products of its blocks (an interconnection): the
        defects and the outputs are then evaluated as the model computes them, so that the
        result is that of stepping the model (module docstring, step 2), not of the rounded
        products. Default: the matrices' products.

    Returns
    -------
    numpy.ndarray
        Outputs, ``p x N``.

    Raises
    ------
    SpecError
        A matrix of the wrong shape or with a non-finite entry.
    SignalError
        ``u`` or ``x0`` of the wrong shape or with a non-finite value.

    Examples
    --------
    >>> from ilcdob.statespace import simulate
    >>> simulate([[0.5]], [[1.0]], [[1.0]], [[0.0]], [1.0, 0.0, 0.0, 0.0])
    array([[0.  , 1.  , 0.5 , 0.25]])
    """
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise SpecError(f"`a`: got shape {a.shape}, expected a square matrix (n x n for n states)")
    n = a.shape[0]
    a = _matrix(a, "a", (n, n), "n x n")
    u_arr = np.asarray(u, dtype=float)
    if u_arr.ndim == 1:
        u_arr = u_arr.reshape(1, -1)
    if u_arr.ndim != 2:
        raise SignalError(f"`u`: got shape {u_arr.shape}, expected inputs x samples (2-D) or one input's samples (1-D)")
    m, length = u_arr.shape
    if not np.all(np.isfinite(u_arr)):
        row, col = (int(i[0]) for i in np.nonzero(~np.isfinite(u_arr)))
        raise SignalError(f"`u`: non-finite value {float(u_arr[row, col])!r} at sample {col} of input {row}")
    b = _matrix(b, "b", (n, m), f"{n} states x {m} inputs, from u")
    c_shape = np.shape(c)
    p = c_shape[0] if len(c_shape) == 2 else 1
    c = _matrix(c, "c", (p, n), f"{p} outputs x {n} states")
    d = _matrix(d, "d", (p, m), f"{p} outputs x {m} inputs")
    state = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    if state.shape != (n,) or not np.all(np.isfinite(state)):
        raise SignalError(f"`x0`: got {np.asarray(x0)!r}, expected {n} finite state values (a 1-D array)")
    if evaluate is not None and not callable(evaluate):
        raise SpecError(f"`evaluate`: got {type(evaluate).__name__}, expected a callable (x, u) -> (x_next, y)")
    if length == 0:
        return np.zeros((p, 0))
    if n == 0:
        return _product(d, u_arr) if evaluate is None else evaluate(np.zeros((0, length)), u_arr)[1]
    if n > DENSE_MAX_STATES and evaluate is None:
        return _outputs(c, d, u_arr, _plain(a, b, u_arr, state, evaluate), state, evaluate)
    # the matrix products are small (n rows): BLAS threads only add wake-ups, up to 20 times the CPU
    # time on a loaded machine (measured at 22 states), so the trial runs single-threaded
    with _blas_controller().limit(limits=1, user_api="blas"):
        form = _schur(a, b, c)
        chunk = max(MIN_CHUNK, CHUNK_ENTRIES // n)
        y = np.empty((p, length))
        for k0 in range(0, length, chunk):
            k1 = min(k0 + chunk, length)
            y[:, k0:k1], state = _chunk(a, b, c, d, form, u_arr[:, k0:k1], state, evaluate)
    return y
