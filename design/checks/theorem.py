"""Will learning help? The exact worst case per learning pair and frequency, and the paper's condition.

**The paper's first-order condition** (docs/theory.md section 2). With true plant
``P = (1 + Delta) P_hat``, learning from system j-1 leaves system j with
``e_j ~ -2 Delta_{j-1} / (1 + P_{j-1} C_{j-1}) {e'_j}``, so learning helps at the
frequencies where::

    |Delta_{j-1}(e^{jw Ts})|  <  |1 + P_{j-1}(e^{jw Ts}) C_{j-1}(e^{jw Ts})| / 2

checked frequency by frequency with the discrete model ``P_hat`` and PID ``C`` of system j-1
(:func:`ilcdob.loop.freqresp`) and ``|Delta|`` from the Delta set's bound ``W`` (3 sigma of the
identification, or the fleet bound) or from its sampled plants (``max_k |Delta_k|``). The
margin is ``rhs / lhs`` (> 1: the condition holds). It is a first-order expansion in Delta and
neither sufficient nor necessary: an all-pass ``|Delta| = 0.3`` passes it with margin 1.09 on
the built-in fleet's UAV3 and makes the error 1.09 times worse than the DOB alone; a
slow-PID vehicle fails it at 0.65-1.01 rad/s and still learns to a ratio of 0.51
(tests/test_check_exact.py).

**The exact worst case** (:mod:`..methods.robust_set`, module docstring). Per frequency, system j's
error with learning over its error with the DOB alone is, for any plant of system j::

    T(w) = e_j / e'_j = 1 - F(w) (1 + Delta) / (1 + T0 Delta),    T0 = P_hat (M + C) / D_hat

(``T0``: complementary sensitivity of system j-1's nominal DOB loop, ``D_hat = 1 - Q + P_hat (M + C)``;
``F``: what the law puts in front of the closed-form filters, 1 for the Theorem's filters). The
Moebius map ``Delta -> (1 + Delta)/(1 + T0 Delta)`` takes the disc ``|Delta| <= W`` onto a
disc, so ``max_{|Delta| <= W} |T(w)|`` is a closed form (:func:`exact_worst_ratio`), exact with no
expansion; it is unbounded (``inf``) where ``W |T0| >= 1``: there the disc contains
``Delta = -1/T0``, an admissible error that brings system j-1's loop to its stability boundary.
When the fleet file states a system's plant and its model, its Delta is known and
``|T(w)|`` is evaluated for it (:func:`exact_ratio_for_delta`).

What it covers, as :mod:`..methods.robust_set`'s guarantee: every Delta (any phase) with
``|Delta(e^{jw Ts})| <= W(w)``, hence conservative for a structured set (real gains, fixed-order
high-pass errors); the disturbance part of the error over trials long against the filters'
memory (Parseval); not the source's own learning signal (modelled with its nominal ``Gf``),
reference terms or noise that differs between the vehicles.

**The law as applied.** The law a vehicle flies passes the learning band (:mod:`ilcdob.design.filters.band`),
a real gain ``F_band`` in [0, 1]; a designed filter given by its response relative to the closed
form multiplies it. The exact figures use ``F = F_band F_design``. The first-order figure of the
band, ``1 - F + F |Delta| / (|1 + P C|/2)`` (:attr:`PairCheck.filtered_ratio`), is kept for
reference (the band's model edge is chosen on it).

**Verdict** (:attr:`PairCheck.holds_exact`): improvement is guaranteed when the exact worst case
of the law as applied stays within ``1 +`` :data:`EXACT_TOL` at every frequency of the checked
grid (the Delta set's grid, refined :data:`REFINE` times between its points) and, when the
plant is stated, the ratio for its Delta does too. The paper's condition is shown beside it;
:attr:`PairCheck.statement` says in words where the two disagree.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass
from functools import partial
from typing import Callable

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem, freqresp

from ..filters.band import AMPLIFICATION_TOL, LearningBand
from ..sets.delta import DeltaSet, delta_bound
from ..sets.worst_case import mask_intervals, ratio_for_delta, uncertainty_cones, worst_case_ratio

__all__ = ["PairCheck", "theorem_check", "theorem_rhs", "format_theorem_table", "learning_pairs",
           "exact_worst_ratio", "exact_worst_on_set", "exact_ratio_for_delta", "bound_delta_sets", "EXACT_TOL",
           "REFINE"]

_SOURCES = ("bound", "samples")

#: The exact worst case of the law as applied may exceed 1 by this much at a frequency before the
#: verdict fails (the learning band's own tolerance, :data:`~ilcdob.design.filters.band.AMPLIFICATION_TOL`).
EXACT_TOL = AMPLIFICATION_TOL
#: The exact figures are evaluated on the Delta set's grid with this many log-spaced steps between
#: two of its points (200 points to Nyquist become ~1600: steps of about 0.5 % in frequency).
REFINE = 8


def _inf_to_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _bands_text(bands: list[tuple[float, float]]) -> str:
    return ", ".join(f"{lo:.3g}" if lo == hi else f"{lo:.3g}-{hi:.3g}" for lo, hi in bands) + " rad/s"


@dataclass(frozen=True)
class PairCheck:
    """Learning step ``source`` (j-1) -> ``target`` (j): the exact worst case and the paper's condition.

    The paper's first-order condition (paper Sec. III, Case II; docs/theory.md section 2) on
    ``w``, and the exact worst-case error ratio of the law as applied (module docstring) on
    ``exact_w``.

    Attributes
    ----------
    source, target : str
        Names of systems j-1 and j.
    w : numpy.ndarray
        Frequencies of the paper's condition, rad/s.
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
    exact_w : numpy.ndarray or None
        Frequencies of the exact figures, rad/s (None: not computed).
    exact_bound : numpy.ndarray or None
        ``W`` on ``exact_w``: the radius of the disc of admissible ``Delta_{j-1}``.
    exact : numpy.ndarray or None
        ``max_{|Delta| <= W} |e_j / e'_j|`` of the law as applied (band and designed filter), per
        frequency of ``exact_w`` (``inf`` where unbounded).
    exact_unfiltered : numpy.ndarray or None
        The same for the Theorem's filters alone (``F = 1``, the law of the paper's condition).
    reach : numpy.ndarray or None
        ``W |T0|`` on ``exact_w``; ``>= 1``: the disc contains ``Delta = -1/T0`` (system j-1's
        loop at its stability boundary) and the worst case is unbounded wherever ``F != 0``.
    known : numpy.ndarray or None
        ``|e_j / e'_j|`` of the law as applied for system j-1's stated plant (fleet file: plant
        and model), on ``exact_w``; None when the model is the plant.
    known_delta : numpy.ndarray or None
        ``|Delta_{j-1}|`` of the stated plant on ``exact_w``.
    law : str
        What ``F`` is: ``"closed form"`` (the band only) or ``"designed filter"``.
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
    exact_w: np.ndarray | None = None
    exact_bound: np.ndarray | None = None
    exact: np.ndarray | None = None
    exact_unfiltered: np.ndarray | None = None
    reach: np.ndarray | None = None
    known: np.ndarray | None = None
    known_delta: np.ndarray | None = None
    law: str = "closed form"

    # ---- the paper's first-order condition -------------------------------------------------------
    @property
    def holds_everywhere(self) -> bool:
        """Whether the paper's first-order condition holds at every frequency of ``w`` (unfiltered law)."""
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
        """Largest :attr:`filtered_ratio` (first order; <= 1: the filtered law never makes a frequency worse)."""
        return float(np.max(self.filtered_ratio))

    @property
    def holds_filtered(self) -> bool:
        """The first-order verdict for the law with its band: :attr:`amplification` <= 1 + AMPLIFICATION_TOL."""
        return self.amplification <= 1.0 + AMPLIFICATION_TOL

    @property
    def failing_band(self) -> tuple[float, float] | None:
        """``(lowest, highest)`` frequency where the paper's condition fails, rad/s, or None."""
        bad = self.w[~self.holds]
        return None if bad.size == 0 else (float(bad.min()), float(bad.max()))

    # ---- the exact worst case ----------------------------------------------------------------------
    def _require_exact(self) -> None:
        if self.exact is None:
            raise SpecError(f"pair {self.source} -> {self.target}: no exact figures (built without them); "
                            "use theorem_check(...)")

    @property
    def exact_worst(self) -> float:
        """Largest exact worst-case ratio of the law as applied over ``exact_w`` (``inf``: unbounded)."""
        self._require_exact()
        return float(np.max(self.exact))

    @property
    def exact_worst_w(self) -> float:
        """Frequency of :attr:`exact_worst`, rad/s (the lowest, if it is unbounded on a band)."""
        self._require_exact()
        return float(self.exact_w[int(np.argmax(self.exact))])

    @property
    def exact_unfiltered_worst(self) -> float:
        """Largest exact worst case of the Theorem's filters alone (``F = 1``)."""
        self._require_exact()
        return float(np.max(self.exact_unfiltered))

    @property
    def exact_unfiltered_worst_w(self) -> float:
        """Frequency of :attr:`exact_unfiltered_worst`, rad/s."""
        self._require_exact()
        return float(self.exact_w[int(np.argmax(self.exact_unfiltered))])

    @property
    def guaranteed(self) -> bool:
        """Whether the exact worst case over the disc stays within ``1 + EXACT_TOL`` at every frequency."""
        return self.exact_worst <= 1.0 + EXACT_TOL

    @property
    def boundary_bands(self) -> list[tuple[float, float]]:
        """Frequency intervals (rad/s) where ``W |T0| >= 1``: the stated set reaches system j-1's
        stability boundary (``Delta = -1/T0`` admissible)."""
        self._require_exact()
        return mask_intervals(self.exact_w, self.reach >= 1.0)

    @property
    def exceed_bands(self) -> list[tuple[float, float]]:
        """Frequency intervals (rad/s) where the exact worst case exceeds ``1 + EXACT_TOL``."""
        self._require_exact()
        return mask_intervals(self.exact_w, self.exact > 1.0 + EXACT_TOL)

    @property
    def known_worst(self) -> float | None:
        """Largest ratio for the stated plant's Delta (None: no plant stated apart from the model)."""
        return None if self.known is None else float(np.max(self.known))

    @property
    def known_worst_w(self) -> float | None:
        """Frequency of :attr:`known_worst`, rad/s."""
        return None if self.known is None else float(self.exact_w[int(np.argmax(self.known))])

    @property
    def known_outside(self) -> list[tuple[float, float]]:
        """Frequency intervals (rad/s) where the stated plant's ``|Delta|`` exceeds the bound ``W``
        (by more than 0.1 %): there the disc does not cover it."""
        if self.known_delta is None:
            return []
        return mask_intervals(self.exact_w, self.known_delta > self.exact_bound * (1 + 1e-3))

    @property
    def holds_exact(self) -> bool:
        """The verdict: :attr:`guaranteed`, and the stated plant's ratio (if any) within ``1 + EXACT_TOL``."""
        return self.guaranteed and (self.known is None or self.known_worst <= 1.0 + EXACT_TOL)

    @property
    def agrees(self) -> bool:
        """Whether the paper's first-order condition (:attr:`holds_everywhere`) and :attr:`holds_exact` agree."""
        return self.holds_everywhere == self.holds_exact

    @property
    def statement(self) -> str:
        """The verdict, and where the paper's condition disagrees with it, in words (one paragraph)."""
        self._require_exact()
        pair = f"{self.source} -> {self.target}"
        worst = "unbounded" if not np.isfinite(self.exact_worst) else f"{self.exact_worst:.3g}"
        applied = "the law as applied" + ("" if self.band is None or self.band.cutoff is None
                                          else f" (learning band {self.band.cutoff:.4g} rad/s)")
        parts = []
        plant_said = False
        if self.holds_exact:
            what = ("improvement guaranteed" if self.exact_worst <= 1.0 else
                    f"guaranteed at most {100 * (self.exact_worst - 1):.2g} % worse than the DOB alone (no improvement "
                    "guaranteed)")
            parts.append(f"{pair}: {what}: the exact worst case of |e_j/e'_j| over |Delta| <= W is "
                         f"{worst} (at {self.exact_worst_w:.4g} rad/s) for {applied}, within 1 + {EXACT_TOL:g}.")
        elif self.guaranteed:  # the disc is fine, the stated plant (outside it) is not
            plant_said = True
            parts.append(f"{pair}: improvement NOT guaranteed: over |Delta| <= W the exact worst case of |e_j/e'_j| "
                         f"is {worst} (at {self.exact_worst_w:.4g} rad/s) for {applied}, but for {self.source}'s "
                         f"stated plant (Delta known) it is {self.known_worst:.3g} at {self.known_worst_w:.4g} rad/s: "
                         f"learning makes {self.target}'s error worse than the DOB alone.")
        else:
            parts.append(f"{pair}: improvement NOT guaranteed: the exact worst case of |e_j/e'_j| over |Delta| <= W "
                         f"is {worst} at {self.exact_worst_w:.4g} rad/s for {applied}; learning can make "
                         f"{self.target}'s error worse than the DOB alone"
                         + (f" at {_bands_text(self.exceed_bands)}." if self.exceed_bands else "."))
        if self.boundary_bands:
            parts.append(f"The stated bound lets {self.source}'s loop reach its stability boundary inside the set "
                         f"(W |T0| >= 1, Delta = -1/T0 admissible) at {_bands_text(self.boundary_bands)}: the worst "
                         "case is unbounded there wherever the law learns.")
        if self.known is not None and not plant_said:
            kw = self.known_worst
            parts.append(f"For {self.source}'s stated plant (Delta known) the ratio is at most {kw:.3g} at "
                         f"{self.known_worst_w:.4g} rad/s" + (" (worse than the DOB alone)." if kw > 1 + EXACT_TOL
                                                              else "."))
        if self.known_outside:
            parts.append(f"The stated plant's |Delta| exceeds the stated bound at {_bands_text(self.known_outside)}: "
                         "the disc does not cover it there.")
        if not self.agrees:
            if self.holds_everywhere:
                parts.append(f"The paper's first-order condition holds (min margin {self.min_margin:.3g}) and "
                             "DISAGREES with the exact figure.")
            else:
                lo, hi = self.failing_band
                why = ("the learning band keeps the law safe there"
                       if self.exact_unfiltered_worst > 1.0 + EXACT_TOL else
                       f"the Theorem's filters improve anyway (exact worst case without the band "
                       f"{self.exact_unfiltered_worst:.3g} at {self.exact_unfiltered_worst_w:.4g} rad/s)")
                parts.append(f"The paper's first-order condition fails at {lo:.3g}-{hi:.3g} rad/s (min margin "
                             f"{self.min_margin:.3g}) and DISAGREES with the exact figure: {why}.")
        return " ".join(parts)

    def to_dict(self) -> dict:
        """The check as a JSON-ready dict.

        Returns
        -------
        dict
            The paper's first-order condition as before (every attribute on ``w``, arrays as
            lists, infinite margins as None, ``holds_everywhere``, ``failing_band``,
            ``filtered_ratio``, ``amplification``, ``holds_filtered``), and:

            ``exact``
                the exact worst case of the law as applied: ``description``, ``units``,
                ``w_rad_s``, ``bound``, ``ratio`` (None where unbounded), ``worst_ratio``
                (None: unbounded), ``worst_w_rad_s``, ``unfiltered_worst_ratio`` and
                ``unfiltered_worst_w_rad_s`` (the Theorem's filters alone), ``boundary_bands_rad_s``,
                ``tolerance``, ``guaranteed``;
            ``stated_plant``
                None, or the ratio for the stated plant's Delta (``ratio``, ``abs_delta``,
                ``worst_ratio``, ``worst_w_rad_s``, ``outside_bound_rad_s``);
            ``verdict``
                ``"holds"`` or ``"fails"`` (:attr:`holds_exact`), ``verdict_basis``, ``agrees``
                (with the paper's condition) and ``statement`` (:attr:`statement`).
        """
        band = self.failing_band
        out = {"source": self.source, "target": self.target, "w": self.w.tolist(),
               "delta": self.delta.tolist(), "rhs": self.rhs.tolist(), "holds": self.holds.tolist(),
               "margin": [float(m) if np.isfinite(m) else None for m in self.margin],
               "min_margin": self.min_margin if np.isfinite(self.min_margin) else None,
               "worst_w": self.worst_w, "holds_everywhere": self.holds_everywhere,
               "failing_band": list(band) if band else None, "delta_source": self.delta_source,
               "learning_band": self.band.to_dict() if self.band is not None else None,
               "filtered_ratio": self.filtered_ratio.tolist(), "amplification": self.amplification,
               "holds_filtered": self.holds_filtered, "amplification_tolerance": AMPLIFICATION_TOL,
               "paper_first_order": {
                   "description": "the paper's first-order condition |Delta| < |1 + P C|/2 of the source's model at "
                                  "every frequency (Theorem's filters, unfiltered); keys holds_everywhere, margin "
                                  "(= rhs/delta), min_margin, worst_w (rad/s), failing_band (rad/s); the first-order "
                                  "ratio of the law with its band is filtered_ratio / amplification",
                   "holds": self.holds_everywhere}}
        if self.exact is None:
            return out
        out["exact"] = {
            "description": "exact worst case of |e_j / e'_j| (target's error with learning over its error with the "
                           "DOB alone, per frequency) over every Delta of the source with |Delta| <= W, for the law as "
                           f"applied ({self.law} filters times the learning band); null where unbounded (W |T0| >= 1: "
                           "the source's loop can reach its stability boundary inside the set)",
            "units": {"w_rad_s": "rad/s", "bound": "1 (relative model error)", "ratio": "1 (|e_j| / |e'_j|)"},
            "w_rad_s": self.exact_w.tolist(), "bound": self.exact_bound.tolist(),
            "ratio": [_inf_to_none(x) for x in self.exact],
            "worst_ratio": _inf_to_none(self.exact_worst), "worst_w_rad_s": self.exact_worst_w,
            "unfiltered_worst_ratio": _inf_to_none(self.exact_unfiltered_worst),
            "unfiltered_worst_w_rad_s": self.exact_unfiltered_worst_w,
            "boundary_bands_rad_s": [list(b) for b in self.boundary_bands],
            "tolerance": EXACT_TOL, "guaranteed": self.guaranteed}
        out["stated_plant"] = None if self.known is None else {
            "description": "|e_j / e'_j| of the law as applied for the source's stated plant (fleet file: plant and "
                           "model, so Delta = P/P_hat - 1 is known)",
            "units": {"ratio": "1 (|e_j| / |e'_j|)", "abs_delta": "1", "w": "rad/s (exact.w_rad_s)"},
            "ratio": [_inf_to_none(x) for x in self.known], "abs_delta": self.known_delta.tolist(),
            "worst_ratio": _inf_to_none(self.known_worst), "worst_w_rad_s": self.known_worst_w,
            "outside_bound_rad_s": [list(b) for b in self.known_outside]}
        out.update({"verdict": "holds" if self.holds_exact else "fails",
                    "verdict_basis": f"exact worst case <= 1 + {EXACT_TOL:g} at every frequency of exact.w_rad_s "
                                     "(and for the stated plant, if any)",
                    "agrees": self.agrees, "statement": self.statement})
        return out


