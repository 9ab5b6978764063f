"""Time-domain simulation of the block diagram of one system (docs/theory.md section 1).

Unlike the closed-loop maps of :mod:`ilcdob.loop`, this steps each discrete block (P, C, Q,
M) sample by sample exactly as a flight computer would, so it is an independent check of
the maps: the plant ``P`` here, the control law through :class:`ilcdob.controller.OuterLoopController`,
the object any vehicle flies. Per sample ``k``::

    y[k]     = P output (strictly proper: depends on the state only)
    e[k]     = r[k] - y[k]
    u1[k]    = C{e}[k]
    d_hat[k] = M{y}[k] - Q{u2}[k]        (Q strictly proper: no algebraic loop)
    u2[k]    = u1[k] + a_ff[k] - d_hat[k] - d_f[k]   (a_ff: reference acceleration,
                                                   if the controller feeds it forward)
    plant input = u2[k] + d[k]

Modes: ``"no_dob"`` (d_hat = 0 and no learning signal), ``"dob"`` (with ``d_f`` if given).

With position-sensor noise ``n`` the controller and the DOB see the measured position
``y_m = y + n`` (``e_m = r - y_m``, ``d_hat = M{y_m} - Q{u2}``); the flight records both the
true and the measured signals, and its RMSE is that of the true error.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ilcdob.controller import OuterLoopController
from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal

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
    y_meas, e_meas : arrays, m
        Measured position and tracking error (what the controller, the DOB and the learning
        see); empty when the sensor is exact (then :attr:`measured_error` is ``e``).
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
    y_meas: np.ndarray = field(default_factory=lambda: np.zeros(0))
    e_meas: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def measured_error(self) -> np.ndarray:
        """The tracking error as measured (``e_meas``; ``e`` when the sensor is exact), m."""
        return self.e_meas if self.e_meas.size else self.e

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
                    mode: str = "dob", a_ref: object | None = None, sensor_noise: object | None = None) -> Flight:
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
    sensor_noise : array, m, optional
        Position-sensor noise added to the measured output (module docstring).
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
    noise = None if sensor_noise is None else as_signal(sensor_noise, "sensor_noise", n)
    if mode == "no_dob" and np.any(df):
        raise SpecError("`d_f`: a learning signal needs the DOB loop (mode='dob')")
    ap, bp, cp, dp = _mats(loop.P)
    if dp != 0:
        raise SpecError("P must be strictly proper in discrete time (algebraic loop)")
    ctl = OuterLoopController(loop, dob=mode == "dob")  # the control law, as any vehicle flies it
    xp = np.zeros(ap.shape[0])
    y, e, dh, u2 = (np.zeros(n) for _ in range(4))
    nz = np.zeros(n) if noise is None else noise
    # Python floats into the per-sample law: NumPy scalar arithmetic there costs more than the products
    r_l, aff_l, df_l, nz_l, d_l = r.tolist(), aff.tolist(), df.tolist(), nz.tolist(), d.tolist()
    for k in range(n):
        yk = float(cp @ xp)
        ymk = yk + nz_l[k]
        u2k = ctl.step(r_l[k], ymk, feedforward=aff_l[k], learning=df_l[k])
        xp = ap @ xp + bp * (u2k + d_l[k])
        y[k], e[k], dh[k], u2[k] = yk, r_l[k] - ymk, ctl.d_hat, u2k
    t = np.arange(n) * loop.ts
    if noise is None:
        return Flight(system=loop.name, mode=mode, t=t, r=r, y=y, e=e, d=d, d_hat=dh, d_f=df, u2=u2)
    return Flight(system=loop.name, mode=mode, t=t, r=r, y=y, e=r - y, d=d, d_hat=dh, d_f=df, u2=u2,
                  y_meas=y + noise, e_meas=e)
