"""The Theorem's condition, checked per learning pair and frequency (docs/theory.md section 2).

With true plant ``P = (1 + Delta) P_hat``, learning from system j-1 leaves system j with
``e_j ~ -2 Delta_{j-1} / (1 + P_{j-1} C_{j-1}) {e'_j}``, so learning helps at the
frequencies where::

    |Delta_{j-1}(e^{jw Ts})|  <  |1 + P_{j-1}(e^{jw Ts}) C_{j-1}(e^{jw Ts})| / 2

This is checked frequency by frequency (not as a ratio of two H-infinity norms), with the
discrete model ``P_hat`` and PID ``C`` of system j-1 (:func:`ilcdob.loop.freqresp`) and
``|Delta|`` either from the Delta set's bound (3 sigma of the identification, or the fleet
bound) or from its sampled plants (``max_k |Delta_k|``). The margin is ``rhs / lhs`` (> 1:
the condition holds). At high frequency ``P C -> 0``, so ``rhs -> 1/2``: any uncertainty
above 50 % there breaks the condition.

The law a vehicle flies passes the learning band F (:mod:`ilcdob.design.band`): per
frequency it leaves ``e_j = (1 - F) e'_j + F e_j,Theorem``, so to the same first order its
error ratio is at most::

    1 - F + F |Delta_{j-1}| / (|1 + P C|/2)

(F: the band's real gain in [0, 1]). Where the paper's condition fails but F is small the
filtered law is still safe. The check reports both; the verdict of :attr:`PairCheck.holds_filtered`
is that this ratio stays within 1 + :data:`~ilcdob.design.band.AMPLIFICATION_TOL` at every frequency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem, freqresp

from .band import AMPLIFICATION_TOL, LearningBand
from .delta import DeltaSet

__all__ = ["PairCheck", "theorem_check", "theorem_rhs", "format_theorem_table", "learning_pairs"]

_SOURCES = ("bound", "samples")


@dataclass(frozen=True)
class PairCheck:
    """The Theorem's condition for one learning step ``source`` (j-1) -> ``target`` (j).

    The condition of the Theorem (paper Sec. III, Case II; docs/theory.md section 2),
    frequency by frequency.

    Attributes
    ----------
    source, target : str
        Names of systems j-1 and j.
    w : numpy.ndarray
        Frequencies, rad/s.
    delta : numpy.ndarray
        ``|Delta_{j-1}(e^{jw Ts})|`` (bound or largest sample).
    rhs : numpy.ndarray
        ``|1 + P_{j-1} C_{j-1}| / 2`` with the model of system j-1.
    holds : numpy.ndarray of bool
        ``delta < rhs`` per frequency.
    margin : numpy.ndarray
        ``rhs / delta`` (inf where ``delta = 0``).
    min_margin : float
        Smallest margin (< 1: the condition fails somewhere).
    worst_w : float
        Frequency of ``min_margin``, rad/s.
    delta_source : str
        ``"bound"`` or ``"samples"``.
    band : LearningBand or None
        The learning band of the law flown for this pair (None: the Theorem's filters
        unfiltered, as the paper).
    """

    source: str
    target: str
    w: np.ndarray
    delta: np.ndarray
    rhs: np.ndarray
    holds: np.ndarray
    margin: np.ndarray
    min_margin: float
    worst_w: float
    delta_source: str
    band: LearningBand | None = None

    @property
    def holds_everywhere(self) -> bool:
        """Whether the paper's condition holds at every frequency of ``w`` (unfiltered law)."""
        return bool(np.all(self.holds))

    @property
    def filtered_ratio(self) -> np.ndarray:
        """First-order worst-case error ratio of the law with its band, ``1 - F + F / margin``."""
        f = self.band.response(self.w) if self.band is not None else np.ones_like(self.w)
        with np.errstate(divide="ignore"):
            inv = np.where(np.isfinite(self.margin), 1.0 / self.margin, 0.0)
        return 1.0 - f + f * inv

    @property
    def amplification(self) -> float:
        """Largest :attr:`filtered_ratio` (<= 1: the filtered law never makes a frequency worse)."""
        return float(np.max(self.filtered_ratio))

    @property
    def holds_filtered(self) -> bool:
        """The verdict for the law as flown: :attr:`amplification` <= 1 + AMPLIFICATION_TOL."""
        return self.amplification <= 1.0 + AMPLIFICATION_TOL

    @property
    def failing_band(self) -> tuple[float, float] | None:
        """``(lowest, highest)`` failing frequency, rad/s, or None."""
        bad = self.w[~self.holds]
        return None if bad.size == 0 else (float(bad.min()), float(bad.max()))

    def to_dict(self) -> dict:
        """The check as a JSON-ready dict.

        Returns
        -------
        dict
            Every attribute (arrays as lists; infinite margins as None) plus
            ``holds_everywhere`` and ``failing_band`` (the paper's condition) and
            ``filtered_ratio``, ``amplification`` and ``holds_filtered`` (the law with its band).
        """
        band = self.failing_band
        return {"source": self.source, "target": self.target, "w": self.w.tolist(),
                "delta": self.delta.tolist(), "rhs": self.rhs.tolist(), "holds": self.holds.tolist(),
                "margin": [float(m) if np.isfinite(m) else None for m in self.margin],
                "min_margin": self.min_margin if np.isfinite(self.min_margin) else None,
                "worst_w": self.worst_w, "holds_everywhere": self.holds_everywhere,
                "failing_band": list(band) if band else None, "delta_source": self.delta_source,
                "learning_band": self.band.to_dict() if self.band is not None else None,
                "filtered_ratio": self.filtered_ratio.tolist(), "amplification": self.amplification,
                "holds_filtered": self.holds_filtered, "amplification_tolerance": AMPLIFICATION_TOL}


