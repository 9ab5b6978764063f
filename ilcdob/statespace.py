"""Simulating a discrete LTI state-space system over a trial, in compiled code.

The recursion of a realisation ``(A, B, C, D)`` from a state ``x[0]`` (rest by default)::

    y[k]     = C x[k] + D u[k]
    x[k + 1] = A x[k] + B u[k]

is what :func:`simulate` computes, to the accuracy of that recursion evaluated sample by sample
in double precision, without a Python loop over the samples. The trial is cut into ``J`` blocks
of ``L`` samples (``L`` about the square root of the trial's length, less with a model's own
step) and the recursion runs in all blocks at once:

1. **Block starts.** The state at the start of block ``j + 1`` is ``A^L s[j] + e[j]``, ``e[j]``
   the response of the block's inputs from rest, ``Gamma u_j`` with ``Gamma = [A^(L-1) B, ...,
   A B, B]`` (one matrix product over the trial); the starts ``s[j]`` follow by a scan over the
   ``J`` blocks, from ``s[0] = x[0]`` exactly (itself in the same two levels: groups of blocks,
   their starts from powers of ``A^L``, then the steps in all groups at once).
2. **Recursion.** From those starts the recursion itself runs ``L`` steps, each step one matrix
   product ``[A B; C D] [x; u]`` for the ``J`` blocks together (a Python loop of ``L`` BLAS
   calls instead of ``N`` small ones): within a block the states and outputs are the
   sample-by-sample recursion's, with its rounding. States that only copy another state (the
   shift registers of a delay line: a row of ``[A B]`` with a single entry, 1) are copied
   instead of multiplied, and the product has only the columns the other rows use.
3. **Refinement.** The powers of ``A`` are rounded differently from the recursion (more so for
   the nearly defective cluster of a high-order Q filter about ``Ts/tau`` from ``z = 1``), and
   with a model's own step (below) they are not even the same system's, so the block starts
   are not exactly where the recursion of the previous block ends (without this step the
   outputs were off by up to 3e-13 of the peak for eight poles at 0.993, and a DOB estimate by
   1.8e-12 with the 1 ms, ``q_order`` 8 loops' own step). Those defects
   ``r[j] = x_end[j] - s[j + 1]`` are the only ones (within a block the recursion holds to its
   rounding); the correction they drive obeys the same block recursion,
   ``ds[j + 1] = A^L ds[j] + r[j]``, ``ds[0] = 0`` (a scan), and changes the outputs of block
   ``j`` by ``C A^i ds[j]`` (one matrix product over the trial). When the correction is at most
   :data:`REFINE_RTOL` of the largest state it is applied so (its own relative error, that of
   the powers, then leaves below ``REFINE_RTOL`` times that: far below the recursion's
   rounding); otherwise the recursion runs again from the corrected starts (step 2), at most
   :data:`MAX_REFINE` times. If it has not settled then (an unstable system whose powers
   overflow), the chunk is computed by the plain recursion, a Python loop: slow, but the same
   result. The result is the recursion with a defect of the powers' rounding times the
   correction's relative size at each block boundary: on the built-in fleet and the stress
   loops (trials up to 3e5 samples) within a few 1e-14 of the peak of an 80-bit recursion, as
   the plain double one is (docs/performance.md).

When the matrices are products of a model's blocks (an interconnection: a plant closed by a
controller), their rounding makes a slightly different system than the blocks stepped one by
one, and a signal that is a small difference of large ones (a DOB's estimate ``M{y} - Q{u2}``)
shows it (1.5e-12 of its peak, measured at 1 ms). The caller then passes the model's own step
(``evaluate``): step 2 runs it (for all blocks at once) instead of the matrices, so the states
and outputs are those of the model as stepped; the matrices only serve steps 1 and 3, whose
results the refinement makes consistent with that step.

Long trials run in chunks of about :data:`CHUNK_ENTRIES` input and output samples, the state
carried from one chunk to the next, with BLAS on one thread (its threads only add wake-ups to
products of n rows). The block forms of the last few realisations are kept: a design simulates
the same map many times.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Callable

import numpy as np
from threadpoolctl import ThreadpoolController

from .errors import SignalError, SpecError

__all__ = ["simulate", "Evaluate", "REFINE_RTOL", "MAX_REFINE", "CHUNK_ENTRIES"]

#: The correction of the block starts is applied in closed form when it is at most this fraction of the
#: largest state; otherwise the recursion runs again from the corrected starts.
REFINE_RTOL = 1e-7
#: Most runs of the recursion on one chunk before the plain recursion takes over.
MAX_REFINE = 4
#: Input and output samples (rows x samples) per chunk of a long trial.
CHUNK_ENTRIES = 1 << 20
#: Block length L about sqrt(scale x chunk length), a power of two, with the matrices' product and with a
#: model's own step (fastest measured: UAV1 and the stress loops, N = 3000 and 1e5, benchmarks/bench_loops.py).
_SPAN_SCALE, _SPAN_SCALE_EVALUATE = 1.0, 1.0 / 32.0


class _Blocks:
    """The block form of a realisation for blocks of ``span`` samples (module docstring)."""

    def __init__(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, span: int) -> None:
        n, m = b.shape
        p = c.shape[0]
        self.n, self.m, self.p, self.span = n, m, p, span
        ab = np.hstack([a, b])
        # shift rows: x_i[k + 1] = x_j[k] exactly (one entry in the row of [A B], a 1 at a state)
        nonzero = ab != 0
        src = np.argmax(nonzero[:, :n], axis=1)
        shift = (nonzero.sum(axis=1) == 1) & (ab[np.arange(n), src] == 1.0)
        rows = np.vstack([ab[~shift], np.hstack([c, d])])  # the rows multiplied: the others, then C D
        used = np.any(rows[:, :n] != 0, axis=0)
        general = np.flatnonzero(~shift)
        #: states permuted: the multiplied rows, the copied ones whose state is used, the other copied
        self.order = np.concatenate([general, np.flatnonzero(shift & used), np.flatnonzero(shift & ~used)])
        self.back = np.argsort(self.order)
        self.g = general.size
        self.k = m + self.g + int(np.sum(shift & used))  # columns of the product: [u; x_order[:k - m]]
        self.step = np.ascontiguousarray(rows[:, np.concatenate([n + np.arange(m), self.order[:self.k - m]])])
        self.src = m + self.back[src[self.order[self.g:]]]  # where the copied states come from in [u; x]
        # the powers: P = A^L, Gamma = [A^(L-1) B, ..., B] (n x L m), O = [C; C A; ...; C A^(L-1)] (L p x n)
        with np.errstate(over="ignore", invalid="ignore"):
            self.power = np.linalg.matrix_power(a, span)
            gamma = np.empty((n, span * m))
            obs = np.empty((span * p, n))
            ab_k, ca_k = b, c
            for i in range(span):
                gamma[:, (span - 1 - i) * m:(span - i) * m] = ab_k
                obs[i * p:(i + 1) * p] = ca_k
                if i + 1 < span:
                    ab_k, ca_k = a @ ab_k, ca_k @ a
        self.gamma, self.obs = gamma, obs
        self._group_powers: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # of the scan over the blocks

    def scan(self, start: np.ndarray, drive: np.ndarray) -> np.ndarray:
        """``s[0] = start``, ``s[j + 1] = P s[j] + drive[:, j]`` with ``P = A^L``: n x (columns of drive + 1).

        The same two levels as the trial's: the scan's steps in groups of G, the groups' starts from
        ``P^G`` and ``[P^(G-1), ..., P, I]`` (one product), then the G steps in all groups at once."""
        n, count = self.n, drive.shape[1]
        if count == 0:
            return np.array(start, dtype=float).reshape(n, 1)
        group = 1 << max(0, int(round(0.5 * np.log2(count))))
        if group not in self._group_powers:
            stack = np.empty((n, group * n))  # [P^(G-1), ..., P, I]
            power_k = np.eye(n)
            for i in range(group):
                stack[:, (group - 1 - i) * n:(group - i) * n] = power_k
                power_k = self.power @ power_k
            self._group_powers[group] = (power_k, stack)
        power_group, stack = self._group_powers[group]
        groups = -(-count // group)
        padded = np.zeros((n, groups * group))
        padded[:, :count] = drive
        steps = np.ascontiguousarray(padded.reshape(n, groups, group).transpose(2, 0, 1))  # [i, :, j]: step j G + i
        ends = stack @ steps.reshape(group * n, groups)
        heads = np.empty((n, groups))
        prev = heads[:, 0] = start
        for j in range(groups - 1):
            prev = heads[:, j + 1] = power_group @ prev + ends[:, j]
        s = np.empty((group, n, groups))
        x = heads
        for i in range(group):
            x = s[i] = self.power @ x + steps[i]
        out = np.empty((n, count + 1))
        out[:, 0] = start
        out[:, 1:] = s.transpose(1, 2, 0).reshape(n, groups * group)[:, :count]
        return out

    def run(self, starts: np.ndarray, u: np.ndarray, evaluate: Evaluate | None) -> tuple[np.ndarray, np.ndarray]:
        """The recursion over the blocks from their ``starts`` (n x J), inputs ``u`` (L x m x J):
        outputs (L x p x J) and the states at the blocks' ends (n x J)."""
        m, p, g = self.m, self.p, self.g
        y = np.empty((u.shape[0], p, u.shape[2]))
        if evaluate is not None:
            x = starts
            for i in range(u.shape[0]):
                x, y[i] = evaluate(x, u[i])
            return y, x
        z, nxt = np.empty((m + self.n, u.shape[2])), np.empty((m + self.n, u.shape[2]))  # [u; x permuted]
        z[m:] = starts[self.order]
        out = np.empty((g + p, u.shape[2]))
        step, k, src = self.step, self.k, self.src
        for i in range(u.shape[0]):
            z[:m] = u[i]
            np.dot(step, z[:k], out=out)
            y[i] = out[g:]
            nxt[m:m + g] = out[:g]
            if src.size:
                z.take(src, axis=0, out=nxt[m + g:])
            z, nxt = nxt, z
        return y, z[m:][self.back]


