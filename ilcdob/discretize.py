"""Discretisation of the loop's blocks at sample time ``Ts``.

How each block is discretised (documented once, used everywhere):

* plant ``P`` (and the model ``P_hat`` used for learning): zero-order hold, exact for a
  piecewise-constant commanded acceleration, including a fractional input delay
  (modified z-transform, :func:`zoh_with_delay`);
* PID ``C``: Tustin (bilinear) transform; the integrator pole lands exactly at z = 1;
* DOB ``Q``: zero-order hold. ``Q`` is strictly proper in continuous time, so its ZOH is
  strictly proper (no algebraic loop). When the model has an input delay, the Q branch
  carries the same delay (``Q e^{-s tau}``), so that ``M P_hat = Q e^{-s tau}`` is causal;
* a model with right-half-plane zeros (non-minimum phase) is split ``P_hat = P_mp A``, ``A``
  all-pass with ``A(0) = 1``: ``M = Q/P_mp`` and the Q branch is ``Q A e^{-s tau}`` (ZOH), so
  ``M P_hat = Q A e^{-s tau}`` stays causal and stable (docs/theory.md section 1);
* DOB ``M = Q/P_hat``: Tustin. ``M`` is biproper when ``q_order`` equals the model's
  relative degree and has the model's integrators as zeros at s = 0. Tustin maps those to
  z = 1 exactly and keeps ``M_d P_d = Q_d`` to ~1e-5 below 10 rad/s for the built-in
  fleet; the ZOH equivalent of ``M`` misplaces them (its zeros are not e^{sTs}) and leaves
  ``|M_d P_d - Q_d|`` near 0.6 at 0.5 rad/s, which ruins the DOB at low frequency.

ZOH of a plant of relative degree >= 2 has sampling zeros; for relative degree 3 one lies
near z = -3.7, so the discrete plant is non-minimum phase (docs/theory.md section 1).

Conditioning (fast sampling, high ``q_order``). ``Q = 1/(tau s + 1)^n`` has an n-fold pole
and ``M`` the same n-fold pole after Tustin; at ``Ts = 1 ms`` both sit about ``Ts/tau`` from
z = 1. Realised from polynomials (companion form), such a cluster is numerically a Jordan
block whose eigenvalues and responses are lost to rounding (errors ~ eps^(1/n): a stable DOB
loop computed as unstable at |z| = 1.02, learning filters off by 3.5e-4). The blocks are
therefore never realised from high-degree polynomials:

* ``Q`` is a cascade of ``n`` unit-DC-gain first-order lags (each state is one lag's
  output); its zero-order hold is written in closed form (entries ``e^{-h} h^k/k!`` and
  regularised incomplete gamma functions, ``h = Ts/tau``), accurate entry by entry; the
  model's input delay stays on the Q branch, as delay states after the lags;
* ``P`` is realised in the normalised variable ``s Ts`` (coefficients ``den_k Ts^k``) before
  its zero-order hold, so its input entries (``~Ts^r`` for relative degree ``r``) and with them
  its sampling zeros keep their relative accuracy (2.5e-8 -> 3e-13 for relative degree 3
  with a fractional delay at 1 ms);
* ``M`` and ``C`` are mapped pole by pole and zero by zero with Tustin,
  ``z = (1 + s Ts/2)/(1 - s Ts/2)``, zeros at z = -1 for the relative-degree deficit, gain
  matched (the exact bilinear substitution), and realised as a cascade of first- and
  second-order sections (``M``) or in parallel form (``C``). Measured against 40-digit
  Tustin: ``M`` through polynomials was off by 1.5e-7 (0.01 rad/s, 20 ms, ``q_order`` 3) and
  by a factor of 7 (1 ms, ``q_order`` 6); the sections are within 1e-12;
* every block also carries ``A - I`` computed without cancellation (its "delta form":
  ``(A - I)/Ts`` tends to the continuous ``A`` as ``Ts -> 0``): ``A - I = A_c int_0^Ts e^{A_c s} ds``
  for a ZOH, ``Ts gamma`` with ``gamma = s/(1 - s Ts/2)`` for Tustin. Eigenvalues and
  frequency responses are computed from it (``z - 1`` as ``expm1(j w Ts)``), so closely
  spaced poles near z = 1 are not rounded together by the representation ``1 - small``.

Poles of ``Q``, ``M`` and ``C`` are known analytically (:attr:`DiscreteBlock.poles`), so
the learning filters need no eigenvalues of these blocks (``design/maps/closed_form.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import control as ct
import numpy as np
from scipy.linalg import eigvals as _gen_eigvals
from scipy.linalg import expm
from scipy.special import gammainc

from .errors import SpecError
from .specs import DOBSpec, PIDSpec, PlantSpec

__all__ = ["zoh_with_delay", "discretize_plant", "discretize_pid", "q_filter", "discretize_q", "discretize_m",
           "DiscreteBlock", "plant_block", "pid_block", "q_block", "m_block", "tustin_map", "rhp_zeros", "cancel_roots",
           "MAX_DELAY_SAMPLES", "MAX_Q_SPAN"]


@dataclass(frozen=True)
class DiscreteBlock:
    """A sampled SISO block with what accurate numerics need (module docstring, "Conditioning").

    Attributes
    ----------
    sys : control.StateSpace
        The discrete realisation, ``dt = ts``; ``sys.A = I + a_minus_i`` (rounded).
    a_minus_i : numpy.ndarray
        ``A - I`` computed without cancellation (the delta form times ``Ts``).
    poles : numpy.ndarray
        Its poles in the z-plane: exact images of the continuous poles where the mapping is
        known (Tustin, the lags of ``Q``, the delay states at 0), else eigenvalues of the
        delta form.
    zeros : numpy.ndarray or None
        Its finite zeros in the z-plane: exact Tustin images (``M``, ``C``), the sampled
        plant's zeros from the delta-form pencil (``P``); None for ``Q``.
    gain : float or None
        With ``zeros`` and ``poles``: the gain ``k`` of ``k prod(z - z_i)/prod(z - p_i)``.
    delay_states : int
        How many of the last states hold the delayed input ``u[k-1], ..., u[k-delay_states]``
        (:func:`zoh_with_delay`); 0 without input delay.
    """

    sys: ct.StateSpace
    a_minus_i: np.ndarray
    poles: np.ndarray
    zeros: np.ndarray | None = None
    gain: float | None = None
    delay_states: int = 0

    @property
    def ts(self) -> float:
        """Sample time, s."""
        return float(self.sys.dt)

    def response(self, w: np.ndarray) -> np.ndarray:
        """Frequency response ``H(e^{j w Ts})`` from the delta form (no ``z - A`` cancellation).

        ``zI - A = (z - 1) I - (A - I)`` with ``z - 1 = expm1(j w Ts)``.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex response, the shape of ``w``.
        """
        w = np.asarray(w, dtype=float)
        zm1 = np.expm1(1j * w.ravel() * self.ts)
        b = np.asarray(self.sys.B, dtype=float)[:, 0]
        c = np.asarray(self.sys.C, dtype=float)[0]
        d = float(np.asarray(self.sys.D, dtype=float)[0, 0])
        n = self.a_minus_i.shape[0]
        if n == 0:
            return np.full(w.shape, d, dtype=complex)
        mats = zm1[:, None, None] * np.eye(n) - self.a_minus_i
        x = np.linalg.solve(mats, np.broadcast_to(b.astype(complex), (zm1.size, n))[..., None])[..., 0]
        return (x @ c + d).reshape(w.shape)


def _zoh_integrals(a: np.ndarray, b: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(exp(A t), int_0^t exp(A s) ds B)`` from one matrix exponential."""
    n, m = b.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n] = a * t
    big[:n, n:] = b * t
    e = expm(big)
    return e[:n, :n], e[:n, n:]