def theorem_rhs(loop: LoopSystem, w: np.ndarray) -> np.ndarray:
    """The Theorem's bound ``|1 + P_hat C| / 2`` of a source's model on ``w`` (rad/s).

    Parameters
    ----------
    loop : LoopSystem
        System j-1 (its model's loop is used).
    w : array_like
        Frequencies, rad/s.

    Returns
    -------
    numpy.ndarray
        The bound per frequency.
    """
    model = loop.nominal
    return np.abs(1.0 + freqresp(model.P, w) * freqresp(model.C, w)) / 2.0


def learning_pairs(names: list[str], order: list[str] | tuple[str, ...]) -> list[tuple[str, str]]:
    """Cyclic learning pairs ``(order[i-1], order[i])``: ``[a, b, c]`` -> ``(a, b), (b, c), (c, a)``.

    Parameters
    ----------
    names : list of str
        The fleet's system names.
    order : sequence of str
        Learning order (paper Sec. IV: scenario 4 flies ``["UAV1", "UAV3", "UAV2"]``); each
        name once, at least two.

    Returns
    -------
    list of (str, str)
        ``(source, target)`` pairs, the cycle closed by ``(order[-1], order[0])``.

    Raises
    ------
    SpecError
        Fewer than two names, an unknown or a repeated name.
    """
    order = list(order)
    if len(order) < 2:
        raise SpecError(f"`order`: got {order!r}, expected at least two system names")
    unknown = [n for n in order if n not in names]
    if unknown:
        raise SpecError(f"`order`: unknown systems {unknown}; the fleet has {list(names)}")
    if len(set(order)) != len(order):
        raise SpecError(f"`order`: got {order!r}; each system may appear once (the cycle closes itself)")
    return [(order[i - 1], order[i]) for i in range(1, len(order))] + [(order[-1], order[0])]


