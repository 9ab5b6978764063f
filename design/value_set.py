"""Structured model errors, frequency by frequency: value sets and their worst-case cones.

The robust-set design (:mod:`.robust_set`) guarantees the improvement for every multiplicative
model error of the source system, ``P = (1 + Delta) P_hat``. Over the unstructured disc
``|Delta(e^{jw Ts})| <= W`` it must cover every phase of ``Delta``; near the peak of the
source's complementary sensitivity ``T0`` the disc admits plants that bring the source's loop to
its stability boundary, and the guarantee forces the learning off. The errors users have are
structured (paper Sec. III's Delta set, docs/theory.md section 3):

* the family a fleet's ``uncertainty = { bound = b }`` stands for (:mod:`.delta`): a real gain
  error ``Delta = r``, or a first-order high-pass error ``Delta(s) = r s tau/(s tau + 1)``
  (unmodelled fast dynamics), with ``|r| <= b`` and ``tau`` in ``TAU_RANGE`` (s);
* an identified model's 3-sigma parameter ellipsoid, linearised as the frequency-wise bound
  is (:func:`ilcdob.uncertainty.multiplicative_bound`): at each frequency ``Delta(jw)`` fills
  the ellipse ``{A u : |u| <= 1}``, ``A = 3 [Re g; Im g] Cov^(1/2) / |G|`` (``g``: the
  response's gradient in the parameters).

At each frequency the set of values ``Delta(jw)`` is sampled on a grid and mapped through
``g(Delta) = (1 + Delta)/(1 + T0 Delta)`` (the exact ratio ``Gd/Gd_hat`` of the source's true
and nominal disturbance maps, :mod:`.robust_set`). The target's error ratio
``|1 - F g|`` is convex in ``g``, so its maximum over the convex hull of the image is reached at
a hull vertex. Between grid lines the image bulges out of the sampled polygon by at most the
grid's sagitta ``eps`` (measured on a grid twice as fine: the largest distance of a midpoint
from the chord of its neighbours), and ``|1 - F g| <= |1 - F g_v| + eps |F|`` covers it. Each
hull vertex ``g_v`` is therefore one cone row ``(a, b, R) = (1, g_v, eps)`` of the form the
robust-set design already solves (``(|a - b F| + R |F|)/a <= rho``).

Values of ``Delta`` with ``|1 + T0 Delta| < margin`` (the source's true loop closer than
``margin`` to its stability boundary at that frequency) are left out, as the disc design
does where the disc reaches the boundary: the guarantee covers the plants of the set that
keep that margin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem, freqresp

__all__ = ["TAU_RANGE", "ValueSet", "complementary_sensitivity", "bound_family", "ellipse_family", "value_set_cones", "worst_over_set"]

#: Time constants of the high-pass errors of a fleet bound (s): log-uniform in this range.
TAU_RANGE = (0.01, 1.0)


@dataclass(frozen=True)
class ValueSet:
    """Sampled values of a structured ``Delta(e^{jw Ts})`` on a grid, frequency by frequency.

    Attributes
    ----------
    w : numpy.ndarray
        Frequencies, rad/s.
    values : numpy.ndarray
        ``len(w) x (2 n1 - 1) x (2 n2 - 1)`` complex samples: a 2-D grid of the family's
        parameters at each frequency, refined twice (the even rows and columns are the grid
        whose hull is taken; the odd ones measure how far the family bulges between them).
    source : str
        What the set stands for (for reports).
    """

    w: np.ndarray
    values: np.ndarray
    source: str


def _check_bound(bound: float) -> float:
    if not (np.isfinite(bound) and 0 < bound < 1):
        raise SpecError(f"`bound`: got {bound!r}, expected a relative error in (0, 1)")
    return float(bound)


def bound_family(bound: float, w: np.ndarray, n_r: int = 81, n_tau: int = 60) -> ValueSet:
    """Values of the fleet-bound family (module docstring) on ``w``.

    Parameters
    ----------
    bound : float
        ``b`` in (0, 1): ``|r| <= b``.
    w : array_like
        Frequencies, rad/s.
    n_r, n_tau : int
        Grid points in ``r`` and in ``tau`` (log-spaced over :data:`TAU_RANGE`).

    Returns
    -------
    ValueSet
        At each frequency the grid ``r x (1, h(tau_1), ..., h(tau_n))``, ``h = jw tau/(1 + jw tau)``
        (``tau`` from the gain row's side ``tau -> inf``, ``h -> 1``, to the smallest ``tau``),
        refined twice.
    """
    b = _check_bound(bound)
    w = np.asarray(w, float).reshape(-1)
    r = np.linspace(-b, b, 2 * n_r - 1)
    tau = np.geomspace(TAU_RANGE[1], TAU_RANGE[0], 2 * n_tau - 1)
    h = 1j * w[:, None] * tau[None, :] / (1 + 1j * w[:, None] * tau[None, :])
    h = np.concatenate([np.ones((w.size, 1)), h], axis=1)
    return ValueSet(w, r[None, :, None] * h[:, None, :], f"gain or first-order high-pass error within {b:g} "
                    f"(time constants {TAU_RANGE[0]:g}-{TAU_RANGE[1]:g} s)")


def ellipse_family(axes: np.ndarray, w: np.ndarray, n_phi: int = 72, n_rad: int = 6) -> ValueSet:
    """Values filling the ellipses ``{A(w) u : |u| <= 1}`` of a linearised parameter ellipsoid.

    Parameters
    ----------
    axes : array_like
        ``len(w) x 2 x 2`` real matrices ``A(w)`` mapping the unit disc onto the set of
        ``(Re Delta, Im Delta)`` (a ``2 x p`` map reduced to its ``2 x 2`` left singular form).
    w : array_like
        Frequencies, rad/s.
    n_phi, n_rad : int
        Grid points in angle and in radius (0 to 1).

    Returns
    -------
    ValueSet
        Polar grid ``rho (cos phi, sin phi)`` mapped by ``A`` at each frequency, refined twice
        (the angle closes on itself).
    """
    a = np.asarray(axes, float)
    w = np.asarray(w, float).reshape(-1)
    if a.shape != (w.size, 2, 2) or not np.all(np.isfinite(a)):
        raise SpecError(f"`axes`: got shape {a.shape}, expected ({w.size}, 2, 2) finite matrices")
    phi = np.linspace(0, 2 * np.pi, 2 * n_phi + 1)
    rho = np.linspace(0, 1, 2 * n_rad - 1)
    u = rho[:, None, None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)[None]   # n_rad x n_phi x 2
    xy = np.einsum("wij,rpj->wrpi", a, u)
    return ValueSet(w, xy[..., 0] + 1j * xy[..., 1], "linearised 3-sigma parameter ellipsoid")


def complementary_sensitivity(source: LoopSystem, w: np.ndarray) -> np.ndarray:
    """``T0 = P_hat (M + C) / (1 - Q + P_hat (M + C))`` of a system's nominal DOB loop.

    The Moebius map ``g(Delta) = (1 + Delta)/(1 + T0 Delta)`` of the module docstring and of
    :mod:`.robust_set` takes a model error of the source to its error-ratio factor.

    Parameters
    ----------
    source : LoopSystem
        The system (its nominal loop is used).
    w : array_like
        Frequencies, rad/s.

    Returns
    -------
    numpy.ndarray
        ``T0(e^{j w Ts})``, complex.
    """
    src = source.nominal
    p, m, c, q = (freqresp(blk, w) for blk in (src.P, src.M, src.C, src.Q))
    pm = p * (m + c)
    return pm / (1 - q + pm)


def _image(values: np.ndarray, t0: complex, margin: float) -> tuple[np.ndarray, np.ndarray]:
    den = 1 + t0 * values
    keep = np.abs(den) >= margin
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(keep, (1 + values) / den, np.nan), keep


def _sagitta(g: np.ndarray) -> float:
    """Largest distance of a twice-refined grid's odd points from the chord of their even neighbours."""
    out = 0.0
    for arr in (g, g.T):
        a, m, b = arr[0:-2:2], arr[1:-1:2], arr[2::2]
        chord = b - a
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(np.real((m - a) * np.conj(chord)) / np.abs(chord) ** 2, 0, 1)
            d = np.abs(m - (a + np.where(np.abs(chord) > 0, t, 0) * chord))
        d = d[np.isfinite(d)]
        if d.size:
            out = max(out, float(np.max(d)))
    return out


def _hull(points: np.ndarray) -> np.ndarray:
    pts = np.unique(np.round(np.column_stack([points.real, points.imag]), 15), axis=0)
    if pts.shape[0] < 3:
        return pts[:, 0] + 1j * pts[:, 1]
    try:
        idx = ConvexHull(pts).vertices
    except QhullError:  # collinear (e.g. a real gain error with real T0): the segment's ends
        d = pts - pts.mean(axis=0)
        direction = np.linalg.svd(d, full_matrices=False)[2][0]
        proj = d @ direction
        idx = [int(np.argmin(proj)), int(np.argmax(proj))]
    return pts[idx, 0] + 1j * pts[idx, 1]


def value_set_cones(source: LoopSystem, vs: ValueSet, margin: float = 0.5) -> tuple[np.ndarray, ...]:
    """Cone rows ``(index, a, b, R)`` bounding ``|1 - F g(Delta)|`` over a value set (module docstring).

    Parameters
    ----------
    source : LoopSystem
        System j-1 (its nominal loop gives ``T0``).
    vs : ValueSet
        Its structured ``Delta`` values on ``vs.w``.
    margin : float
        Values with ``|1 + T0 Delta| < margin`` are left out (0 <= margin < 1).

    Returns
    -------
    index : numpy.ndarray
        Frequency index (into ``vs.w``) of each row.
    a, b, R : numpy.ndarray
        Row data: ``|1 - F g| <= (|a - b F| + R |F|)/a`` for every kept ``Delta`` at that frequency.
    """
    if not 0 <= margin < 1:
        raise SpecError(f"`margin`: got {margin!r}, expected a number in [0, 1)")
    t0 = complementary_sensitivity(source, vs.w)
    rows_i, rows_b, rows_r = [], [], []
    for i in range(vs.w.size):
        g, keep = _image(vs.values[i], t0[i], margin)
        eps = _sagitta(g)
        coarse, kept = g[::2, ::2], keep[::2, ::2]
        vert = _hull(coarse[kept]) if np.any(kept) else np.zeros(0, dtype=complex)
        rows_i.append(np.full(vert.size, i))
        rows_b.append(vert)
        rows_r.append(np.full(vert.size, eps))
    idx = np.concatenate(rows_i)
    b = np.concatenate(rows_b)
    return idx, np.ones(idx.size), b, np.concatenate(rows_r)


def worst_over_set(F: np.ndarray, index: np.ndarray, a: np.ndarray, b: np.ndarray, R: np.ndarray,
                   n_w: int) -> np.ndarray:
    """``max |1 - F g|`` per frequency over the cone rows of :func:`value_set_cones`.

    Parameters
    ----------
    F : array_like
        The learning filter's response relative to the closed form, one value per frequency.
    index, a, b, R : numpy.ndarray
        Cone rows.
    n_w : int
        Number of frequencies.

    Returns
    -------
    numpy.ndarray
        The bound per frequency (``n_w`` values; ``nan`` where a frequency has no rows: every
        value of the set there is closer than the margin to the stability boundary).
    """
    F = np.asarray(F, complex).reshape(-1)
    per_row = (np.abs(a - b * F[index]) + R * np.abs(F[index])) / a
    out = np.full(n_w, -np.inf)
    np.maximum.at(out, index, per_row)
    return np.where(np.isfinite(out), out, np.nan)
