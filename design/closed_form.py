"""Closed-form learning filters of the Theorem (paper Sec. III): the `paper` learning law.

System j learns from system j-1::

    d_f,j = L1_j{e_{j-1}} + L2_j{d_f,{j-1}}
    L1_j  = (Gf_j Gd_{j-1})^{-1} Gd_j = -(1 - Q_j) Gd_{j-1}^{-1}
    L2_j  = L1_j Gf_{j-1}

(hats on the j-1 maps: they are built from system j-1's *model*). Because the factors
commute, ``d_f,j = L1_j{e'_{j-1}}`` with ``e'_{j-1} = e_{j-1} + Gf_{j-1}{d_f,{j-1}}`` the
error system j-1 would have had without learning. :meth:`LearningFilters.apply` runs the two
filters on their own signals, as the exported C code does: ``L2`` is causal and stable, so
it needs no continuation of ``d_f,{j-1}`` past the trial's end.

Zeros and poles of ``L1_j`` come from the blocks, never from a quotient of polynomials::

    Gd^{-1} = D / (P (1 - Q))  -> zeros: closed-loop poles of j-1 (eigenvalues of the
                                  interconnection); poles: zeros of P_hat, of (1 - Q),
                                  poles of M and of C
    (1 - Q_j)/(1 - Q_{j-1}): the common zero at z = 1 is cancelled analytically (the
                              root z = 1 is removed from both zero sets).

One integrator (the PID's) remains: the loop rejects constant disturbances, so the error
carries their derivative only. The ZOH sampling zero of P_hat outside the unit circle
becomes an anti-causal pole (stable inversion, :mod:`ilcdob.design.noncausal`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import control as ct
import numpy as np

from ilcdob.errors import IlcdobError, SpecError
from ilcdob.loop import LoopSystem, freqresp
from ilcdob.signals import as_signal

from .noncausal import ZPKFilter

__all__ = ["LearningFilters", "closed_form_filters", "simulate_map", "inverse_gd_filter",
           "reconstruct_disturbance", "one_minus", "matched"]

_GAIN_CHECK_W = np.array([0.37, 1.3, 5.1, 17.0])  # rad/s, points where the zpk form is checked


def simulate_map(sys: ct.StateSpace, u: np.ndarray) -> np.ndarray:
    """Causal response of a discrete SISO system to an input trial, from rest.

    Parameters
    ----------
    sys : control.StateSpace
        Discrete-time SISO system (e.g. a loop map ``G_f``, or ``1 - Q``).
    u : array_like
        Input, one sample per sample time.

    Returns
    -------
    numpy.ndarray
        Output, same length as ``u``.
    """
    resp = ct.forced_response(sys, U=np.asarray(u, dtype=float))
    return np.asarray(resp.outputs, dtype=float).reshape(-1)


def one_minus(sys: ct.StateSpace) -> ct.StateSpace:
    """State-space realisation of ``1 - sys`` (same states, same sample time).

    Used for ``1 - Q``, the part of a disturbance the DOB leaves (``G_d = P (1 - Q) / D``,
    paper Sec. II, docs/theory.md section 1); built on the realisation of ``sys`` so that its
    zeros, among them the root ``z = 1`` of a unit-DC-gain ``Q``, stay exact.

    Parameters
    ----------
    sys : control.StateSpace
        A SISO system (discrete or continuous).

    Returns
    -------
    control.StateSpace
        ``(A, B, -C, 1 - D)`` with ``sys``'s sample time.
    """
    return ct.ss(sys.A, sys.B, -sys.C, 1.0 - sys.D, sys.dt)


def _zeros_without_one(sys: ct.StateSpace, what: str) -> np.ndarray:
    z = np.asarray(sys.zeros(), dtype=complex)
    z = z[np.isfinite(z)]
    i = int(np.argmin(np.abs(z - 1.0)))
    if abs(z[i] - 1.0) > 1e-5:
        raise SpecError(f"{what}: 1 - Q has no zero at z = 1 (nearest {z[i]:.6g}); Q must have unit DC gain")
    return np.delete(z, i)


def _l1_exact(prev: LoopSystem, nxt: LoopSystem, w: np.ndarray) -> np.ndarray:
    """``-(1 - Q_j) (1/P_hat + (M + C)/(1 - Q_{j-1}))`` evaluated from block responses."""
    q_j = freqresp(nxt.Q, w)
    p = freqresp(prev.P, w)
    m = freqresp(prev.M, w)
    c = freqresp(prev.C, w)
    q = freqresp(prev.Q, w)
    return -(1 - q_j) * (1.0 / p + (m + c) / (1 - q))


@dataclass(frozen=True)
class LearningFilters:
    """The pair (L1, L2) for system ``target`` learning from system ``source``.

    Attributes
    ----------
    source : LoopSystem
        System j-1's *nominal* loop (its model), whose data are learned from.
    target : LoopSystem
        System j (its Q is known exactly: it is software).
    L1 : ZPKFilter
        ``-(1 - Q_j) Gd_{j-1}^{-1}`` applied non-causally.
    L2 : ZPKFilter
        ``L1 Gf_{j-1} = (1 - Q_j)/(1 - Q_{j-1})`` (causal, stable; 1 when both Q are equal).
    """

    source: LoopSystem
    target: LoopSystem
    L1: ZPKFilter
    L2: ZPKFilter

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """Learning signal of system j: ``L1{e_{j-1}} + L2{d_f,{j-1}}`` (the Theorem).

        Parameters
        ----------
        e_prev : array, m
            Tracking error of system j-1 over the trial.
        df_prev : array, m/s^2
            Learning signal system j-1 flew with (zeros if none).

        Returns
        -------
        numpy.ndarray
            ``d_f,j`` in m/s^2, same length.
        """
        e = as_signal(e_prev, "e_prev")
        df = as_signal(df_prev, "df_prev", e.size)
        out = self.L1.apply(e, "e_prev")
        return out + self.L2.apply(df, "df_prev") if np.any(df) else out

    def l1_response(self, w: np.ndarray) -> np.ndarray:
        """Frequency response of ``L1``.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            ``L1(e^{j w Ts})``, complex.
        """
        return self.L1.freqresp(w)

    def l2_response(self, w: np.ndarray) -> np.ndarray:
        """Frequency response of ``L2 = L1 Gf_{j-1}``.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            ``L2(e^{j w Ts})``, complex.
        """
        return self.L1.freqresp(w) * freqresp(self.source.G_f, w)

    def te_responses(self, w: np.ndarray, source_true: LoopSystem | None = None,
                     target_true: LoopSystem | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Error-propagation maps ``e_j = Te1{e_{j-1}} + Te2{d_f,{j-1}}`` with learning.

        ``Te1 = Gd_j Gd_{j-1}^{-1} - Gf_j L1`` and ``Te2 = Te1 Gf_{j-1}``, with the *true*
        loops (defaults: the models, for which both vanish, Case I of the Theorem, paper
        Sec. III; docs/theory.md section 2).

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.
        source_true : LoopSystem, optional
            System j-1's true loop (default: its model, :attr:`source`).
        target_true : LoopSystem, optional
            System j's true loop (default: :attr:`target`).

        Returns
        -------
        te1, te2 : numpy.ndarray
            Complex responses of ``Te1`` and ``Te2``.
        """
        src = source_true if source_true is not None else self.source
        tgt = target_true if target_true is not None else self.target
        gd_j, gd_p = freqresp(tgt.G_d, w), freqresp(src.G_d, w)
        te1 = gd_j / gd_p - freqresp(tgt.G_f, w) * self.l1_response(w)
        return te1, te1 * freqresp(src.G_f, w)


