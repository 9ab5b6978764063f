"""Figures of a fit: measured vs simulated, residual correlations, Bode with uncertainty band.

:func:`fit_figures` builds the figures as :class:`matplotlib.figure.Figure` objects (no
pyplot, no global backend: safe in threads and in programs with their own GUI backend);
the application writes them (``ilcdob identify --plot DIR``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ilcdob.display import time_text
from ilcdob.signals import FlightData

from .results import TFEstimate, fit_percent

__all__ = ["fit_figures", "phase_deg"]

#: Resolution of the figures (dots per inch), used when they are saved.
DPI = 110
#: Time stamps from this size on are an absolute clock (epoch seconds): the compare figure counts from the first
#: sample and states it, instead of ticks matplotlib offsets by "+1.7e9".
ABSOLUTE_CLOCK_S = 1e6
#: The Bode legend says the uncertainty band is too narrow to see where its widest extent (dB) is below this
#: share of the magnitude axis' span.
BAND_VISIBLE = 0.01


def _compare_axes(ax, fd: FlightData, est: TFEstimate, label: str, shown: str) -> None:
    y = fd[est.output]
    yhat = est.predict(fd[est.input], y)
    t0 = float(fd.t[0]) if abs(float(fd.t[0])) >= ABSOLUTE_CLOCK_S else 0.0  # an epoch clock: from the first sample
    ax.plot(fd.t - t0, y, color="k", lw=0.9, label="measured")
    ax.plot(fd.t - t0, yhat, color="#dd8452", lw=0.9, ls="--", label=f"model ({fit_percent(y, yhat):.1f} % fit)")
    ax.set_title(f"{label}: {Path(fd.source).name}" + (f" (time from t = {time_text(t0)} s)" if t0 else ""),
                 fontsize=9)
    ax.set_ylabel(f"{shown} ({fd.units.get(est.output) or '-'})")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)


def _compare_figure(est: TFEstimate, estimation: list[FlightData], validation: list[FlightData],
                    shown: str) -> Figure:
    sets = [("estimation", fd) for fd in estimation] + [("validation", fd) for fd in validation]
    fig = Figure(figsize=(9, 2.4 * len(sets)), dpi=DPI)
    axes = fig.subplots(len(sets), 1, squeeze=False)
    for ax, (label, fd) in zip(axes[:, 0], sets):
        _compare_axes(ax, fd, est, label, shown)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    return fig


def _residuals_figure(est: TFEstimate) -> Figure:
    fig = Figure(figsize=(8, 5.5), dpi=DPI)
    axes = fig.subplots(2, 1)
    for ax, test, title in [(axes[0], est.whiteness, "residual autocorrelation"),
                            (axes[1], est.input_correlation, f"cross-correlation of {est.input} and residuals")]:
        ax.stem(test.lags, test.values, basefmt=" ")
        ax.axhspan(-test.bound, test.bound, color="#4c72b0", alpha=0.15, label="99 % band")
        ax.set_title(f"{title} ({100 * test.share_inside:.0f} % inside)", fontsize=9)
        ax.set_xlabel("lag (samples)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _bode_figure(est: TFEstimate, w: np.ndarray | None) -> Figure:
    if w is None:
        w = np.logspace(-2, np.log10(0.999 * np.pi / est.ts), 300)
    g = est.frequency_response(w)
    bound = est.uncertainty(w)
    fig = Figure(figsize=(8, 6), dpi=DPI)
    axes = fig.subplots(2, 1, sharex=True)
    mag = 20 * np.log10(np.abs(g))
    axes[0].semilogx(w, mag, color="k", label="estimate")
    lo = 20 * np.log10(np.maximum(1 - bound, 1e-6))
    hi = 20 * np.log10(1 + bound)
    widest = float(np.max(bound))
    unseen = float(np.max(hi - lo)) < BAND_VISIBLE * max(float(np.ptp(mag)), 1e-12)
    axes[0].fill_between(w, mag + lo, mag + hi, color="#dd8452", alpha=0.35,
                         label=f"3-sigma |Delta| band (at most {100 * widest:.2g} %"
                               + (", too narrow to see at this scale)" if unseen else ")"))
    axes[0].set_ylabel("magnitude (dB)")
    axes[0].legend(fontsize=7)
    ph = phase_deg(est, w)
    axes[1].semilogx(w, ph, color="k")
    dphi = np.degrees(np.arcsin(np.clip(bound, 0, 1)))
    axes[1].fill_between(w, ph - dphi, ph + dphi, color="#dd8452", alpha=0.35)
    axes[1].set_ylabel("phase (deg)")
    axes[1].set_xlabel("frequency (rad/s)")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title("Identified model with its multiplicative uncertainty bound", fontsize=9)
    fig.tight_layout()
    return fig


def phase_deg(est: TFEstimate, w: np.ndarray) -> np.ndarray:
    """The model's phase at ``w`` (rad/s), degrees, continuous and anchored at its low-frequency asymptote.

    Summed factor by factor, ``arg G(jw) = arg k + sum arg(jw - z_i) - sum arg(jw - p_i) - w tau``, each term
    continuous in ``w``; an unwrapped ``angle`` of the product instead starts wherever the first sample's
    principal value lies (``10 / (s^2 (s + 10))`` would read +180 deg falling to +90 deg, not -180 to -270).
    A negative gain counts -180 deg.

    Parameters
    ----------
    est : TFEstimate
        The model (``num``, ``den``, ``delay``).
    w : numpy.ndarray
        Frequencies, rad/s.

    Returns
    -------
    numpy.ndarray
        The phase at each frequency, deg.
    """
    w = np.asarray(w, float)
    jw = 1j * w[:, None]
    num, den = np.trim_zeros(np.asarray(est.num, float), "f"), np.asarray(est.den, float)
    gain = num[0] / den[0]
    out = (-180.0 if gain < 0 else 0.0) - np.degrees(w * est.delay)
    for roots, sign in ((np.roots(num), 1.0), (np.roots(den), -1.0)):
        if roots.size:
            out = out + sign * np.degrees(np.angle(jw - roots[None, :])).sum(axis=1)
    return out


def fit_figures(est: TFEstimate, estimation: list[FlightData], validation: list[FlightData],
                w: np.ndarray | None = None, signals: tuple[str, str] | None = None) -> dict[str, Figure]:
    """The figures of a fit, by file name.

    Parameters
    ----------
    est : TFEstimate
        The fitted model.
    estimation : list of FlightData
        The experiments it was fitted to.
    validation : list of FlightData
        Held-out experiments (may be empty).
    w : numpy.ndarray, optional
        Frequencies of the Bode figure, rad/s (default: 300 log-spaced points from 0.01 rad/s
        to just below Nyquist).
    signals : (str, str), optional
        The input's and output's names as the user gave them, for the axis labels (default: the names
        in ``est``, which the command line sets to ``u`` and ``y``).

    Returns
    -------
    dict of str to matplotlib.figure.Figure
        ``"compare.png"``: measured and simulated output of every experiment, with its fit
        percent; ``"residuals.png"``: residual autocorrelation and input-residual
        cross-correlation with their 99 % bands; ``"bode.png"``: the model's Bode diagram (phase by
        :func:`phase_deg`) with the 3-sigma multiplicative uncertainty band, its widest value in the legend
        (docs/identification.md). The figures are
        not attached to pyplot; their resolution is :data:`DPI`.
    """
    shown = signals[1] if signals else est.output
    return {"compare.png": _compare_figure(est, list(estimation), list(validation), shown),
            "residuals.png": _residuals_figure(est),
            "bode.png": _bode_figure(est, w)}
