"""The ends of a trial for a non-causal filter: the reconstructed disturbance continued past the
trial's end along its trend, a look-ahead FIR run over the trial with its output before ``t = 0``
replaced by the signal over the first samples that has the same effect on the target's error
(:class:`StartMatch`; older designs fold it back in), the robust-set law
(:meth:`~..methods.robust_set.RobustSetDesign.apply`), and the check that a learning signal's ends stay
near its interior (:func:`end_peaks`). docs/theory.md section 6 derives the start's continuation.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np

from ilcdob.errors import LearningEndWarning, SpecError
from ilcdob.lifted import markov_parameters

from .band import END_FIT_S, fade_out, fold_start
from .entries import check_state_space

__all__ = ["trend_weights", "end_continuation", "fir_on_trial", "StartMatch", "START_SPAN_S", "START_WINDOW",
           "START_RIDGE", "EndPeaks", "end_peaks", "END_PEAK_FACTOR"]

#: Longest span over the trial's first samples that takes the learning signal's part before ``t = 0``, s
#: (at most the FIR's look-ahead; :class:`StartMatch`).
START_SPAN_S = 1.0
#: The window over which the start's effect on the target's error is matched, in spans.
START_WINDOW = 3
#: Ridge of the start's least squares, relative to the mean diagonal of its normal matrix: what keeps the
#: continuation smooth (1e-6 put a peak of 1.15x the interior at the start; 1e-2 none, with trials as good).
START_RIDGE = 1e-2

#: An end of a learning signal whose peak exceeds its interior peak this many times is flagged (:func:`end_peaks`).
END_PEAK_FACTOR = 2.0


def trend_weights(n: int) -> np.ndarray:
    """Weights of the trend's least-squares fit over ``n`` samples: ``numpy.hanning(n + 2)[1:-1]`` (all > 0).

    Parameters
    ----------
    n : int
        Samples of the fit.
    """
    return np.hanning(int(n) + 2)[1:-1]


def end_continuation(d_hat: np.ndarray, advance: int, fade: int) -> np.ndarray:
    """``d_hat`` continued ``advance`` samples past the trial along its trend
    (:meth:`~..methods.robust_set.RobustSetDesign.apply`).

    The line fitted by least squares, weighted by :func:`trend_weights` (a Hann window), to the
    ``2 advance`` samples before the last ``fade`` ones (fewer when the trial is shorter; a constant
    from one sample; zero without any), blended into over the last ``fade`` samples with
    :func:`~.band.fade_out` and continued for ``advance`` samples. The weights make the fit blind
    to oscillations of the window (unweighted, a disturbance near the Nyquist frequency tilts the
    line, and the whole-trial figure ``rho_N`` rose to 36-560).

    Parameters
    ----------
    d_hat : numpy.ndarray
        The reconstructed disturbance, ``n`` samples.
    advance : int
        Samples to continue.
    fade : int
        Samples at the end to blend into the line.

    Returns
    -------
    numpy.ndarray
        ``n + advance`` samples.
    """
    n = d_hat.size
    m = min(int(fade), n)
    fit = min(2 * int(advance), n - m)
    k_out = np.arange(n - m, n + advance, dtype=float)
    if fit >= 2:
        coef = np.polyfit(np.arange(n - m - fit, n - m, dtype=float), d_hat[n - m - fit:n - m], 1,
                          w=np.sqrt(trend_weights(fit)))
        line = np.polyval(coef, k_out)
    else:
        line = np.full(k_out.size, d_hat[n - m - 1] if fit == 1 else 0.0)
    out = np.concatenate([d_hat, line[m:]])
    out[n - m:n] = line[:m] + fade_out(m) * (d_hat[n - m:] - line[:m])
    return out


@dataclass(frozen=True)
class StartMatch:
    """What a look-ahead filter's output before ``t = 0`` does to the target, done over the trial's first samples.

    Over an infinite horizon the learning signal starts before the trial; on a trial it cannot. Its part
    before ``t = 0``, ``p``, would leave the map ``H`` from this signal to the target's error (the target
    model's ``Gf_hat_j (1 - Q_j)``) in the state ``x0`` at ``t = 0``, whose free response ``O x0`` is what
    the error over the trial misses. The continuation ``c`` over the first :attr:`span` samples is the
    ridge-regularised least-squares input with that effect, ``c = argmin ||H_M c - O x0||^2 + r ||c||^2``
    over :data:`START_WINDOW` spans (``r``: :data:`START_RIDGE` x the mean diagonal of ``H_M^T H_M``), so
    ``c = gain x0``; docs/theory.md section 6 gives the derivation and the figures it changed.

    Attributes
    ----------
    a, b : numpy.ndarray
        ``H``'s state matrices ``A`` (n x n) and ``B`` (n values): ``x(k + 1) = A x(k) + B p(k)`` from rest.
    c, d : numpy.ndarray
        Its output matrices (kept so the entry is the whole map ``H``).
    gain : numpy.ndarray
        ``(span, n)``: the continuation per unit of ``x0``.
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    gain: np.ndarray

    @classmethod
    def design(cls, target_map: ct.StateSpace, advance: int) -> "StartMatch":
        """The continuation for a look-ahead of ``advance`` samples into ``target_map`` (``H``, discrete).

        Parameters
        ----------
        target_map : control.StateSpace
            ``H``: the learning signal (before the target's ``1 - Q``) to the target model's error.
        advance : int
            The FIR's look-ahead, samples (>= 1).

        Returns
        -------
        StartMatch
        """
        a, b, c, d = (np.asarray(x, float) for x in (target_map.A, target_map.B, target_map.C, target_map.D))
        m = max(1, min(int(advance), int(round(START_SPAN_S / target_map.dt))))
        n_w = START_WINDOW * m
        mk = markov_parameters(target_map, n_w)
        hm = np.zeros((n_w, m))
        for i in range(m):  # lower-triangular Toeplitz: H from rest over the window
            hm[i:, i] = mk[:n_w - i]
        obs = np.empty((n_w, a.shape[0]))
        row = c.reshape(1, -1)
        for k in range(n_w):
            obs[k] = row
            row = row @ a
        g = hm.T @ hm
        ridge = START_RIDGE * np.trace(g) / m
        gain = np.linalg.solve(g + ridge * np.eye(m), hm.T @ obs)
        return cls(a, b.reshape(-1), c.reshape(-1), d.reshape(-1), gain)

    @property
    def span(self) -> int:
        """Samples of the continuation."""
        return self.gain.shape[0]

    def state(self, pre: np.ndarray) -> np.ndarray:
        """``x0``: ``H``'s state after ``pre`` (the signal before ``t = 0``, oldest first) from rest.

        Parameters
        ----------
        pre : numpy.ndarray
            The signal before the trial.
        """
        return self._columns(len(pre)) @ np.asarray(pre, float)

    def matrix(self, advance: int) -> np.ndarray:
        """``(span, advance)``: the continuation as a matrix on the ``advance`` samples before ``t = 0``.

        Parameters
        ----------
        advance : int
            Samples before the trial.
        """
        return self.gain @ self._columns(advance)

    def _columns(self, advance: int) -> np.ndarray:
        """``(n, advance)``: ``x0 = sum_k A^(advance - 1 - k) B p(k)`` as a matrix on the samples before ``t = 0``."""
        cols = np.empty((self.b.size, int(advance)))
        v = self.b.copy()
        for k in range(int(advance) - 1, -1, -1):
            cols[:, k] = v
            v = self.a @ v
        return cols

    def to_dict(self) -> dict[str, Any]:
        """``filters.json`` entry ``trial_ends.start``."""
        return {"kind": "matched", "target_map": {"A": self.a.tolist(), "B": self.b.reshape(-1, 1).tolist(),
                                                  "C": self.c.reshape(1, -1).tolist(), "D": float(self.d[0])},
                "gain": self.gain.tolist()}

    @classmethod
    def from_dict(cls, entry: object, key: str = "trial_ends.start") -> "StartMatch":
        """The entry :meth:`to_dict` writes, checked.

        Parameters
        ----------
        entry : object
            The entry.
        key : str
            Its name, for messages.

        Raises
        ------
        SpecError
            Not a ``"matched"`` entry, a bad state space, or a gain not of ``(span >= 1, states)`` finite values.
        """
        if not isinstance(entry, dict) or entry.get("kind") != "matched":
            raise SpecError(f"`{key}`: got {entry!r:.80}, expected {{'kind': 'matched', 'target_map': ..., "
                            "'gain': ...}")
        a, b, c, d = check_state_space(entry.get("target_map"), f"{key}.target_map")
        try:
            gain = np.asarray(entry.get("gain"), dtype=float)
        except (TypeError, ValueError):
            gain = np.empty(0)
        if gain.ndim != 2 or gain.shape[0] < 1 or gain.shape[1] != b.size or not np.all(np.isfinite(gain)):
            raise SpecError(f"`{key}.gain`: got shape {gain.shape}, expected finite values of (span >= 1, "
                            f"{b.size} states)")
        return cls(a, b, c, d, gain)