def theorem_check(fleet, order: list[str] | tuple[str, ...] | None, deltas: dict[str, DeltaSet],
                  w: np.ndarray | None = None, source: str = "bound",
                  bands: dict[tuple[str, str], LearningBand | None] | None = None) -> list[PairCheck]:
    """Check ``|Delta_{j-1}| < |1 + P_{j-1} C_{j-1}| / 2`` for every cyclic pair of ``order``.

    Parameters
    ----------
    fleet : ilcdob.Fleet
        The fleet.
    order : list of str or None
        Learning order (cyclic; None: the fleet's order). Scenario 4 flies
        ``["UAV1", "UAV3", "UAV2"]``.
    deltas : dict of str -> DeltaSet
        Delta set of every system that is a source of some pair.
    w : array, rad/s, optional
        Frequencies; default each Delta set's own grid. With ``source="bound"`` the bound is
        interpolated (log-log) onto ``w``, which must lie inside the set's grid.
    source : {"bound", "samples"}
        ``|Delta|`` from the set's bound, or ``max_k |Delta_k|`` of its sampled plants.
    bands : dict of (source, target) to LearningBand, optional
        The learning band of each pair's law (missing pairs: unfiltered).

    Returns
    -------
    list of PairCheck
        One per pair, in the order of the pairs.
    """
    if source not in _SOURCES:
        raise SpecError(f"`source`: got {source!r}, expected one of {_SOURCES}")
    names = list(fleet.names)
    loops = dict(zip(names, fleet.loops))
    pairs = learning_pairs(names, names if order is None else order)
    out = []
    for src, tgt in pairs:
        if src not in deltas:
            raise SpecError(f"`deltas`: no Delta set for system {src!r} (source of {src} -> {tgt}); "
                            f"build one with ilcdob.design.delta_set(...) and pass it under {src!r}")
        ds = deltas[src]
        if not isinstance(ds, DeltaSet):
            raise SpecError(f"`deltas[{src!r}]`: expected a DeltaSet, got {type(ds).__name__}")
        ww = np.asarray(ds.w if w is None else w, dtype=float)
        if ww.ndim != 1 or ww.size == 0 or np.any(ww <= 0) or np.any(ww >= np.pi / loops[src].ts):
            raise SpecError(f"`w`: expected a 1-D array of frequencies in (0, Nyquist = "
                            f"{np.pi / loops[src].ts:.4g}) rad/s")
        if source == "bound":
            bw, bb = np.asarray(ds.w, float), np.asarray(ds.bound, float)
            if w is not None and (ww.min() < bw.min() * (1 - 1e-12) or ww.max() > bw.max() * (1 + 1e-12)):
                raise SpecError(f"`w`: [{ww.min():.4g}, {ww.max():.4g}] rad/s leaves the Delta set's grid "
                                f"[{bw.min():.4g}, {bw.max():.4g}]; pass w inside it or use source='samples'")
            delta = bb if w is None else np.exp(np.interp(np.log(ww), np.log(bw), np.log(np.maximum(bb, 1e-300))))
        else:
            delta = np.max(np.abs(ds.deltas(ww)), axis=0)
        rhs = theorem_rhs(loops[src], ww)
        with np.errstate(divide="ignore"):
            margin = np.where(delta > 0, rhs / np.where(delta > 0, delta, 1.0), np.inf)
        i = int(np.argmin(margin))
        out.append(PairCheck(source=src, target=tgt, w=ww, delta=np.asarray(delta, float), rhs=rhs,
                             holds=delta < rhs, margin=margin, min_margin=float(margin[i]),
                             worst_w=float(ww[i]), delta_source=source, band=(bands or {}).get((src, tgt))))
    return out


def format_theorem_table(checks: list[PairCheck]) -> str:
    """Plain-text table: per pair the paper's condition (unfiltered) and the law with its band.

    Parameters
    ----------
    checks : list of PairCheck
        Results of :func:`theorem_check`.

    Returns
    -------
    str
        The table, a header row and a rule first: the paper's condition (holds, minimum
        margin, worst frequency, failing band), the learning band and the filtered law's
        largest first-order error ratio and verdict.
    """
    head = (f"{'pair':<16} {'paper':<6} {'min margin':>10} {'worst w':>9}  {'failing band':<18} "
            f"{'band [rad/s]':>12} {'max ratio':>10}  {'verdict':<7}")
    rows = [head, "-" * len(head)]
    for c in checks:
        band = c.failing_band
        band_s = "-" if band is None else f"{band[0]:.4g} .. {band[1]:.4g}"
        mm = f"{c.min_margin:.3g}" if np.isfinite(c.min_margin) else "inf"
        cutoff = "off" if c.band is None or c.band.cutoff is None else f"{c.band.cutoff:.4g}"
        rows.append(f"{c.source + ' -> ' + c.target:<16} {'yes' if c.holds_everywhere else 'NO':<6} "
                    f"{mm:>10} {c.worst_w:>9.4g}  {band_s:<18} {cutoff:>12} {c.amplification:>10.4g}  "
                    f"{'holds' if c.holds_filtered else 'FAILS':<7}")
    rows.append("paper: |Delta| < |1 + P C|/2 at every frequency (the Theorem's filters unfiltered); "
                f"max ratio: largest 1 - F + F |Delta|/(|1 + P C|/2) with the learning band F; verdict: "
                f"max ratio <= 1 + {AMPLIFICATION_TOL:g}")
    return "\n".join(rows)
