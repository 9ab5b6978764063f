"""Structured model errors, frequency by frequency: value sets and their worst-case cones.

The robust-set design (:mod:`..methods.robust_set`) guarantees the improvement for every multiplicative
model error of the source system, ``P = (1 + Delta) P_hat``. Over the unstructured disc
``|Delta(e^{jw Ts})| <= W`` it must cover every phase of ``Delta``; near the peak of the
source's complementary sensitivity ``T0`` the disc admits plants that bring the source's loop to
its stability boundary, and the guarantee forces the learning off. The errors users have are
structured (paper Sec. III's Delta set, docs/theory.md section 3):

* the family a fleet's ``uncertainty = { bound = b }`` stands for (:mod:`.delta`): a real gain
  error ``Delta = r``, or a first-order high-pass error ``Delta(s) = r s tau/(s tau + 1)``
  (unmodelled fast dynamics), with ``|r| <= b`` and ``tau`` in ``TAU_RANGE`` (s);
* an identified model's parameter ellipsoid, linearised as the frequency-wise bound is
  (:func:`ilcdob.uncertainty.multiplicative_bound`): at each frequency ``Delta`` fills an
  ellipse ``{A u : |u| <= 1}`` (below: ``A`` from the relative gradient of the sampled response).

The bound family is cut to the plants that keep system j-1's loop stable and its disturbance map
within ``1/margin`` of the model's (:func:`admissible_range`, per plant); an ellipse's values
are kept where ``|g| <= 1/margin`` (per value).

Where the margin cuts a set at one frequency, the kept values' image is bounded partly by the margin
circle ``|g| = 1/m``, and a polygon of the kept grid samples alone misses the plants between a kept and
a left-out sample (by up to 0.3 in ``|1 - F g|`` on the built-in fleet). Both families therefore
sample that boundary itself:

* the bound family's ``r`` grid is spread, frequency by frequency and error shape by error shape,
  between the limits of the values keeping ``|g| <= 1/m`` there (:func:`_frequency_limits`: along one
  shape ``r h`` the left-out values form an interval not containing 0 or two half-lines, whose nearest
  ends are the exact roots of a quadratic in ``r``), so the grid's end rows lie on the circle where it
  cuts and on the plant-wise limits elsewhere: the kept set is again a grid's domain, covered as an
  uncut one is (the values with ``|g| <= 1/m`` beyond such an interval along a shape, inside the
  plant-wise limits, are left out at that frequency);
* an ellipse is cut value by value (:func:`_ellipse_cut`): ``g`` is one-to-one, so the kept image is
  bounded by the ring's kept arcs and the arcs of the circle inside the ellipse's image; the polygon is
  built from the kept ring values, the circle's exact crossings of the ring (bisection in the ring's
  angle) and the circle's points whose preimage lies in the ellipse, and its sagitta covers the ring's
  kept pieces and the circle's steps.

At each frequency the set of values ``Delta(jw)`` is sampled on a grid and mapped through
``g(Delta) = (1 + Delta)/(1 + T0 Delta)`` (the exact ratio ``Gd/Gd_hat`` of the source's true
and nominal disturbance maps, :mod:`..methods.robust_set`). The target's error ratio
``|1 - F g|`` is convex in ``g``, so its maximum over any convex polygon containing the image is
reached at a vertex of that polygon. The polygon used is the outer one of ``K`` (:data:`DIRECTIONS`)
supporting lines: in each direction ``n_k = e^{j 2 pi k/K}`` the largest ``Re(g conj(n_k))`` over the
sampled image, and the vertices where consecutive lines meet. It contains the sampled image's
convex hull (sound), it has exactly ``K`` vertices at every frequency, and it is computed for all
frequencies at once; it exceeds the hull by at most ``tan(pi/K)`` times the hull's edge lengths
(0.05 for ``K = 64``). Between grid lines the image bulges out of the sampled polygon by at most the
grid's sagitta ``eps``, and ``|1 - F g| <= |1 - F g_v| + eps |F|`` covers it. ``eps`` is the largest
bulge of a grid piece (:func:`_bulge`, on a grid twice as fine: each piece runs from an even point
through an odd one to the next): the piece's distance from its chord in the ``Delta``-plane (measured
at the odd point; exact for the lines of ``r``, straight, and for an ellipse's ring), carried through
``g`` with the exact distance of the chord's image, a circular arc, from the images' chord and the
largest ``|g'|`` near it. Taken in the ``g``-plane instead, the bulge of a piece near the pole, whose image
moves fast and unevenly along it, was under-estimated (measured: docs/performance.md, "Measured figures
behind the design's choices"). Each vertex ``g_v`` is therefore one cone row ``(a, b, R) = (1, g_v, eps)`` of the
form the robust-set design already solves (``(|a - b F| + R |F|)/a <= rho``).

Where every value of the set keeps the margin, its boundary decides the polygon
(:class:`Boundary`, :func:`family_cones`): ``g`` is conformal away from its pole, so a point
inside the parameter domain where the parametrisation is regular maps inside the image, and the
supporting lines touch the image of the domain's boundary. The polygon and the sagitta are then
built from the boundary values only (an ellipse's outer ring, 145 of its 1,595 values; the
family's gain errors and its high-pass errors at the ends of ``r`` and of ``tau``, 242 of 2,460):
the polygon lies inside the whole grid's and the sagitta, measured along the boundary, is at most
the whole grid's (the inner lines' bulge lies inside the image). Where a boundary value is left
out or the margin cuts the bound family's grid, the parametrisation folds, or the boundary winds
around the pole, the whole grid is used; an ellipse the margin cuts is bounded as said above.

In :func:`value_set_cones` values with ``|g| > 1/margin`` (the source's true disturbance map more
than ``1/margin`` times its model's: a resonance near its stability boundary) are left out; the
guarantee covers the plants of the set that keep that margin. On a bare :class:`ValueSet` this is done
sample by sample, and the rows bound the kept samples' polygon only; :func:`family_cones` (what the
robust-set design uses) also covers the kept values between a kept and a left-out sample, as above.
(The disc design's margin is on ``|1 + T0 Delta|`` instead, :mod:`..methods.robust_set`; on a structured set
that would drop every plant with less than ``margin`` times the model's gain, harmless ones included.)

The robust-set design takes a structured set as a :class:`BoundFamily` or an
:class:`EllipseFamily`. Both evaluate ``Delta`` on the *sampled* loop, ``Delta_d(e^{jw Ts}) =
P_d / P_hat_d - 1`` with both plants zero-order held (what the vehicle's loop sees; near Nyquist
it differs from ``Delta(jw)``):

* the fleet-bound family is linear in ``r``: ``P_d = P_hat_d + r ZOH[h P_hat]``, and
  ``ZOH[h P_hat] = P_hat_d - ZOH[P_hat/(s tau + 1)]``, so ``Delta_d = r (1 - ZOH[P_hat/(s tau + 1)]/P_hat_d)``
  exactly, one sampled plant per grid ``tau``;
* the ellipsoid is linearised in the sampled response: ``A = k [Re g; Im g] Cov^(1/2)`` with ``g`` the
  gradient of ``P_d/P_hat_d`` in the parameters (forward differences of the sampled model) and
  ``k = sqrt(chi2_p^-1(0.99))``, so the ellipsoid holds 99 % of the Gaussian estimate's mass
  (``p`` parameters).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy.stats import chi2

from ilcdob.channel_loop import ChannelLoop
from ilcdob.discretize import plant_block
from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem, freqresp
from ilcdob.specs import PlantSpec
from ilcdob.uncertainty import ModelStructure

from .delta import TAU_RANGE, dense_grid

__all__ = ["DIRECTIONS", "TAU_RANGE", "ValueSet", "Boundary", "BoundFamily", "EllipseFamily", "complementary_sensitivity", "bound_family",
           "ellipse_family", "admissible_range", "value_set_cones", "worst_over_set", "family_cones"]

#: Supporting directions of the outer polygon that bounds a value set at each frequency.
DIRECTIONS = 64



@dataclass(frozen=True)
class ValueSet:
    """Sampled values of a structured ``Delta(e^{jw Ts})`` on a grid, frequency by frequency.

    Attributes
    ----------
    w : numpy.ndarray
        Frequencies, rad/s.
    values : tuple of numpy.ndarray
        One array per connected piece of the family (the fleet-bound family: its gain errors and
        its high-pass errors), each ``len(w) x (2 n1 - 1) x (2 n2 - 1)`` complex samples: a 2-D grid
        of the piece's parameters at each frequency, refined twice (the even rows and columns are
        the grid that bounds the set; the odd ones measure how far the piece bulges between them).
    source : str
        What the set stands for (for reports).
    """

    w: np.ndarray
    values: tuple
    source: str


@dataclass(frozen=True)
class Boundary:
    """A structured set's values on the boundary of its parameter domain, frequency by frequency.

    What bounds the set's image where the boundary suffices (:func:`family_cones`): the Moebius
    map ``g`` is conformal away from its pole, so an interior point of the parameter domain where
    the parametrisation is regular maps to an interior point of the image; the image's supporting
    lines therefore touch it on the image of the domain's boundary (or of its critical points).

    Attributes
    ----------
    values : ValueSet
        The boundary as lines of the set's twice-refined grid (pieces ``len(w) x 1 x L`` or
        ``len(w) x L x 1``), the critical points added.
    loop : numpy.ndarray
        ``len(w) x L``: the domain's boundary as one closed curve of Delta values (the last sample
        joins the first), on which the pole ``-1/T0`` is sought.
    regular : numpy.ndarray
        Per frequency, whether the parametrisation has no critical point inside the domain other
        than those in ``values``.
    cut : numpy.ndarray or None
        Per frequency, whether the domain itself was cut for the margin there (the fleet-bound
        family's limits of ``r``, :func:`_frequency_limits`); None: the margin is applied value by value.
    axes : numpy.ndarray or None
        An ellipse's matrices ``A(w)`` (:meth:`EllipseFamily.axes`), for the part of its boundary the
        margin circle makes (:func:`_ellipse_cut`); None for other sets.
    """

    values: ValueSet
    loop: np.ndarray
    regular: np.ndarray
    cut: np.ndarray | None = None
    axes: np.ndarray | None = None


def _check_bound(bound: float) -> float:
    if not (np.isfinite(bound) and 0 < bound < 1):
        raise SpecError(f"`bound`: got {bound!r}, expected a relative error in (0, 1)")
    return float(bound)


@lru_cache(maxsize=32)
def _lag_blocks(model: PlantSpec, ts: float, tau: tuple) -> tuple:
    """The sampled model and the sampled ``P_hat/(s tau + 1)`` for every ``tau`` (built once per source)."""
    return (plant_block(model, ts),
            *(plant_block(PlantSpec(model.num, tuple(np.polymul(model.den, [t, 1.0])), model.delay), ts) for t in tau))


def bound_family(bound: float, w: np.ndarray, n_r: int = 21, n_tau: int = 30,
                 source: LoopSystem | None = None, margin: float = 0.0, t0: np.ndarray | None = None) -> ValueSet:
    """Values of the fleet-bound family (module docstring) on ``w``.

    Parameters
    ----------
    bound : float
        ``b`` in (0, 1): ``|r| <= b``.
    w : array_like
        Frequencies, rad/s.
    n_r, n_tau : int
        Grid points in ``r`` and in ``tau`` (log-spaced over :data:`TAU_RANGE`).
    source : LoopSystem, optional
        The system whose model the errors multiply: with it ``Delta`` is the sampled loop's
        ``Delta_d`` (module docstring) and ``r`` is limited, per error shape, to the plants whose
        loop is stable and keeps the margin (:func:`admissible_range`); without it the continuous
        ``Delta(jw)`` over ``|r| <= b``.
    margin : float
        With ``source``: the margin ``m`` of :func:`admissible_range`.
    t0 : numpy.ndarray, optional
        ``T0`` of ``source`` on ``w`` (:func:`complementary_sensitivity`), if known.

    Returns
    -------
    ValueSet
        Two pieces: the gain errors ``r`` (one column) and the high-pass errors, the grid
        ``r x (h(tau_1), ..., h(tau_n))``, ``h = jw tau/(1 + jw tau)``, both refined twice.
    """
    w, r, h, what, _ = _bound_grid(bound, w, n_r, n_tau, source, margin, t0)
    gain = np.broadcast_to(r[:, :, :1], (w.size, r.shape[1], 1)).astype(complex)
    return ValueSet(w, (gain, r[:, :, 1:] * h[:, None, :]), what)


def _bound_grid(bound: float, w: np.ndarray, n_r: int, n_tau: int, source: LoopSystem | None,
                margin: float, t0: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, str, np.ndarray]:
    """``(w, r, h, description, cut)`` of :func:`bound_family`: the gains ``r``, ``len(w) (or 1) x (2 n_r - 1) x
    (1 + len(tau))`` (the gain error's column first), the high-pass shapes ``h``, ``len(w) x len(tau)``, and per
    frequency whether the margin cuts some error shape's ``r`` there (:func:`_frequency_limits`)."""
    b = _check_bound(bound)
    w = np.asarray(w, float).reshape(-1)
    tau = np.geomspace(TAU_RANGE[1], TAU_RANGE[0], 2 * n_tau - 1)
    unit = np.linspace(0.0, 1.0, 2 * n_r - 1)
    cut = np.zeros(w.size, bool)
    if source is None:
        h = 1j * w[:, None] * tau[None, :] / (1 + 1j * w[:, None] * tau[None, :])
        lo, hi = np.full((1, tau.size + 1), -b), np.full((1, tau.size + 1), b)
    else:
        h = _highpass(source, tuple(tau), w)
        lo, hi = admissible_range(source, tuple(tau), margin)
        lo, hi = np.maximum(lo, -b)[None, :], np.minimum(hi, b)[None, :]
        if margin > 0:
            lo, hi, cut = _frequency_limits(source, w, h, lo, hi, margin, t0)
    r = lo[:, None, :] + unit[None, :, None] * (hi - lo)[:, None, :]
    what = "stable " if source is not None else ""
    return w, r, h, (f"{what}gain or first-order high-pass error within {b:g} (time constants "
                     f"{TAU_RANGE[0]:g}-{TAU_RANGE[1]:g} s)"), cut


#: Relative margin of the per-frequency limits of :func:`_frequency_limits`: the values at the limits keep
#: ``|g| <= 1/margin`` by this much, so that rounding does not put them outside the margin circle.
_LIMIT_SLACK = 1e-9


def _frequency_limits(source: LoopSystem, w: np.ndarray, h: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                      margin: float, t0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frequency and error shape, the ``r`` interval of the plants whose value there keeps ``|g| <= 1/margin``.

    The plant-wise limits ``lo, hi`` (``1 x (1 + len(tau))``, :func:`admissible_range`; ``t0``: ``T0`` on ``w``
    if known) hold ``|g| <= 1/(0.99 m)``
    on a dense grid; at one frequency the values with ``1/m < |g|`` are left out. Along one shape ``r h`` that
    set is an interval not containing 0 or two half-lines (:func:`_margin_limits`), so its nearest ends on
    each side of 0, solved exactly from the quadratic in ``r``, are the kept values' limits there: the grid of
    ``r`` is spread between them, frequency by frequency, and its end rows lie on the margin circle
    ``|g| = 1/m`` wherever the margin cuts (a plant beyond a band of ``|g| > 1/m`` along its shape, but
    inside the plant-wise limits, is left out at that frequency).

    Returns
    -------
    lo, hi : numpy.ndarray
        ``len(w) x (1 + len(tau))``.
    cut : numpy.ndarray
        Per frequency, whether the margin moved a limit.
    """
    hh = np.column_stack([np.ones(w.size), h])
    c = (complementary_sensitivity(source, w) if t0 is None else np.asarray(t0).reshape(-1))[:, None] * hh
    m_lo, m_hi = _margin_limits(c[None], hh[None], margin * (1 + _LIMIT_SLACK))
    lo_w, hi_w = np.maximum(lo, m_lo), np.minimum(hi, m_hi)
    return lo_w, hi_w, np.any((lo_w > lo) | (hi_w < hi), axis=1)


def _highpass(source: LoopSystem, tau: tuple, w: np.ndarray) -> np.ndarray:
    """``h_d = 1 - ZOH[P_hat/(s tau + 1)]/P_hat_d`` of every ``tau`` on ``w`` (module docstring), ``len(w) x len(tau)``."""
    model, *lags = _lag_blocks(source.spec.nominal_plant, source.ts, tau)
    p_d = model.response(w)
    return np.column_stack([1 - blk.response(w) / p_d for blk in lags])


_RANGES: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def admissible_range(source: LoopSystem, tau: tuple, margin: float = 0.0,
                     n: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """Per error shape (the gain, then every ``tau``) the interval ``(r_lo, r_hi)`` around 0 of the ``r`` whose
    true loop of system j-1 is stable and keeps the margin.

    Stability: with ``Delta = r h`` the true loop's return difference is the model's times ``1 + r T0 h``
    (:mod:`..methods.robust_set`); starting stable at ``r = 0``, its poles reach the unit circle first where
    ``1 + r T0(w) h(w) = 0``, i.e. at the real values ``r = -1/(T0 h)`` taken where ``T0 h`` is real
    (sign changes of its imaginary part, interpolated). Margin: the plant's disturbance map stays
    within ``1/m`` of the model's at every frequency, ``|g| = |1 + r h|/|1 + r T0 h| <= 1/m``: at each
    frequency a quadratic inequality in ``r`` whose violation set is an interval, or two half-lines,
    not containing 0. Low-gain plants keep ``g`` near 1 where ``T0`` is, so the margin leaves out
    only plants near their stability boundary (a margin on ``|1 + T0 Delta|`` itself would drop every
    plant with less than ``m`` times the model's gain). Both on a dense grid (``n`` linear points to
    Nyquist and 200 log-spaced below its first); the nearest limit on each side bounds the interval
    (``-inf``/``inf`` when there is none): a stability limit less 1 % (the set's image is unbounded
    there), a margin limit that of ``0.99 m``, so that the interval holds every plant a sampler keeping
    ``|Gd/Gd_hat| <= 1/m`` on another grid keeps (:func:`~ilcdob.design.sets.delta.delta_set`); the values
    beyond ``1/m`` are left out of the image value by value.

    Parameters
    ----------
    source : LoopSystem
        System j-1.
    tau : tuple of float
        Time constants of the high-pass shapes, s.
    margin : float
        ``m`` in [0, 1); 0: stability only.
    n : int
        Linear grid points.

    Returns
    -------
    lo, hi : numpy.ndarray
        ``1 + len(tau)`` limits each.
    """
    key = (repr(source.nominal.spec), source.ts, tau, float(margin), n)
    if key not in _RANGES:
        w = dense_grid(source.ts, n)
        h = np.column_stack([np.ones(w.size), _highpass(source, tau, w)])
        c = complementary_sensitivity(source, w)[:, None] * h
        im0, im1 = c.imag[:-1], c.imag[1:]
        cross = (np.sign(im0) != np.sign(im1)) | (im0 == 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(im0 == im1, 0.0, im0 / (im0 - im1))
            re = c.real[:-1] + t * (c.real[1:] - c.real[:-1])
            r_star = np.where(cross & (re != 0), -1.0 / re, np.nan)
        lo = 0.99 * np.max(np.where(r_star < 0, r_star, -np.inf), axis=0)
        hi = 0.99 * np.min(np.where(r_star > 0, r_star, np.inf), axis=0)
        if margin > 0:
            m_lo, m_hi = _margin_limits(c, h, 0.99 * margin)
            lo, hi = np.maximum(lo, m_lo), np.minimum(hi, m_hi)
        _RANGES[key] = (lo, hi)
    return _RANGES[key]


def _margin_limits(c: np.ndarray, h: np.ndarray, m: float) -> tuple[np.ndarray, np.ndarray]:
    """Nearest ``r`` on each side of 0 with ``|1 + r c| < m |1 + r h|`` at some grid frequency (per column)."""
    qa = np.abs(c) ** 2 - m**2 * np.abs(h) ** 2          # violation: qa r^2 + 2 qb r + qc < 0
    qb = c.real - m**2 * h.real
    qc = 1.0 - m**2
    disc = qb**2 - qa * qc
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.where(disc >= 0, disc, np.nan))
        r1, r2 = (-qb - root) / qa, (-qb + root) / qa        # qa > 0: r1 < r2; qa < 0: r2 < 0 < r1
        lin = -qc / (2 * qb)                                   # qa == 0: one limit
    small = np.abs(qa) < 1e-14
    pos = np.where(small, np.where(lin > 0, lin, np.inf),
                   np.where(qa > 0, np.where(np.fmin(r1, r2) > 0, np.fmin(r1, r2), np.inf), r1))
    neg = np.where(small, np.where(lin < 0, lin, -np.inf),
                   np.where(qa > 0, np.where(np.fmax(r1, r2) < 0, np.fmax(r1, r2), -np.inf), r2))
    return np.max(np.nan_to_num(neg, nan=-np.inf), axis=0), np.min(np.nan_to_num(pos, nan=np.inf), axis=0)


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
    return ValueSet(w, (_ellipse_points(a, rho[:, None] * np.cos(phi), rho[:, None] * np.sin(phi)),),
                    "linearised parameter ellipsoid")


def _ellipse_points(a: np.ndarray, ux: np.ndarray, uy: np.ndarray) -> np.ndarray:
    """``A(w) (ux, uy)`` as complex numbers, ``len(w) x ux.shape``."""
    a = a.reshape(a.shape[0], 2, 2, *([1] * ux.ndim))
    return (a[:, 0, 0] * ux + a[:, 0, 1] * uy) + 1j * (a[:, 1, 0] * ux + a[:, 1, 1] * uy)


@dataclass(frozen=True)
class BoundFamily:
    """The fleet-bound family as a structured Delta set of the robust-set design (module docstring).

    Attributes
    ----------
    bound : float
        ``|r| <= bound``, in (0, 1).
    n_r, n_tau : int
        Grid points in ``r`` and ``tau`` (:func:`bound_family`).
    """

    bound: float
    n_r: int = 21
    n_tau: int = 30

    def __post_init__(self) -> None:
        _check_bound(self.bound)
        for name in ("n_r", "n_tau"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= 2):
                raise SpecError(f"`{name}`: got {v!r}, expected an integer >= 2")

    def values(self, source: LoopSystem, w: np.ndarray, margin: float = 0.0,
               t0: np.ndarray | None = None) -> ValueSet:
        """Sampled ``Delta_d`` of ``source`` on ``w``, its plants stable and keeping ``margin`` (:func:`bound_family`).

        Parameters
        ----------
        source : LoopSystem
            System j-1.
        w : array_like
            Frequencies, rad/s.
        margin : float
            Per-plant margin ``m`` of :func:`admissible_range`, and at each frequency the values' (the grid of
            ``r`` spread between the limits of the values keeping ``|g| <= 1/m`` there, :func:`_frequency_limits`).
        t0 : numpy.ndarray, optional
            ``T0`` on ``w`` (:func:`complementary_sensitivity`), if known.

        Returns
        -------
        ValueSet
        """
        return bound_family(self.bound, w, self.n_r, self.n_tau, source, margin, t0)

    def boundary(self, source: LoopSystem, w: np.ndarray, margin: float = 0.0,
                 t0: np.ndarray | None = None) -> Boundary:
        """The values of :meth:`values` that bound the set's image where the boundary suffices (:class:`Boundary`).

        The high-pass piece is parametrised by ``(u, tau)``, ``r = lo + u (hi - lo)``: its boundary is
        ``u = 0``, ``u = 1`` (every ``tau``) and the first and last ``tau`` (every ``r``); its critical
        points are ``r = 0`` (``Delta = 0``, added) and where the angle of ``h(tau)`` stops moving
        monotonically (``regular`` is False there, and where that angle turns by ``pi`` or more: the
        halves ``r < 0`` and ``r > 0`` would overlap, with opposite orientations, and the boundary's
        winding number would not see the pole there; 79 degrees at most on the built-in fleet). The
        gain piece, a segment, is kept whole.

        Parameters
        ----------
        source : LoopSystem
            System j-1.
        w : array_like
            Frequencies, rad/s.
        margin : float
            Per-plant margin ``m`` of :func:`admissible_range`, and per frequency as in :meth:`values`.
        t0 : numpy.ndarray, optional
            ``T0`` on ``w`` (:func:`complementary_sensitivity`), if known.

        Returns
        -------
        Boundary
        """
        w, r, h, what, cut = _bound_grid(self.bound, w, self.n_r, self.n_tau, source, margin, t0)
        n = w.size
        gain = np.broadcast_to(r[:, :, :1], (n, r.shape[1], 1)).astype(complex)
        row_lo, row_hi = r[:, 0, 1:] * h, r[:, -1, 1:] * h                 # u = 0, u = 1: len(w) x len(tau)
        col_first, col_last = r[:, :, 1] * h[:, :1], r[:, :, -1] * h[:, -1:]   # len(w) x (2 n_r - 1)
        pieces = (gain, row_lo[:, None, :], row_hi[:, None, :], col_first[:, :, None], col_last[:, :, None],
                  np.zeros((n, 1, 1), complex))
        loop = np.concatenate([row_lo, col_last, row_hi[:, ::-1], col_first[:, ::-1]], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            turn = np.angle(h[:, 1:] / h[:, :-1])
        regular = ((np.all(turn > 0, axis=1) | np.all(turn < 0, axis=1)) & (np.abs(turn.sum(axis=1)) < np.pi)
                   & np.all(r[:, -1, 1:] > r[:, 0, 1:], axis=1))
        return Boundary(ValueSet(w, pieces, what), loop, regular, cut)

    def describe(self) -> str:
        """One line for reports."""
        return (f"structured: gain or first-order high-pass error within {self.bound:g} (time constants "
                f"{TAU_RANGE[0]:g}-{TAU_RANGE[1]:g} s)")


@dataclass(frozen=True)
class EllipseFamily:
    """An identified model's parameter ellipsoid as a structured Delta set (module docstring).

    Attributes
    ----------
    structure : ModelStructure
        The model's orders.
    theta : tuple of float
        Its parameters (the model's ``P_hat``).
    covariance : tuple of tuple of float
        Their covariance (last row and column: the delay's, when ``delay_estimated``).
    delay : float
        The model's input delay, s.
    delay_estimated : bool
        Whether the delay is a parameter.
    confidence : float
        Probability mass of the Gaussian estimate inside the ellipsoid, in (0, 1).
    n_phi, n_rad : int
        Grid points of the ellipse (:func:`ellipse_family`).
    """

    structure: ModelStructure
    theta: tuple
    covariance: tuple
    delay: float
    delay_estimated: bool
    confidence: float = 0.99
    n_phi: int = 72
    n_rad: int = 6
    _sqrt_cov: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not 0 < self.confidence < 1:
            raise SpecError(f"`confidence`: got {self.confidence!r}, expected a probability in (0, 1)")
        cov = np.asarray(self.covariance, float)
        p = len(self.theta) + (1 if self.delay_estimated else 0)
        if cov.shape != (p, p) or not np.all(np.isfinite(cov)):
            raise SpecError(f"`covariance`: got shape {cov.shape}, expected ({p}, {p}) finite values")
        lam, vec = np.linalg.eigh(0.5 * (cov + cov.T))
        object.__setattr__(self, "_sqrt_cov", vec * np.sqrt(np.clip(lam, 0, None)))

    @classmethod
    def from_spec(cls, spec, confidence: float = 0.99) -> "EllipseFamily":
        """The ellipsoid of a system's identification (``SystemSpec.identification``).

        Parameters
        ----------
        spec : SystemSpec
            The system.
        confidence : float
            Probability mass inside the ellipsoid.

        Returns
        -------
        EllipseFamily

        Raises
        ------
        SpecError
            The system carries no identification.
        """
        ident = spec.identification
        if ident is None:
            raise SpecError(f"system {spec.name!r}: no identification, so no parameter ellipsoid; state a bound "
                            "(`uncertainty = { bound = 0.2 }`) instead")
        return cls(ModelStructure(ident.poles, ident.zeros, ident.integrators), tuple(ident.parameters),
                   tuple(tuple(r) for r in ident.covariance), float(spec.nominal_plant.delay),
                   bool(ident.delay_estimated), confidence)

    @property
    def k(self) -> float:
        """Radius of the ellipsoid in standard deviations, ``sqrt(chi2_p^-1(confidence))``."""
        return float(np.sqrt(chi2.ppf(self.confidence, self._sqrt_cov.shape[0])))

    def axes(self, ts: float, w: np.ndarray) -> np.ndarray:
        """``len(w) x 2 x 2`` matrices ``A(w)`` of the linearised, sampled ellipse (module docstring).

        Parameters
        ----------
        ts : float
            Sample time, s.
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            ``{A(w) v : |v| <= 1}`` is the set of ``(Re Delta_d, Im Delta_d)`` at each frequency.
        """
        w = np.asarray(w, float).reshape(-1)
        model, *moved = _perturbed_blocks(self, ts)
        g0 = model.response(w)
        grads = np.array([(blk.response(w) / g0 - 1) / step for step, blk in moved]).reshape(-1, w.size)
        jac = self.k * np.stack([grads.real.T @ self._sqrt_cov, grads.imag.T @ self._sqrt_cov], axis=1)  # w x 2 x p
        lam, vec = np.linalg.eigh(jac @ np.swapaxes(jac, 1, 2))  # {J u : |u| <= 1} = {(J J')^(1/2) v : |v| <= 1}
        return vec * np.sqrt(np.clip(lam, 0, None))[:, None, :]

    def values(self, source: LoopSystem, w: np.ndarray, margin: float = 0.0,
               t0: np.ndarray | None = None) -> ValueSet:
        """Sampled ``Delta_d`` of the ellipse on ``w`` (:func:`ellipse_family`).

        Parameters
        ----------
        source : LoopSystem
            System j-1 (its sample time is used).
        w : array_like
            Frequencies, rad/s.
        margin : float
            Not used here: the margin is applied value by value (:func:`value_set_cones`).
        t0 : numpy.ndarray, optional
            Not used here (the interface of :meth:`BoundFamily.values`).

        Returns
        -------
        ValueSet
        """
        w = np.asarray(w, float).reshape(-1)
        vs = ellipse_family(self.axes(source.ts, w), w, self.n_phi, self.n_rad)
        return ValueSet(vs.w, vs.values, self.describe())

    def boundary(self, source: LoopSystem, w: np.ndarray, margin: float = 0.0,
                 t0: np.ndarray | None = None) -> Boundary:
        """The values of :meth:`values` that bound the set's image where the boundary suffices (:class:`Boundary`).

        The ellipse ``{A u : |u| <= 1}`` is a linear image of the unit disc: its boundary is the
        image of the unit circle (the outer ring of :func:`ellipse_family`'s grid; a degenerate
        ``A`` maps the circle onto the whole segment), and it has no critical point inside.

        Parameters
        ----------
        source : LoopSystem
            System j-1 (its sample time is used).
        w : array_like
            Frequencies, rad/s.
        margin : float
            Not used here: the margin is applied value by value (:func:`value_set_cones`, :func:`_ellipse_cut`).
        t0 : numpy.ndarray, optional
            Not used here (the interface of :meth:`BoundFamily.boundary`).

        Returns
        -------
        Boundary
        """
        w = np.asarray(w, float).reshape(-1)
        phi = np.linspace(0, 2 * np.pi, 2 * self.n_phi + 1)
        axes = self.axes(source.ts, w)
        ring = _ellipse_points(axes, np.cos(phi), np.sin(phi))
        return Boundary(ValueSet(w, (ring[:, None, :],), self.describe()), ring[:, :-1], np.ones(w.size, bool),
                        axes=axes)

    def plant(self, x: np.ndarray) -> PlantSpec:
        """The continuous plant of parameters ``x`` (``theta``, then the delay in s when it is estimated).

        Parameters
        ----------
        x : array_like
            ``len(theta)`` parameters, one more when ``delay_estimated`` (a negative delay is taken as 0).

        Returns
        -------
        PlantSpec
        """
        x = np.asarray(x, float).reshape(-1)
        th, d = (x[:-1], max(0.0, float(x[-1]))) if self.delay_estimated else (x, self.delay)
        den, num = self.structure.split(th)
        return PlantSpec(tuple(num), tuple(den), d)

    def members(self) -> list[tuple[str, PlantSpec]]:
        """The ellipsoid's extreme parameter vectors: ``x0 +- k sigma_i v_i`` along each principal axis ``v_i`` of
        the covariance (``sigma_i^2`` its eigenvalue, ``k`` :attr:`k`), the plants a whole trial flies
        (docs/theory.md section 6). Axes of zero variance are left out.

        Returns
        -------
        list of (str, PlantSpec)
            Label and continuous plant, two per axis.
        """
        x0 = np.concatenate([self.theta, [self.delay]]) if self.delay_estimated else np.asarray(self.theta, float)
        out = []
        for i in range(self._sqrt_cov.shape[1]):
            step = self.k * self._sqrt_cov[:, i]
            if np.any(step != 0):
                out += [(f"ellipsoid axis {i + 1} {sign}{self.k:.3g} sigma", self.plant(x0 + s * step))
                        for sign, s in (("+", 1.0), ("-", -1.0))]
        return out

    def describe(self) -> str:
        """One line for reports."""
        return (f"structured: the identification's {100 * self.confidence:g} % parameter ellipsoid "
                f"({self.k:.3g} sigma, linearised)")


@lru_cache(maxsize=32)
def _perturbed_blocks(family: EllipseFamily, ts: float) -> tuple:
    """The sampled model and, per parameter, ``(step, sampled model with that parameter stepped)``."""
    x0 = np.concatenate([family.theta, [family.delay]]) if family.delay_estimated else np.asarray(family.theta, float)

    def block(x: np.ndarray):
        return plant_block(family.plant(x), ts)

    moved = []
    for i in range(x0.size):
        x = x0.copy()
        x[i] += 1e-6 * max(1.0, abs(x0[i]))
        moved.append((x[i] - x0[i], block(x)))
    return (block(x0), *moved)


def complementary_sensitivity(source: LoopSystem | ChannelLoop, w: np.ndarray) -> np.ndarray:
    """``T0 = P_hat (M + C) / (1 - Q + P_hat (M + C))`` of a system's nominal DOB loop.

    The Moebius map ``g(Delta) = (1 + Delta)/(1 + T0 Delta)`` of the module docstring and of
    :mod:`..methods.robust_set` takes a model error of the source to its error-ratio factor. A vehicle on
    its own controller has ``T0 = 0``: its identified map's error is ``Gd/Gd_hat = 1 + Delta`` itself
    (:mod:`..methods.channel_robust_set`).

    Parameters
    ----------
    source : LoopSystem or ChannelLoop
        The system (its nominal loop is used).
    w : array_like
        Frequencies, rad/s.

    Returns
    -------
    numpy.ndarray
        ``T0(e^{j w Ts})``, complex.
    """
    if isinstance(source, ChannelLoop):
        return np.zeros(np.shape(w), complex)
    src = source.nominal
    p, m, c, q = (freqresp(blk, w) for blk in (src.P, src.M, src.C, src.Q))
    pm = p * (m + c)
    return pm / (1 - q + pm)


def _image(values: np.ndarray, t0: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """``g(Delta)`` of ``values`` (frequency first) and which values keep the margin, ``|g| <= 1/margin``."""
    t0 = np.asarray(t0).reshape((-1,) + (1,) * (values.ndim - 1))
    den = 1 + t0 * values
    keep = np.isfinite(values) & (np.abs(den) >= margin * np.abs(1 + values)) & (np.abs(den) > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(keep, (1 + values) / den, np.nan), keep


def _distance_to_chord(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of ``p`` from the segment ``[a, b]`` (complex, elementwise)."""
    chord = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.real((p - a) * np.conj(chord)) / np.abs(chord) ** 2, 0, 1)
        return np.abs(p - (a + np.where(np.abs(chord) > 0, t, 0) * chord))


def _bulge(da: np.ndarray, dm: np.ndarray, db: np.ndarray, t0: np.ndarray, ga: np.ndarray | None = None,
           gb: np.ndarray | None = None) -> np.ndarray:
    """How far the image ``g`` of a grid piece may lie from the chord of its ends' images (elementwise).

    The piece runs from ``da`` to ``db`` through ``dm`` (``Delta`` at the middle of its parameter). In
    the ``Delta``-plane it lies within ``d`` of its chord ``[da, db]``, ``d`` the distance of ``dm``
    from it (measured, as the grid's sagitta is; exact for the straight lines of ``r`` and for the
    ellipse's ring, an affine image of a circle, whose middle is its farthest point from the chord). The
    chord maps onto a circular arc (``g`` is a Moebius map) whose distance from the images' chord is
    exact: ``c^2/4/(R + sqrt(R^2 - c^2/4))`` for a minor arc of radius ``R`` over the chord ``c``,
    ``R + sqrt(R^2 - c^2/4)`` for a major one. A point within ``d`` of the arc's preimage moves by at
    most ``d`` times the largest ``|g'| = |1 - T0|/|1 + T0 Delta|^2`` on that neighbourhood, where
    ``|1 + T0 Delta|`` is at least its distance from 0 on the chord less ``|T0| d`` (``inf`` if that
    reaches 0: the pole). The sum bounds the piece's bulge; nan where an end is not finite. ``ga``,
    ``gb``: the ends' images, if known.
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        d = _distance_to_chord(dm, da, db)
        ua, ub = 1 + t0 * da, 1 + t0 * db
        ga = (1 + da) / ua if ga is None else ga
        gb = (1 + db) / ub if gb is None else gb
        dc = 0.5 * (da + db)
        gc = (1 + dc) / (0.5 * (ua + ub))
        u, v = ga - gc, gb - gc
        uv = np.conj(u) * v
        c2 = np.abs(gb - ga) ** 2
        area2 = np.abs(uv.imag)                                       # twice the triangle's area
        radius = np.abs(u) * np.abs(v) * np.sqrt(c2) / (2 * area2)
        half = np.sqrt(np.maximum(radius**2 - 0.25 * c2, 0.0))
        arc = np.where(uv.real <= 0, 0.25 * c2 / (radius + half), radius + half)  # obtuse at gc: the minor arc
        arc = np.where(area2 > 0, arc, 0.0)                           # collinear, gc between: a straight image
        near = _distance_to_chord(np.zeros_like(ua), ua, ub) - np.abs(t0) * d
        widen = np.where(d > 0, np.where(near > 0, d * np.abs(1 - t0) / near**2, np.inf), 0.0)
        out = arc + widen
    return np.where(np.isfinite(ga) & np.isfinite(gb), out, np.nan)


def _sagitta(values: np.ndarray, t0: np.ndarray, keep: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Per frequency (first axis), the largest :func:`_bulge` of a twice-refined grid's pieces (each an even
    point, the odd one after it and the next even one, along either grid direction) whose ends are kept
    (0 where nothing is measured); ``g``: the values' images."""
    out = np.zeros(values.shape[0])
    t0 = np.asarray(t0).reshape(-1, 1, 1)
    for arr, kp, im in ((values, keep, g), (np.swapaxes(values, 1, 2), np.swapaxes(keep, 1, 2), np.swapaxes(g, 1, 2))):
        a, m, b = arr[:, 0:-2:2], arr[:, 1:-1:2], arr[:, 2::2]
        if not a.size:
            continue
        ok = kp[:, 0:-2:2] & kp[:, 2::2]
        d = np.where(ok, _bulge(a, m, b, t0, im[:, 0:-2:2], im[:, 2::2]), 0.0)
        d = np.where(np.isnan(d), 0.0, d).reshape(values.shape[0], -1)
        out = np.maximum(out, d.max(axis=1))
    return out


def _outer_polygon(g: np.ndarray, keep: np.ndarray, k: int = 0) -> np.ndarray:
    """Vertices (``len x K``) of the outer polygon of ``K`` supporting lines of each row's kept points
    (``len x n`` arrays; module docstring); rows without any kept point are nan."""
    k = k or DIRECTIONS
    theta = 2 * np.pi * np.arange(k) / k
    pts = np.where(keep, g, np.nan)
    support = np.full((g.shape[0], k), -np.inf)
    for i in range(k):  # one direction at a time keeps the temporaries at the size of the points
        proj = pts.real * np.cos(theta[i]) + pts.imag * np.sin(theta[i])
        support[:, i] = np.max(np.where(np.isfinite(proj), proj, -np.inf), axis=1)
    s0, s1 = support, np.roll(support, -1, axis=1)
    t0, t1 = theta, np.roll(theta, -1)
    det = np.sin(2 * np.pi / k)
    with np.errstate(invalid="ignore"):
        x = (s0 * np.sin(t1) - s1 * np.sin(t0)) / det
        y = (s1 * np.cos(t0) - s0 * np.cos(t1)) / det
    return np.where(np.isfinite(support).all(axis=1, keepdims=True), x + 1j * y, np.nan)


def value_set_cones(source: LoopSystem, vs: ValueSet, margin: float = 0.5) -> tuple[np.ndarray, ...]:
    """Cone rows ``(index, a, b, R)`` bounding ``|1 - F g(Delta)|`` over a value set (module docstring).

    Parameters
    ----------
    source : LoopSystem
        System j-1 (its nominal loop gives ``T0``).
    vs : ValueSet
        Its structured ``Delta`` values on ``vs.w``.
    margin : float
        Values with ``|g| > 1/margin`` are left out (0 <= margin < 1), sample by sample: where a frequency
        has left-out samples the rows do not cover the kept values between them and the kept ones (the
        margin circle is not sampled); :func:`family_cones` does.

    Returns
    -------
    index : numpy.ndarray
        Frequency index (into ``vs.w``) of each row.
    a, b, R : numpy.ndarray
        Row data: ``|1 - F g| <= (|a - b F| + R |F|)/a`` for every kept ``Delta`` at that frequency.
    """
    if not 0 <= margin < 1:
        raise SpecError(f"`margin`: got {margin!r}, expected a number in [0, 1)")
    return _cone_rows(vs, complementary_sensitivity(source, vs.w), margin)[:4]


def _cone_rows(vs: ValueSet, t0: np.ndarray, margin: float, directions: int = 0) -> tuple[np.ndarray, ...]:
    """:func:`value_set_cones` given ``T0``, and per frequency whether some value was left out."""
    images = [_image(piece, t0, margin) for piece in vs.values]
    eps = np.max([_sagitta(piece, t0, k, g) for piece, (g, k) in zip(vs.values, images)], axis=0)
    n = vs.w.size
    vert = _outer_polygon(np.concatenate([g[:, ::2, ::2].reshape(n, -1) for g, _ in images], axis=1),
                          np.concatenate([k[:, ::2, ::2].reshape(n, -1) for _, k in images], axis=1), directions)
    idx = np.repeat(np.arange(n), vert.shape[1])
    ok = np.isfinite(vert.reshape(-1))
    excluded = ~np.all([k.all(axis=(1, 2)) for _, k in images], axis=0)
    return (idx[ok], np.ones(int(ok.sum())), vert.reshape(-1)[ok], np.repeat(eps, vert.shape[1])[ok], excluded)


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
    f = F[index]
    with np.errstate(divide="ignore", invalid="ignore"):  # a <= 0 (a disc reaching the stability boundary):
        per_row = np.where(a > 0, (np.abs(a - b * f) + R * np.abs(f)) / a,   # unbounded unless F = 0
                           np.where(np.abs(f) == 0, 1.0, np.inf))
    out = np.full(n_w, -np.inf)
    np.maximum.at(out, index, per_row)
    return np.where(np.isfinite(out), out, np.nan)


def family_cones(source: LoopSystem, family, w: np.ndarray, margin: float = 0.5, directions: int = 0,
                 chunk: int = 400) -> tuple[np.ndarray, ...]:
    """:func:`value_set_cones` of a structured set on ``w``, its values built a chunk of frequencies at a time.

    At each frequency the polygon is built from the set's boundary values (:class:`Boundary`,
    about a tenth of its grid) where they decide it: every boundary value keeps the margin, the
    parametrisation is regular, and the boundary does not wind around the Moebius map's pole
    ``Delta = -1/T0``. Then the whole set keeps the margin and its image is bounded by the image
    of its boundary: the values ``Delta`` with ``|g| > 1/m`` form a disc around the pole, the
    outside of a disc or a half-plane; meeting the set without meeting its boundary, it would lie
    inside the set and so would the pole. The bound family's grid is cut to the margin frequency by
    frequency (its end rows on the margin circle, :func:`_frequency_limits`); an ellipse the margin cuts is
    bounded by its kept ring values, the circle's crossings of the ring and the circle's points inside it
    (:func:`_ellipse_cut`). Elsewhere the whole grid is used, as :meth:`values` gives it.
    The boundary's polygon lies inside the whole grid's and its sagitta is at most the whole grid's.

    Parameters
    ----------
    source : LoopSystem
        System j-1.
    family : BoundFamily or EllipseFamily
        Its structured Delta set.
    w : array_like
        Frequencies, rad/s.
    margin : float
        As in :func:`value_set_cones`.
    directions : int
        Supporting directions of the outer polygon (default :data:`DIRECTIONS`); fewer give fewer,
        more conservative rows (a polygon of ``K`` directions contains that of every multiple of ``K``).
    chunk : int
        Frequencies whose values are held at once.

    Returns
    -------
    index, a, b, R : numpy.ndarray
        The cone rows (``index`` into ``w``).
    excluded : numpy.ndarray
        Per frequency, whether some value of the set was left out for the margin.
    """
    if not 0 <= margin < 1:
        raise SpecError(f"`margin`: got {margin!r}, expected a number in [0, 1)")
    w = np.asarray(w, float).reshape(-1)
    t0 = complementary_sensitivity(source, w)
    parts = [_family_rows(source, family, w[lo:lo + chunk], t0[lo:lo + chunk], margin, directions)
             for lo in range(0, w.size, chunk)]
    starts = range(0, w.size, chunk)
    return (np.concatenate([p[0] + lo for p, lo in zip(parts, starts)]),
            *(np.concatenate([p[k] for p in parts]) for k in range(1, 5)))


def _family_rows(source: LoopSystem, family, w: np.ndarray, t0: np.ndarray, margin: float,
                 directions: int) -> tuple[np.ndarray, ...]:
    """:func:`family_cones` on one chunk: the boundary's rows; an ellipse cut by the margin circle, the rows of
    its kept boundary (:func:`_ellipse_cut`); the whole grid's where the boundary does not decide."""
    bd = family.boundary(source, w, margin, t0=t0)
    idx, a, b, r, excluded = _cone_rows(bd.values, t0, margin, directions)
    if bd.cut is not None:
        excluded = excluded | bd.cut
    cut = np.zeros(w.size, bool)
    if bd.axes is not None and margin > 0:
        pts, eps, cut = _ellipse_cut(bd.axes, t0, margin, bd.values.values[0][:, 0, :])
    whole = (excluded | ~bd.regular | _encloses(bd.loop, t0)) & ~cut
    if not np.any(whole | cut):
        return idx, a, b, r, excluded
    mine = ~(whole | cut)[idx]
    parts = [(idx[mine], a[mine], b[mine], r[mine])]
    if np.any(cut):
        sub = np.flatnonzero(cut)
        vert = _outer_polygon(pts[sub], np.isfinite(pts[sub]), directions)
        ok = np.isfinite(vert)
        parts.append((np.repeat(sub, vert.shape[1]).reshape(vert.shape)[ok], np.ones(int(ok.sum())), vert[ok],
                      np.repeat(eps[sub], vert.shape[1]).reshape(vert.shape)[ok]))
    excluded = excluded | cut
    if np.any(whole):
        sub = np.flatnonzero(whole)
        s_idx, s_a, s_b, s_r, s_excluded = _cone_rows(family.values(source, w[sub], margin, t0=t0[sub]), t0[sub],
                                                      margin, directions)
        parts.append((sub[s_idx], s_a, s_b, s_r))
        excluded[sub] = s_excluded | (False if bd.cut is None else bd.cut[sub])
    idx = np.concatenate([p[0] for p in parts])
    order = np.argsort(idx, kind="stable")
    return (idx[order], *(np.concatenate([p[k] for p in parts])[order] for k in (1, 2, 3)), excluded)


#: Samples of the margin circle ``|g| = 1/m`` where it bounds an ellipse's kept values (:func:`_ellipse_cut`);
#: an arc between two of them lies within ``(1 - cos(pi/256))/m`` (7.5e-5/m) of its chord.
_CIRCLE_SAMPLES = 256


def _ellipse_cut(axes: np.ndarray, t0: np.ndarray, margin: float, ring: np.ndarray) -> tuple[np.ndarray, ...]:
    """Points and sagitta bounding the kept values ``{Delta = A u : |u| <= 1, |g(Delta)| <= 1/m}`` of an ellipse.

    The Moebius map ``g`` is one-to-one, so the image ``K`` of the kept values is bounded by the image
    of their boundary: the ring's kept arcs and, where the margin circle ``|g| = 1/m`` passes through the
    ellipse's image, arcs of that circle. Both are sampled: the ring's ``2 n_phi`` values (``ring``, the
    last joining the first), the exact crossings of the circle on every piece between a kept and a
    left-out ring value (bisection in the ring's angle to rounding), and the circle's
    :data:`_CIRCLE_SAMPLES` points whose preimage ``Delta = (g - 1)/(1 - T0 g)`` lies in the ellipse
    (``|A^-1 Delta| <= 1``). Every point of ``K``'s boundary is within ``eps`` of a chord between two of
    these points: a kept ring piece (from a sample or a crossing to the next) within its bulge, measured
    at the middle of its angle as the grid's sagitta is; a circle arc between two points at most one
    circle step apart (an arc of the circle inside the ellipse's image ends at a crossing or at a sampled
    point) within the sagitta ``(1 - cos(pi/n))/m`` of that step's chord. So ``K`` lies in their convex
    hull widened by ``eps``, which the outer polygon and the rows' ``R = eps`` cover.

    Returns
    -------
    points : numpy.ndarray
        ``len(w) x k`` complex ``g`` values (nan where unused; ``k = 0`` where the margin cuts nowhere).
    eps : numpy.ndarray
        Per frequency, the sagitta.
    cut : numpy.ndarray
        Per frequency, whether the margin cuts the ellipse there (some ring value left out, or some
        circle point inside): only there are ``points`` and ``eps`` meant to be used.
    """
    n, big = t0.size, 1.0 / margin
    tt = t0[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        g_ring = (1 + ring) / (1 + tt * ring)
    keep = np.isfinite(g_ring) & (np.abs(g_ring) <= big)
    th = 2 * np.pi * np.arange(_CIRCLE_SAMPLES) / _CIRCLE_SAMPLES
    gc = big * np.exp(1j * th)[None, :]
    # the ellipse lies in |Delta| <= sigma (its largest semi-axis), whose image is the disc of uncertainty_cones
    # (robust_set): where that disc keeps the margin strictly, no point of the circle has its preimage inside
    sigma = np.linalg.norm(axes, ord=2, axis=(1, 2))
    s_ = 1 - np.abs(t0) ** 2 * sigma**2
    with np.errstate(divide="ignore", invalid="ignore"):
        far = (s_ > 0) & (np.abs(1 - np.conj(t0) * sigma**2) / s_ + np.abs(1 - t0) * sigma / s_ < big)
    inside = np.zeros((n, _CIRCLE_SAMPLES), bool)
    near = np.flatnonzero(~far)
    if near.size:
        ax = axes[near]
        with np.errstate(divide="ignore", invalid="ignore"):
            dc = (gc - 1) / (1 - tt[near] * gc)
            det = ax[:, 0, 0] * ax[:, 1, 1] - ax[:, 0, 1] * ax[:, 1, 0]
            ux = (ax[:, 1, 1, None] * dc.real - ax[:, 0, 1, None] * dc.imag) / det[:, None]
            uy = (ax[:, 0, 0, None] * dc.imag - ax[:, 1, 0, None] * dc.real) / det[:, None]
        inside[near] = np.isfinite(ux) & np.isfinite(uy) & (ux**2 + uy**2 <= 1)
    cut = ~keep.all(axis=1) | inside.any(axis=1)
    eps = np.zeros(n)
    if not np.any(cut):
        return np.full((n, 0), np.nan + 0j), eps, cut
    pts = np.full((n, ring.shape[1] + (ring.shape[1] - 1) + _CIRCLE_SAMPLES), np.nan + 0j)
    sub = np.flatnonzero(cut)
    phi = np.linspace(0, 2 * np.pi, ring.shape[1])
    a = axes[sub]

    def delta(fi: np.ndarray, angle: np.ndarray) -> np.ndarray:  # the ring's value at these angles
        return ((a[fi, 0, 0] * np.cos(angle) + a[fi, 0, 1] * np.sin(angle))
                + 1j * (a[fi, 1, 0] * np.cos(angle) + a[fi, 1, 1] * np.sin(angle)))

    def image(fi: np.ndarray, angle: np.ndarray) -> np.ndarray:  # g of the ring's value at these angles
        d = delta(fi, angle)
        with np.errstate(divide="ignore", invalid="ignore"):
            return (1 + d) / (1 + t0[sub][fi] * d)

    ka, kb = keep[sub, :-1], keep[sub, 1:]
    fi = np.broadcast_to(np.arange(sub.size)[:, None], ka.shape)
    p0, p1 = np.broadcast_to(phi[:-1], ka.shape), np.broadcast_to(phi[1:], ka.shape)
    change = ka != kb
    lo, hi = np.where(ka, p0, p1)[change], np.where(ka, p1, p0)[change]     # kept end, left-out end
    fc = fi[change]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        gm = image(fc, mid)
        ok = np.isfinite(gm) & (np.abs(gm) <= big)
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    cross = np.full(ka.shape, np.nan)
    cross[change] = lo                                                       # the crossing, on the kept side
    s0 = np.where(change & ~ka, cross, p0)
    s1 = np.where(change & ka, cross, p1)
    piece = (ka & kb) | change
    fp = fi[piece]
    d = _bulge(delta(fp, s0[piece]), delta(fp, 0.5 * (s0 + s1)[piece]), delta(fp, s1[piece]), t0[sub][fp])
    bulge = np.zeros(ka.shape)
    bulge[piece] = np.where(np.isnan(d), np.inf, d)
    step = big * (1 - np.cos(np.pi / _CIRCLE_SAMPLES))
    eps[sub] = np.maximum(bulge.max(axis=1), step)
    g_cross = np.full(ka.shape, np.nan + 0j)
    g_cross[change] = image(fc, lo)
    k = ring.shape[1]
    pts[sub, :k] = np.where(keep[sub], g_ring[sub], np.nan)
    pts[sub, k:2 * k - 1] = g_cross
    pts[sub, 2 * k - 1:] = np.where(inside[sub], gc, np.nan)
    return pts, eps, cut


def _encloses(loop: np.ndarray, t0: np.ndarray) -> np.ndarray:
    """Per row, whether the closed curve ``loop`` (last sample joined to the first) winds around ``-1/T0``
    (or passes through it, or is not finite)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        d = loop * t0[:, None] + 1                     # T0 (Delta + 1/T0): same winding, no division
        turns = np.angle(np.concatenate([d[:, 1:], d[:, :1]], axis=1) / d).sum(axis=1) / (2 * np.pi)
    return ~np.isfinite(turns) | (np.abs(turns) > 0.5) | np.any(d == 0, axis=1)
