"""The ends of a trial for a non-causal filter: the reconstructed disturbance continued past the
trial's end along its trend, a look-ahead FIR run over the trial with its output before
``t = 0`` folded back in (the robust-set law, :meth:`~..methods.robust_set.RobustSetDesign.apply`),
and the check that a learning signal's ends stay near its interior (:func:`end_peaks`).
"""

from __future__ import annotations

import numpy as np

import warnings
from dataclasses import dataclass

from ilcdob.errors import LearningEndWarning

from .band import END_FIT_S, fade_out, fold_start

__all__ = ["trend_weights", "end_continuation", "fir_on_trial", "EndPeaks", "end_peaks", "END_PEAK_FACTOR"]

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


def fir_on_trial(d_hat: np.ndarray, h: np.ndarray, advance: int, fade: int) -> np.ndarray:
    """The robustness FIR over a trial of the reconstructed disturbance
    (:meth:`~..methods.robust_set.RobustSetDesign.apply`, extended).

    ``d_hat`` is continued past the trial along its trend (:func:`end_continuation`), taken as zero
    before it, and filtered by ``output(k) = sum_i h[i] d_hat(k + advance - i)``; the output before
    ``t = 0`` is added, time-reversed, to the trial's first samples (:func:`~.band.fold_start`).

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

    Returns
    -------
    numpy.ndarray
        ``n`` samples.
    """
    n = d_hat.size
    if advance:
        d_hat = end_continuation(d_hat, advance, fade)
    full = np.convolve(d_hat, h)  # F's output at times -advance, -advance + 1, ...
    return fold_start(full[:advance + n], advance, n) if advance else full[:n].copy()


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
