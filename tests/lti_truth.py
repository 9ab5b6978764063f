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
