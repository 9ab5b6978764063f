"""A pair's law on whole trials over the source's stated set, as ``filters.json`` records it (docs/theory.md section 6).

The band of a closed-form (or FIR) design keeps the exact worst case over the stated set within ``1 + tol`` per
frequency (:mod:`.theorem`); a vehicle flies a finite trial. :func:`pair_whole_trial` flies the design's own law
(:meth:`~ilcdob.design.law.stage.LearningLaw.error_map`) on whole trials for the set's extreme plants and the
disturbances that meet a trial's ends (:func:`~..maps.whole_trial.whole_trial_figure`), with the sinusoid at the
frequency where the check's worst case lies, and says whether the worst trial keeps what the band claims.
robust-set designs carry their own figure (:attr:`~..methods.robust_set.RobustSetDesign.whole_trial`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ilcdob.loop import LoopSystem

from ..filters.band import AMPLIFICATION_TOL
from ..maps.whole_trial import whole_trial_figure
from .theorem import bound_delta_sets, exact_worst_on_set

__all__ = ["WHOLE_TRIAL_S", "pair_whole_trial"]

#: Length of the whole trials a design records, s.
WHOLE_TRIAL_S = 60.0


def pair_whole_trial(fleet: Any, design: Any, source: str, target: str,
                     duration_s: float = WHOLE_TRIAL_S) -> dict[str, Any] | None:
    """The worst whole trial of ``design``'s law over the source's stated bound, for ``filters.json``.

    Parameters
    ----------
    fleet : ilcdob.Fleet
        The fleet the design was made for.
    design : PairDesign
        A design whose law is linear (:meth:`~ilcdob.design.pair.PairDesign.learning_law`, ``error_map``).
    source, target : str
        Systems j-1 and j.
    duration_s : float
        Trial length, s.

    Returns
    -------
    dict or None
        :meth:`~..maps.whole_trial.WholeTrialFigure.to_dict` with ``claimed`` (``1 + tol``, the check's
        tolerance, :data:`~..filters.band.AMPLIFICATION_TOL`), ``guaranteed`` (the worst trial keeps it; None if
        no plant was flown) and ``meaning``; None where the source states no constant bound or the loops are
        not the DOB loops whole trials are flown through.
    """
    src, tgt = fleet.loop(source), fleet.loop(target)
    unc = src.spec.uncertainty if isinstance(src, LoopSystem) else None
    if unc is None or getattr(unc, "bound", None) is None or not isinstance(tgt, LoopSystem):
        return None
    bound = float(unc.bound)
    ds = bound_delta_sets(fleet, [source])[source]
    we, worst = exact_worst_on_set(src, ds.w, ds.bound)
    response = np.ones(we.size) if design.band is None else design.band.response(we)
    w_worst = float(we[int(np.nanargmax(worst(response)))])  # an unbounded point (inf) is the worst
    n = int(round(duration_s / src.ts))
    f = whole_trial_figure(design.learning_law().error_map(n), src, tgt, bound, [w_worst], duration_s)
    claimed = 1.0 + AMPLIFICATION_TOL
    return {**f.to_dict(), "claimed": claimed, "guaranteed": bool(f.ratio <= claimed) if f.plants else None,
            "meaning": "largest ||e_j|| / ||e'_j|| of the law as written over whole trials of the source's stated "
                       "set's extreme plants (the model, gains and all-pass errors at the bound) and disturbances "
                       "meeting the trial's ends (design/maps/whole_trial.py); guaranteed: at most 1 + the check's "
                       "tolerance"}
