"""Held-input segments: stretches of a log where the input sits at its extreme and the output does not follow.

A vehicle on the ground under a climb setpoint, or a setpoint clipped at its limit while the vehicle cannot
answer, logs an input held constant at the largest (or smallest) value of the file while the output stays
where it is. No linear model of the flight explains that stretch: it is a landed or saturated segment, not
noise and not a glitch. The test is made in samples and in shares of each signal's range, so it does not
depend on the unit of time or of the signals (docs/identification.md, "Scores and notes").
"""

from __future__ import annotations

import numpy as np

__all__ = ["HELD_MIN_SAMPLES", "HELD_MIN_SHARE", "HELD_STILL", "HELD_MODEL_MOVES", "held_runs", "held_segments"]

#: A held run lasts at least this many samples ...
HELD_MIN_SAMPLES = 20
#: ... and at least this share of its file.
HELD_MIN_SHARE = 0.02
#: Over a held run the measured output moves (peak to peak) at most this share of its range over the file.
HELD_STILL = 0.05
#: The fitted model's output over the run moves at least this many times what was measured (the model expects
#: the vehicle to answer the held input; a vehicle at rest under a zero input does not count).
HELD_MODEL_MOVES = 4.0

_EQUAL = 1e-9  # two input samples are "the same value" within this share of the input's range


def held_runs(u: np.ndarray, y: np.ndarray) -> list[tuple[int, int, float, str]]:
    """Runs of the input held at its extreme of the file while the measured output stays still.

    Parameters
    ----------
    u, y : ndarray
        One file's input and output, equal lengths.

    Returns
    -------
    list of (first, stop, value, extreme)
        Sample range ``[first, stop)``, the held value and ``"maximum"`` or ``"minimum"``; runs of at least
        :data:`HELD_MIN_SAMPLES` samples and :data:`HELD_MIN_SHARE` of the file along which ``y`` moves at most
        :data:`HELD_STILL` of its range over the file. Empty for a constant input or output.
    """
    u, y = np.asarray(u, float), np.asarray(y, float)
    span_u, span_y = float(np.ptp(u)) if u.size else 0.0, float(np.ptp(y)) if y.size else 0.0
    if span_u <= 0.0 or span_y <= 0.0:
        return []
    tol = _EQUAL * span_u
    change = np.flatnonzero(np.abs(np.diff(u)) > tol) + 1
    starts, stops = np.concatenate([[0], change]), np.concatenate([change, [u.size]])
    need = max(HELD_MIN_SAMPLES, int(np.ceil(HELD_MIN_SHARE * u.size)))
    out = []
    for k in np.flatnonzero(stops - starts >= need):
        a, b = int(starts[k]), int(stops[k])
        value = float(u[a])
        extreme = "maximum" if value >= u.max() - tol else "minimum" if value <= u.min() + tol else None
        if extreme and np.ptp(y[a:b]) <= HELD_STILL * span_y:
            out.append((a, b, value, extreme))
    return out


def held_segments(experiments: list[tuple[np.ndarray, np.ndarray]], fitted: list[np.ndarray], sources: list[str],
                  ts: float) -> list[dict]:
    """The held runs (:func:`held_runs`) the fitted model does not explain: it expects the output to move there.

    Parameters
    ----------
    experiments : list of (u, y)
        The files as fitted.
    fitted : list of ndarray
        The model's output per file (same lengths).
    sources : list of str
        The files' names.
    ts : float
        Sample time, s (for the durations reported).

    Returns
    -------
    list of dict
        ``source``, ``first`` and ``last`` sample, ``samples``, ``seconds``, ``value`` of the input and
        ``extreme`` (``"maximum"`` / ``"minimum"``), for runs along which the model's output moves at least
        :data:`HELD_MODEL_MOVES` times the measured one.
    """
    out = []
    for (u, y), f, src in zip(experiments, fitted, sources):
        for a, b, value, extreme in held_runs(u, y):
            if np.ptp(f[a:b]) >= HELD_MODEL_MOVES * max(float(np.ptp(y[a:b])), np.finfo(float).tiny):
                out.append({"source": src, "first": a, "last": b - 1, "samples": b - a, "seconds": (b - a) * ts,
                            "value": value, "extreme": extreme})
    return out
