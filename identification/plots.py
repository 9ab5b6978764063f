"""Figures of a fit: measured vs simulated, residual correlations, Bode with uncertainty band."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ilcdob.atomic import savefig_atomic  # noqa: E402
from ilcdob.signals import FlightData  # noqa: E402

from .results import TFEstimate, fit_percent  # noqa: E402

__all__ = ["plot_fit"]


def _compare_axes(ax, fd: FlightData, est: TFEstimate, label: str) -> None:
    y = fd[est.output]
    yhat = est.predict(fd[est.input], y)
    ax.plot(fd.t, y, color="k", lw=0.9, label="measured")
    ax.plot(fd.t, yhat, color="#dd8452", lw=0.9, ls="--", label=f"model ({fit_percent(y, yhat):.1f} % fit)")
    ax.set_title(f"{label}: {Path(fd.source).name}", fontsize=9)
    ax.set_ylabel(f"{est.output} ({fd.units.get(est.output) or '-'})")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)


def plot_fit(est: TFEstimate, estimation: list[FlightData], validation: list[FlightData], out: str | Path,
             w: np.ndarray | None = None) -> list[Path]:
    """Write ``compare.png``, ``residuals.png`` and ``bode.png`` into ``out``; returns the paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    sets = [("estimation", fd) for fd in estimation] + [("validation", fd) for fd in validation]
    fig, axes = plt.subplots(len(sets), 1, figsize=(9, 2.4 * len(sets)), squeeze=False)
    for ax, (label, fd) in zip(axes[:, 0], sets):
        _compare_axes(ax, fd, est, label)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    savefig_atomic(fig, out / "compare.png", dpi=110)
    plt.close(fig)
    paths.append(out / "compare.png")

    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5))
    for ax, test, title in [(axes[0], est.whiteness, "residual autocorrelation"),
                            (axes[1], est.input_correlation, f"cross-correlation of {est.input} and residuals")]:
        ax.stem(test.lags, test.values, basefmt=" ")
        ax.axhspan(-test.bound, test.bound, color="#4c72b0", alpha=0.15, label="99 % band")
        ax.set_title(f"{title} ({100 * test.share_inside:.0f} % inside)", fontsize=9)
        ax.set_xlabel("lag (samples)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    savefig_atomic(fig, out / "residuals.png", dpi=110)
    plt.close(fig)
    paths.append(out / "residuals.png")

    if w is None:
        w = np.logspace(-2, np.log10(0.999 * np.pi / est.ts), 300)
    g = est.frequency_response(w)
    bound = est.uncertainty(w)
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    mag = 20 * np.log10(np.abs(g))
    axes[0].semilogx(w, mag, color="k", label="estimate")
    lo = 20 * np.log10(np.maximum(1 - bound, 1e-6))
    hi = 20 * np.log10(1 + bound)
    axes[0].fill_between(w, mag + lo, mag + hi, color="#dd8452", alpha=0.35, label="3-sigma |Delta| band")
    axes[0].set_ylabel("magnitude (dB)")
    axes[0].legend(fontsize=7)
    axes[1].semilogx(w, np.degrees(np.unwrap(np.angle(g))), color="k")
    dphi = np.degrees(np.arcsin(np.clip(bound, 0, 1)))
    ph = np.degrees(np.unwrap(np.angle(g)))
    axes[1].fill_between(w, ph - dphi, ph + dphi, color="#dd8452", alpha=0.35)
    axes[1].set_ylabel("phase (deg)")
    axes[1].set_xlabel("frequency (rad/s)")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title("Identified model with its multiplicative uncertainty bound", fontsize=9)
    fig.tight_layout()
    savefig_atomic(fig, out / "bode.png", dpi=110)
    plt.close(fig)
    paths.append(out / "bode.png")
    return paths
