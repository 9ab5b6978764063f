"""Discretisation of the loop's blocks at sample time ``Ts``.

How each block is discretised (documented once, used everywhere):

* plant ``P`` (and the model ``P_hat`` used for learning): zero-order hold, exact for a
  piecewise-constant commanded acceleration, including a fractional input delay
  (modified z-transform, :func:`zoh_with_delay`);
* PID ``C``: Tustin (bilinear) transform; the integrator pole lands exactly at z = 1;
* DOB ``Q``: zero-order hold. ``Q`` is strictly proper in continuous time, so its ZOH is
  strictly proper (no algebraic loop). When the model has an input delay, the Q branch
  carries the same delay (``Q e^{-s tau}``), so that ``M P_hat = Q e^{-s tau}`` is causal;
* DOB ``M = Q/P_hat``: Tustin. ``M`` is biproper when ``q_order`` equals the model's
  relative degree and has the model's integrators as zeros at s = 0. Tustin maps those to
  z = 1 exactly and keeps ``M_d P_d = Q_d`` to ~1e-5 below 10 rad/s for the built-in
  fleet; the ZOH equivalent of ``M`` misplaces them (its zeros are not e^{sTs}) and leaves
  ``|M_d P_d - Q_d|`` near 0.6 at 0.5 rad/s, which ruins the DOB at low frequency.

ZOH of a plant of relative degree >= 2 has sampling zeros; for relative degree 3 one lies
near z = -3.7, so the discrete plant is non-minimum phase (docs/theory.md section 1).
"""

from __future__ import annotations

import math

import control as ct
import numpy as np
from scipy.linalg import expm

from .errors import SpecError
from .specs import DOBSpec, PIDSpec, PlantSpec

__all__ = ["zoh_with_delay", "discretize_plant", "discretize_pid", "q_filter", "discretize_q", "discretize_m"]


