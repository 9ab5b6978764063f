"""Time-domain simulation of the block diagram of one system (docs/theory.md section 1).

Unlike the closed-loop maps of :mod:`ilcdob.loop`, this steps each discrete block (P, C, Q,
M) sample by sample exactly as a flight computer would, so it is an independent check of
the maps. Per sample ``k``::

    y[k]     = P output (strictly proper: depends on the state only)
    e[k]     = r[k] - y[k]
    u1[k]    = C{e}[k]
    d_hat[k] = M{y}[k] - Q{u2}[k]        (Q strictly proper: no algebraic loop)
    u2[k]    = u1[k] + a_ff[k] - d_hat[k] - d_f[k]   (a_ff: reference acceleration,
                                                   if the controller feeds it forward)
    plant input = u2[k] + d[k]

Modes: ``"no_dob"`` (d_hat = 0 and no learning signal), ``"dob"`` (with ``d_f`` if given).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ilcdob.signals import as_signal
from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem

__all__ = ["Flight", "simulate_flight", "rmse"]


def rmse(x: np.ndarray) -> float:
    """Root-mean-square value of a signal.

    Parameters
    ----------
    x : array
        The signal.
    """
    return float(np.sqrt(np.mean(np.square(x))))


@dataclass(frozen=True)
class Flight:
    """One simulated trial. Rows are signals, columns time (all arrays length N).

    Attributes
    ----------
    system : str
    mode : str
        ``"no_dob"`` or ``"dob"``.
    t : array, s
    r, y, e : arrays, m
        Reference, position, tracking error ``r - y``.
    d : array, m/s^2
        True total disturbance at the plant input (wind + the system's own noise).
    d_hat : array, m/s^2
        DOB estimate (zeros without DOB).
    d_f : array, m/s^2
        Learning signal flown (zeros if none).
    u2 : array, m/s^2
        Signal sent to the plant.
    """

    system: str
    mode: str
    t: np.ndarray
    r: np.ndarray
    y: np.ndarray
    e: np.ndarray
    d: np.ndarray
    d_hat: np.ndarray
    d_f: np.ndarray
    u2: np.ndarray

    @property
    def rmse(self) -> float:
        """RMSE of the tracking error, m."""
        return rmse(self.e)

    @property
    def rmse_dhat(self) -> float:
        """RMSE of (d_hat + d_f - d): total disturbance estimate against the truth, m/s^2."""
        return rmse(self.d_hat + self.d_f - self.d)


def _mats(sys):
    return (np.asarray(sys.A, float), np.asarray(sys.B, float)[:, 0], np.asarray(sys.C, float)[0],
            float(np.asarray(sys.D).ravel()[0]))


def simulate_flight(loop: LoopSystem, r: object, d: object, d_f: object | None = None,
                    mode: str = "dob", a_ref: object | None = None) -> Flight:
    """Simulate one trial of ``loop`` from rest.

    Parameters
    ----------
    loop : LoopSystem
    r : array, m
        Reference position over the trial (``N`` samples at ``loop.ts``).
    d : array, m/s^2
        Total disturbance at the plant input.
    d_f : array, m/s^2, optional
        Learning signal (mode ``"dob"`` only).
    mode : {"dob", "no_dob"}
    a_ref : array, m/s^2, optional
        Reference acceleration ``d^2 r/dt^2``; fed forward when the controller's
        ``acceleration_feedforward`` is on, ignored (by design) otherwise.
    """
    if mode not in ("dob", "no_dob"):
        raise SpecError(f"`mode`: got {mode!r}, expected 'dob' or 'no_dob'")
    r = as_signal(r, "r")
    n = r.size
    d = as_signal(d, "d", n)
    df = np.zeros(n) if d_f is None else as_signal(d_f, "d_f", n)
    aff = np.zeros(n)
    if a_ref is not None and loop.spec.controller.acceleration_feedforward:
        aff = as_signal(a_ref, "a_ref", n)
    if mode == "no_dob" and np.any(df):
        raise SpecError("`d_f`: a learning signal needs the DOB loop (mode='dob')")
    ap, bp, cp, dp = _mats(loop.P)
    ac, bc, cc, dc = _mats(loop.C)
    aq, bq, cq, dq = _mats(loop.Q)
    am, bm, cm, dm = _mats(loop.M)
    if dp != 0 or dq != 0:
        raise SpecError("P and Q must be strictly proper in discrete time (algebraic loop)")
    xp, xc = np.zeros(ap.shape[0]), np.zeros(ac.shape[0])
    xq, xm = np.zeros(aq.shape[0]), np.zeros(am.shape[0])
    y, e, dh, u2 = (np.zeros(n) for _ in range(4))
    use_dob = mode == "dob"
    for k in range(n):
        yk = cp @ xp
        ek = r[k] - yk
        u1 = cc @ xc + dc * ek + aff[k]
        if use_dob:
            dhk = (cm @ xm + dm * yk) - cq @ xq
            u2k = u1 - dhk - df[k]
            xq = aq @ xq + bq * u2k
            xm = am @ xm + bm * yk
        else:
            dhk = 0.0
            u2k = u1
        xp = ap @ xp + bp * (u2k + d[k])
        xc = ac @ xc + bc * ek
        y[k], e[k], dh[k], u2[k] = yk, ek, dhk, u2k
    t = np.arange(n) * loop.ts
    return Flight(system=loop.name, mode=mode, t=t, r=r, y=y, e=e, d=d, d_hat=dh, d_f=df, u2=u2)
