"""Keeping the reference term exactly (beyond the paper; its future work).

The Theorem's filters treat all of system j-1's error as disturbance-driven: the reference
term ``(1 - G_r) r`` (plus the acceleration feed-forward's share, if the controller has one)
is dropped. On aggressive trajectories that term is not small; it leaks into the
reconstructed disturbance and is missing from what system j must cancel. Kept exactly::

    e_ref,i = r - G_r,i{r} + G_f,i{a_ref}          (model maps; a_ref only with feed-forward)
    d_f,j   = L1{e_{j-1} - e_ref,{j-1}} + L2{d_f,{j-1}}  +  G_f,j^{-1}{e_ref,j}

(the Theorem's derivation, paper Sec. III, with the reference term kept;
``G_f,j^{-1} = -D_j / P_hat_j = -(1 - Q_j)/P_hat_j - (M_j + C_j)`` applied non-causally with
the same stable inversion as ``L1``). With exact models and no noise the learning flight of
system j has zero error, on any trajectory.

A vehicle on its own controller (:class:`~ilcdob.channel_loop.ChannelLoop`) has ``e_ref = r - T{r}`` with
its reference map ``T`` (:attr:`~ilcdob.channel_loop.ChannelLoop.G_r`: what the flight stack feeds
forward of ``r`` is inside it, so there is no ``a_ref`` term), and its ``G_f`` is its channel's
(channel -> position, :mod:`ilcdob.channel_loop`); the terms are then in the learner's channel unit and
sign (:func:`~ilcdob.design.law.laws.reference_terms`). This is the ``exact-reference`` learning law of
:mod:`ilcdob.design.law.laws` (``law="exact-reference"`` in ``reproduce``, ``design_pair``,
``compare_designs`` and campaigns).
"""

from __future__ import annotations

import numpy as np

from ilcdob.channel_loop import ChannelLoop
from ilcdob.loop import LoopSystem, freqresp
from ilcdob.signals import as_signal

from .channel_filters import channel_map_zeros, channel_view
from .closed_form import LearningFilters, matched, simulate_map
from ..filters.noncausal import ZPKFilter

__all__ = ["reference_error", "inverse_gf_filter", "ExactReferenceLearning"]


def reference_error(loop: LoopSystem | ChannelLoop, r: object, a_ref: object | None = None) -> np.ndarray:
    """Error of ``loop``'s model flying reference ``r`` (m) without disturbance or learning, m.

    ``e_ref = r - G_r{r} + G_f{a_ref}`` with the model's maps; ``r - T{r}`` for a vehicle on its own
    controller (module docstring).

    Parameters
    ----------
    loop : LoopSystem or ChannelLoop
        The system (its model, ``loop.nominal``, is flown).
    r : array_like
        Position reference, m.
    a_ref : array_like, optional
        Reference acceleration, m/s^2, same length; fed forward only if the controller's
        ``acceleration_feedforward`` is on, as in :func:`ilcdob.validation.simulate.simulate_flight`.

    Returns
    -------
    numpy.ndarray
        ``e_ref``, m, same length as ``r``.

    Raises
    ------
    SpecError
        A vehicle on its own controller whose reference map is not known (:attr:`ChannelLoop.G_r`).
    """
    r = as_signal(r, "r")
    if isinstance(loop, ChannelLoop):
        return r - simulate_map(loop.G_r, r)
    src = loop.nominal
    e = r - simulate_map(src.G_r, r)
    if a_ref is not None and loop.spec.controller.acceleration_feedforward:
        e = e + simulate_map(src.G_f, as_signal(a_ref, "a_ref", r.size))
    return e


def inverse_gf_filter(loop: LoopSystem | ChannelLoop) -> ZPKFilter:
    """``G_f^{-1} = -D / P_hat`` of ``loop``'s model, for non-causal application.

    Zeros: the closed-loop poles; poles: zeros of P_hat (the ZOH sampling zero outside the unit
    circle becomes anti-causal) and the poles of Q, M and C. For a vehicle on its own controller:
    ``(K Gd)^{-1}`` of its channel, from its sampled disturbance map's poles and zeros and those of ``K``'s
    sampled ratio where ``K`` depends on frequency (:func:`~.channel_filters.gain_roots`).

    Parameters
    ----------
    loop : LoopSystem or ChannelLoop
        The system whose model's learning map ``G_f`` is inverted.

    Returns
    -------
    ZPKFilter
        ``G_f^{-1}``, with its gain matched to the block formula
        (:func:`~ilcdob.design.maps.closed_form.matched`).
    """
    if isinstance(loop, ChannelLoop):
        blk, view = loop.block, channel_view(loop)
        return matched(np.concatenate([blk.poles, view.gain_poles]),
                       np.concatenate([channel_map_zeros(loop), view.gain_zeros]), loop.ts,
                       lambda w: 1.0 / (view.gain(w) * blk.response(w)), f"Gf^-1 of {loop.name!r}")
    src = loop.nominal
    p_zeros = np.asarray(src.P.zeros(), dtype=complex)
    poles = np.concatenate([p_zeros[np.isfinite(p_zeros)], np.linalg.eigvals(src.Q.A),
                            np.linalg.eigvals(src.M.A), np.linalg.eigvals(src.C.A)])
    zeros = np.linalg.eigvals(src.closed_loop.A)

    def exact(w):
        p, m, c, q = (freqresp(s, w) for s in (src.P, src.M, src.C, src.Q))
        return -((1 - q) / p + m + c)

    return matched(zeros, poles, src.ts, exact, f"Gf^-1 of {loop.name!r}")


class ExactReferenceLearning:
    """The closed-form learning of system j from j-1 with the reference term kept (module docstring).

    Parameters
    ----------
    filters : LearningFilters
        The Theorem's pair for (j-1 -> j) (:func:`~ilcdob.design.closed_form_filters`).
    r : array, m
        Reference of the trial (both systems fly the same task).
    a_ref : array, m/s^2, optional
        Reference acceleration (fed forward by controllers that have it).
    """

    def __init__(self, filters: LearningFilters, r: object, a_ref: object | None = None):
        self.filters = filters
        self.r = as_signal(r, "r")
        self.e_ref_prev = reference_error(filters.source, self.r, a_ref)
        self.correction = inverse_gf_filter(filters.target).apply(reference_error(filters.target, self.r, a_ref),
                                                                  "e_ref")

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """Learning signal of system j from system j-1's trial, reference term kept (module docstring).

        Parameters
        ----------
        e_prev : array_like
            Tracking error of system j-1, m, the length of ``r``.
        df_prev : array_like
            Learning signal system j-1 flew with, m/s^2 (zeros if none), same length.

        Returns
        -------
        numpy.ndarray
            ``d_f,j``, m/s^2.
        """
        e = as_signal(e_prev, "e_prev", self.r.size)
        return self.filters.apply(e - self.e_ref_prev, df_prev) + self.correction