def _on_grid(w_set: np.ndarray, bound: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A Delta set's bound interpolated log-log from its grid ``w_set`` onto ``x`` (rad/s)."""
    order = np.argsort(w_set)
    return np.exp(np.interp(np.log(x), np.log(w_set[order]), np.log(np.maximum(bound[order], 1e-300))))


def exact_worst_on_set(source: LoopSystem, w_set: np.ndarray, bound: np.ndarray
                       ) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """The exact worst case over a source's Delta set as :func:`theorem_check` evaluates it, for any law ``F``.

    Parameters
    ----------
    source : LoopSystem
        System j-1.
    w_set, bound : array_like
        The Delta set's grid (rad/s) and its radius ``W`` there.

    Returns
    -------
    (numpy.ndarray, callable)
        The check's grid (``w_set`` refined :data:`REFINE` times, ``W`` interpolated log-log) and
        ``worst(F)``: :func:`exact_worst_ratio` on it for a law response ``F`` there (the learning band's
        ``model`` edge, :func:`~ilcdob.design.filters.band.choose_band`).
    """
    w_set, bound = np.asarray(w_set, float), np.asarray(bound, float)
    we = _refined(w_set)
    a, b, r, _, _ = uncertainty_cones(source, we, _on_grid(w_set, bound, we), margin=0.0)
    return we, lambda f: worst_case_ratio(f, a, b, r)


def exact_worst_ratio(source: LoopSystem, w: np.ndarray, W: np.ndarray, F: np.ndarray | None = None) -> np.ndarray:
    """Exact ``max_{|Delta| <= W} |e_j / e'_j|`` per frequency for learning from ``source`` (module docstring).

    Parameters
    ----------
    source : LoopSystem
        System j-1 (its nominal loop: model ``P_hat``, ``M``, ``C``, ``Q``).
    w : array_like
        Frequencies, rad/s.
    W : array_like
        Radius of the disc of admissible ``Delta`` on ``w`` (a scalar: constant).
    F : array_like, optional
        Response of what the law puts in front of the closed-form filters on ``w`` (complex;
        default 1: the Theorem's filters).

    Returns
    -------
    numpy.ndarray
        The worst case per frequency; ``inf`` where ``W |T0| >= 1`` and ``F != 0`` (the disc reaches
        system j-1's stability boundary), 1 there where ``F = 0``.
    """
    w = np.asarray(w, float)
    W = np.broadcast_to(np.asarray(W, float), w.shape)
    a, b, r, _, _ = uncertainty_cones(source, w, W, margin=0.0)
    return worst_case_ratio(np.ones(w.shape) if F is None else F, a, b, r)


def exact_ratio_for_delta(source: LoopSystem, w: np.ndarray, delta: np.ndarray,
                          F: np.ndarray | None = None) -> np.ndarray:
    """``|e_j / e'_j| = |1 - F (1 + Delta)/(1 + T0 Delta)|`` for one known ``Delta(w)`` of ``source``.

    Parameters
    ----------
    source : LoopSystem
        System j-1.
    w : array_like
        Frequencies, rad/s.
    delta : array_like
        Its multiplicative model error ``Delta(e^{jw Ts}) = P/P_hat - 1`` on ``w`` (complex).
    F : array_like, optional
        As in :func:`exact_worst_ratio`.

    Returns
    -------
    numpy.ndarray
        The ratio per frequency (``inf`` where ``1 + T0 Delta = 0``).
    """
    w = np.asarray(w, float)
    t0 = uncertainty_cones(source, w, np.zeros(w.shape), margin=0.0)[3]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = ratio_for_delta(np.ones(w.shape) if F is None else F, t0, delta)
    return np.where(np.isfinite(out), out, np.inf)


def _refined(w: np.ndarray, k: int = REFINE) -> np.ndarray:
    """``w`` with ``k - 1`` log-spaced points inserted between neighbours (sorted, unique)."""
    ws = np.unique(w)
    if ws.size < 2 or k <= 1:
        return ws
    lw = np.log(ws)
    steps = lw[:-1, None] + np.outer(np.diff(lw), np.arange(k) / k)
    return np.exp(np.concatenate([steps.ravel(), lw[-1:]]))


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


def bound_delta_sets(fleet, names: list[str] | tuple[str, ...] | None = None) -> dict[str, DeltaSet]:
    """Delta sets of the named systems holding their bound only, without sampled plants.

    :func:`theorem_check` with ``source="bound"`` and the learning band's model edge
    (:func:`ilcdob.design.pair.pair_band`) read a Delta set's ``w`` and ``bound`` and nothing
    else. Those are :func:`~ilcdob.design.sets.delta.delta_bound` of the system, the same arrays
    :func:`~ilcdob.design.sets.delta.delta_set` (and :func:`~ilcdob.design.pair.fleet_delta_sets`)
    attach to its samples for any sample count, seed or order of the systems, so a check on
    these sets is the check on the sampled sets, without building a closed loop per sampled
    plant. The sets have no loops (``loops == ()``): :meth:`DeltaSet.deltas` and
    ``theorem_check(..., source="samples")`` need the sampled sets.

    Parameters
    ----------
    fleet : ilcdob.Fleet
        The fleet.
    names : sequence of str, optional
        Systems, each once (default: every system of the fleet).

    Returns
    -------
    dict of str to DeltaSet
        Name -> the system's bound on ``w`` (``nominal``: the loop of its model, ``rejected`` 0).

    Raises
    ------
    SpecError
        An unknown or repeated name; a system with neither an identification nor a bound in
        the fleet file.
    """
    names = list(fleet.names if names is None else names)
    unknown = [n for n in names if n not in fleet.names]
    if unknown or len(set(names)) != len(names):
        raise SpecError(f"`names`: got {names!r}, expected system names of the fleet, each once; the fleet has "
                        f"{list(fleet.names)}")
    specs = {s.name: s for s in fleet.systems}
    out = {}
    for name in names:
        found = delta_bound(specs[name], fleet.sample_time)
        if found is None:
            raise SpecError(f"system {name!r}: no identification in the fleet and no `uncertainty` bound, so no "
                            "Delta set; identify it (ilcdob identify-fleet) or state `uncertainty = { bound = 0.2 }` "
                            "in the fleet file")
        w, bound, source = found
        out[name] = DeltaSet(name, fleet.loop(name).nominal, (), w, bound, 0, source)
    return out


def theorem_check(fleet, order: list[str] | tuple[str, ...] | None, deltas: dict[str, DeltaSet],
                  w: np.ndarray | None = None, source: str = "bound",
                  bands: dict[tuple[str, str], LearningBand | None] | None = None,
                  filters: dict[tuple[str, str], Callable[[np.ndarray], np.ndarray]] | None = None) -> list[PairCheck]:
    """The exact worst case and the paper's condition for every cyclic pair of ``order`` (module docstring).

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
        Frequencies of both figures; default each Delta set's own grid for the paper's
        condition, refined :data:`REFINE` times for the exact figures. With ``source="bound"``
        the bound is interpolated (log-log) between the set's points, and ``w`` must lie
        inside the set's grid.
    source : {"bound", "samples"}
        ``|Delta|`` (and the disc's radius ``W``) from the set's bound, or ``max_k |Delta_k|``
        of its sampled plants.
    bands : dict of (source, target) to LearningBand, optional
        The learning band of each pair's law (missing pairs: unfiltered).
    filters : dict of (source, target) to callable, optional
        ``F(w)`` (rad/s -> complex response) of a designed filter the pair's law applies
        relative to the closed form (e.g. :meth:`~ilcdob.design.methods.robust_set.RobustSetDesign.response`);
        it multiplies the band in the exact figures (missing pairs: the closed form, ``F = 1``).

    Returns
    -------
    list of PairCheck
        One per pair, in the order of the pairs.
    """
    if source not in _SOURCES:
        raise SpecError(f"`source`: got {source!r}, expected one of {_SOURCES}")
    fleet.require_paper_loops("theorem_check (ilcdob.design.checks.channel.channel_check serves such pairs)")
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
        loop = loops[src]
        if ww.ndim != 1 or ww.size == 0 or np.any(ww <= 0) or np.any(ww >= np.pi / loop.ts):
            raise SpecError(f"`w`: expected a 1-D array of frequencies in (0, Nyquist = "
                            f"{np.pi / loop.ts:.4g}) rad/s")
        we = ww if w is not None else _refined(ww)
        if source == "bound":
            bw, bb = np.asarray(ds.w, float), np.asarray(ds.bound, float)
            if w is not None and (ww.min() < bw.min() * (1 - 1e-12) or ww.max() > bw.max() * (1 + 1e-12)):
                raise SpecError(f"`w`: [{ww.min():.4g}, {ww.max():.4g}] rad/s leaves the Delta set's grid "
                                f"[{bw.min():.4g}, {bw.max():.4g}]; pass w inside it or use source='samples'")
            on = partial(_on_grid, bw, bb)
            delta = bb if w is None else on(ww)
            W = on(we)
        else:
            if not ds.loops:
                raise SpecError(f"`deltas[{src!r}]`: holds the bound only (no sampled plants), so source='samples' "
                                "has nothing to take |Delta| from; draw the set with ilcdob.design.delta_set(...) or "
                                "use source='bound'")
            delta = np.max(np.abs(ds.deltas(ww)), axis=0)
            W = delta if w is not None else np.max(np.abs(ds.deltas(we)), axis=0)
        rhs = theorem_rhs(loop, ww)
        with np.errstate(divide="ignore"):
            margin = np.where(delta > 0, rhs / np.where(delta > 0, delta, 1.0), np.inf)
        i = int(np.argmin(margin))
        band = (bands or {}).get((src, tgt))
        design = (filters or {}).get((src, tgt))
        f_law = band.response(we).astype(complex) if band is not None else np.ones(we.shape, complex)
        if design is not None:
            f_law = f_law * np.asarray(design(we), complex).reshape(we.shape)
        a, b, r, t0, _ = uncertainty_cones(loop, we, W, margin=0.0)
        exact = worst_case_ratio(f_law, a, b, r)
        unfiltered = worst_case_ratio(np.ones(we.shape), a, b, r)
        known = known_delta = None
        spec = next(s for s in fleet.systems if s.name == src)
        if spec.model is not None:
            dk = freqresp(loop.P, we) / freqresp(loop.nominal.P, we) - 1.0
            known, known_delta = exact_ratio_for_delta(loop, we, dk, f_law), np.abs(dk)
        out.append(PairCheck(source=src, target=tgt, w=ww, delta=np.asarray(delta, float), rhs=rhs,
                             holds=delta < rhs, margin=margin, min_margin=float(margin[i]),
                             worst_w=float(ww[i]), delta_source=source, band=band, exact_w=we,
                             exact_bound=np.asarray(W, float), exact=exact, exact_unfiltered=unfiltered,
                             reach=np.abs(t0) * W, known=known, known_delta=known_delta,
                             law="designed filter" if design is not None else "closed form"))
    return out


def _ratio(x: float | None) -> str:
    if x is None:
        return "-"
    return "inf" if not np.isfinite(x) else f"{x:.3g}"


def format_theorem_table(checks: list[PairCheck]) -> str:
    """Plain-text table: per pair the paper's first-order condition and the exact worst case of the law.

    Parameters
    ----------
    checks : list of PairCheck
        Results of :func:`theorem_check`.

    Returns
    -------
    str
        A header row and a rule, one row per pair (the paper's first-order condition: holds,
        minimum margin, its frequency, failing band; the learning band; the exact worst-case
        ratio of the law as applied and its frequency; the ratio for a stated plant; the
        verdict), then one paragraph per pair in words (:attr:`PairCheck.statement`) and the legend.
    """
    head = (f"{'pair':<16} {'paper':<6} {'min margin':>10} {'margin w':>8}  {'failing band':<16} "
            f"{'band [rad/s]':>12} {'exact worst':>11} {'worst w':>8} {'plant':>7}  {'verdict':<7} agree")
    rows = [head, "-" * len(head)]
    for c in checks:
        band = c.failing_band
        band_s = "-" if band is None else f"{band[0]:.3g} .. {band[1]:.3g}"
        mm = f"{c.min_margin:.3g}" if np.isfinite(c.min_margin) else "inf"
        cutoff = "off" if c.band is None or c.band.cutoff is None else f"{c.band.cutoff:.4g}"
        rows.append(f"{c.source + ' -> ' + c.target:<16} {'yes' if c.holds_everywhere else 'NO':<6} "
                    f"{mm:>10} {c.worst_w:>8.4g}  {band_s:<16} {cutoff:>12} {_ratio(c.exact_worst):>11} "
                    f"{c.exact_worst_w:>8.4g} {_ratio(c.known_worst):>7}  "
                    f"{'holds' if c.holds_exact else 'FAILS':<7} {'yes' if c.agrees else 'NO'}")
    rows.append("")
    for c in checks:
        rows.extend(textwrap.wrap(c.statement, width=len(head), subsequent_indent="  ", break_on_hyphens=False))
    rows.append("")
    rows.extend(textwrap.wrap(
        "paper: the paper's first-order condition |Delta| < |1 + P C|/2 at every frequency (the Theorem's "
        "filters, unfiltered; min margin = min (|1 + P C|/2)/|Delta|). exact worst: max over |Delta| <= W of "
        "|e_j/e'_j| for the law as applied (closed-form filters times the learning band), exact (Moebius map "
        "of the disc), inf where the set reaches the source's stability boundary; plant: the same ratio for "
        "the stated plant's Delta (fleet file: plant and model). verdict: exact worst <= 1 + "
        f"{EXACT_TOL:g} at every checked frequency (improvement guaranteed); agree: the paper's condition "
        "gives the same verdict; frequencies in rad/s.", width=len(head), break_on_hyphens=False))
    return "\n".join(rows)
