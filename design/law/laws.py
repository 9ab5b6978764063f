"""Learning laws: what system j's learning signal is computed from (paper Sec. III and beyond).

A *law* says which trials system j learns from and which part of their error it treats as
disturbance; a *method* (:data:`ilcdob.design.methods.METHODS`) says how the filter from that
error to the learning signal is designed. Three laws:

``paper`` (the default everywhere)
    The Theorem of Sec. III (docs/theory.md section 2): system j learns from system j-1's
    last trial::

        d_f,j = L1_j{e_{j-1}} + L2_j{d_f,{j-1}},   L1_j = -(1 - Q_j) Gd_hat_{j-1}^{-1},
        L2_j = L1_j Gf_hat_{j-1}

    Assumes that all of e_{j-1} is driven by the disturbance: the derivation drops the
    reference term ``(1 - G_r) r`` (and the acceleration feed-forward's ``G_f a_ref``). Exact
    (Case I: e_j = 0) when models are exact, there is no noise and the reference does not
    move (hover); on moving references the reference term leaks into the reconstructed
    disturbance and system j's own reference term is not cancelled.
``exact-reference``
    The same filters with the reference term kept (:mod:`ilcdob.design.maps.reference`)::

        d_f,j = L1_j{e_{j-1} - e_ref,{j-1}} + L2_j{d_f,{j-1}} + Gf_hat_j^{-1}{e_ref,j},
        e_ref,i = r - G_r,i{r} + G_f,i{a_ref}     (model maps; a_ref only with feed-forward)

    Assumes the reference trajectory ``r`` (m) of the trial is known (and its acceleration
    ``a_ref``, m/s^2, for controllers that feed it forward) and both systems fly the same
    reference. With exact models and no noise the learning flight has zero error on any
    trajectory (up to trial-boundary effects of the non-causal filters). With other methods
    than the closed form, their filter replaces ``L1``/``L2`` on the disturbance part and the
    two reference terms are added the same way.
``multi-source``
    System j learns from the latest trial of *every* system that has flown so far
    (:mod:`ilcdob.design.law.multi_source`): each trial gives a reconstruction of the common
    disturbance through its system's model, the reconstructions are averaged per frequency
    with weights from each model's Delta set (inverse mean-square reconstruction error; equal
    weights for systems without a Delta set), and ``d_f,j = (1 - Q_j){d_hat}``. With one
    earlier trial it is the paper's law. Assumes every earlier trial flew the same task in
    the same disturbance; like the paper's law it drops the reference term. It is a law of
    a learning *chain* (``ilcdob reproduce``); commands that design one pair from one trial
    (``design``, ``compare``, ``campaign``) refuse it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ilcdob.channel_loop import CHANNEL_UNITS, ChannelLoop
from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal

from ..maps.channel_filters import learning_channel
from ..maps.reference import inverse_gf_filter, reference_error

__all__ = ["LAWS", "DEFAULT_LAW", "LAW_DESCRIPTIONS", "check_law", "ExactReference", "law_for",
           "ReferenceTerms", "reference_terms"]

#: The learning laws (module docstring).
LAWS = ("paper", "exact-reference", "multi-source")
#: The law used when none is chosen: the Theorem of paper Sec. III.
DEFAULT_LAW = "paper"
#: One line per law, for results, reports and help texts.
LAW_DESCRIPTIONS: dict[str, str] = {
    "paper": "the Theorem's filters (paper Sec. III): L1 on the previous system's error, L2 on its learning "
             "signal; the reference term (1 - G_r) r is dropped",
    "exact-reference": "the Theorem's filters with the reference term (1 - G_r) r kept exactly: the previous "
                       "system's reference error is removed before L1 and the learning system's own is cancelled "
                       "through Gf_j^-1 (needs the reference trajectory)",
    "multi-source": "learning from the latest trial of every earlier system at once, reconstructions weighted per "
                    "frequency by model confidence (Delta sets), then (1 - Q_j); reference term dropped",
}


def check_law(law: object, what: str = "law") -> str:
    """Return ``law`` if it is one of :data:`LAWS`, else raise :class:`SpecError` listing them.

    Parameters
    ----------
    law : object
        The law to check.
    what : str
        Name of the input in the message (e.g. ``"--law"``).
    """
    if not isinstance(law, str) or law not in LAWS:
        raise SpecError(f"`{what}`: got {law!r}, valid learning laws are {list(LAWS)} (paper: the Theorem's "
                        "filters; exact-reference: the same with the reference term kept; multi-source: every "
                        "earlier system's trial at once)")
    return law


@dataclass(frozen=True)
class ExactReference:
    """The ``exact-reference`` law with the trial's reference it needs (module docstring).

    Attributes
    ----------
    reference : array_like
        Reference position of the trial, m, one sample per fleet sample time.
    acceleration : array_like, optional
        Its acceleration, m/s^2, for controllers that feed it forward.
    """

    reference: object
    acceleration: object = None
    name = "exact-reference"


def law_for(name: object, reference: object = None, acceleration: object = None,
            what: str = "law") -> str | ExactReference:
    """The law a design is asked for by ``name``: the name, or for ``exact-reference`` the law with
    the trial's reference (:class:`ExactReference`).

    Parameters
    ----------
    name : str
        One of :data:`LAWS`.
    reference, acceleration : array_like, optional
        The trial's reference (m) and acceleration (m/s^2); only ``exact-reference`` uses them.
    what : str
        Name of the input in messages.

    Returns
    -------
    str or ExactReference

    Raises
    ------
    SpecError
        Unknown law.
    """
    if check_law(name, what) == ExactReference.name and reference is not None:
        return ExactReference(reference, acceleration)
    return name


@dataclass(frozen=True)
class ReferenceTerms:
    """The two reference terms of the ``exact-reference`` law for one pair and one trajectory.

    Attributes
    ----------
    source_error : numpy.ndarray, m
        ``e_ref,{j-1}``: the error system j-1's model makes flying the reference without
        disturbance or learning; removed from its trial error before the learning filter.
    correction : numpy.ndarray, in ``unit``
        ``Gf_hat_j^{-1}{e_ref,j}``: added to system j's learning signal, cancelling its own
        reference error.
    unit : str
        The learning signal's unit: m/s^2 for the paper's loop, the channel's for a vehicle on its own
        controller (:data:`ilcdob.channel_loop.CHANNEL_UNITS`).
    """

    source_error: np.ndarray
    correction: np.ndarray
    unit: str = "m/s^2"

    def error_in(self, e_prev: object) -> np.ndarray:
        """System j-1's error with its reference term removed.

        Parameters
        ----------
        e_prev : array_like
            Tracking error of system j-1, m, the length of the trajectory.

        Returns
        -------
        numpy.ndarray
            ``e_{j-1} - e_ref,{j-1}``, m.
        """
        return as_signal(e_prev, "e_prev", self.source_error.size) - self.source_error

    def signal_out(self, d_f: object) -> np.ndarray:
        """A learning signal of the disturbance part plus the reference correction.

        Parameters
        ----------
        d_f : array_like
            Learning signal computed from the disturbance part, m/s^2.

        Returns
        -------
        numpy.ndarray
            ``d_f + Gf_hat_j^{-1}{e_ref,j}``, m/s^2.
        """
        return as_signal(d_f, "d_f", self.correction.size) + self.correction

    def wrap(self, learn: Callable[[np.ndarray, np.ndarray], np.ndarray]
             ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        """A learning function with both reference terms applied around it.

        Parameters
        ----------
        learn : callable
            ``learn(e_prev, df_prev) -> d_f,j`` of the paper's law (m, m/s^2 -> m/s^2).

        Returns
        -------
        callable
            ``(e_prev, df_prev) -> signal_out(learn(error_in(e_prev), df_prev))``.
        """

        def exact_reference_learn(e_prev: np.ndarray, df_prev: np.ndarray) -> np.ndarray:
            return self.signal_out(learn(self.error_in(e_prev), df_prev))

        return exact_reference_learn

    def to_dict(self) -> dict[str, object]:
        """Summary for ``filters.json`` (the signals themselves go to a CSV)."""
        return {"samples": int(self.source_error.size),
                "source_error_rms_m": float(np.sqrt(np.mean(self.source_error ** 2))),
                f"correction_rms_{self.unit.replace('/', '_').replace('^', '')}":
                    float(np.sqrt(np.mean(self.correction ** 2)))}


def reference_terms(source: LoopSystem | ChannelLoop, target: LoopSystem | ChannelLoop, r: object,
                    a_ref: object | None = None) -> ReferenceTerms:
    """The reference terms of ``source`` (j-1) -> ``target`` (j) for reference ``r`` (module docstring).

    Where either flies its own controller the pair learns through the target's channel
    (:mod:`~ilcdob.design.maps.channel_filters`): the correction is in that channel's unit and sign (for
    ilcdob's loop as the target, its acceleration feed-forward ``-d_f``; :mod:`~ilcdob.design.maps.reference`).

    Parameters
    ----------
    source, target : LoopSystem or ChannelLoop
        Systems j-1 and j (their models are used).
    r : array, m
        Reference position of the trial, sampled at the fleet's sample time.
    a_ref : array, m/s^2, optional
        Reference acceleration, used for controllers with ``acceleration_feedforward``.

    Raises
    ------
    SignalError
        ``r`` or ``a_ref`` is not a finite 1-D signal (of equal lengths).
    SpecError
        No ``a_ref`` while a controller of the pair feeds the reference acceleration forward.
    """
    r = as_signal(r, "reference")
    if a_ref is not None:
        a_ref = as_signal(a_ref, "acceleration", r.size)
    else:
        ff = [lp.name for lp in (source, target)
              if isinstance(lp, LoopSystem) and lp.spec.controller.acceleration_feedforward]
        if ff:
            raise SpecError(f"`acceleration`: systems {ff} feed the reference acceleration forward "
                            "(controller.acceleration_feedforward), so their reference error depends on it; give the "
                            "reference acceleration (m/s^2), e.g. an `acceleration` column in the trial CSV")
    e_src = reference_error(source, r, a_ref)
    e_tgt = e_src if target is source else reference_error(target, r, a_ref)
    correction = inverse_gf_filter(target).apply(e_tgt, "e_ref")
    if not any(isinstance(lp, ChannelLoop) for lp in (source, target)):
        return ReferenceTerms(source_error=e_src, correction=correction)
    sign = 1.0 if isinstance(target, ChannelLoop) else -1.0  # ilcdob's loop learns on -d_f there
    return ReferenceTerms(e_src, sign * correction, CHANNEL_UNITS[learning_channel(target)])