def _cancel_common(zeros: np.ndarray, poles: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Remove pole/zero pairs that coincide (e.g. the PID's derivative-filter pole, present in
    both D and C): they cancel exactly and only raise the order."""
    zs, ps = list(zeros), list(poles)
    kept = []
    for z in zs:
        if ps:
            d = np.abs(np.asarray(ps) - z)
            j = int(np.argmin(d))
            if d[j] <= tol * max(1.0, abs(z)):
                ps.pop(j)
                continue
        kept.append(z)
    return np.asarray(kept, dtype=complex), np.asarray(ps, dtype=complex)


def matched(zeros: np.ndarray, poles: np.ndarray, ts: float, exact: Callable, what: str) -> ZPKFilter:
    """Zero-pole filter whose gain is matched to a block formula, and checked against it.

    The zeros and poles of a learning filter are collected from the blocks of the loop
    (never from a quotient of polynomials, docs/theory.md section 2); coinciding pole/zero
    pairs are cancelled first. The gain is the mean ratio of ``exact(w)`` to the unit-gain
    filter's response at four frequencies between 0.37 and 17 rad/s, and every ratio must
    agree with it to 1e-5 relative, which also checks the zeros and poles.

    Parameters
    ----------
    zeros, poles : numpy.ndarray
        Zeros and poles in the z-plane (complex; anti-causal poles ``|p| > 1`` allowed).
    ts : float
        Sample time, s.
    exact : callable
        ``exact(w)`` -> the filter's frequency response at ``w`` rad/s, evaluated from the
        blocks' responses.
    what : str
        What the filter is, for the error message.

    Returns
    -------
    ZPKFilter
        The filter with the matched gain.

    Raises
    ------
    IlcdobError
        The zero-pole form does not match ``exact`` (numerical trouble in the loop).
    """
    zeros, poles = _cancel_common(zeros, poles)
    unit = ZPKFilter(zeros, poles, 1.0, ts)
    ratio = exact(_GAIN_CHECK_W) / unit.exact_freqresp(_GAIN_CHECK_W)
    gain = float(np.real(np.mean(ratio)))
    if np.max(np.abs(ratio / gain - 1)) > 1e-5:
        raise IlcdobError(f"{what}: zero-pole form does not match the block formula (gain ratios {ratio}); "
                          "the loop is probably badly conditioned. Report this fleet.")
    return ZPKFilter(zeros, poles, gain, ts)


def inverse_gd_filter(loop: LoopSystem, model: bool = True) -> ZPKFilter:
    """``Gd^{-1} = D / (P (1 - Q))`` of a loop, for non-causal application.

    Poles: zeros of P_hat, of (1 - Q) (including z = 1) and the poles of M and C; zeros: the
    closed-loop poles. Two poles sit at z = 1 (constant disturbances leave no trace in the
    error, so their reconstruction integrates twice from rest). Paper Sec. II-III,
    docs/theory.md section 2.

    Parameters
    ----------
    loop : LoopSystem
        The loop whose disturbance map is inverted.
    model : bool
        True: invert the map of ``loop``'s model (its nominal loop); False: of ``loop``
        itself (its plant, with the model's C, Q and M).

    Returns
    -------
    ZPKFilter
        ``Gd^{-1}``, anti-causal where the plant's sampling zero lies outside the unit circle.
    """
    src = loop.nominal if model else loop
    p_zeros = np.asarray(src.P.zeros(), dtype=complex)
    q_zeros = np.asarray(one_minus(src.Q).zeros(), dtype=complex)
    zeros = np.linalg.eigvals(src.closed_loop.A)
    poles = np.concatenate([p_zeros[np.isfinite(p_zeros)], q_zeros[np.isfinite(q_zeros)],
                            np.linalg.eigvals(src.M.A), np.linalg.eigvals(src.C.A)])

    def exact(w):
        p, m, c, q = (freqresp(s, w) for s in (src.P, src.M, src.C, src.Q))
        return 1.0 / p + (m + c) / (1 - q)

    return matched(zeros, poles, src.ts, exact, f"Gd^-1 of {loop.name!r}")


def reconstruct_disturbance(loop: LoopSystem, e: object, d_f: object, model: bool = True) -> np.ndarray:
    """Disturbance that explains a flight of ``loop``: ``-Gd^{-1}{e + Gf{d_f}}`` (m/s^2).

    With ``model=True`` (the closed form) the maps are those of ``loop``'s model, exact in
    Case I; with ``model=False`` they are those of ``loop`` itself, i.e. of a sampled true
    plant flown with the model's DOB (used by the robust design to reconstruct under every
    hypothesis of the Delta set). The constant part of a disturbance is invisible in the
    error and is reconstructed from rest (docs/theory.md section 2).

    Parameters
    ----------
    loop : LoopSystem
        The system that flew.
    e : array_like
        Its tracking error over the trial, m.
    d_f : array_like
        The learning signal it flew with, m/s^2 (zeros if none), same length.
    model : bool
        Use the maps of ``loop``'s model (True) or of ``loop`` itself (False).

    Returns
    -------
    numpy.ndarray
        The reconstructed disturbance, m/s^2, same length as ``e``.
    """
    e = as_signal(e, "e")
    df = as_signal(d_f, "d_f", e.size)
    src = loop.nominal if model else loop
    e_virtual = e + simulate_map(src.G_f, df) if np.any(df) else e
    return -inverse_gd_filter(loop, model).apply(e_virtual, "e")


def closed_form_filters(prev: LoopSystem, nxt: LoopSystem) -> LearningFilters:
    """Build the closed-form filters for system ``nxt`` learning from ``prev``.

    ``prev``'s nominal loop (its model ``P_hat``) is used; ``nxt`` contributes its Q only.
    ``L1 = -(1 - Q_j) Gd_{j-1}^{-1}``, ``L2 = L1 Gf_{j-1}`` (the Theorem, paper Sec. III;
    docs/theory.md section 2), zeros and poles from the blocks (module docstring).

    Parameters
    ----------
    prev : LoopSystem
        System j-1, learned from.
    nxt : LoopSystem
        System j, the learning system.

    Returns
    -------
    LearningFilters
        The pair ``(L1, L2)``.

    Raises
    ------
    SpecError
        Different sample times, or a Q without unit DC gain.
    IlcdobError
        The zero-pole-gain form disagrees with the block formula (numerical trouble).
    """
    if abs(prev.ts - nxt.ts) > 1e-12:
        raise SpecError(f"`sample_time`: systems {prev.name!r} ({prev.ts} s) and {nxt.name!r} "
                        f"({nxt.ts} s) must share one sample time")
    src = prev.nominal
    zeros = np.concatenate([
        _zeros_without_one(one_minus(nxt.Q), f"system {nxt.name!r}"),
        np.linalg.eigvals(src.closed_loop.A),
    ])
    p_zeros = np.asarray(src.P.zeros(), dtype=complex)
    poles = np.concatenate([
        np.linalg.eigvals(nxt.Q.A),
        p_zeros[np.isfinite(p_zeros)],
        _zeros_without_one(one_minus(src.Q), f"system {prev.name!r}"),
        np.linalg.eigvals(src.M.A),
        np.linalg.eigvals(src.C.A),
    ])
    l1 = matched(zeros, poles, src.ts, lambda w: _l1_exact(src, nxt, w),
                  f"learning filter {prev.name!r} -> {nxt.name!r}")
    l2_zeros = np.concatenate([_zeros_without_one(one_minus(nxt.Q), f"system {nxt.name!r}"),
                               np.linalg.eigvals(src.Q.A)])
    l2_poles = np.concatenate([np.linalg.eigvals(nxt.Q.A),
                               _zeros_without_one(one_minus(src.Q), f"system {prev.name!r}")])
    l2 = matched(l2_zeros, l2_poles, src.ts, lambda w: _l1_exact(src, nxt, w) * freqresp(src.G_f, w),
                  f"learning filter L2 {prev.name!r} -> {nxt.name!r}")
    return LearningFilters(source=src, target=nxt, L1=l1, L2=l2)
