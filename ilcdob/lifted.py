"""Lifted (matrix) operators of discrete LTI maps over a finite trial (design notes section 3).

Over ``N`` samples a causal SISO map is the lower-triangular Toeplitz matrix of its Markov
parameters ``h[0] = D``, ``h[k] = C A^{k-1} B``. A relative degree (delay) of ``m`` samples
makes the first ``m`` diagonals zero; solve with the shifted operator instead of inverting a
singular matrix.
"""

from __future__ import annotations

import control as ct
import numpy as np
from scipy.linalg import toeplitz

from .errors import SignalError

__all__ = ["markov_parameters", "lifted_operator", "relative_degree"]


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