def _phi_minus_i(a: np.ndarray, t: float) -> np.ndarray:
    """``exp(A t) - I = A int_0^t exp(A s) ds`` without the cancellation of ``exp(A t) - I``."""
    n = a.shape[0]
    big = np.zeros((2 * n, 2 * n))
    big[:n, :n] = a * t
    big[:n, n:] = np.eye(n) * t
    return a @ expm(big)[:n, n:]


def _split_delay(delay: float, ts: float) -> tuple[int, float]:
    """``delay = n Ts + f`` with ``0 <= f < Ts`` (``f`` below 1e-9 Ts taken as 0)."""
    n_del = int(math.floor(delay / ts + 1e-9))
    frac = delay - n_del * ts
    if frac < 1e-9 * ts:
        frac = 0.0
    return n_del, frac


#: Most whole samples of input delay: each is a state of the discretised loop (measured: a fleet check with
#: 1000 takes 2 s and 340 MB; with 5000, 2 min and 4 GB).
MAX_DELAY_SAMPLES = 1000


def _check_ts_delay(ts: float, delay: float) -> None:
    if not (math.isfinite(ts) and ts > 0):
        raise SpecError(f"`sample_time`: got {ts!r}, expected a finite number > 0 (s)")
    if not (math.isfinite(delay) and delay >= 0):
        raise SpecError(f"`delay`: got {delay!r}, expected a finite number >= 0 (s)")
    if delay / ts > MAX_DELAY_SAMPLES:
        raise SpecError(f"`delay`: got {delay:g} s, {delay / ts:.4g} samples of {ts:g} s; expected at most "
                        f"{MAX_DELAY_SAMPLES} samples ({MAX_DELAY_SAMPLES * ts:g} s): every sample of delay is a "
                        "state of the discretised loop (a plant input delay is milliseconds; check its unit)")


