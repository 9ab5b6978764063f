"""Closed-loop flights of a linear plant under a PID: synthetic identification data.

Before flying an identification experiment, or to test an identification set-up on data with
known truth, it helps to have the flight a linear model of the vehicle would give: the plant
(ZOH-sampled with its input delay, optional actuator limit) under the outer-loop PID
of :class:`~ilcdob.specs.PIDSpec` (Tustin), with measurement noise fed back as a real
position loop feeds it back. The logged input is what the plant received (after the limit).
"""

from __future__ import annotations

import math

import numpy as np

from ilcdob.discretize import discretize_pid, discretize_plant
from ilcdob.errors import SpecError
from ilcdob.specs import PIDSpec, PlantSpec

__all__ = ["closed_loop_flight"]


def closed_loop_flight(plant: PlantSpec, pid: PIDSpec, reference: np.ndarray, ts: float,
                       noise: np.ndarray | None = None, limit: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Input and noise-free output of ``plant`` flying ``reference`` under ``pid``.

    Parameters
    ----------
    plant : PlantSpec
        Continuous-time plant with its input delay (:func:`ilcdob.discretize.discretize_plant`).
    pid : PIDSpec
        ``C(s) = kp + ki/s + kd s/(derivative_filter s + 1)``, sampled with Tustin
        (:func:`ilcdob.discretize.discretize_pid`).
    reference : array
        Reference samples (m).
    ts : float
        Sample time, s.
    noise : array, optional
        Measurement noise added to the fed-back output (m); not included in the returned
        output.
    limit : float, optional
        Actuator limit: the plant input is clipped to ``[-limit, limit]`` (m/s^2).

    Returns
    -------
    (u, y) : arrays
        The plant input (after the limit) and the plant output, one value per reference sample.
    """
    r = np.asarray(reference, dtype=float)
    v = np.zeros_like(r) if noise is None else np.asarray(noise, dtype=float)
    if v.shape != r.shape:
        raise SpecError(f"`noise`: got shape {v.shape}, expected the reference's {r.shape}")
    if limit is not None and not (math.isfinite(limit) and limit > 0):
        raise SpecError(f"`limit`: got {limit!r}, expected None or a number > 0 (m/s^2)")
    p = discretize_plant(plant, ts)          # the input delay as extra states
    c = discretize_pid(pid, ts)
    pa, pb, pc = p.A, p.B[:, 0], p.C[0]
    ca, cb, cc, cd = c.A, c.B[:, 0], c.C[0], float(c.D[0, 0])
    xp, xc = np.zeros(p.nstates), np.zeros(c.nstates)
    y, u = np.zeros(r.size), np.zeros(r.size)
    for k in range(r.size):
        y[k] = pc @ xp
        e = r[k] - (y[k] + v[k])
        u[k] = cc @ xc + cd * e
        if limit is not None:
            u[k] = min(max(u[k], -limit), limit)
        xp = pa @ xp + pb * u[k]
        xc = ca @ xc + cb * e
    return u, y
