"""Robust-set between vehicles on their own controller: the closed form with a robustness FIR guaranteed over the
source's whole identified disc (docs/closed_loop.md, "The uncertainty set and the check").

For a vehicle on its own controller ``Gf = K Gd`` exactly (:mod:`ilcdob.channel_loop`), so the learner's error
with learning over its error without is, per frequency and for any true maps of both vehicles,
``T(w) = 1 - F(w) Gd_{j-1}/Gd_hat_{j-1}`` with ``Gd_{j-1} = (1 + Delta) Gd_hat_{j-1}``. That is the paper loop's
ratio of :mod:`.robust_set` with ``T0 = 0``: the disc ``|Delta| <= W`` maps onto the disc of centre 1 and
radius ``W``, and ``max |T| = |1 - F| + W |F|`` exactly. The same SOCP and exchange design ``F``
(:func:`~.robust_set.design_robust_set`'s steps; ``W`` the fit's 3-sigma bound or a stated one). On a trial::

    d_hat = -Gd_hat_{j-1}^{-1}{e_{j-1} + Gf_hat_{j-1}{u_{j-1}}},      u_j = -F{d_hat} / K_j

``F`` acting on the reconstructed disturbance continued past the trial's end along its trend, as the paper
loop's extended law (:func:`~ilcdob.design.filters.trial_edges.fir_on_trial`, its output before ``t = 0``
continued into the first samples by its effect on the target model, ``StartMatch``). Built for vehicles without
the add-on DOB; the guarantee is per frequency (an infinite horizon); the design flies whole trials of the disc's
extreme maps (:mod:`..maps.whole_trial`) and says where one exceeds it, as for the paper loop.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from functools import cached_property

import numpy as np

from ilcdob.channel_loop import ChannelLoop
from ilcdob.errors import SpecError
from ilcdob.signals import as_signal

from ..filters.noncausal import ZPKFilter, lookahead
from ..filters.trial_edges import StartMatch, fir_on_trial
from ..maps.channel_filters import channel_filters, channel_view
from ..maps.closed_form import matched, simulate_map
from ..maps.finite_horizon import LinearMap, fir_map, law_map, trend_map, zpk_map
from ..maps.whole_trial import WholeTrialFigure, whole_trial_figure
from .robust_set import (RobustSetDesign, RobustSetOptions, _design_filter, check_feasible, check_whole_trial,
                         choose_start)

__all__ = ["ChannelRobustSetDesign", "design_channel_robust_set"]


@dataclass(frozen=True)
class ChannelRobustSetDesign(RobustSetDesign):
    """:class:`~.robust_set.RobustSetDesign` of two vehicles on their own controller (module docstring).

    Attributes
    ----------
    filters : LearningFilters
        The Theorem's channel pair (:func:`~..maps.channel_filters.channel_filters`).
    F, rho, rho_best, rho_design, rho_guaranteed, feasible, nominal_worst, margin_bands, w, worst, exchanges, \