#: Most sample times the DOB's time constant may be, and least (its reciprocal): Q's matrices hold
#: ``(Ts/tau)^k / k!`` and M's gain ``1/tau^q_order`` (``q_order`` up to 20), in double range up to here.
#: A time constant a million times the sample time (or a millionth of it) is a unit slip, not a DOB.
MAX_Q_SPAN = 1e6


def _check_q_time_constant(dob: DOBSpec, ts: float) -> None:
    tau = dob.q_time_constant
    if not 1.0 / MAX_Q_SPAN <= tau / ts <= MAX_Q_SPAN:
        raise SpecError(f"`dob.q_time_constant`: got {tau:g} s, {tau / ts:.4g} sample times of {ts:g} s; expected "
                        f"{ts / MAX_Q_SPAN:g} to {ts * MAX_Q_SPAN:g} s (within {MAX_Q_SPAN:g} times the sample time "
                        "either way; the DOB bandwidth is about 1/q_time_constant rad/s: check its unit, s)")


def _augment_delay(phi: np.ndarray, phi_m1: np.ndarray, g0: np.ndarray, g1: np.ndarray, c: np.ndarray,
                   d: np.ndarray, n_del: int, frac: float, ts: float) -> tuple[ct.StateSpace, np.ndarray]:
    """The sampled system ``x[k+1] = Phi x[k] + G0 u[k-n] + G1 u[k-n-1]`` with the delayed inputs
    as extra states ``[x; u[k-1]; ...]``; returns it and its ``A - I``."""
    nx = phi.shape[0]
    n_extra = n_del + (1 if frac > 0 else 0)
    if n_extra == 0:
        return ct.ss(phi, g0, c, d, ts), phi_m1.copy()
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
    big_m1 = big_a - np.eye(nx + n_extra)
    big_m1[:nx, :nx] = phi_m1
    big_c = np.hstack([c, np.zeros((1, n_extra))])
    return ct.ss(big_a, big_b, big_c, np.zeros((1, 1)), ts), big_m1


