"""The ends of a trial for a non-causal filter: the reconstructed disturbance continued past the
trial's end along its trend, and a look-ahead FIR run over the trial with its output before
``t = 0`` folded back in (the robust-set law, :meth:`~..methods.robust_set.RobustSetDesign.apply`).
"""

from __future__ import annotations

import numpy as np

from .band import fade_out, fold_start

__all__ = ["trend_weights", "end_continuation", "fir_on_trial"]


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
