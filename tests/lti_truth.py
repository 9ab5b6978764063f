"""Helpers of the tests whose truth is python-control alone: fly a continuous map sampled with a zero-order
hold, and the log chirp the identification flights excite with. Nothing of ilcdob is used here."""

from __future__ import annotations

import control as ct
import numpy as np


def fly(sys: ct.TransferFunction, t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Output of the continuous ``sys`` sampled with a zero-order hold at ``t``'s step, from rest, driven by ``u``."""
    return ct.forced_response(ct.c2d(ct.ss(sys), float(t[1] - t[0]), "zoh"), t, u).outputs


def chirp(t: np.ndarray, amplitude: float, seed: int, w0: float = 0.1, w1: float = 15.0,
          white: float = 0.2) -> np.ndarray:
    """A log chirp ``w0 -> w1`` rad/s over ``t`` of ``amplitude``, plus ``white`` times as much white excitation."""
    dur = t[-1]
    phase = w0 * dur / np.log(w1 / w0) * (np.exp(t / dur * np.log(w1 / w0)) - 1)
    return amplitude * (np.sin(phase) + white * np.random.default_rng(seed).standard_normal(t.size))


def alias_radius(num, den, delay: float, ts: float, w: np.ndarray, bound: float, aliases: int = 4000) -> np.ndarray:
    """Radius on ``z = e^{jwTs}`` of the continuous set ``|Delta(jw)| <= bound`` of the plant ``num/den e^{-s delay}``
    sampled with a zero-order hold: ``bound sum_k |a_k| / |sum_k a_k|``, ``a_k = P(j w_k)/(j w_k)`` over the aliases
    ``w_k = w + 2 pi k / ts``, ``|k| <= aliases`` (the sampled response is ``(1 - e^{-jwTs})/Ts sum_k a_k``)."""
    k = np.arange(-aliases, aliases + 1)
    s = 1j * (np.asarray(w, float)[:, None] + 2 * np.pi * k[None, :] / ts)
    a = np.polyval(num, s) / (np.polyval(den, s) * s) * np.exp(-s * delay)
    return bound * np.sum(np.abs(a), axis=1) / np.abs(np.sum(a, axis=1))
