"""Frequency responses of discrete filters on the unit circle, ``z = e^{j w Ts}``.

One place computes what every filter object of ilcdob reports as its ``freqresp``:

* :func:`response` - ``H(e^{jw Ts}) = e^{jw Ts a} F_1(z) F_2(z) ...``: a product of factors,
  each anything callable at complex points ``z`` (a discrete python-control system, a
  zero-pole-gain filter), with an optional look-ahead ``z^a``. It serves
  :func:`ilcdob.loop.freqresp` (one system, no look-ahead),
  :meth:`ilcdob.design.filters.noncausal.ZPKFilter.freqresp` and
  :meth:`ilcdob.design.export.objects.LearningFilterTF.freqresp` (the factors of ``filters.json`` and
  their look-ahead);
* :func:`fir_response` - the same response of a non-causal FIR ``z^a sum_i h[i] z^-i``
  (:class:`ilcdob.design.methods.fir.FIRFilter`), evaluated as ``sum_i h[i] e^{-jw Ts (i - a)}`` with
  the look-ahead inside each tap's exponent (:func:`fir_matrix`, also the matrix the FIR
  designs fit with): one rounding of the phase per tap, where ``e^{jw Ts a}`` times a
  polynomial in ``z^-1`` would add the rounding of a long sum of cancelling terms.

Conventions: frequencies ``w`` in rad/s (Nyquist is ``pi/Ts``), the sample time ``Ts`` in s,
look-aheads in samples; a response has the shape of ``w``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["unit_circle", "response", "fir_matrix", "fir_response"]


def unit_circle(w: ArrayLike, ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The frequencies as a float array and their points ``z = e^{j w Ts}`` on the unit circle.

    Parameters
    ----------
    w : array_like
        Frequencies, rad/s.
    ts : float
        Sample time, s.

    Returns
    -------
    w : numpy.ndarray
        ``w`` as floats, its shape kept.
    z : numpy.ndarray
        ``e^{j w Ts}``, the shape of ``w``.
    """
    w = np.asarray(w, dtype=float)
    return w, np.exp(1j * w * ts)


def response(factors: Iterable[Callable[[np.ndarray], ArrayLike]], w: ArrayLike, ts: float,
             advance: int | None = None) -> np.ndarray:
    """Frequency response ``H(e^{jw Ts}) = e^{jw Ts advance} prod_k F_k(e^{jw Ts})``.

    The product is formed left to right, the look-ahead factor first: ``((e^{jw Ts a} F_1) F_2) ...``.

    Parameters
    ----------
    factors : iterable of callable
        The factors ``F_k``, each called once with the complex array ``z = e^{jw Ts}`` (the
        shape of ``w``) and returning its values there (a discrete ``control.LTI`` is such a
        callable). At least one, unless ``advance`` is given.
    w : array_like
        Frequencies, rad/s (up to Nyquist ``pi/Ts``).
    ts : float
        Sample time, s.
    advance : int, optional
        Look-ahead ``a``, samples. None (default): no look-ahead factor at all. An integer, 0
        included, multiplies by ``e^{jw Ts a}`` (for ``a = 0`` exactly ``1 + 0j``, which leaves
        finite values as they are and turns an infinite one into ``inf + nan j``).

    Returns
    -------
    numpy.ndarray
        Complex response, the shape of ``w``.

    Raises
    ------
    ValueError
        No factor and no ``advance``; or a factor's values do not fit the shape of ``w`` (a
        factor's own error, e.g. python-control's for a ``w`` of more than one dimension, is
        passed on).
    """
    w, z = unit_circle(w, ts)
    h = None if advance is None else np.exp(1j * w * ts * advance)
    for factor in factors:
        part = np.asarray(factor(z), dtype=complex).reshape(w.shape)
        h = part if h is None else h * part
    if h is None:
        raise ValueError("response: no factor and no advance given")
    return h


def fir_matrix(w: ArrayLike, n: int, advance: int, ts: float) -> np.ndarray:
    """Rows ``e^{-jw Ts (i - a)}``, ``i = 0..n-1``: the FIR response on ``w`` is ``E @ h``.

    Parameters
    ----------
    w : array_like
        Frequencies, rad/s (one dimension).
    n : int
        Number of taps.
    advance : int
        Look-ahead ``a``, samples.
    ts : float
        Sample time, s.

    Returns
    -------
    numpy.ndarray
        Complex ``len(w) x n`` matrix.
    """
    return np.exp(-1j * np.outer(np.asarray(w, float) * ts, np.arange(n) - advance))


def fir_response(h: np.ndarray, w: ArrayLike, ts: float, advance: int) -> np.ndarray:
    """Frequency response ``H(e^{jw Ts}) = e^{jw Ts a} sum_i h[i] e^{-jw Ts i}`` of a non-causal FIR.

    Parameters
    ----------
    h : numpy.ndarray
        Taps ``h[0..n-1]`` (``h[0]`` multiplies the input ``advance`` samples ahead).
    w : array_like
        Frequencies, rad/s.
    ts : float
        Sample time, s.
    advance : int
        Look-ahead ``a``, samples.

    Returns
    -------
    numpy.ndarray
        Complex response, the shape of ``w`` (:func:`fir_matrix` times ``h``).
    """
    w = np.asarray(w, dtype=float)
    return fir_matrix(w.reshape(-1), h.size, advance, ts).dot(h).reshape(w.shape)