@lru_cache(maxsize=1)
def _blas_controller() -> ThreadpoolController:
    return ThreadpoolController()


@lru_cache(maxsize=32)
def _blocks_cached(a: bytes, b: bytes, c: bytes, d: bytes, n: int, m: int, p: int, span: int) -> _Blocks:
    return _Blocks(np.frombuffer(a).reshape(n, n), np.frombuffer(b).reshape(n, m), np.frombuffer(c).reshape(p, n),
                   np.frombuffer(d).reshape(p, m), span)


def _blocks(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, span: int) -> _Blocks:
    """The block form of a realisation, kept for the last few (a design simulates the same map many times)."""
    a, b, c, d = (np.ascontiguousarray(x, dtype=float) for x in (a, b, c, d))
    return _blocks_cached(a.tobytes(), b.tobytes(), c.tobytes(), d.tobytes(), a.shape[0], b.shape[1], c.shape[0], span)


def _product(b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``b @ u`` (for one input a broadcast product: a matrix product of inner size 1 is several times slower)."""
    return b * u if b.shape[1] == 1 else b @ u


#: ``evaluate(x, u) -> (x_next, y)`` for a run of samples (columns): the model's own arithmetic.
Evaluate = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def _plain(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, u: np.ndarray, x0: np.ndarray,
           evaluate: Evaluate | None) -> tuple[np.ndarray, np.ndarray]:
    """``y[0..N-1]`` and ``x[N]`` by the recursion sample by sample (the last resort)."""
    y = np.empty((c.shape[0], u.shape[1]))
    x = x0
    if evaluate is None:
        w = _product(b, u)
        for k in range(u.shape[1]):
            y[:, k] = c @ x
            x = a @ x + w[:, k]
        y += _product(d, u)
    else:
        for k in range(u.shape[1]):
            nxt, out = evaluate(x[:, None], u[:, k:k + 1])
            x, y[:, k] = nxt[:, 0], out[:, 0]
    return y, x


def _chunk(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, form: _Blocks, u: np.ndarray,
           x0: np.ndarray, evaluate: Evaluate | None) -> tuple[np.ndarray, np.ndarray]:
    """``y[0..N-1]`` (p x N) and ``x[N]`` of one chunk of ``N`` samples from ``x[0] = x0`` (module
    docstring); ``x[N]`` only when the chunk is a whole number of blocks (all chunks but the last)."""
    m, p, span = form.m, form.p, form.span
    length = u.shape[1]
    nb = -(-length // span)
    padded = np.zeros((m, nb * span))  # zero after the trial's end
    padded[:, :length] = u
    blocked = np.ascontiguousarray(padded.reshape(m, nb, span).transpose(2, 0, 1))  # u[j L + i] at [i, :, j]
    with np.errstate(over="ignore", invalid="ignore"):
        starts = form.scan(x0, (form.gamma @ blocked.reshape(span * m, nb))[:, :-1])
        for _ in range(MAX_REFINE):
            y, ends = form.run(starts, blocked, evaluate)
            corr = form.scan(np.zeros(form.n), ends[:, :-1] - starts[:, 1:])
            size = float(np.max(np.abs(corr)))
            if not np.isfinite(size):
                break
            if size <= REFINE_RTOL * max(float(np.max(np.abs(starts))), float(np.max(np.abs(ends)))):
                if size > 0.0:
                    y += (form.obs @ corr).reshape(span, p, nb)
                    ends[:, -1] += form.power @ corr[:, -1]
                return y.transpose(1, 2, 0).reshape(p, nb * span)[:, :length], ends[:, -1]
            starts = starts + corr
    return _plain(a, b, c, d, u, x0, evaluate)


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

    Compiled: the recursion run in all blocks of the trial at once from block starts computed
    by matrix powers, then refined (module docstring); the result is that of the
    sample-by-sample recursion to its own rounding (about 1e-14 of the peak).

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
        recursion is then run by this step (for all blocks at once), so that the result is
        that of stepping the model (module docstring, step 2), not of the rounded products;
        the matrices only give the block starts and their refinement. Default: the matrices'
        products.

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
    # the matrix products are small (n rows): BLAS threads only add wake-ups, up to 20 times the CPU
    # time on a loaded machine (measured at 22 states), so the trial runs single-threaded
    with _blas_controller().limit(limits=1, user_api="blas"):
        chunk = min(length, max(1, CHUNK_ENTRIES // (m + p)))
        # L steps of the recursion and two scans of J = chunk / L steps: L about sqrt(chunk) balances their
        # Python-level costs, sqrt(chunk / 32) with a model's own step, which costs more
        scale = _SPAN_SCALE_EVALUATE if evaluate is not None else _SPAN_SCALE
        span = 1 << max(0, int(round(0.5 * np.log2(scale * chunk))))
        chunk = -(-chunk // span) * span
        form = _blocks(a, b, c, d, span)
        y = np.empty((p, length))
        for k0 in range(0, length, chunk):
            k1 = min(k0 + chunk, length)
            y[:, k0:k1], state = _chunk(a, b, c, d, form, u_arr[:, k0:k1], state, evaluate)
    return y
