"""Worst cases over a Delta set, per frequency: the cone data of a disc of multiplicative model
errors, the bound they give on the learning ratio, the ratio for one given error, and the bands
where a condition holds (docs/theory.md, section 2, "The check", and section 3).

With ``T0`` the complementary sensitivity of system j-1's nominal DOB loop and ``F`` a filter's
response on the grid, learning leaves system j the ratio ``|T| = |1 - F (1 + Delta)/(1 + T0 Delta)|``.
For every ``Delta`` of the disc ``|Delta| <= W`` (or the part of it that keeps the loop's stability
margin) the Moebius image of the disc bounds it: :func:`uncertainty_cones` gives the disc data,
:func:`worst_case_ratio` the bound. The robust-set design (:mod:`..methods.robust_set`) constrains it, the
Theorem's exact check (:mod:`..checks.theorem`) evaluates it.
"""

from __future__ import annotations

import numpy as np

from ilcdob.loop import LoopSystem

from .value_set import complementary_sensitivity

__all__ = ["uncertainty_cones", "worst_case_ratio", "ratio_for_delta", "mask_intervals"]


def uncertainty_cones(source: LoopSystem, w: np.ndarray, W: np.ndarray,
                      margin: float = 0.5) -> tuple[np.ndarray, ...]:
    """Worst-case data ``(a, b, R, T0, kind)`` of system j-1's Delta set on ``w``.

    For every admissible ``Delta`` at ``w``, ``(1 + Delta)/(1 + T0 Delta)`` lies in a disc, so
    ``|T| = |1 - F (1+Delta)/(1+T0 Delta)| <= (|a - b F| + R |F|) / a`` with ``a > 0``
    (module docstring):

    * ``kind == 0``, the exact image of the whole disc ``|Delta| <= W`` (needs ``s > 0``):
      ``a = s = 1 - |T0|^2 W^2``, ``b = 1 - conj(T0) W^2``, ``R = |1 - T0| W``;
    * ``kind == 1``, where ``W |T0| > 1 - margin`` and this bound is tighter (or the first does not
      exist): the Deltas that keep ``|1 + T0 Delta| >= margin``,
      ``(1+Delta)/(1+T0 Delta) = 1/T0 + (1 - 1/T0)/(1 + T0 Delta)`` in the disc with centre
      ``1/T0`` and radius ``|1 - 1/T0| / margin``: ``a = |T0|``, ``b = |T0|/T0``, ``R = |T0 - 1|/margin``.

    Where ``W |T0| <= 1 - margin`` every Delta of the disc has ``|1 + T0 Delta| >= margin``, so the
    first (exact) bound is used and nothing is excluded.

    Parameters
    ----------
    source : LoopSystem
        System j-1 (its nominal loop is used).
    w : array, rad/s
    W : array
        Multiplicative bound on ``w``.
    margin : float
        Stability margin ``m`` in [0, 1) assumed of system j-1's true loop where the disc reaches
        its stability boundary; 0 keeps the whole disc everywhere (then ``kind == 1`` never
        occurs and ``a <= 0`` marks frequencies with an unbounded worst case).
    """
    t0 = complementary_sensitivity(source, w)
    W = np.asarray(W, float)
    s = 1 - np.abs(t0) ** 2 * W**2
    b1 = 1 - np.conj(t0) * W**2
    r1 = np.abs(1 - t0) * W
    a, b, r = s.copy(), b1.copy(), r1.copy()
    kind = np.zeros(np.shape(w), dtype=int)
    if margin > 0:
        with np.errstate(divide="ignore", invalid="ignore"):
            a2, b2, r2 = np.abs(t0), np.abs(t0) / t0, np.abs(t0 - 1) / margin
            use2 = (W * np.abs(t0) > 1 - margin) & ((s <= 1e-12) | (r2 / np.abs(b2) < r1 / np.abs(b1)))
        a, b, r = np.where(use2, a2, a), np.where(use2, b2, b), np.where(use2, r2, r)
        kind[use2] = 1
    return a, b, r, t0, kind


def worst_case_ratio(F: np.ndarray, a: np.ndarray, b: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Bound ``max |T(w)|`` per frequency, ``(|a - b F| + R |F|) / a`` (exact for the whole disc).

    ``inf`` where ``a <= 0`` (unbounded image: the disc reaches the stability boundary) and
    ``F != 0``; 1 there if ``F = 0``.

    Parameters
    ----------
    F : array_like
        Response of the robustness filter on the grid (complex).
    a, b, R : numpy.ndarray
        Cone data of :func:`uncertainty_cones` on the same grid.

    Returns
    -------
    numpy.ndarray
        The worst-case ``|T(w)|`` per frequency.
    """
    F = np.asarray(F, complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = (np.abs(a - b * F) + R * np.abs(F)) / a
    return np.where(a > 0, out, np.where(np.abs(F) == 0, 1.0, np.inf))


def ratio_for_delta(F: np.ndarray, t0: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """``|T(w)| = |1 - F (1 + Delta)/(1 + T0 Delta)|`` for one given ``Delta(w)`` (module docstring).

    Parameters
    ----------
    F : array_like
        Response of the robustness filter (complex).
    t0 : numpy.ndarray
        ``T0``, complementary sensitivity of system j-1's nominal DOB loop, same grid.
    delta : array_like
        The multiplicative model error ``Delta(w)`` (complex), same grid.

    Returns
    -------
    numpy.ndarray
        ``|T(w)|``.
    """
    delta = np.asarray(delta, complex)
    return np.abs(1 - np.asarray(F, complex) * (1 + delta) / (1 + t0 * delta))


def mask_intervals(w: np.ndarray, mask: np.ndarray) -> list[tuple[float, float]]:
    """Contiguous runs of ``mask`` as frequency intervals.

    Parameters
    ----------
    w : numpy.ndarray
        Frequencies, rad/s.
    mask : numpy.ndarray
        Booleans on ``w``.

    Returns
    -------
    list of (float, float)
        ``(w_first, w_last)`` of every run of True, rad/s.
    """
    out, start = [], None
    for i, flag in enumerate(mask):
        if flag and start is None:
            start = i
        if start is not None and (not flag or i == mask.size - 1):
            end = i if flag else i - 1
            out.append((float(w[start]), float(w[end])))
            start = None
    return out
