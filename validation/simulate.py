"""Time-domain simulation of the block diagram of one system (docs/theory.md section 1).

Unlike the closed-loop maps of :mod:`ilcdob.loop`, this builds the loop from the discrete
blocks as a flight computer runs them, so it is an independent check of the maps: the plant
``P`` here, the control law through :class:`ilcdob.controller.OuterLoopController`, the object
any vehicle flies. Per sample ``k``::

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

Two ways to run a trial, the same result to rounding (1e-15 to 1e-14 of each signal's peak; up
to 8e-13 for ``d_hat``, a small difference of large signals, whose own rounding in either way is
that large; held to 1e-12 by tests/test_statespace.py on the built-in fleet and on 1 ms,
``q_order`` 8 loops):

* default: the closed loop is assembled from the plant's state-space matrices and the
  controller's own equations in matrix form (:meth:`OuterLoopController.state_space`, never
  :mod:`ilcdob.loop`'s interconnection), inputs ``(r, d, d_f, a_ff, n)``, and the trial is
  simulated at once in compiled code (:func:`ilcdob.statespace.simulate`; it steps the blocks'
  own equations, :meth:`LawStateSpace.evaluate`, for all blocks of the trial at once, so that the
  result is that of the blocks stepped, not of the rounded products in the assembled matrices);
* ``stepped=True``: the plant and the controller object stepped sample by sample in Python,
  exactly as a flight computer calls it (10 to 30 times slower; what the default is tested
  against).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ilcdob.controller import LawStateSpace, OuterLoopController
from ilcdob.errors import SpecError
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal
from ilcdob.statespace import simulate

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


def _closed_loop(plant: tuple, law: LawStateSpace) -> tuple[np.ndarray, ...]:
    """``(A, B, C, D)`` of the plant closed by the law: states ``[plant, law]``, inputs
    ``(r, d, d_f, a_ff, n)``, outputs ``(y, u2, d_hat)`` (module docstring)."""
    ap, bp, cp, _ = plant
    npl, nk = ap.shape[0], law.a.shape[0]
    # the law's inputs (r, y_m, a_ff, d_f) from the states and the trial's inputs: y_m = y + n
    v_x = np.zeros((4, npl + nk))
    v_x[1, :npl] = cp
    v_w = np.zeros((4, 5))
    v_w[0, 0] = v_w[1, 4] = v_w[2, 3] = v_w[3, 2] = 1.0
    # the law's outputs (u2, d_hat) = o_x x + o_w w
    o_x = law.d @ v_x
    o_x[:, npl:] += law.c
    o_w = law.d @ v_w
    a = np.zeros((npl + nk, npl + nk))
    a[:npl, :npl] = ap
    a[:npl] += np.outer(bp, o_x[0])  # plant input u2 + d
    a[npl:] += law.b @ v_x
    a[npl:, npl:] += law.a
    b = np.zeros((npl + nk, 5))
    b[:npl] = np.outer(bp, o_w[0])
    b[:npl, 1] += bp
    b[npl:] = law.b @ v_w
    c = np.vstack([np.concatenate([cp, np.zeros(nk)]), o_x])
    d = np.vstack([np.zeros(5), o_w])
    return a, b, c, d


def _evaluate(plant: tuple, law: LawStateSpace):
    """The closed loop's step and outputs ``(y, u2, d_hat)`` for a run of samples, computed block by block
    (plant here, law by :meth:`LawStateSpace.evaluate`), as the stepped trial computes them."""
    ap, bp, cp, _ = plant
    npl = ap.shape[0]

    def evaluate(x: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r, d, df, aff, nz = w
        y = cp @ x[:npl]
        nxt_law, (u2, d_hat) = law.evaluate(x[npl:], (r, y + nz, aff, df))
        nxt = np.empty_like(x)
        np.matmul(ap, x[:npl], out=nxt[:npl])
        nxt[:npl] += bp[:, None] * (u2 + d)
        nxt[npl:] = nxt_law
        return nxt, np.vstack([y, u2, d_hat])

    return evaluate


def _stepped(ctl: OuterLoopController, plant: tuple, r: np.ndarray, d: np.ndarray, df: np.ndarray,
             aff: np.ndarray, nz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(y, d_hat, u2)``: the plant and the controller object stepped sample by sample."""
    ap, bp, cp, _ = plant
    n = r.size
    xp = np.zeros(ap.shape[0])
    y, dh, u2 = (np.zeros(n) for _ in range(3))
    # Python floats into the per-sample law: NumPy scalar arithmetic there costs more than the products
    r_l, aff_l, df_l, nz_l, d_l = r.tolist(), aff.tolist(), df.tolist(), nz.tolist(), d.tolist()
    for k in range(n):
        yk = float(cp @ xp)
        u2k = ctl.step(r_l[k], yk + nz_l[k], feedforward=aff_l[k], learning=df_l[k])
        xp = ap @ xp + bp * (u2k + d_l[k])
        y[k], dh[k], u2[k] = yk, ctl.d_hat, u2k
    return y, dh, u2


def simulate_flight(loop: LoopSystem, r: object, d: object, d_f: object | None = None,
                    mode: str = "dob", a_ref: object | None = None, sensor_noise: object | None = None,
                    stepped: bool = False) -> Flight:
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
    stepped : bool
        Step the controller object sample by sample instead of simulating the assembled
        closed loop at once (module docstring; the same result, much slower).
    """
    if mode not in ("dob", "no_dob"):
        raise SpecError(f"`mode`: got {mode!r}, expected 'dob' or 'no_dob'")
    if not isinstance(stepped, bool):
        raise SpecError(f"`stepped`: got {stepped!r}, expected True or False")
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
    plant = _mats(loop.P)
    if plant[3] != 0:
        raise SpecError("P must be strictly proper in discrete time (algebraic loop)")
    ctl = OuterLoopController(loop, dob=mode == "dob")  # the control law, as any vehicle flies it
    nz = np.zeros(n) if noise is None else noise
    if stepped:
        y, dh, u2 = _stepped(ctl, plant, r, d, df, aff, nz)
    else:
        law = ctl.state_space()
        y, u2, dh = simulate(*_closed_loop(plant, law), np.vstack([r, d, df, aff, nz]), evaluate=_evaluate(plant, law))
        if mode == "no_dob":
            dh = np.zeros(n)
    e = r - (y + nz)  # the measured error, as the controller computes it
    t = np.arange(n) * loop.ts
    if noise is None:
        return Flight(system=loop.name, mode=mode, t=t, r=r, y=y, e=e, d=d, d_hat=dh, d_f=df, u2=u2)
    return Flight(system=loop.name, mode=mode, t=t, r=r, y=y, e=r - y, d=d, d_hat=dh, d_f=df, u2=u2,
                  y_meas=y + noise, e_meas=e)