solve_time, delta_set, finite, trial, whole_trial, start, fold_worst
        As :class:`~.robust_set.RobustSetDesign` (``finite`` None: no figure over every disturbance; ``start``
        as :attr:`~.robust_set.RobustSetOptions.start` chooses, matched to the target model's ``Gd``, which ``-1/K_j`` and ``Gf = K_j Gd`` leave as the map from ``F``'s
        output to its error up to sign; ``whole_trial`` over the disc's gains and all-pass errors at the
        bound's smallest value, of the channel map ``G_ch``).
    """

    @cached_property
    def inverse(self) -> ZPKFilter:
        """``Gd_hat_{j-1}^{-1}`` of the source's map, for non-causal application."""
        view = channel_view(self.filters.source)
        return matched(view.inverse_zeros, view.inverse_poles, view.ts, view.inverse,
                       f"Gd^-1 of {self.filters.source.name!r}")

    @cached_property
    def end_fade(self) -> int:
        """Samples of ``d_hat`` the inverse built from the error continued past the trial's end (its anti-causal
        look-ahead and advance): blended into the trend (as :attr:`RobustSetDesign.end_fade`)."""
        if self.F.advance == 0:
            return 0
        inv = self.inverse.realised
        return int(max((lookahead(p) for p in inv.anticausal_poles), default=0) + inv.advance)

    def projected(self, n: int) -> bool:  # noqa: D102 - the extended law only
        return False

    def _d_hat(self, e_prev: object, df_prev: object) -> np.ndarray:
        e = as_signal(e_prev, "e_prev")
        df = as_signal(df_prev, "df_prev", e.size)
        src = self.filters.source
        e_virtual = e + simulate_map(src.G_f, df) if np.any(df) else e
        return -self.inverse.apply(e_virtual, "e")

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """The target's learning signal on its channel, ``-F{d_hat}/K_j`` (module docstring).

        Parameters
        ----------
        e_prev : array_like
            Tracking error of the source, m.
        df_prev : array_like
            The learning signal it flew on its channel (zeros if none), same length.

        Returns
        -------
        numpy.ndarray
            In the target's channel unit, same length.
        """
        d_hat = self._d_hat(e_prev, df_prev)
        return (-fir_on_trial(d_hat, self.F.h, self.F.advance, self.end_fade, self.start)
                / self.filters.target.gain.constant)

    def trial_map(self, n: int) -> LinearMap:
        """:meth:`apply` on a trial of ``n`` samples, the source flying without learning, as a linear map
        ``e_{j-1} -> u_j``.

        Parameters
        ----------
        n : int
            Samples of the trial.
        """
        a, k = self.F.advance, self.filters.target.gain.constant
        out = -zpk_map(self.inverse, n)
        if a:
            out = trend_map(n, a, self.end_fade) @ out
        out = fir_map(self.F.h, a, n, n_in=n + a, start=self.start) @ out
        return LinearMap(n, n, lambda x: -x / k, lambda y: -y / k, "-1/K_j") @ out

    def to_dict(self) -> dict:
        """Summary for ``filters.json``: :meth:`RobustSetDesign.to_dict` (no figure over every disturbance)."""
        return {**super().to_dict(), "finite_trial": None}


def design_channel_robust_set(source: ChannelLoop, target: ChannelLoop, w_bound: np.ndarray, bound: np.ndarray,
                              options: RobustSetOptions | None = None) -> ChannelRobustSetDesign:
    """The robustness FIR guaranteed over the source's disc ``|Delta| <= W`` (module docstring).

    Parameters
    ----------
    source, target : ChannelLoop
        Vehicles j-1 and j on their own controller, without the add-on DOB.
    w_bound, bound : array
        The source's multiplicative bound ``W`` on ``w_bound`` (rad/s): its fit's 3-sigma bound
        (:meth:`~ilcdob.channel_loop.ChannelLoop.delta`) or a stated one.
    options : RobustSetOptions, optional
        As for the paper's loop; ``trial="extended"`` only.

    Returns
    -------
    ChannelRobustSetDesign

    Raises
    ------
    SpecError
        Not two vehicles on their own controller, an add-on DOB, a ``K`` that depends on frequency, or the
        projected trial law.
    RobustSetInfeasibleError
        As :func:`~.robust_set.design_robust_set`.
    """
    o = options or RobustSetOptions()
    kinds = [lp.name for lp in (source, target)
             if not isinstance(lp, ChannelLoop) or lp.dob is not None or lp.gain.constant is None]
    if kinds:
        raise SpecError(f"robust-set between vehicles on their own controller: {kinds} are ilcdob's loop, fly the "
                        "add-on DOB or have a K that depends on frequency (a cascade's setpoint channel), for which "
                        "it is not built; design with 'closed-form' or 'robust'")
    if o.trial != "extended":
        raise SpecError(f"`trial`: got {o.trial!r}; robust-set for vehicles on their own controller has the extended "
                        "trial law only")
    made = _design_filter(source, target, w_bound, bound, o, None)
    design = ChannelRobustSetDesign(**{f.name: getattr(made, f.name) for f in fields(made)})
    check_feasible(design, source, target, o)
    start = StartMatch.design(target.nominal.G_d, design.F.advance) if design.F.advance else None
    n = int(round(o.whole_trial_s / source.ts))
    w_worst = [float(design.w[np.nanargmax(design.worst)])]

    def fly(d: ChannelRobustSetDesign) -> WholeTrialFigure | None:
        if n < 10:
            return None
        return whole_trial_figure(law_map(d, n), source, target, float(np.min(bound)), w_worst, o.whole_trial_s)

    design = choose_start(replace(design, filters=channel_filters(source, target)), start, o, fly)
    check_whole_trial(design, source, target, o)
    return design
