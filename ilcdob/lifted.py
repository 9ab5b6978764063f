"""Lifted (matrix) operators of discrete LTI maps over a finite trial (docs/theory.md section 3).

Over ``N`` samples a causal SISO map is the lower-triangular Toeplitz matrix of its Markov
parameters ``h[0] = D``, ``h[k] = C A^{k-1} B``. A relative degree (delay) of ``m`` samples
makes the first ``m`` diagonals zero; solve with the shifted operator instead of inverting a
singular matrix.
"""

from __future__ import annotations

import control as ct
import numpy as np
from scipy.linalg import toeplitz
from scipy.signal import fftconvolve
from scipy.sparse.linalg import LinearOperator

from .errors import SignalError

__all__ = ["markov_parameters", "lifted_operator", "relative_degree", "toeplitz_matvec", "toeplitz_rmatvec",
           "lifted_linear_operator"]


def markov_parameters(sys: ct.StateSpace, n: int) -> np.ndarray:
    """First ``n`` Markov parameters (impulse response samples) of a discrete SISO system."""
    if n < 1:
        raise SignalError(f"`n`: got {n}, expected a trial length >= 1")
    a, b, c = np.asarray(sys.A), np.asarray(sys.B)[:, 0], np.asarray(sys.C)[0]
    h = np.empty(n)
    h[0] = float(np.asarray(sys.D).ravel()[0])
    x = b.copy()
    for k in range(1, n):
        h[k] = c @ x
        x = a @ x
    return h


def lifted_operator(h: np.ndarray) -> np.ndarray:
    """Lower-triangular Toeplitz matrix ``T[i, j] = h[i - j]`` (``i >= j``)."""
    h = np.asarray(h, dtype=float)
    return toeplitz(h, np.zeros_like(h))


def relative_degree(h: np.ndarray, rtol: float = 1e-9) -> int:
    """Number of leading Markov parameters that are zero relative to ``max |h|``."""
    h = np.asarray(h, dtype=float)
    big = np.max(np.abs(h))
    if big == 0:
        raise SignalError("`h`: all Markov parameters are zero (the map is zero)")
    return int(np.flatnonzero(np.abs(h) > rtol * big)[0])


def toeplitz_matvec(h: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``T(h) x`` without forming ``T``: the causal convolution, by FFT (O(N log N))."""
    x = np.asarray(x, dtype=float)
    return fftconvolve(np.asarray(h, float), x)[: x.size]


def toeplitz_rmatvec(h: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``T(h)' y`` without forming ``T``: anti-causal correlation (time-reverse, convolve, reverse)."""
    y = np.asarray(y, dtype=float)
    return fftconvolve(np.asarray(h, float), y[::-1])[: y.size][::-1]


def lifted_linear_operator(sys: ct.StateSpace, n: int) -> LinearOperator:
    """Matrix-free lifted operator of ``sys`` over ``n`` samples (scipy ``LinearOperator``)."""
    h = markov_parameters(sys, n)
    return LinearOperator((n, n), matvec=lambda x: toeplitz_matvec(h, np.ravel(x)),
                          rmatvec=lambda y: toeplitz_rmatvec(h, np.ravel(y)), dtype=float)
