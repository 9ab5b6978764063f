"""Learning from every previous system at once, weighted by model confidence (beyond the paper).

The paper's system j learns from system j-1 only. Every earlier system i < j flew the same
task in the same disturbance, and each trial gives a reconstruction of it through that
system's model (:func:`~ilcdob.design.reconstruct_disturbance`)::

    d_hat_i = -Gd_hat_i^{-1}{e_i + Gf_hat_i{d_f,i}}  =  (Gd_i / Gd_hat_i) d  (+ noise terms)

so its relative error at frequency w is ``r_i(w) = Gd_i(w)/Gd_hat_i(w) - 1``, which the
system's Delta set (identified covariance or fleet bound) samples. The joint reconstruction
weights each system by its confidence, frequency by frequency (inverse mean-square error over
its Delta samples, plus a floor ``floor`` for the error sources a Delta set does not hold:
each system's own noise)::

    v_i(w)   = mean_k |r_i,k(w)|^2 + floor
    d_hat(w) = sum_i (1/v_i) d_hat_i(w) / sum_i (1/v_i)

and system j's learning signal is the Theorem's ``L1`` acting on it: since
``L1_j = -(1 - Q_j) Gd_hat_{j-1}^{-1}``, ``d_f,j = (1 - Q_j){d_hat}`` (the Theorem's L1, paper
Sec. III, factored). With one source this is exactly the closed form. This is the
``multi-source`` learning law of :mod:`ilcdob.design.law.laws` (``reproduce(law="multi-source")``).
The weighting is applied on the FFT grid of the zero-padded trial (the weights are smooth in
w, so wrap-around is negligible).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem, freqresp
from ilcdob.signals import as_signal

from ..maps.closed_form import one_minus, reconstruct_disturbance, simulate_map
from ..sets.delta import DeltaSet

__all__ = ["SourceTrial", "reconstruction_error_power", "joint_disturbance", "multi_source_learning"]

#: Default floor of the reconstruction error power (relative): 1e-4, a 1 % error never weighs more.
FLOOR = 1e-4


@dataclass(frozen=True)
class SourceTrial:
    """One earlier system's trial and the uncertainty of its model.

    Attributes
    ----------
    loop : LoopSystem
        The system (its model is used for the reconstruction).
    e : array, m
        Its tracking error over the trial.
    d_f : array, m/s^2
        The learning signal it flew (zeros if none).
    delta : DeltaSet, optional
        Its Delta set; without one the model counts as exact (error power = floor).
    """

    loop: LoopSystem
    e: np.ndarray
    d_f: np.ndarray
    delta: DeltaSet | None = None


def reconstruction_error_power(trial: SourceTrial, w: np.ndarray, floor: float = FLOOR) -> np.ndarray:
    """Error power of one system's reconstruction, ``v_i(w)`` (module docstring).

    ``v_i(w) = mean_k |Gd_i,k(w)/Gd_hat_i(w) - 1|^2 + floor`` over the Delta samples ``k``.

    Parameters
    ----------
    trial : SourceTrial
        The system and its Delta set (without one: ``floor`` everywhere).
    w : array_like
        Frequencies, rad/s.
    floor : float
        Error-power floor added (the error sources a Delta set does not hold).

    Returns
    -------
    numpy.ndarray
        ``v_i(w)``, the shape of ``w``.
    """
    if trial.delta is None:
        return np.full(np.shape(w), floor)
    gd_hat = freqresp(trial.loop.nominal.G_d, w)
    errs = np.array([freqresp(lp.G_d, w) / gd_hat - 1.0 for lp in trial.delta.loops])
    return np.mean(np.abs(errs) ** 2, axis=0) + floor


def joint_disturbance(trials: Sequence[SourceTrial], weighting: str = "confidence",
                      floor: float = FLOOR, power_cache: dict | None = None) -> np.ndarray:
    """Confidence-weighted joint reconstruction of the common disturbance (m/s^2).

    Parameters
    ----------
    trials : sequence of SourceTrial
        Earlier systems' trials, all of the same length and sample time.
    weighting : {"confidence", "equal"}
        Inverse error power per frequency, or a plain average.
    floor : float
        Error-power floor (> 0).
    power_cache : dict, optional
        Reused across calls for the error powers ``v_i(w)`` (keyed by system name, grid and
        floor; a learning chain evaluates the same systems' Delta sets on the same grid at every
        step). Only valid while each name keeps its Delta set.

    Returns
    -------
    numpy.ndarray
        ``d_hat``, m/s^2, the length of the trials.

    Raises
    ------
    SpecError
        No trials, an unknown ``weighting``, a bad ``floor``, or trials of different lengths or
        sample times.
    """
    if not trials:
        raise SpecError("`trials`: got none, expected at least one earlier system's trial")
    if weighting not in ("confidence", "equal"):
        raise SpecError(f"`weighting`: got {weighting!r}, expected 'confidence' or 'equal'")
    if not (np.isfinite(floor) and floor > 0):
        raise SpecError(f"`floor`: got {floor!r}, expected a relative error power > 0 (e.g. 1e-4)")
    n = as_signal(trials[0].e, "e").size
    ts = trials[0].loop.ts
    for tr in trials:
        if abs(tr.loop.ts - ts) > 1e-12 or np.size(tr.e) != n:
            raise SpecError(f"`trials`: system {tr.loop.name!r} has {np.size(tr.e)} samples at {tr.loop.ts} s, "
                            f"expected {n} at {ts} s like the first")
    recs = np.array([reconstruct_disturbance(tr.loop, tr.e, tr.d_f) for tr in trials])
    if len(trials) == 1:
        return recs[0]
    m = 2 * n
    w = 2 * np.pi * np.fft.rfftfreq(m, ts)
    w[0] = 1e-3 * w[1]  # the DC bin: the error power is continuous there
    if weighting == "equal":
        weights = np.full((len(trials), w.size), 1.0 / len(trials))
    else:
        def power(tr: SourceTrial) -> np.ndarray:
            if power_cache is None:
                return reconstruction_error_power(tr, w, floor)
            key = (tr.loop.name, id(tr.delta), m, ts, floor)
            if key not in power_cache:
                power_cache[key] = reconstruction_error_power(tr, w, floor)
            return power_cache[key]

        inv = 1.0 / np.array([power(tr) for tr in trials])
        weights = inv / inv.sum(axis=0)
    spec = np.fft.rfft(recs, m, axis=1)
    return np.fft.irfft(np.sum(weights * spec, axis=0), m)[:n]


def multi_source_learning(target: LoopSystem, trials: Sequence[SourceTrial], weighting: str = "confidence",
                          floor: float = FLOOR, power_cache: dict | None = None) -> np.ndarray:
    """Learning signal of ``target`` from every earlier trial: ``(1 - Q_j){d_hat}`` (m/s^2).

    Parameters
    ----------
    target : LoopSystem
        System j, the learning system (its ``Q`` is used).
    trials : sequence of SourceTrial
        Earlier systems' trials (see :func:`joint_disturbance`).
    weighting : {"confidence", "equal"}
        Inverse error power per frequency, or a plain average.
    floor : float
        Error-power floor (> 0).
    power_cache : dict, optional
        Cache of the error powers, see :func:`joint_disturbance`.

    Returns
    -------
    numpy.ndarray
        ``d_f,j``, m/s^2, the length of the trials.
    """
    return simulate_map(one_minus(target.Q), joint_disturbance(trials, weighting, floor, power_cache))
