"""The Theorem's filters between vehicles on their own controllers (paper Sec. III; docs/closed_loop.md).

With ``Gf = K Gd`` per vehicle (:mod:`ilcdob.vehicles.channel_loop`) the Theorem's pair is::

    L1_j = Gd_j / (Gf_j Gd_{j-1}) = 1 / (K_j Gd_{j-1})
    L2_j = L1_j Gf_{j-1}          = K_{j-1} / K_j

so vehicle j learns ``u_j = L1{e_{j-1}} + L2{u_{j-1}}``, and ``Gf_j u_j = -Gd_j d`` when the maps
are exact: the disturbance the source met, in the learner's channel. ``L1`` inverts the source's
identified disturbance map: its zeros are ``Gd_{j-1}``'s poles, its poles ``Gd_{j-1}``'s zeros
(the ZOH sampling zero outside the unit circle becomes anti-causal, a delay an advance), taken
from the sampled map's analytic poles and zeros (:func:`ilcdob.discretize.plant_block`) and
checked against ``1/(K_j Gd_{j-1}(e^{jwTs}))`` (:func:`~.closed_form.matched`).
"""

from __future__ import annotations

import numpy as np

from ilcdob.vehicles.channel_loop import ChannelLoop
from ilcdob.errors import SpecError

from ..filters.noncausal import ZPKFilter
from .closed_form import LearningFilters, matched

__all__ = ["channel_filters"]


def channel_filters(source: ChannelLoop, target: ChannelLoop) -> LearningFilters:
    """The closed-form pair for ``target`` learning from ``source`` (module docstring).

    Parameters
    ----------
    source, target : ChannelLoop
        Vehicles j-1 and j.

    Returns
    -------
    LearningFilters
        ``L1`` (channel unit of the target per m) and ``L2`` (target's channel unit per source's).

    Raises
    ------
    SpecError
        Not channel loops, or different sample times.
    NumericalError
        The zero-pole form of ``L1`` disagrees with its formula.
    """
    for what, lp in (("source", source), ("target", target)):
        if not isinstance(lp, ChannelLoop):
            raise SpecError(f"`{what}`: got {type(lp).__name__}, expected a ChannelLoop (ilcdob.vehicles.channel_loop)")
    if abs(source.ts - target.ts) > 1e-12 * source.ts:
        raise SpecError(f"`ts`: vehicles {source.name!r} ({source.ts} s) and {target.name!r} ({target.ts} s) must "
                        "share one setpoint period")
    blk = source.block
    zeros = blk.zeros if blk.zeros is not None else np.zeros(0, complex)
    k_j = target.channel_gain
    l1 = matched(blk.poles, zeros, source.ts, lambda w: 1.0 / (k_j * blk.response(w)),
                 f"learning filter {source.name!r} -> {target.name!r}")
    l2 = ZPKFilter(np.zeros(0, complex), np.zeros(0, complex), source.channel_gain / k_j, source.ts)
    return LearningFilters(source=source, target=target, L1=l1, L2=l2)