def fir_on_trial(d_hat: np.ndarray, h: np.ndarray, advance: int, fade: int,
                 start: StartMatch | None = None) -> np.ndarray:
    """The robustness FIR over a trial of the reconstructed disturbance
    (:meth:`~..methods.robust_set.RobustSetDesign.apply`, extended).

    ``d_hat`` is continued past the trial along its trend (:func:`end_continuation`), taken as zero
    before it, and filtered by ``output(k) = sum_i h[i] d_hat(k + advance - i)``; the output before
    ``t = 0`` is replaced by ``start``'s continuation over the first samples (:class:`StartMatch`), or
    without one (designs written before it) added, time-reversed, to them (:func:`~.band.fold_start`).

    Parameters
    ----------
    d_hat : numpy.ndarray
        The reconstructed disturbance, ``n`` samples, m/s^2.
    h : numpy.ndarray
        The FIR's taps.
    advance : int
        Its look-ahead, samples.
    fade : int
        Samples at the end blended into the trend (:attr:`~..methods.robust_set.RobustSetDesign.end_fade`).
    start : StartMatch, optional
        The start's continuation; None folds.

    Returns
    -------
    numpy.ndarray
        ``n`` samples.
    """
    n = d_hat.size
    if not advance:
        return np.convolve(d_hat, h)[:n]
    full = np.convolve(end_continuation(d_hat, advance, fade), h)  # F's output at times -advance, -advance + 1, ...
    if start is None:
        return fold_start(full[:advance + n], advance, n)
    out = full[advance:advance + n].copy()
    m = min(start.span, n)
    out[:m] += (start.gain @ start.state(full[:advance]))[:m]
    return out