def _zoh_block(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, ts: float,
               delay: float) -> tuple[ct.StateSpace, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """ZOH with input delay (:func:`zoh_with_delay`); also ``A - I`` and the parts ``(Phi, Phi - I, G0, G1)``."""
    n_del, frac = _split_delay(delay, ts)
    phi, g_full = _zoh_integrals(a, b, ts)
    phi_m1 = _phi_minus_i(a, ts)
    if frac == 0.0:
        g0, g1 = g_full, np.zeros_like(g_full)
    else:
        phi_rest, g0 = _zoh_integrals(a, b, ts - frac)
        _, g_f = _zoh_integrals(a, b, frac)
        g1 = phi_rest @ g_f
    sys_d, a_m1 = _augment_delay(phi, phi_m1, g0, g1, c, d, n_del, frac, ts)
    return sys_d, a_m1, (phi, phi_m1, g0, g1)


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
    _check_ts_delay(ts, delay)
    a, b, c, d = (np.asarray(m, dtype=float) for m in (sys_c.A, sys_c.B, sys_c.C, sys_c.D))
    if np.any(d != 0) and delay > 0:
        raise SpecError("`plant`: a delayed plant must be strictly proper")
    return _zoh_block(a, b, c, d, ts, delay)[0]


def _delta_zeros(a_m1: np.ndarray, b: np.ndarray, c: np.ndarray, d: float) -> np.ndarray:
    """Finite invariant zeros (z-plane) of the SISO system ``(I + a_m1, b, c, d)`` from the delta-form
    pencil ``[[a_m1, b], [c, d]] - (z - 1) [[I, 0], [0, 0]]``."""
    n = a_m1.shape[0]
    if n == 0:
        return np.zeros(0, dtype=complex)
    big = np.zeros((n + 1, n + 1))
    big[:n, :n], big[:n, n], big[n, :n], big[n, n] = a_m1, b, c, d
    e = np.zeros((n + 1, n + 1))
    e[:n, :n] = np.eye(n)
    with np.errstate(all="ignore"):
        lam = _gen_eigvals(big, e)
    lam = lam[np.isfinite(lam)]
    scale = max(1.0, float(np.max(np.abs(a_m1))) if a_m1.size else 1.0)
    lam = lam[np.abs(lam) < 1e10 * scale]
    return 1.0 + lam.astype(complex)


def _sampled_zeros(parts: tuple, c: np.ndarray, d: float, frac: float) -> np.ndarray:
    """Zeros of the rational part of a sampled delayed system, ``C (zI - Phi)^{-1} (G0 z + G1)``
    (= ``C G0 + C (zI - Phi)^{-1} (Phi G0 + G1)``), or of ``C (zI - Phi)^{-1} G0 + D`` without a
    fractional delay; the delay's extra states only add poles at z = 0."""
    phi, phi_m1, g0, g1 = parts
    if frac > 0:
        return _delta_zeros(phi_m1, (phi @ g0 + g1)[:, 0], c, float(c @ g0[:, 0]))
    return _delta_zeros(phi_m1, g0[:, 0], c, d)


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
    return plant_block(plant, ts).sys


def plant_block(plant: PlantSpec, ts: float) -> DiscreteBlock:
    """:func:`discretize_plant` with the delta form, poles and (ZOH) zeros of the sampled plant.

    The zeros are those of ``C (zI - Phi)^{-1} (G0 z + G1)`` (the delay's extra states add
    poles at z = 0 only), from the delta-form pencil.

    Parameters
    ----------
    plant : PlantSpec
        Numerator, denominator and input delay.
    ts : float
        Sample time, s.

    Returns
    -------
    DiscreteBlock
        ``zeros`` holds the sampling and mapped zeros; ``gain`` is None.
    """
    _check_ts_delay(ts, plant.delay)
    sys_c = ct.tf2ss(ct.tf(list(plant.num), list(plant.den)))
    _check_realisation(plant, sys_c, ts)
    sys_c = _time_scaled_realisation(plant, ts, sys_c)
    a, b, c, d = (np.asarray(m, dtype=float) for m in (sys_c.A, sys_c.B, sys_c.C, sys_c.D))
    if np.any(d != 0) and plant.delay > 0:
        raise SpecError("`plant`: a delayed plant must be strictly proper")
    sys_d, a_m1, parts = _zoh_block(a, b, c, d, ts, plant.delay)
    phi_m1 = parts[1]
    if not all(np.all(np.isfinite(np.asarray(m, dtype=float))) for m in (sys_d.A, sys_d.B, sys_d.C, sys_d.D)) \
            or not np.all(np.isfinite(a_m1)):
        raise SpecError(f"`plant`: num = {list(plant.num)}, den = {list(plant.den)}: its zero-order-hold "
                        f"discretisation at {ts:g} s overflows (non-finite matrices); {_RESCALE}")
    n_del, frac = _split_delay(plant.delay, ts)
    n_extra = n_del + (1 if frac > 0 else 0)
    zeros = _sampled_zeros(parts, c[0], float(d[0, 0]), frac)
    poles = np.concatenate([1.0 + np.linalg.eigvals(phi_m1).astype(complex), np.zeros(n_extra, dtype=complex)])
    return DiscreteBlock(sys_d, a_m1, poles, zeros, None, n_extra)


def _time_scaled_realisation(plant: PlantSpec, ts: float, fallback: ct.StateSpace) -> ct.StateSpace:
    """A realisation of ``num/den`` whose ``A Ts`` is well scaled: the canonical form of the
    polynomials in the normalised variable ``s Ts`` (coefficients ``den_k Ts^k``), with
    ``A = A_hat/Ts``, ``B = B_hat/Ts``. Its zero-order hold has entries of comparable size, so the
    sampled plant's small input entries (``~Ts^r`` for relative degree ``r``), and with them its
    sampling zeros, keep their relative accuracy; ``fallback`` (the checked ``tf2ss`` realisation)
    when the scaled one does not reproduce the plant."""
    num = np.trim_zeros(np.asarray(plant.num, dtype=float), "f")
    den = np.trim_zeros(np.asarray(plant.den, dtype=float), "f")
    n, m = den.size - 1, num.size - 1
    if n < 1 or num.size == 0:
        return fallback
    with np.errstate(all="ignore"):
        den_s = den * ts ** np.arange(n + 1)
        num_s = num * ts ** (n - m + np.arange(m + 1))
    if not (np.all(np.isfinite(den_s)) and np.all(np.isfinite(num_s))) or den_s[0] == 0:
        return fallback
    try:
        hat = ct.tf2ss(ct.tf(list(num_s), list(den_s)))
    except Exception:  # noqa: BLE001 - any failure: keep the checked realisation
        return fallback
    scaled = ct.ss(np.asarray(hat.A) / ts, np.asarray(hat.B) / ts, hat.C, hat.D)
    try:
        _check_realisation(plant, scaled, ts)
    except SpecError:
        return fallback
    return scaled


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
    return pid_block(pid, ts).sys


def tustin_map(s: np.ndarray, ts: float, what: str = "a pole or zero") -> np.ndarray:
    """``z - 1`` of the Tustin images of continuous roots ``s``: ``Ts s/(1 - s Ts/2)`` (no cancellation).

    Parameters
    ----------
    s : array_like
        Continuous poles or zeros, rad/s.
    ts : float
        Sample time, s.
    what : str
        What the roots are, for the error message.

    Returns
    -------
    numpy.ndarray
        ``z - 1`` (complex), so ``z = 1 + tustin_map(s, ts)``.

    Raises
    ------
    SpecError
        A root at ``s = 2/Ts``, which Tustin maps to infinity.
    """
    s = np.asarray(s, dtype=complex)
    den = 1.0 - s * ts / 2.0
    if np.any(np.abs(den) < 1e-12):
        raise SpecError(f"{what} at s = {2.0 / ts:g} rad/s = 2/Ts: the Tustin transform at {ts:g} s maps it to "
                        "infinity; change the sample time")
    return s * ts / den


def _delta_from_gamma(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: float,
                      ts: float) -> tuple[ct.StateSpace, np.ndarray]:
    """The discrete system of delta-form matrices ``(gamma = (z - 1)/Ts)``: ``A = I + Ts a``, ``B = Ts b``."""
    n = a.shape[0]
    a_m1 = ts * a
    sys_d = ct.ss(np.eye(n) + a_m1, ts * b.reshape(n, 1), c.reshape(1, n), np.array([[d]]), ts)
    return sys_d, a_m1


def pid_block(pid: PIDSpec, ts: float) -> DiscreteBlock:
    """:func:`discretize_pid` in parallel form, with analytic poles, zeros and gain.

    With ``gamma = (z - 1)/Ts`` Tustin substitutes ``s = gamma/(1 + gamma Ts/2)``, which gives
    ``C = kp + ki Ts/2 + kd/T' + ki/gamma + (kd/T') gamma_d/(gamma - gamma_d)`` with
    ``T' = Tf + Ts/2``, ``gamma_d = -1/T'``: an integrator state and a unit-DC-gain lag state.

    Parameters
    ----------
    pid : PIDSpec
        The controller.
    ts : float
        Sample time, s.

    Returns
    -------
    DiscreteBlock
        Poles z = 1 (with ``ki > 0``) and ``1 - Ts/T'`` (exact Tustin images).
    """
    _check_ts_delay(ts, 0.0)
    t_d = pid.derivative_filter + ts / 2.0
    g_d = -1.0 / t_d
    kdd = pid.kd / t_d
    if pid.ki > 0:
        a = np.diag([0.0, g_d])
        b = np.array([1.0, -g_d])
        c = np.array([pid.ki, -kdd])
        d = pid.kp + pid.ki * ts / 2.0 + kdd
        num = [pid.kp * pid.derivative_filter + pid.kd, pid.kp + pid.ki * pid.derivative_filter, pid.ki]
        s_poles = np.array([0.0, -1.0 / pid.derivative_filter])
    else:
        a = np.array([[g_d]])
        b = np.array([-g_d])
        c = np.array([-kdd])
        d = pid.kp + kdd
        num = [pid.kp * pid.derivative_filter + pid.kd, pid.kp]
        s_poles = np.array([-1.0 / pid.derivative_filter])
    sys_d, a_m1 = _delta_from_gamma(a, b, c, d, ts)
    poles = 1.0 + ts * np.diag(a).astype(complex)
    k_s = num[0] / pid.derivative_filter
    zeros, _, gain = _tustin_zpk(k_s, np.roots(num), s_poles, ts, "a zero of the PID")
    return DiscreteBlock(sys_d, a_m1, poles, zeros, gain)


def _tustin_zpk(k: float, zeros_s: np.ndarray, poles_s: np.ndarray, ts: float,
                what: str) -> tuple[np.ndarray, np.ndarray, float]:
    """Tustin images of ``k prod(s - z_i)/prod(s - p_i)``: ``(zeros, poles, gain)`` in the z-plane, with
    ``np - nz`` zeros at z = -1 (``(s - x) = (1 - x Ts/2)(z - z_x)/(Ts/2 (z + 1))``)."""
    zeros_s = np.asarray(zeros_s, dtype=complex)
    poles_s = np.asarray(poles_s, dtype=complex)
    gz = tustin_map(zeros_s, ts, what)
    gp = tustin_map(poles_s, ts, what.replace("zero", "pole"))
    extra = len(poles_s) - len(zeros_s)
    gain = k * np.prod(1.0 - zeros_s * ts / 2.0) / np.prod(1.0 - poles_s * ts / 2.0) * (ts / 2.0) ** extra
    zeros = np.concatenate([1.0 + gz, -np.ones(extra, dtype=complex)])
    return zeros, 1.0 + gp, float(np.real(gain))


def _real_roots(x: np.ndarray) -> np.ndarray:
    """Roots with negligible imaginary parts made real (conjugate pairs kept)."""
    x = np.asarray(x, dtype=complex)
    small = np.abs(x.imag) <= 1e-12 * np.maximum(1.0, np.abs(x))
    return np.where(small, x.real + 0j, x)


def _group(roots: np.ndarray) -> tuple[list[complex], list[complex]]:
    """Real roots, and one member (Im > 0) of every conjugate pair."""
    reals = [complex(r.real) for r in roots if r.imag == 0]
    pairs = [complex(r) for r in roots if r.imag > 0]
    return reals, pairs


def _section(poles: list[complex], zeros: list[complex]) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Delta-form realisation ``(a, b, c, d)`` of the monic section ``prod(gamma - z)/prod(gamma - p)``
    with one real pole or two poles (a real pair or a conjugate pair) and as many zeros.

    One pole: the state is a unit-DC-gain lag of the input (an integrator when p = 0). Two
    poles: modal form for a conjugate pair, two cascaded lags for real poles; ``c`` is solved
    from the numerator."""
    if len(poles) == 1:
        p, z = poles[0].real, zeros[0].real
        if p == 0.0:
            return np.array([[0.0]]), np.array([1.0]), np.array([p - z]), 1.0
        return np.array([[p]]), np.array([-p]), np.array([(z - p) / p]), 1.0
    p1, p2 = poles
    if abs(p1.imag) > 0:
        sig, om = p1.real, abs(p1.imag)
        a = np.array([[sig, om], [-om, sig]])
        b = np.array([0.0, max(abs(p1), 1e-300)])
    else:
        r1, r2 = p1.real, p2.real
        a = np.array([[r1, 0.0], [-r2 if r2 != 0 else 1.0, r2]])
        b = np.array([-r1 if r1 != 0 else 1.0, 0.0])
    # strictly proper part: prod(g - z) - prod(g - p) = n1 g + n0
    n1 = float(np.real(-(zeros[0] + zeros[1]) + (p1 + p2)))
    n0 = float(np.real(zeros[0] * zeros[1] - p1 * p2))
    v1 = b
    v0 = np.array([-a[1, 1] * b[0] + a[0, 1] * b[1], a[1, 0] * b[0] - a[0, 0] * b[1]])
    c = np.linalg.solve(np.vstack([v1, v0]), np.array([n1, n0]))
    return a, b, c, 1.0


def _pair_sections(poles: np.ndarray, zeros: np.ndarray) -> list[tuple[list[complex], list[complex]]]:
    """Pair poles with as many zeros (both in the gamma domain) into first/second-order sections."""
    p_real, p_pair = _group(poles)
    z_real, z_pair = _group(zeros)
    sections = []

    def nearest(pool, x):
        return int(np.argmin([abs(y - x) for y in pool]))

    for p in sorted(p_pair, key=abs):
        if z_pair:
            z = z_pair.pop(nearest(z_pair, p))
            sections.append(([p, p.conjugate()], [z, z.conjugate()]))
        else:
            z1 = z_real.pop(nearest(z_real, p))
            z2 = z_real.pop(nearest(z_real, p))
            sections.append(([p, p.conjugate()], [z1, z2]))
    p_real.sort(key=abs)
    while z_pair:
        z = z_pair.pop()
        p1 = p_real.pop(0)
        p2 = p_real.pop(0)
        sections.append(([p1, p2], [z, z.conjugate()]))
    for p in p_real:
        z = z_real.pop(nearest(z_real, p))
        sections.append(([p], [z]))
    return sections


def _cascade(sections: list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]) -> tuple[np.ndarray, ...]:
    """Series connection (first section at the input) of delta-form sections."""
    a = np.zeros((0, 0))
    b = np.zeros(0)
    c = np.zeros(0)
    d = 1.0
    for a2, b2, c2, d2 in sections:
        n1, n2 = a.shape[0], a2.shape[0]
        big = np.zeros((n1 + n2, n1 + n2))
        big[:n1, :n1] = a
        big[n1:, :n1] = np.outer(b2, c)
        big[n1:, n1:] = a2
        b = np.concatenate([b, b2 * d])
        c = np.concatenate([d2 * c, c2])
        d = d2 * d
        a = big
    return a, b, c, d


def _tustin_cascade(k: float, zeros_s: np.ndarray, poles_s: np.ndarray, ts: float,
                    what: str) -> DiscreteBlock:
    """Tustin image of ``k prod(s - z_i)/prod(s - p_i)`` (proper) as a cascade of sections in
    delta form; the gain is spread evenly over the sections."""
    zeros_s = _real_roots(zeros_s)
    poles_s = _real_roots(poles_s)
    zeros, poles, gain = _tustin_zpk(k, zeros_s, poles_s, ts, what)
    n = len(poles)
    if n == 0:
        sys_d = ct.ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[gain]]), ts)
        return DiscreteBlock(sys_d, np.zeros((0, 0)), poles, zeros, gain)
    # the gamma domain, gamma = (z - 1)/Ts: sections prod(gamma - gamma_z)/prod(gamma - gamma_p)
    g_z = _real_roots(np.concatenate([tustin_map(zeros_s, ts, what) / ts, np.full(n - len(zeros_s), -2.0 / ts)]))
    g_p = _real_roots(tustin_map(poles_s, ts, what) / ts)
    pairs = _pair_sections(g_p, g_z)
    per = abs(gain) ** (1.0 / len(pairs))
    sections = []
    for i, (p, z) in enumerate(pairs):
        a, b, c, d = _section(p, z)
        scale = per * (np.sign(gain) if i == 0 and gain != 0 else 1.0)
        sections.append((a, b, scale * c, scale * d))
    a, b, c, d = _cascade(sections)
    sys_d, a_m1 = _delta_from_gamma(a, b, c, d, ts)
    return DiscreteBlock(sys_d, a_m1, poles, zeros, gain)


def q_filter(dob: DOBSpec) -> ct.TransferFunction:
    """The DOB's continuous low-pass ``Q(s) = 1/(tau s + 1)^n`` (unit DC gain).

    Parameters
    ----------
    dob : DOBSpec
        Order ``n`` (``q_order``) and time constant ``tau`` (``q_time_constant``, s).

    Returns
    -------
    control.TransferFunction
        ``Q(s)``, continuous time (for display; the loop realises ``Q`` as a cascade of lags,
        :func:`q_block`).
    """
    den = np.poly(np.full(dob.q_order, -1.0 / dob.q_time_constant)) * dob.q_time_constant**dob.q_order
    return ct.tf([1.0], list(den))


def _lag_cascade_zoh(n: int, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZOH over ``t = h tau`` of ``n`` cascaded lags ``1/(tau s + 1)`` (state i = output of lag i):
    ``(Phi, Phi - I, Gamma)`` with ``Phi_ij = e^{-h} h^(i-j)/(i-j)!`` and ``Gamma_i = P(i, h)``, the
    regularised lower incomplete gamma function (accurate for small ``h``)."""
    phi = np.zeros((n, n))
    eh = math.exp(-h)
    for k in range(n):
        val = eh * h**k / math.factorial(k)
        for i in range(k, n):
            phi[i, i - k] = val
    phi_m1 = phi.copy()
    np.fill_diagonal(phi_m1, math.expm1(-h))
    gam = gammainc(np.arange(1, n + 1), h).reshape(n, 1)
    return phi, phi_m1, gam


def rhp_zeros(model: PlantSpec) -> np.ndarray:
    """Zeros of the model in the open right half-plane (non-minimum phase), conjugate pairs complete.

    Parameters
    ----------
    model : PlantSpec
        The plant model ``P_hat``.

    Returns
    -------
    numpy.ndarray
        Complex zeros with ``Re z > 1e-9 |z|``.
    """
    num = np.trim_zeros(np.asarray(model.num, dtype=float), "f")
    z = np.roots(num) if num.size > 1 else np.zeros(0, dtype=complex)
    return np.asarray(z[z.real > 1e-9 * np.abs(z)], dtype=complex)


def _allpass(rhp: np.ndarray) -> ct.StateSpace:
    """``A(s) = prod (z_i - s)/(z_i + s)`` (``A(0) = 1``, ``|A(jw)| = 1``) as a continuous state space."""
    num, den = np.array([1.0]), np.array([1.0])
    for z in rhp:
        num = np.polymul(num, [-1.0, z])
        den = np.polymul(den, [1.0, z])
    return ct.ss(ct.tf(np.real(num), np.real(den)))


def _q_allpass_block(n: int, tau: float, rhp: np.ndarray, delay: float, ts: float) -> DiscreteBlock:
    """ZOH of the Q branch ``Q(s) A(s) e^{-s delay}`` of a non-minimum-phase model (module docstring):
    the lags, then the all-pass ``A`` of the model's right-half-plane zeros."""
    a_l = (np.eye(n, k=-1) - np.eye(n)) / tau
    b_l = np.zeros((n, 1))
    b_l[0, 0] = 1.0 / tau
    c_l = np.zeros((1, n))
    c_l[0, -1] = 1.0
    qa = ct.series(ct.ss(a_l, b_l, c_l, np.zeros((1, 1))), _allpass(rhp))
    sys_d, a_m1, _ = _zoh_block(*(np.asarray(m, dtype=float) for m in (qa.A, qa.B, qa.C, qa.D)), ts, delay)
    n_del, frac = _split_delay(delay, ts)
    n_extra = n_del + (1 if frac > 0 else 0)
    poles = np.concatenate([np.full(n, math.exp(-ts / tau), dtype=complex), np.exp(-rhp * ts),
                            np.zeros(n_extra, dtype=complex)])
    return DiscreteBlock(sys_d, a_m1, poles, delay_states=n_extra)


def q_block(dob: DOBSpec, model: PlantSpec, ts: float) -> DiscreteBlock:
    """:func:`discretize_q` with its delta form and analytic poles (module docstring, "Conditioning").

    Parameters
    ----------
    dob : DOBSpec
        The DOB's ``Q``.
    model : PlantSpec
        The plant model ``P_hat`` (its input delay goes on the Q branch).
    ts : float
        Sample time, s.

    Returns
    -------
    DiscreteBlock
        Poles ``e^{-Ts/tau}`` (``q_order`` times) and 0 (one per delay state).

    Raises
    ------
    SpecError
        A bad sample time or delay, or ``dob.q_time_constant`` more than :data:`MAX_Q_SPAN`
        sample times (or less than its reciprocal).
    """
    _check_ts_delay(ts, model.delay)
    _check_q_time_constant(dob, ts)
    n, tau = dob.q_order, dob.q_time_constant
    rhp = rhp_zeros(model)
    if rhp.size:
        return _q_allpass_block(n, tau, rhp, model.delay, ts)
    n_del, frac = _split_delay(model.delay, ts)
    phi, phi_m1, g_full = _lag_cascade_zoh(n, ts / tau)
    if frac == 0.0:
        g0, g1 = g_full, np.zeros_like(g_full)
    else:
        phi_rest, _, g0 = _lag_cascade_zoh(n, (ts - frac) / tau)
        _, _, g_f = _lag_cascade_zoh(n, frac / tau)
        g1 = phi_rest @ g_f
    c = np.zeros((1, n))
    c[0, -1] = 1.0
    sys_d, a_m1 = _augment_delay(phi, phi_m1, g0, g1, c, np.zeros((1, 1)), n_del, frac, ts)
    n_extra = n_del + (1 if frac > 0 else 0)
    poles = np.concatenate([np.full(n, math.exp(-ts / tau), dtype=complex), np.zeros(n_extra, dtype=complex)])
    return DiscreteBlock(sys_d, a_m1, poles, delay_states=n_extra)


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
        The sampled Q branch (strictly proper), ``dt = ts``: a cascade of ``q_order`` lags,
        then the delay's states.
    """
    return q_block(dob, model, ts).sys


def cancel_roots(zeros: np.ndarray, poles: np.ndarray, rtol: float = 1e-8) -> tuple[np.ndarray, np.ndarray]:
    """Remove coinciding zero/pole pairs (what ``minreal`` does on a polynomial form).

    Parameters
    ----------
    zeros, poles : numpy.ndarray
        Roots (complex).
    rtol : float
        A zero and its nearest remaining pole cancel when they are within ``rtol * max(1, |z|)``.

    Returns
    -------
    zeros, poles : numpy.ndarray
        What remains, complex.
    """
    ps = list(poles)
    kept = []
    for z in zeros:
        if ps:
            dist = np.abs(np.asarray(ps) - z)
            j = int(np.argmin(dist))
            if dist[j] <= rtol * max(1.0, abs(z)):
                ps.pop(j)
                continue
        kept.append(z)
    return np.asarray(kept, dtype=complex), np.asarray(ps, dtype=complex)


def m_block(dob: DOBSpec, model: PlantSpec, ts: float) -> DiscreteBlock:
    """:func:`discretize_m` as a cascade of Tustin sections, with analytic poles, zeros and gain.

    ``M(s) = den_P(s) / (num_P(s) (tau s + 1)^n)``: zeros at the model's poles, poles at its
    zeros and at ``-1/tau`` (n times), each mapped with Tustin (:func:`tustin_map`).

    Parameters
    ----------
    dob : DOBSpec
        The DOB's ``Q``.
    model : PlantSpec
        The plant model ``P_hat`` (its rational part is inverted).
    ts : float
        Sample time, s.

    Returns
    -------
    DiscreteBlock

    Raises
    ------
    SpecError
        ``M`` is improper, a model zero lies at ``s = 2/Ts``, or ``dob.q_time_constant`` is more
        than :data:`MAX_Q_SPAN` sample times (or less than its reciprocal).
    """
    _check_ts_delay(ts, 0.0)
    _check_q_time_constant(dob, ts)
    num = np.trim_zeros(np.asarray(model.num, dtype=float), "f")
    den = np.trim_zeros(np.asarray(model.den, dtype=float), "f")
    tau, n = dob.q_time_constant, dob.q_order
    zeros_s = np.roots(den) if den.size > 1 else np.zeros(0)
    # a non-minimum-phase model: M = Q/P_mp, its right-half-plane zeros mirrored (the all-pass
    # rest A(s) = prod (z - s)/(z + s) goes on the Q branch, q_block); P_mp = P_hat/A flips the
    # sign of the leading coefficient once per mirrored zero
    model_zeros = np.roots(num) if num.size > 1 else np.zeros(0, dtype=complex)
    rhp = model_zeros.real > 1e-9 * np.abs(model_zeros)
    model_zeros = np.where(rhp, -np.conj(model_zeros), model_zeros)
    poles_s = np.concatenate([model_zeros, np.full(n, -1.0 / tau)])
    zeros_s, poles_s = cancel_roots(zeros_s, poles_s)
    if len(zeros_s) > len(poles_s):
        raise SpecError(
            f"`dob.q_order`: M = Q/P_hat is improper (Q order {dob.q_order} < model relative degree "
            f"{model.relative_degree})"
        )
    k = den[0] / (num[0] * (-1.0) ** int(np.sum(rhp)) * tau**n)
    return _tustin_cascade(k, zeros_s, poles_s, ts, "a zero of the plant model")


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
        The discrete ``M``, ``dt = ts``, a cascade of first/second-order sections.

    Raises
    ------
    SpecError
        ``M`` is improper: ``q_order`` is below the model's relative degree.
    """
    return m_block(dob, model, ts).sys
