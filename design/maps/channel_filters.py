"""The Theorem's filters between vehicles that learn through a setpoint channel (paper Sec. III; docs/closed_loop.md).

Every vehicle here is seen through the channel its learning signal enters
(:mod:`ilcdob.channel_loop`): ``Gf = K G`` and ``Gd = (1 - Q) G`` with ``G = P/D`` of its loop,
``Q`` the DOB's where it flies one (the add-on DOB, :mod:`ilcdob.vehicles.dob_loop`) and ``1 - Q`` read
as 1 where it does not. Where the controller's ``K`` depends on frequency (a cascade's position channel,
:mod:`ilcdob.channel_gain`), ``K`` below is the ratio of the sampled maps, ``K_d = Gf(z) / G(z)``, with its
zeros and poles those of the two zero-order holds (their common poles cancelled). ilcdob's PID + DOB loop
is such a vehicle on its acceleration feed-forward (``K = 1``; a learning signal ``u`` there is ``-d_f`` of
the paper's law). With the ratio
``R = Gd/Gf = (1 - Q)/K`` the Theorem's pair is::

    L1_j = Gd_j / (Gf_j Gd_{j-1}) = R_j Gd_{j-1}^{-1}
    L2_j = L1_j Gf_{j-1}          = R_j / R_{j-1} = (K_{j-1}/K_j) (1 - Q_j)/(1 - Q_{j-1})

so ``Gf_j u_j = -Gd_j d`` when the maps are exact: the disturbance the source met, in the learner's
channel. ``L1`` inverts the source's disturbance map: its zeros are ``Gd_{j-1}``'s poles, its poles
``Gd_{j-1}``'s zeros (the ZOH sampling zero outside the unit circle becomes anti-causal, a delay an
advance), taken from the blocks' analytic poles and zeros (:func:`ilcdob.discretize.plant_block`; for
the PID + DOB loop as :func:`~.closed_form.inverse_gd_filter` takes them) and checked against
``R_j / Gd_{j-1}(e^{jwTs})`` (:func:`~.closed_form.matched`).

A loop that integrates (a cascade's velocity integral; :attr:`~ilcdob.channel_loop.ChannelLoop.integrates`) has
``Gd`` vanishing at ``z = 1`` too: ``L1`` then holds an integrator, run from rest over the trial (the source's
error carries a constant disturbance only through its start transient, as with a DOB), and a learner that
integrates itself does not see the constant part of its signal. On a cascade's position channel ``K_d`` has the
velocity integral's pole at ``z = 1``: ``R`` vanishes there and cancels the source's integrator.

``1 - Q`` vanishes at ``z = 1``. Where both vehicles fly a DOB the common root cancels analytically; a
vehicle without a DOB cannot learn from one with a DOB this way: that source's error holds no trace of
a constant disturbance (its DOB removed it), and ``L2`` would integrate.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import control as ct
import numpy as np

from ilcdob.discretize import DiscreteBlock, cancel_roots
from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.channel_loop import SLOWEST_ROOT, ChannelLoop

from .closed_form import LearningFilters, _block, _inverse_gd_response, _plant_zeros, _zeros_without_one, matched

__all__ = ["channel_filters", "channel_view", "channel_gf", "learning_channel", "ChannelView", "channel_map_zeros",
           "gain_roots", "SLOWEST_ZERO"]


@dataclass(frozen=True)
class ChannelView:
    """One vehicle as the channel learning sees it (module docstring).

    Attributes
    ----------
    name : str
    ts : float
        Sample time, s.
    gain : callable
        ``gain(w)``: ``K`` on ``z = e^{jwTs}`` (``w`` in rad/s); the sampled ratio ``K_d`` where ``K`` depends on
        frequency (module docstring).
    q : DiscreteBlock or None
        The DOB's ``Q`` (None: no DOB).
    inverse_zeros, inverse_poles : numpy.ndarray
        Zeros and poles of ``Gd^{-1}`` (z-plane), without the pole ``z = 1`` of a DOB's ``1/(1 - Q)``.
    inverse : callable
        ``inverse(w)``: ``Gd^{-1}(e^{jwTs})`` from the blocks' responses (``w`` in rad/s).
    gain_zeros, gain_poles : numpy.ndarray
        Zeros and poles of ``K_d`` (z-plane; none for a constant ``K``).
    """

    name: str
    ts: float
    gain: Callable[[np.ndarray], np.ndarray]
    q: DiscreteBlock | None
    inverse_zeros: np.ndarray
    inverse_poles: np.ndarray
    inverse: Callable[[np.ndarray], np.ndarray]
    gain_zeros: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    gain_poles: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))

    def ratio(self, w: np.ndarray) -> np.ndarray:
        """``R = Gd/Gf = (1 - Q)/K``.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Its response on ``z = e^{jwTs}``.
        """
        one = 1.0 if self.q is None else 1.0 - self.q.response(w)
        return one / self.gain(w) * np.ones(np.shape(w))

    def ratio_roots(self, one: bool) -> tuple[np.ndarray, np.ndarray]:
        """Zeros and poles of ``R``: those of ``1 - Q`` (none without a DOB) and of ``1 / K_d``.

        Parameters
        ----------
        one : bool
            Include the zero ``z = 1`` (False where it cancels against the source's).

        Returns
        -------
        (numpy.ndarray, numpy.ndarray)
            Zeros and poles, z-plane.
        """
        zeros, poles = _one_minus_roots(self.q, self.name)
        zeros = np.append(zeros, 1.0 + 0j) if one and self.q is not None else zeros
        return np.concatenate([zeros, self.gain_poles]), np.concatenate([poles, self.gain_zeros])


def _one_minus_roots(q: DiscreteBlock | None, name: str) -> tuple[np.ndarray, np.ndarray]:
    if q is None:
        return np.zeros(0, complex), np.zeros(0, complex)
    return _zeros_without_one(q, f"vehicle {name!r}"), np.asarray(q.poles, complex)


#: Slowest right-half-plane zero (rad/s) a vehicle's map may have (:data:`ilcdob.channel_loop.SLOWEST_ROOT`): slower,
#: it is the zero at s = 0 of a loop that integrates, placed a little off by the fit (its inverse would look ahead
#: for hours).
SLOWEST_ZERO = SLOWEST_ROOT


def channel_map_zeros(vehicle: ChannelLoop) -> np.ndarray:
    """The sampled disturbance map's zeros, the one at ``z = 1`` exact where the loop integrates (module docstring
    of :mod:`ilcdob.identification.origin_zero`).

    Parameters
    ----------
    vehicle : ChannelLoop

    Returns
    -------
    numpy.ndarray
        Zeros in the z-plane (complex).

    Raises
    ------
    SpecError
        A real zero outside the unit circle slower than :data:`SLOWEST_ZERO` rad/s: a zero at ``s = 0`` the fit
        placed a little off.
    """
    blk = vehicle.block
    zeros = np.array(blk.zeros if blk.zeros is not None else [], complex)
    if vehicle.integrates and zeros.size:
        zeros[np.argmin(np.abs(zeros - 1))] = 1.0
    slow = zeros[(np.abs(zeros.imag) < 1e-12) & (zeros.real > 1 + 1e-8)
                 & (np.log(np.maximum(zeros.real, 1.0)) / vehicle.ts < SLOWEST_ZERO)]
    if slow.size:
        s = float(np.log(slow.real.min()) / vehicle.ts)
        raise SpecError(f"vehicle {vehicle.name!r}: its identified map has a zero at s = +{s:.3g} rad/s (time constant "
                        f"{1 / s:.3g} s), which the learning filter would invert with hours of look-ahead: the zero at "
                        "s = 0 of a loop that integrates (a cascade's velocity integral), placed a little off by the "
                        "fit; identify the map with `ilcdob identify --zeros 1 --zero-at-origin` (docs/closed_loop.md)")
    return zeros


def _unit_gain(w: np.ndarray) -> np.ndarray:
    return np.ones(np.shape(w))


def _gain_response(vehicle: ChannelLoop) -> Callable[[np.ndarray], np.ndarray]:
    """``K`` on the unit circle: the constant, or the sampled ratio ``K_d = G_ch(z) / (G_ch / K)(z)``."""
    k, chb, blk = vehicle.gain.constant, vehicle.channel_block, vehicle.block
    if k is not None:
        return lambda w: np.full(np.shape(w), k, dtype=float)
    return lambda w: chb.response(w) / blk.response(w)


def gain_roots(vehicle: ChannelLoop) -> tuple[np.ndarray, np.ndarray]:
    """Zeros and poles of the sampled ``K_d`` of a vehicle whose ``K`` depends on frequency (module docstring): the
    channel map's zeros and ``G_ch / K``'s poles, over ``G_ch / K``'s zeros (its integrator's at ``z = 1`` exact)
    and the channel map's poles, common roots cancelled. None for a constant ``K``.

    Parameters
    ----------
    vehicle : ChannelLoop

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        Zeros and poles, z-plane (complex).
    """
    chb = vehicle.channel_block
    if chb is None:
        return np.zeros(0, complex), np.zeros(0, complex)
    ch_zeros = np.asarray(chb.zeros if chb.zeros is not None else [], complex)
    return cancel_roots(np.concatenate([ch_zeros, vehicle.block.poles]),
                        np.concatenate([channel_map_zeros(vehicle), chb.poles]), rtol=1e-9)


def channel_view(vehicle: ChannelLoop | LoopSystem) -> ChannelView:
    """A vehicle's :class:`ChannelView`: a vehicle on its own controller, or ilcdob's PID + DOB loop on its
    acceleration feed-forward (its model's maps).

    Parameters
    ----------
    vehicle : ChannelLoop or LoopSystem

    Returns
    -------
    ChannelView

    Raises
    ------
    SpecError
        Neither.
    """
    if isinstance(vehicle, ChannelLoop):
        blk, q = vehicle.block, vehicle.q
        zeros = channel_map_zeros(vehicle)
        om_zeros, q_poles = _one_minus_roots(q, vehicle.name)

        def inverse(w):
            one = 1.0 if q is None else 1.0 - q.response(w)
            return 1.0 / (blk.response(w) * one)

        return ChannelView(vehicle.name, vehicle.ts, _gain_response(vehicle), q, np.concatenate([blk.poles, q_poles]),
                           np.concatenate([zeros, om_zeros]), inverse, *gain_roots(vehicle))
    if isinstance(vehicle, LoopSystem):
        src = vehicle.nominal
        q = _block(src, "Q")
        # Gd^-1 = D/(P (1 - Q)): zeros the closed-loop poles; poles the zeros of P_hat and 1 - Q, M's and C's poles
        poles = np.concatenate([_plant_zeros(src), _one_minus_roots(q, vehicle.name)[0],
                                _block(src, "M").poles, _block(src, "C").poles])
        return ChannelView(vehicle.name, vehicle.ts, _unit_gain, q, src.poles(), poles,
                           partial(_inverse_gd_response, src))
    raise SpecError(f"got {type(vehicle).__name__}, expected a ChannelLoop (ilcdob.channel_loop) or a "
                    "LoopSystem (ilcdob's PID + DOB)")


def learning_channel(vehicle: ChannelLoop | LoopSystem) -> str:
    """The channel a vehicle learns through.

    Parameters
    ----------
    vehicle : ChannelLoop or LoopSystem

    Returns
    -------
    str
        Its own channel, or ``"acceleration"`` for ilcdob's PID + DOB.
    """
    return vehicle.channel if isinstance(vehicle, ChannelLoop) else "acceleration"


def channel_gf(vehicle: ChannelLoop | LoopSystem) -> ct.StateSpace:
    """``Gf`` of the vehicle's model on its channel.

    Parameters
    ----------
    vehicle : ChannelLoop or LoopSystem

    Returns
    -------
    control.StateSpace
        Discrete: :attr:`ChannelLoop.G_f`, or ``-G_f`` of ilcdob's PID + DOB loop (the acceleration
        feed-forward is ``-d_f``, module docstring).
    """
    if isinstance(vehicle, ChannelLoop):
        return vehicle.G_f
    return -vehicle.nominal.G_f


def channel_filters(source: ChannelLoop | LoopSystem, target: ChannelLoop | LoopSystem) -> LearningFilters:
    """The closed-form pair for ``target`` learning from ``source`` (module docstring).

    Parameters
    ----------
    source, target : ChannelLoop or LoopSystem
        Vehicles j-1 and j (a LoopSystem: ilcdob's PID + DOB, learning on its acceleration feed-forward).

    Returns
    -------
    LearningFilters
        ``L1`` (channel unit of the target per m) and ``L2`` (target's channel unit per source's).

    Raises
    ------
    SpecError
        Not vehicles, different sample times, or a target without a DOB learning from a source with one.
    NumericalError
        The zero-pole form of a filter disagrees with its formula.
    """
    views = []
    for what, v in (("source", source), ("target", target)):
        try:
            views.append(channel_view(v))
        except SpecError as exc:
            raise SpecError(f"`{what}`: {exc}") from None
    src, tgt = views
    if abs(src.ts - tgt.ts) > 1e-12 * src.ts:
        raise SpecError(f"`ts`: vehicles {src.name!r} ({src.ts} s) and {tgt.name!r} ({tgt.ts} s) must share one "
                        "setpoint period")
    if src.q is not None and tgt.q is None:
        raise SpecError(f"vehicle {tgt.name!r} flies no DOB and cannot learn from {src.name!r}, which does: a DOB "
                        "removes a constant disturbance from its vehicle's error, so that error cannot tell the "
                        f"learner's loop what to cancel; give {tgt.name!r} the add-on DOB "
                        "(ilcdob.vehicles.dob_loop.AddOnDOB) or learn it from a vehicle without one")
    # 1 - Q_j's zero at z = 1 cancels the pole 1/(1 - Q_{j-1}) puts there where both fly a DOB
    (rz_j, rp_j), (rz_p, rp_p) = tgt.ratio_roots(src.q is None), src.ratio_roots(False)
    what = f"learning filter {src.name!r} -> {tgt.name!r}"
    l1 = matched(np.concatenate([rz_j, src.inverse_zeros]), np.concatenate([rp_j, src.inverse_poles]), src.ts,
                 lambda w: tgt.ratio(w) * src.inverse(w), what)
    l2 = matched(np.concatenate([rz_j, rp_p]), np.concatenate([rp_j, rz_p]), src.ts,
                 lambda w: tgt.ratio(w) / src.ratio(w), f"{what} (L2)")
    return LearningFilters(source=source, target=target, L1=l1, L2=l2)
