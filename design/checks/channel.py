"""Will learning help between vehicles that learn through a setpoint channel? The exact worst case per frequency.

For the pair of :mod:`ilcdob.design.maps.channel_filters`, a vehicle's ratio ``R = Gd/Gf = (1 - Q)/K`` is
exact whatever its loop (``K`` is the controller's gain, ``Q`` software), so per frequency the learner's
error with learning over its error without, for any true maps of both vehicles, is::

    T(w) = e_j / e'_j = 1 - F(w) Gd_{j-1} / Gd_hat_{j-1}

with ``F`` what the law puts in front of the Theorem's filters: the learning band's gain and the factor
of a sampling zero inverted with zero phase error (:mod:`ilcdob.design.filters.noncausal`). Only the
source's model error matters; the learner's cancels.

* A vehicle on its own controller carries the uncertainty of its identified channel map,
  ``Gd = Gd_hat (1 + Delta)`` with ``|Delta(jw)| <= W(w)`` (3 sigma of its fit,
  :meth:`ilcdob.channel_loop.ChannelLoop.delta`, or a stated bound), so
  ``max |T| = |1 - F| + |F| W``: learning helps where ``|F| W < 1 - |1 - F|``, with the Theorem's
  filters (``F = 1``) wherever ``W < 1``.
* ilcdob's PID + DOB loop carries its plant's, and ``Gd/Gd_hat`` is the Moebius map of
  :func:`~.theorem.exact_worst_ratio`, evaluated by it.

What it covers: every ``Delta`` of any phase inside the disc, the disturbance part of the error over
trials long against the filters' memory; not the source's own learning signal, reference terms or noise.
Units: rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.channel_loop import ChannelLoop

from ..filters.band import LearningBand
from ..maps.channel_filters import channel_filters
from ..maps.closed_form import LearningFilters
from ..sets.delta import delta_bound, sampled_bound
from ..sets.worst_case import mask_intervals
from .theorem import EXACT_TOL, exact_worst_ratio

__all__ = ["ChannelPairCheck", "channel_check", "channel_worst", "format_channel_table"]


@dataclass(frozen=True)
class ChannelPairCheck:
    """The exact worst case of one pair (module docstring).

    Attributes
    ----------
    source, target : str
        Vehicles j-1 and j.
    w : numpy.ndarray
        Frequencies, rad/s.
    bound : numpy.ndarray
        ``W``: the radius of the source's Delta set on ``w``.
    bound_source : str
        ``"identification"`` (3 sigma of the fit, scaled) or ``"stated bound"``.
    factor : numpy.ndarray
        ``F`` on ``w`` (complex).
    worst : numpy.ndarray
        ``max |T|`` on ``w``.
    band : LearningBand or None
        The learning band the law flies (None: the Theorem's filters).
    """

    source: str
    target: str
    w: np.ndarray
    bound: np.ndarray
    bound_source: str
    factor: np.ndarray
    worst: np.ndarray
    band: LearningBand | None = None

    @property
    def worst_ratio(self) -> float:
        """The largest worst-case ratio on the grid."""
        return float(np.max(self.worst))

    @property
    def worst_w(self) -> float:
        """Where it is, rad/s."""
        return float(self.w[int(np.argmax(self.worst))])

    @property
    def holds(self) -> bool:
        """Whether learning can make the error no worse at any frequency (within ``1 + EXACT_TOL``)."""
        return bool(np.all(self.worst <= 1.0 + EXACT_TOL))

    def worse_bands(self) -> list[tuple[float, float]]:
        """The frequency bands (rad/s) where the worst case exceeds ``1 + EXACT_TOL``."""
        return mask_intervals(self.w, self.worst > 1.0 + EXACT_TOL)

    def to_dict(self) -> dict[str, object]:
        """The check as JSON values: the verdict, the worst case and where, and the curves on ``w`` (rad/s)."""
        return {"source": self.source, "target": self.target, "holds": self.holds, "worst_ratio": self.worst_ratio,
                "worst_w_rad_s": self.worst_w, "worse_bands_rad_s": [list(b) for b in self.worse_bands()],
                "bound_source": self.bound_source,
                "band": None if self.band is None else self.band.to_dict(),
                "w": self.w.tolist(), "bound": self.bound.tolist(), "worst": self.worst.tolist()}

    def __repr__(self) -> str:
        verdict = "never worse" if self.holds else f"can be worse in {self.worse_bands()} rad/s"
        return (f"<ChannelPairCheck {self.source!r} -> {self.target!r}: worst ratio {self.worst_ratio:.4g} at "
                f"{self.worst_w:.4g} rad/s ({self.bound_source}); {verdict}>")


def channel_check(source: ChannelLoop | LoopSystem, target: ChannelLoop | LoopSystem, *,
                  band: LearningBand | None = None, w: np.ndarray | None = None, scale: float = 1.0,
                  bound: float | None = None) -> ChannelPairCheck:
    """The exact worst case of ``target`` learning from ``source`` (module docstring).

    Parameters
    ----------
    source, target : ChannelLoop or LoopSystem
        Vehicles j-1 and j (:func:`~ilcdob.design.maps.channel_filters.channel_filters`).
    band : LearningBand, optional
        The learning band the law flies (default: none, the Theorem's filters).
    w : array_like, optional
        Frequencies, rad/s (default: 400 log-spaced from 0.01 rad/s to 0.999 Nyquist).
    scale : float
        Multiplier (> 0) of the identified standard deviations.
    bound : float, optional
        A stated multiplicative bound in (0, 1) on the source's map instead of its identification.

    Returns
    -------
    ChannelPairCheck

    Raises
    ------
    SpecError
        As :func:`~ilcdob.design.maps.channel_filters.channel_filters`; a source with neither an
        identification nor a bound; a bad ``scale``, ``bound`` or ``band``.
    """
    if band is not None and not isinstance(band, LearningBand):
        raise SpecError(f"`band`: got {type(band).__name__}, expected a LearningBand or None")
    w, radius, origin, factor, worst = channel_worst(source, target, w=w, scale=scale, bound=bound)
    f_band = np.ones(w.size) if band is None else band.response(w)
    return ChannelPairCheck(source.name, target.name, w, radius, origin, factor * f_band, worst(f_band), band)


def channel_worst(source: ChannelLoop | LoopSystem, target: ChannelLoop | LoopSystem, *, w: np.ndarray | None = None,
                  scale: float = 1.0, bound: float | None = None, filters: LearningFilters | None = None
                  ) -> tuple[np.ndarray, np.ndarray, str, np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """The exact worst case of :func:`channel_check` for any learning band: what ``check`` reports and the band's
    ``model`` edge of a channel pair bounds (:func:`~ilcdob.design.filters.band.choose_band`).

    Parameters
    ----------
    source, target : ChannelLoop or LoopSystem
        Vehicles j-1 and j.
    w : array_like, optional
        Frequencies, rad/s (default: 400 log-spaced from 0.01 rad/s to 0.999 Nyquist).
    scale : float
        Multiplier (> 0) of the identified standard deviations.
    bound : float, optional
        A stated multiplicative bound in (0, 1) on the source's map (the continuous one: its radius on the sampled
        map, :func:`~..sets.delta.sampled_bound`).
    filters : LearningFilters, optional
        The pair's filters, if built (default: built here).

    Returns
    -------
    (w, radius, origin, factor, worst)
        The grid, the disc's radius and where it comes from, the factor ``L1 as applied / L1`` on it, and
        ``worst(F)``: the exact worst case for a band gain ``F`` on the grid.

    Raises
    ------
    SpecError
        As :func:`channel_check`.
    """
    lf = channel_filters(source, target) if filters is None else filters
    ts = source.ts
    w = np.geomspace(0.01, 0.999 * np.pi / ts, 400) if w is None else np.asarray(w, float)
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any(w <= 0) or np.any(w >= np.pi / ts):
        raise SpecError(f"`w`: expected frequencies in (0, {np.pi / ts:.6g}) rad/s (below Nyquist)")
    with np.errstate(all="ignore"):
        factor = lf.L1.freqresp(w) / lf.L1.exact_freqresp(w)
    if isinstance(source, LoopSystem):
        got = delta_bound(source.spec, ts, w, scale, bound)
        if got is None:
            raise SpecError(f"system {source.name!r}: neither an identification nor a stated bound, so no Delta set")
        _, radius, origin = got
        origin = "stated bound" if origin == "fleet bound" and bound is not None else origin
        return w, radius, origin, factor, lambda f: exact_worst_ratio(source, w, radius, factor * f)
    if bound is not None:
        if not (isinstance(bound, (int, float)) and np.isfinite(bound) and 0 < bound < 1):
            raise SpecError(f"`bound`: got {bound!r}, expected a relative error in (0, 1)")
        radius, origin = sampled_bound(source.channel_plant(), ts, w, float(bound)), "stated bound"
    else:
        radius, origin = np.asarray(source.delta(w, scale), float), "identification"
    return w, radius, origin, factor, lambda f: np.abs(1.0 - factor * f) + np.abs(factor * f) * radius


def format_channel_table(checks: list[ChannelPairCheck]) -> str:
    """Plain-text table of :func:`channel_check` results: per pair the learning band, the Delta set's origin, the
    largest radius, the exact worst-case ratio and its frequency, and the verdict.

    Parameters
    ----------
    checks : list of ChannelPairCheck

    Returns
    -------
    str
        A header, a rule, one row per pair and a legend.
    """
    head = (f"{'pair':<24} {'band [rad/s]':>12} {'Delta set':<16} {'max W':>7} {'exact worst':>11} "
            f"{'worst w':>8}  verdict")
    rows = [head, "-" * len(head)]
    for c in checks:
        cutoff = "off" if c.band is None or c.band.cutoff is None else f"{c.band.cutoff:.4g}"
        rows.append(f"{c.source + ' -> ' + c.target:<24} {cutoff:>12} {c.bound_source:<16} "
                    f"{float(np.max(c.bound)):>7.3g} {c.worst_ratio:>11.4g} {c.worst_w:>8.4g}  "
                    + ("holds" if c.holds else f"FAILS in {', '.join(f'{a:.3g}-{b:.3g}' for a, b in c.worse_bands())}"
                                              " rad/s"))
    rows += ["", "exact worst = max |e_j / e'_j| = |1 - F| + |F| W per frequency over the source's Delta set "
                 f"(|Delta| <= W); holds: <= 1 + {EXACT_TOL:g} at every frequency (docs/closed_loop.md)"]
    return "\n".join(rows)
