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

from .errors import SignalError

__all__ = ["markov_parameters", "lifted_operator", "relative_degree", "toeplitz_matvec", "toeplitz_rmatvec"]


def markov_parameters(sys: ct.StateSpace, n: int) -> np.ndarray:
    """First ``n`` Markov parameters (impulse response samples) of a discrete SISO system.

    Parameters
    ----------
    sys : control.StateSpace
        Discrete-time SISO system.
    n : int
        Number of samples (the trial length), >= 1.

    Returns
    -------
    numpy.ndarray
        ``h[0] = D``, ``h[k] = C A^{k-1} B`` for ``k = 1..n-1``.

    Raises
    ------
    SignalError
        ``n < 1``.
    """
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
    """The lifted (matrix) form of a causal map over a trial (docs/theory.md section 3).

    Parameters
    ----------
    h : array_like
        Markov parameters of the map (:func:`markov_parameters`), one per sample.

    Returns
    -------
    numpy.ndarray
        Lower-triangular Toeplitz matrix ``T[i, j] = h[i - j]`` (``i >= j``), ``N x N``.
    """
    h = np.asarray(h, dtype=float)
    return toeplitz(h, np.zeros_like(h))


def relative_degree(h: np.ndarray, rtol: float = 1e-9) -> int:
    """Relative degree of a map in samples: its leading Markov parameters that are zero.

    Parameters
    ----------
    h : array_like
        Markov parameters.
    rtol : float
        A parameter counts as zero when ``|h[k]| <= rtol * max |h|``.

    Returns
    -------
    int
        Index of the first non-zero Markov parameter.

    Raises
    ------
    SignalError
        Every Markov parameter is zero.
    """
    h = np.asarray(h, dtype=float)
    big = np.max(np.abs(h))
    if big == 0:
        raise SignalError("`h`: all Markov parameters are zero (the map is zero)")
    return int(np.flatnonzero(np.abs(h) > rtol * big)[0])


def toeplitz_matvec(h: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``T(h) x`` without forming ``T``: the causal convolution, by FFT (O(N log N)).

    Parameters
    ----------
    h : array_like
        Markov parameters (at least as many as ``x`` has samples).
    x : array_like
        The input trial.

    Returns
    -------
    numpy.ndarray
        ``T(h) x``, the length of ``x``.
    """
    x = np.asarray(x, dtype=float)
    return fftconvolve(np.asarray(h, float), x)[: x.size]


def toeplitz_rmatvec(h: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``T(h)' y`` without forming ``T``: anti-causal correlation (time-reverse, convolve, reverse).

    Parameters
    ----------
    h : array_like
        Markov parameters (at least as many as ``y`` has samples).
    y : array_like
        The trial.

    Returns
    -------
    numpy.ndarray
        ``T(h)^T y``, the length of ``y``.
    """
    y = np.asarray(y, dtype=float)
    return fftconvolve(np.asarray(h, float), y[::-1])[: y.size][::-1]