@dataclass(frozen=True)
class EndPeaks:
    """The peaks of a learning signal at a trial's ends and inside it (:func:`end_peaks`).

    Attributes
    ----------
    start, end : float
        Largest magnitude over the first and the last ``window`` samples, in the signal's unit.
    interior : float
        Largest magnitude between them.
    window : int
        Samples of each end.
    ts : float
        Sample time, s.
    """

    start: float
    end: float
    interior: float
    window: int
    ts: float

    @property
    def flagged(self) -> list[str]:
        """The ends (``"start"``, ``"end"``) whose peak exceeds :data:`END_PEAK_FACTOR` times the interior's."""
        return [k for k, v in (("start", self.start), ("end", self.end)) if v > END_PEAK_FACTOR * self.interior]

    def to_dict(self) -> dict:
        """``start_peak``, ``end_peak``, ``interior_peak``, ``window_s`` and ``flagged`` (as in ``learning.json``)."""
        return {"start_peak": self.start, "end_peak": self.end, "interior_peak": self.interior,
                "window_s": self.window * self.ts, "flagged": self.flagged}

    def warn(self, unit: str, band_off: bool) -> None:
        """Warn (:class:`~ilcdob.errors.LearningEndWarning`) where an end is flagged, naming it and the cause.

        Parameters
        ----------
        unit : str
            The signal's unit, for the message.
        band_off : bool
            Whether the law ran without a learning band (the usual cause).
        """
        for k in self.flagged:
            peak = self.start if k == "start" else self.end
            cause = ("the law runs without a learning band, so the source's inverse (its gain ~1/P_hat at high "
                     "frequency) acts on the continuation of the error past the trial's "
                     + ("start" if k == "start" else "end") + "; learn with a band (--bandwidth auto or a corner)"
                     if band_off else
                     "the learning filters act on the continuation of the error past the trial's "
                     + ("start" if k == "start" else "end") + "; a lower --bandwidth or a longer trial shortens it")
            warnings.warn(f"learning signal: its {k} ({self.window * self.ts:.3g} s) peaks at {peak:.4g} {unit}, "
                          f"{peak / self.interior if self.interior > 0 else float('inf'):.3g} x its interior peak "
                          f"({self.interior:.4g} {unit}): {cause}, or fade that part out before flying it",
                          LearningEndWarning, stacklevel=2)


def end_peaks(d_f: np.ndarray, ts: float) -> EndPeaks:
    """Peaks of a learning signal over its first and last :data:`~.band.END_FIT_S` seconds (at least 5 samples, at
    most a tenth of the trial each) and over the samples between.

    Parameters
    ----------
    d_f : numpy.ndarray
        The learning signal of one trial.
    ts : float
        Sample time, s.

    Returns
    -------
    EndPeaks
    """
    d_f = np.abs(np.asarray(d_f, float))
    n = d_f.size
    m = min(max(5, int(round(END_FIT_S / ts))), n // 10)
    if m == 0:
        return EndPeaks(0.0, 0.0, float(d_f.max()) if n else 0.0, 0, ts)
    return EndPeaks(float(d_f[:m].max()), float(d_f[-m:].max()), float(d_f[m:-m].max()), m, ts)