def _zoh_integrals(a: np.ndarray, b: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(exp(A t), int_0^t exp(A s) ds B)`` from one matrix exponential."""
    n, m = b.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n] = a * t
    big[:n, n:] = b * t
    e = expm(big)
    return e[:n, :n], e[:n, n:]


def zoh_with_delay(sys_c: ct.StateSpace, ts: float, delay: float = 0.0) -> ct.StateSpace:
    """Zero-order-hold discretisation of a SISO state-space system with input delay.

    With ``delay = n*Ts + f`` (0 <= f < Ts) the exact sampled system is
    ``x[k+1] = Phi x[k] + G0 u[k-n] + G1 u[k-n-1]``, ``G0 = int_0^{Ts-f} e^{As} ds B``,
    ``G1 = e^{A(Ts-f)} int_0^f e^{As} ds B``; the delayed inputs become extra states.

    Parameters
    ----------
    sys_c : control.StateSpace
        Continuous-time, strictly proper SISO system.
    ts : float
        Sample time in s.
    delay : float
        Input delay in s (>= 0).

    Returns
    -------
    control.StateSpace
        Discrete-time system with ``dt = ts``.
    """
    if not (math.isfinite(ts) and ts > 0):
        raise SpecError(f"`sample_time`: got {ts!r}, expected a finite number > 0 (s)")
    if not (math.isfinite(delay) and delay >= 0):
        raise SpecError(f"`delay`: got {delay!r}, expected a finite number >= 0 (s)")
    a, b, c, d = (np.asarray(m, dtype=float) for m in (sys_c.A, sys_c.B, sys_c.C, sys_c.D))
    if np.any(d != 0) and delay > 0:
        raise SpecError("`plant`: a delayed plant must be strictly proper")
    n_del = int(math.floor(delay / ts + 1e-9))
    frac = delay - n_del * ts
    if frac < 1e-9 * ts:
        frac = 0.0
    phi, g_full = _zoh_integrals(a, b, ts)
    if frac == 0.0:
        g0, g1 = g_full, np.zeros_like(g_full)
    else:
        phi_rest, g0 = _zoh_integrals(a, b, ts - frac)
        _, g_f = _zoh_integrals(a, b, frac)
        g1 = phi_rest @ g_f
    nx = a.shape[0]
    n_extra = n_del + (1 if frac > 0 else 0)
    if n_extra == 0:
        return ct.ss(phi, g0, c, d, ts)
    # augmented state [x; u[k-1]; ...; u[k-n_extra]]
    big_a = np.zeros((nx + n_extra, nx + n_extra))
    big_b = np.zeros((nx + n_extra, 1))
    big_a[:nx, :nx] = phi
    # x[k+1] gets G0 u[k-n_del] + G1 u[k-n_del-1]
    if n_del == 0:
        big_b[:nx] = g0
    else:
        big_a[:nx, nx + n_del - 1:nx + n_del] = g0
    if frac > 0:
        big_a[:nx, nx + n_extra - 1:nx + n_extra] += g1
    big_b[nx, 0] = 1.0
    for i in range(1, n_extra):
        big_a[nx + i, nx + i - 1] = 1.0
    big_c = np.hstack([c, np.zeros((1, n_extra))])
    return ct.ss(big_a, big_b, big_c, np.zeros((1, 1)), ts)


def discretize_plant(plant: PlantSpec, ts: float) -> ct.StateSpace:
    """ZOH discretisation of the plant ``P(s) e^{-s delay}`` (module docstring; paper Sec. II).

    Parameters
    ----------
    plant : PlantSpec
        Numerator, denominator and input delay of ``P`` (a true plant or a model ``P_hat``).
    ts : float
        Sample time, s.

    Returns
    -------
    control.StateSpace
        The sampled plant (delayed inputs as extra states), ``dt = ts``.

    Raises
    ------
    SpecError
        The coefficients are out of double-precision range: the realisation or its
        discretisation is not finite, or it does not reproduce ``num/den``.
    """
    sys_c = ct.tf2ss(ct.tf(list(plant.num), list(plant.den)))
    _check_realisation(plant, sys_c, ts)
    sys_d = zoh_with_delay(sys_c, ts, plant.delay)
    if not all(np.all(np.isfinite(np.asarray(m, dtype=float))) for m in (sys_d.A, sys_d.B, sys_d.C, sys_d.D)):
        raise SpecError(f"`plant`: num = {list(plant.num)}, den = {list(plant.den)}: its zero-order-hold "
                        f"discretisation at {ts:g} s overflows (non-finite matrices); {_RESCALE}")
    return sys_d


_RESCALE = ("the coefficients span too many orders of magnitude for double precision; give a plant whose poles, "
            "zeros and gain are within about 1e-6 to 1e6 (rad/s, m/s^2 -> m), e.g. drop poles far above the "
            "Nyquist frequency")

#: Relative tolerance of the check that the state-space realisation of a plant has its
#: transfer function (at a few frequencies below Nyquist).
REALISATION_RTOL = 1e-6


def _check_realisation(plant: PlantSpec, sys_c: ct.StateSpace, ts: float) -> None:
    """SpecError when ``sys_c`` (``tf2ss`` of the plant) is not finite or lost the plant's dynamics.

    With coefficients spanning hundreds of orders of magnitude the realisation silently drops
    states (``1/(1e-20 s^3 + s^2)`` comes back with none) or overflows; the response is
    compared with ``num(jw)/den(jw)`` at four frequencies between 1e-3 and 0.3 times Nyquist.
    """
    mats = [np.asarray(m, dtype=float) for m in (sys_c.A, sys_c.B, sys_c.C, sys_c.D)]
    what = f"`plant`: num = {list(plant.num)}, den = {list(plant.den)}"
    if not all(np.all(np.isfinite(m)) for m in mats):
        raise SpecError(f"{what}: its state-space realisation is not finite; {_RESCALE}")
    a, b, c, d = mats
    for frac in (1.1e-3, 1.3e-2, 0.117, 0.31):
        s = 1j * frac * math.pi / ts
        with np.errstate(all="ignore"):
            want = np.polyval(plant.num, s) / np.polyval(plant.den, s)
        if not np.isfinite(want) or want == 0:
            continue  # a pole or zero on the axis at this frequency: nothing to compare
        try:
            got = (c @ np.linalg.solve(s * np.eye(a.shape[0]) - a, b) + d).item() if a.size else d.item()
        except np.linalg.LinAlgError:
            got = complex("nan")
        if not abs(got - want) <= REALISATION_RTOL * abs(want):
            raise SpecError(f"{what}: its state-space realisation ({a.shape[0]} of {len(plant.den) - 1} states) does "
                            f"not reproduce the transfer function (|P| at {frac * math.pi / ts:.4g} rad/s: {abs(got):.4g} "
                            f"instead of {abs(want):.4g}); {_RESCALE}")


def discretize_pid(pid: PIDSpec, ts: float) -> ct.StateSpace:
    """Tustin discretisation of the PID ``C(s) = kp + ki/s + kd s/(Tf s + 1)``.

    Parameters
    ----------
    pid : PIDSpec
        Gains ``kp``, ``ki``, ``kd`` and the derivative filter time constant ``Tf``; the
        integral term is left out when ``ki`` is 0.
    ts : float
        Sample time, s.

    Returns
    -------
    control.StateSpace
        The discrete controller (integrator pole exactly at z = 1), ``dt = ts``.
    """
    s = ct.tf("s")
    c = pid.kp + pid.kd * s / (pid.derivative_filter * s + 1)
    if pid.ki > 0:
        c = c + pid.ki / s
    c = ct.tf(c)
    return ct.ss(ct.sample_system(c, ts, method="tustin"))


def q_filter(dob: DOBSpec) -> ct.TransferFunction:
    """The DOB's continuous low-pass ``Q(s) = 1/(tau s + 1)^n`` (unit DC gain).

    Parameters
    ----------
    dob : DOBSpec
        Order ``n`` (``q_order``) and time constant ``tau`` (``q_time_constant``, s).

    Returns
    -------
    control.TransferFunction
        ``Q(s)``, continuous time.
    """
    den = np.poly(np.full(dob.q_order, -1.0 / dob.q_time_constant)) * dob.q_time_constant**dob.q_order
    return ct.tf([1.0], list(den))


def discretize_q(dob: DOBSpec, model: PlantSpec, ts: float) -> ct.StateSpace:
    """ZOH of the DOB's Q branch ``Q(s) e^{-s delay}`` (module docstring).

    Parameters
    ----------
    dob : DOBSpec
        The DOB's ``Q`` (:func:`q_filter`).
    model : PlantSpec
        The plant model ``P_hat``: its input delay is put on the Q branch so that
        ``M P_hat = Q e^{-s delay}`` stays causal.
    ts : float
        Sample time, s.

    Returns
    -------
    control.StateSpace
        The sampled Q branch (strictly proper), ``dt = ts``.
    """
    return zoh_with_delay(ct.tf2ss(q_filter(dob)), ts, model.delay)


def discretize_m(dob: DOBSpec, model: PlantSpec, ts: float) -> ct.StateSpace:
    """Tustin discretisation of the DOB's ``M(s) = Q(s)/P_hat(s)`` (module docstring).

    Parameters
    ----------
    dob : DOBSpec
        The DOB's ``Q`` (:func:`q_filter`).
    model : PlantSpec
        The plant model ``P_hat``; its rational part is inverted (the delay is on the Q
        branch, :func:`discretize_q`).
    ts : float
        Sample time, s.

    Returns
    -------
    control.StateSpace
        The discrete ``M``, ``dt = ts``.

    Raises
    ------
    SpecError
        ``M`` is improper: ``q_order`` is below the model's relative degree.
    """
    q = q_filter(dob)
    m = ct.tf(np.polymul(q.num[0][0], model.den), np.polymul(q.den[0][0], model.num))
    m = ct.minreal(m, verbose=False)
    num, den = m.num[0][0], m.den[0][0]
    if len(np.trim_zeros(num, "f")) > len(np.trim_zeros(den, "f")):
        raise SpecError(
            f"`dob.q_order`: M = Q/P_hat is improper (Q order {dob.q_order} < model relative degree "
            f"{model.relative_degree})"
        )
    return ct.ss(ct.sample_system(m, ts, method="tustin"))
