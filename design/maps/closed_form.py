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

With ``D = 1 - Q + P (M + C)`` over the common denominator of the blocks,
``L1_j = -(1 - Q_j) D/(P (1 - Q))``: the poles of ``Q_{j-1}`` cancel exactly and are never
formed. What is computed, and how, so that it stays accurate at ``Ts`` = 1 ms and ``q_order``
up to 8 (:mod:`ilcdob.discretize`, "Conditioning"; measured against an independent
evaluation of the blocks, ``tests/test_conditioning.py``):

* poles of ``Q_j``, ``M`` and ``C``: analytic (the lags' ``e^{-Ts/tau}``, Tustin images, the
  delay states' 0), not eigenvalues of realisations;
* zeros of ``P_hat``: from the delta-form pencil of the sampled plant (realised in the
  normalised variable ``s Ts``, so its small input entries keep their digits);
* zeros of ``1 - Q``: ``1 + eig((A - I) + B C)`` of the lag cascade in delta form
  (:func:`one_minus_zeros`);
* closed-loop poles: ``1 + eig(A - I)`` of the interconnection assembled from the blocks'
  delta forms, with the exact poles at 0 of a delay line shared by the plant and the Q branch
  deflated (:meth:`ilcdob.loop.LoopSystem.poles`);
* coinciding zero/pole pairs (equal ``Q`` in ``L2``; delay poles) cancel.

The gain is matched to the block formula and the zero-pole form checked against it
(:func:`matched`): a disagreement beyond ``MATCH_RTOL`` is a :class:`~ilcdob.errors.NumericalError`.

One integrator (the PID's) remains: the loop rejects constant disturbances, so the error
carries their derivative only. The ZOH sampling zero of P_hat outside the unit circle
becomes an anti-causal pole (stable inversion, :mod:`ilcdob.design.filters.noncausal`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable

import control as ct
import numpy as np

from ilcdob.discretize import DiscreteBlock, cancel_roots
from ilcdob.errors import NumericalError, SpecError
from ilcdob.loop import LoopSystem, delta_poles, freqresp
from ilcdob.signals import as_signal

from ..filters.noncausal import ZPKFilter

__all__ = ["LearningFilters", "closed_form_filters", "simulate_map", "inverse_gd_filter",
           "reconstruct_disturbance", "one_minus", "one_minus_zeros", "matched", "MATCH_RTOL"]

_GAIN_CHECK_W = np.array([0.37, 1.3, 5.1, 17.0])  # rad/s, points where the zpk form is checked


def simulate_map(sys: ct.StateSpace, u: np.ndarray) -> np.ndarray:
    """Causal response of a discrete SISO system to an input trial, from rest.

    The state-space recursion of ``sys`` in compiled code (:func:`ilcdob.statespace.simulate`:
    the recursion run in all blocks of the trial at once, block starts refined), to the rounding
    of the sample-by-sample recursion.

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

    Raises
    ------
    SpecError
        ``sys`` is not a discrete-time SISO state-space system.
    SignalError
        ``u`` is not a 1-D array of finite samples.
    """
    from ilcdob.statespace import simulate

    if not isinstance(sys, ct.StateSpace) or not sys.isdtime(strict=True) or sys.ninputs != 1 or sys.noutputs != 1:
        got = (f"a system with {sys.ninputs} input(s), {sys.noutputs} output(s), dt={sys.dt!r}"
               if isinstance(sys, ct.StateSpace) else type(sys).__name__)
        raise SpecError(f"`sys`: got {got}, expected a discrete-time SISO control.StateSpace (e.g. a loop map "
                        "such as loop.G_f)")
    arr = np.asarray(u, dtype=float)
    u = as_signal(arr[0] if arr.ndim == 2 and arr.shape[0] == 1 else arr, "u")
    return simulate(sys.A, sys.B, sys.C, sys.D, u)[0]


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


def _block(loop: LoopSystem, key: str) -> DiscreteBlock:
    """The loop's block ``key`` with its delta form and analytic poles (a plain eigenvalue fallback for
    a loop built without them)."""
    blk = loop.blocks.get(key) if loop.blocks else None
    if blk is not None:
        return blk
    sys = getattr(loop, key)
    a = np.asarray(sys.A, dtype=float)
    return DiscreteBlock(sys, a - np.eye(a.shape[0]), np.linalg.eigvals(a).astype(complex) if a.size else
                         np.zeros(0, dtype=complex))


def one_minus_zeros(q: DiscreteBlock) -> np.ndarray:
    """Zeros of ``1 - Q`` (z-plane) from the delta form: ``1 + eig((A - I) + B C/(1 - D))``.

    The zeros of ``(A, B, -C, 1 - D)`` are the eigenvalues of ``A + B C/(1 - D)``; computed as
    ``1 +`` those of ``A - I + B C/(1 - D)`` they keep the digits that ``A`` (entries near 1)
    rounds away at fast sampling (:mod:`ilcdob.discretize`, "Conditioning").

    Parameters
    ----------
    q : DiscreteBlock
        The Q branch (:func:`ilcdob.discretize.q_block`).

    Returns
    -------
    numpy.ndarray
        The zeros, among them ``z = 1`` for a unit-DC-gain ``Q``.
    """
    b = np.asarray(q.sys.B, dtype=float)[:, 0]
    c = np.asarray(q.sys.C, dtype=float)[0]
    d = float(np.asarray(q.sys.D, dtype=float)[0, 0])
    return delta_poles(q.a_minus_i + np.outer(b, c) / (1.0 - d))


def _zeros_without_one(q: DiscreteBlock, what: str) -> np.ndarray:
    z = one_minus_zeros(q)
    i = int(np.argmin(np.abs(z - 1.0)))
    if abs(z[i] - 1.0) > 1e-5:
        raise SpecError(f"{what}: 1 - Q has no zero at z = 1 (nearest {z[i]:.6g}); Q must have unit DC gain")
    return np.delete(z, i)


def _inverse_gd_response(loop: LoopSystem, w: np.ndarray) -> np.ndarray:
    """``Gd^{-1} = 1/P + (M + C)/(1 - Q)`` of ``loop``'s blocks, evaluated from their responses (delta form)."""
    p, m, c, q = (_block(loop, k).response(w) for k in ("P", "M", "C", "Q"))
    return 1.0 / p + (m + c) / (1 - q)


def _l1_exact(prev: LoopSystem, nxt: LoopSystem, w: np.ndarray) -> np.ndarray:
    """``-(1 - Q_j) (1/P_hat + (M + C)/(1 - Q_{j-1}))`` evaluated from block responses (delta form)."""
    return -(1 - _block(nxt, "Q").response(w)) * _inverse_gd_response(prev, w)


def _l2_exact(prev: LoopSystem, nxt: LoopSystem, w: np.ndarray) -> np.ndarray:
    """``L1 Gf_{j-1} = (1 - Q_j)/(1 - Q_{j-1})`` evaluated from block responses (delta form)."""
    return (1 - _block(nxt, "Q").response(w)) / (1 - _block(prev, "Q").response(w))


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

    def __repr__(self) -> str:
        return (f"<LearningFilters {self.source.name!r} -> {self.target.name!r}: L1 {len(self.L1.poles)} poles, "
                f"advance {self.L1.advance}; L2 {len(self.L2.poles)} poles, advance {self.L2.advance}>")

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

        Evaluated as written, the two terms of ``Te1`` cancel to many digits under a small model
        error (``Te1`` near -170 dB at 0.01 rad/s for a 10 % gain error on the built-in fleet,
        where a relative error of 1e-9 in either term is the whole result). With
        ``1/Gd = 1/P + (M + C)/(1 - Q)``, ``Gf (1 - Q) = -Gd`` and the Theorem's
        ``L1* = -(1 - Q_hat_j)/Gd_hat_{j-1}`` (hats: the filters' loops :attr:`source` and
        :attr:`target`), the same ``Te1`` is, for any true loops (plant, C, Q and M may all
        differ from the models')::

            Te1 = Gd_j [(1/P - 1/P_hat) + ((M + C)/(1 - Q) - (M_hat + C_hat)/(1 - Q_hat))]_{j-1}
                  - Gf_j [(Q_hat_j - Q_j)/Gd_hat_{j-1} + (L1 - L1*)]

        and every difference in it is formed from the blocks' responses
        (:meth:`ilcdob.discretize.DiscreteBlock.response`) as a difference of the blocks, e.g.
        ``1/P - 1/P_hat = (P_hat - P)/(P P_hat)``, which is exactly 0 where a true block is the
        model's. ``L1`` is the Theorem's filter as applied: ``L1*`` times the factors of the poles
        inverted with zero phase error (:attr:`~ilcdob.design.filters.noncausal.ZPKFilter.substituted`),
        whose excess over 1 is evaluated without cancellation. The zero-pole form's rounding away
        from ``L1*`` (below :data:`MATCH_RTOL`, checked when it is built, :func:`matched`) is not
        part of the design and is left out: on the built-in fleet it is about 4e-14 ``|L1|`` at
        1e-3 rad/s, which double precision does not resolve (the two responses agree to 1e-12
        there) and which would be a quarter of ``Te1`` under a 10 % gain error (-250 dB).

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

        Raises
        ------
        SpecError
            A true loop's sample time differs from the filters'.
        """
        src = source_true if source_true is not None else self.source
        tgt = target_true if target_true is not None else self.target
        for arg, loop in (("source_true", src), ("target_true", tgt)):
            if abs(loop.ts - self.source.ts) > 1e-12:
                raise SpecError(f"`{arg}`: the loop of {loop.name!r} has sample time {loop.ts} s, the filters "
                                f"{self.source.ts} s; pass the true loop sampled at {self.source.ts} s")
        w = np.asarray(w, dtype=float)
        model, true_prev, true_j = (_block_responses(lp, w) for lp in (self.source, src, tgt))
        q_hat_j = _block(self.target, "Q").response(w)
        d_q_j = (np.zeros(w.shape, dtype=complex) if _same_block(_block(self.target, "Q"), _block(tgt, "Q"))
                 else q_hat_j - true_j["Q"])  # Q_hat_j - Q_j
        d = {k: _block_difference(src, self.source, k, true_prev, model) for k in ("P", "C", "Q", "M")}
        mc_hat = model["M"] + model["C"]
        # 1/Gd_{j-1} - 1/Gd_hat_{j-1}, term by term
        delta = (-d["P"] / (true_prev["P"] * model["P"]) + (d["M"] + d["C"]) / true_prev["1-Q"]
                 + mc_hat * d["Q"] / (true_prev["1-Q"] * model["1-Q"]))
        inv_gd_hat = 1.0 / model["P"] + mc_hat / model["1-Q"]
        l1_star = -(1 - q_hat_j) * inv_gd_hat
        d_l1 = l1_star * _substitution_excess(self.L1, w)  # L1 - L1*
        gd_j, gf_j = _gd_gf(true_j)
        te1 = gd_j * delta - gf_j * (d_q_j * inv_gd_hat + d_l1)
        return te1, te1 * _gd_gf(true_prev)[1]


def _same_block(a: DiscreteBlock, b: DiscreteBlock) -> bool:
    """Whether two blocks are the same system (the same realisation, delta form included)."""
    if a is b:
        return True
    pairs = [(a.a_minus_i, b.a_minus_i)] + [(getattr(a.sys, m), getattr(b.sys, m)) for m in ("A", "B", "C", "D")]
    return a.ts == b.ts and all(np.shape(x) == np.shape(y) and np.array_equal(x, y) for x, y in pairs)


def _block_responses(loop: LoopSystem, w: np.ndarray) -> dict[str, np.ndarray]:
    """Responses of the blocks ``P``, ``C``, ``Q``, ``M`` of ``loop`` from their delta forms, and ``1 - Q``."""
    out = {k: _block(loop, k).response(w) for k in ("P", "C", "Q", "M")}
    out["1-Q"] = 1 - out["Q"]
    return out


def _block_difference(true: LoopSystem, model: LoopSystem, key: str, r_true: dict, r_model: dict) -> np.ndarray:
    """Response of the true block ``key`` minus the model's: exactly 0 where they are the same block."""
    if _same_block(_block(true, key), _block(model, key)):
        return np.zeros(np.shape(r_true[key]), dtype=complex)
    return r_true[key] - r_model[key]


def _gd_gf(r: dict) -> tuple[np.ndarray, np.ndarray]:
    """``Gd = P (1 - Q)/D`` and ``Gf = -P/D``, ``D = 1 - Q + P (M + C)``, from block responses."""
    d = r["1-Q"] + r["P"] * (r["M"] + r["C"])
    return r["P"] * r["1-Q"] / d, -r["P"] / d


def _substitution_excess(f: ZPKFilter, w: np.ndarray) -> np.ndarray:
    """``realised/exact - 1`` of ``f`` (:attr:`ZPKFilter.substituted`), without cancellation.

    Each substituted pole ``p`` multiplies the exact response by
    ``(z^-1 - p)(z - p)/(1 - p)^2 = 1 + 4 p sin^2(w Ts/2)/(1 - p)^2`` on the unit circle."""
    s2 = 4.0 * np.sin(0.5 * np.asarray(w, dtype=float) * f.ts) ** 2
    out = np.zeros(s2.shape, dtype=complex)
    for p in np.asarray(f.substituted, dtype=complex):
        e = p * s2 / (1 - p) ** 2
        out = out + e + out * e  # (1 + out)(1 + e) - 1
    return out


#: Relative tolerance of the check of a zero-pole form against its block formula (:func:`matched`).
MATCH_RTOL = 1e-5


def _check_grid(ts: float) -> np.ndarray:
    """Frequencies where :func:`matched` checks a filter: the gain points below 0.8 Nyquist and 16
    points spaced logarithmically from 0.1 rad/s to 0.8 Nyquist."""
    top = 0.8 * np.pi / ts
    return np.unique(np.concatenate([_GAIN_CHECK_W[_GAIN_CHECK_W < top], np.geomspace(min(0.1, top / 10), top, 16)]))


def _rational_response(f: ZPKFilter, w: np.ndarray) -> np.ndarray:
    """The response of ``f``'s zeros, poles and gain exactly as given (not as applied)."""
    exact = getattr(f, "exact_freqresp", None)
    if exact is not None:
        return exact(w)
    return f(np.exp(1j * np.asarray(w, dtype=float) * f.ts))


def matched(zeros: np.ndarray, poles: np.ndarray, ts: float, exact: Callable, what: str) -> ZPKFilter:
    """Zero-pole filter whose gain is matched to a block formula, and checked against it.

    The zeros and poles of a learning filter are collected from the blocks of the loop
    (never from a quotient of polynomials, docs/theory.md section 2); coinciding pole/zero
    pairs are cancelled first. The gain is the mean ratio of ``exact(w)`` to the unit-gain
    rational response at the frequencies of ``_GAIN_CHECK_W`` (0.37 to 17 rad/s) below 0.8
    times Nyquist. The filter's exact rational response (:meth:`ZPKFilter.exact_freqresp`, not
    the response as applied) must then agree with ``exact`` to ``MATCH_RTOL`` relative at those
    points and on a logarithmic grid from 0.1 rad/s to 0.8 Nyquist, which checks the zeros and
    poles.

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
    NumericalError
        The zero-pole form does not match ``exact`` (the message names the filter, the largest
        relative disagreement and its frequency).
    """
    zeros, poles = cancel_roots(zeros, poles, rtol=1e-9)
    unit = ZPKFilter(zeros, poles, 1.0, ts)
    w_gain = _GAIN_CHECK_W[_GAIN_CHECK_W < 0.8 * np.pi / ts]
    if w_gain.size < 2:
        w_gain = np.geomspace(0.1, 0.8 * np.pi / ts, 4)
    with np.errstate(all="ignore"):
        ratio = exact(w_gain) / _rational_response(unit, w_gain)
    gain = float(np.real(np.mean(ratio)))
    filt = ZPKFilter(zeros, poles, gain, ts)
    w = _check_grid(ts)
    with np.errstate(all="ignore"):
        want = exact(w)
        err = np.abs(_rational_response(filt, w) / want - 1)
    err = np.where(np.isfinite(err), err, np.inf)
    i = int(np.argmax(err))
    if not (gain != 0 and np.isfinite(gain) and err[i] <= MATCH_RTOL):
        raise NumericalError(
            f"{what}: the zero-pole form ({len(zeros)} zeros, {len(poles)} poles) does not match the block "
            f"formula: relative disagreement {err[i]:.3g} at {w[i]:.4g} rad/s (tolerance {MATCH_RTOL:g}, Ts = "
            f"{ts:g} s); the loop is too badly conditioned at this sample time and DOB order")
    return filt


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
    poles = np.concatenate([_plant_zeros(src), one_minus_zeros(_block(src, "Q")), _block(src, "M").poles,
                            _block(src, "C").poles])
    return matched(src.poles(), poles, src.ts, partial(_inverse_gd_response, src), f"Gd^-1 of {loop.name!r}")


def _finite_zeros(sys: ct.StateSpace) -> np.ndarray:
    z = np.asarray(sys.zeros(), dtype=complex)
    return z[np.isfinite(z)]


def _plant_zeros(loop: LoopSystem) -> np.ndarray:
    blk = _block(loop, "P")
    return blk.zeros if blk.zeros is not None else _finite_zeros(loop.P)


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
    NumericalError
        The zero-pole-gain form disagrees with the block formula (numerical trouble).
    """
    if abs(prev.ts - nxt.ts) > 1e-12:
        raise SpecError(f"`sample_time`: systems {prev.name!r} ({prev.ts} s) and {nxt.name!r} "
                        f"({nxt.ts} s) must share one sample time")
    src = prev.nominal
    q_j, q_p = _block(nxt, "Q"), _block(src, "Q")
    omq_j = _zeros_without_one(q_j, f"system {nxt.name!r}")
    omq_p = _zeros_without_one(q_p, f"system {prev.name!r}")
    # L1 = -(1 - Q_j) D/(P (1 - Q)): zeros of 1 - Q_j and of D (the closed-loop poles); poles of Q_j,
    # zeros of P_hat and of 1 - Q, poles of M and C (Q's poles cancel; z = 1 cancels analytically)
    zeros = np.concatenate([omq_j, src.poles()])
    poles = np.concatenate([q_j.poles, _plant_zeros(src), omq_p, _block(src, "M").poles, _block(src, "C").poles])
    l1 = matched(zeros, poles, src.ts, lambda w: _l1_exact(src, nxt, w),
                 f"learning filter {prev.name!r} -> {nxt.name!r}")
    l2 = matched(np.concatenate([omq_j, q_p.poles]), np.concatenate([q_j.poles, omq_p]), src.ts,
                 lambda w: _l2_exact(src, nxt, w), f"learning filter L2 {prev.name!r} -> {nxt.name!r}")
    return LearningFilters(source=src, target=nxt, L1=l1, L2=l2)
