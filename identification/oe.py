"""Exact sampled responses of a continuous-time model and their parameter sensitivities.

The model of :mod:`ilcdob.uncertainty`, ``G(s) = B(s) / (s^K A(s)) e^{-s tau}``, driven by a zero-order
hold input, is in controllable companion form ``x' = A_c x + e_n u(t - tau)``; sampled
exactly at ``ts`` with the delay split as ``tau = nd ts + f`` (``0 <= f < ts``)::

    x[k+1] = Phi x[k] + G0 u[k-nd] + G1 u[k-nd-1]
    Phi = e^{A_c ts},  G0 = int_0^{ts-f} e^{A_c s} ds e_n,  G1 = e^{A_c (ts-f)} int_0^f e^{A_c s} ds e_n

(the modified z-transform; the input is zero before the record). The output is
``yhat[k] = C x_forced[k] + e_1' Phi^k beta + trend``: the forced response from rest, a free
response written in the modes of ``1/(s^K A(s))`` (``beta``: one coefficient per pole,
linear, per experiment) and an optional polynomial trend per experiment.

Every signal needed by the fit -- the output and its derivative with respect to each
parameter -- is the output of a small discrete LTI system, and is computed by filtering
(:func:`response`): the numerator from the system's Markov parameters, then a FIR pass and
an all-pole pass in second-order sections whose poles are the exact ``e^{p ts}`` of the
continuous poles ``p`` (so integrators stay exactly at ``z = 1``). Cost O(N) per signal,
in C (``scipy.signal.sosfilt``).

Sensitivities (exact, not finite differences):

* ``d yhat / d b_j`` = ``x_j`` of the forced response (the companion states);
* ``d yhat / d beta_i`` = ``e_1' Phi^k e_i``;
* ``d yhat / d a_i``: differentiating the recursion gives ``S[k+1] = Phi S[k] + Phi' x[k] +
  G0' u[k-nd] + G1' u[k-nd-1]``, ``S[0] = 0``: the output of the block-triangular system
  ``[[Phi, 0], [Phi', Phi]]`` of twice the order, with ``Phi'``, ``G0'``, ``G1'`` from one
  block matrix exponential (Van Loan, 1978);
* ``d yhat / d tau`` = ``C S_f`` with ``S_f[k+1] = Phi S_f[k] + e^{A_c (ts-f)} e_n
  (u[k-nd-1] - u[k-nd])``, continuous across whole samples for relative degree >= 2.

Memory: a handful of float arrays of the record's length per parameter (the Jacobian
columns), no per-sample Python objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.linalg import expm

from ilcdob.uncertainty import ModelStructure, companion

__all__ = ["Discretisation", "discretise", "response", "simulate_zoh", "zoh_inputs", "allpole_sos", "delay_split",
           "delayed_input"]


def delay_split(delay: float, ts: float) -> tuple[int, float]:
    """Split a delay into whole samples and a fraction: ``delay = nd * ts + f``.

    Parameters
    ----------
    delay : float
        Input delay, s (>= 0).
    ts : float
        Sample time, s.

    Returns
    -------
    nd : int
        Whole samples, >= 0.
    f : float
        Fraction, s, ``0 <= f < ts`` (below ``1e-12 ts``: 0).
    """
    nd = int(math.floor(delay / ts + 1e-9))
    f = delay - nd * ts
    if f < 1e-12 * ts:
        f = 0.0
    return nd, min(f, ts * (1 - 1e-12))


def delayed_input(u: np.ndarray, nd: int) -> np.ndarray:
    """The input delayed by whole samples, ``u[k - nd]``, zero before the record.

    Parameters
    ----------
    u : numpy.ndarray
        The input.
    nd : int
        Delay, samples (``<= 0``: ``u`` itself).

    Returns
    -------
    numpy.ndarray
        The delayed input, same length.
    """
    if nd <= 0:
        return u
    out = np.zeros_like(u)
    if nd < u.size:
        out[nd:] = u[: u.size - nd]
    return out


def allpole_sos(poles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All-pole second-order sections ``1 / prod(1 - p z^-1)`` and the denominator polynomial.

    Conjugate pairs share a section, real poles are paired in sorted order; poles at exactly
    1 give the exact coefficients ``[1, -2, 1]``.

    Parameters
    ----------
    poles : array_like
        z-plane poles (complex ones with their conjugates).

    Returns
    -------
    sos : numpy.ndarray
        Sections, rows ``[1, 0, 0, 1, a1, a2]``.
    a : numpy.ndarray
        Product of the sections' denominators (powers of ``z^-1``), ``len(poles) + 1``
        coefficients.
    """
    poles = np.asarray(poles, complex)
    cplx = poles[poles.imag > 1e-12 * np.maximum(1.0, np.abs(poles))]
    real = np.sort(poles[np.abs(poles.imag) <= 1e-12 * np.maximum(1.0, np.abs(poles))].real)
    rows = [[1.0, 0.0, 0.0, 1.0, -2.0 * p.real, abs(p) ** 2] for p in cplx]
    for i in range(0, real.size - 1, 2):
        rows.append([1.0, 0.0, 0.0, 1.0, -(real[i] + real[i + 1]), real[i] * real[i + 1]])
    if real.size % 2:
        rows.append([1.0, 0.0, 0.0, 1.0, -real[-1], 0.0])
    sos = np.asarray(rows, float).reshape(-1, 6)
    a = np.array([1.0])
    for row in sos:
        a = np.convolve(a, row[3:])
    return sos, a[: poles.size + 1]


@dataclass(frozen=True)
class Discretisation:
    """Sampled model at one parameter point (see module docstring).

    ``dphi``, ``dg0``, ``dg1`` hold one matrix per free denominator coefficient
    ``a_{nf-1} .. a_0`` (the order of ``theta``).

    Attributes
    ----------
    phi : numpy.ndarray
        ``Phi = e^{A_c ts}``.
    g0, g1 : numpy.ndarray
        Input vectors of ``u[k-nd]`` and ``u[k-nd-1]`` (``g1`` zero without a fractional
        delay).
    c : numpy.ndarray
        Output row (numerator coefficients, companion form), ``1 x n``.
    nd : int
        Whole samples of the delay.
    f : float
        Fractional part of the delay, s.
    dphi, dg0, dg1 : tuple of numpy.ndarray
        Derivatives of ``phi``, ``g0``, ``g1`` along each free denominator coefficient.
    g_delay : numpy.ndarray
        ``e^{A_c (ts - f)} e_n``, the input vector of the delay sensitivity.
    poles : numpy.ndarray
        Discrete poles ``e^{p ts}`` (integrators exactly at 1).
    sos, den : numpy.ndarray
        All-pole sections of ``poles`` and their product polynomial (:func:`allpole_sos`).
    sos2, den2 : numpy.ndarray
        The same for every pole twice (the block-triangular sensitivity systems); without
        ``derivatives``, no sections and ``[1.0]``.
    """

    phi: np.ndarray
    g0: np.ndarray
    g1: np.ndarray
    c: np.ndarray
    nd: int
    f: float
    dphi: tuple[np.ndarray, ...]
    dg0: tuple[np.ndarray, ...]
    dg1: tuple[np.ndarray, ...]
    g_delay: np.ndarray
    poles: np.ndarray
    sos: np.ndarray
    den: np.ndarray
    sos2: np.ndarray
    den2: np.ndarray


def _block_expm(a: np.ndarray, b: np.ndarray, das: list[np.ndarray], t: float):
    """``e^{A t}``, ``int_0^t e^{A s} ds b`` and their derivatives along each ``dA`` (Van Loan)."""
    n = a.shape[0]
    m = n + 1
    q = len(das)
    big = np.zeros(((q + 1) * m, (q + 1) * m))
    blk = np.zeros((m, m))
    blk[:n, :n] = a
    blk[:n, n:] = b
    for i in range(q + 1):
        big[i * m:(i + 1) * m, i * m:(i + 1) * m] = blk
    for i, da in enumerate(das):
        big[:n, (i + 1) * m:(i + 1) * m + n] = da
    e = expm(big * t)
    phi, gam = e[:n, :n], e[:n, n:m]
    dphi = [e[:n, (i + 1) * m:(i + 1) * m + n] for i in range(q)]
    dgam = [e[:n, (i + 1) * m + n:(i + 2) * m] for i in range(q)]
    return phi, gam, dphi, dgam


def discretise(structure: ModelStructure, theta: np.ndarray, ts: float, delay: float,
               derivatives: bool = True) -> Discretisation:
    """Exact ZOH sampling of the model and (optionally) the derivatives of its matrices.

    Parameters
    ----------
    structure : ModelStructure
        The model's orders.
    theta : numpy.ndarray
        Its parameters (:meth:`~ilcdob.uncertainty.ModelStructure.split`).
    ts : float
        Sample time, s.
    delay : float
        Input delay, s (split by :func:`delay_split`; modified z-transform for the fraction).
    derivatives : bool
        Also compute ``dphi``, ``dg0``, ``dg1`` (Van Loan's block exponential).

    Returns
    -------
    Discretisation
        The sampled model.
    """
    den, num = structure.split(theta)
    a, b, c = companion(den, num)
    n = a.shape[0]
    nd, f = delay_split(delay, ts)
    das = []
    if derivatives:
        for i in range(structure.n_free_poles):
            # theta[i] is a_{nf-1-i}, the coefficient of s^{K + nf-1-i} in s^K A(s)
            col = structure.n_integrators + structure.n_free_poles - 1 - i
            da = np.zeros((n, n))
            da[-1, col] = -1.0
            das.append(da)
    phi_r, g0, dphi_r, dg0 = _block_expm(a, b, das, ts - f)
    if f > 0:
        phi_f, gam_f, dphi_f, dgam_f = _block_expm(a, b, das, f)
        phi = phi_r @ phi_f
        g1 = phi_r @ gam_f
        dphi = [dr @ phi_f + phi_r @ df for dr, df in zip(dphi_r, dphi_f)]
        dg1 = [dr @ gam_f + phi_r @ dgf for dr, dgf in zip(dphi_r, dgam_f)]
    else:
        phi, g1 = phi_r, np.zeros_like(g0)
        dphi, dg1 = dphi_r, [np.zeros_like(g0) for _ in das]
    free = den[: structure.n_free_poles + 1]
    roots = np.roots(free) if structure.n_free_poles else np.zeros(0)
    poles = np.concatenate([np.exp(roots * ts), np.ones(structure.n_integrators)])
    sos, dpoly = allpole_sos(poles)
    # the doubled sections serve the sensitivities only
    sos2, dpoly2 = allpole_sos(np.concatenate([poles, poles])) if derivatives else (np.zeros((0, 6)), np.ones(1))
    return Discretisation(phi=phi, g0=g0, g1=g1, c=c, nd=nd, f=f, dphi=tuple(dphi), dg0=tuple(dg0),
                          dg1=tuple(dg1), g_delay=phi_r @ b, poles=poles, sos=sos, den=dpoly, sos2=sos2,
                          den2=dpoly2)


def zoh_inputs(d: Discretisation, u: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The ``(g, v)`` input pairs of :func:`response` for a ZOH input.

    Parameters
    ----------
    d : Discretisation
        The sampled model.
    u : numpy.ndarray
        The input samples.

    Returns
    -------
    list of (numpy.ndarray, numpy.ndarray)
        ``(G0, u[k-nd])`` and, with a fractional delay, ``(G1, u[k-nd-1])``.
    """
    ud = delayed_input(u, d.nd)
    return [(d.g0, ud), (d.g1, delayed_input(ud, 1))] if d.f > 0 else [(d.g0, ud)]


def _markov(phi: np.ndarray, c: np.ndarray, vec: np.ndarray, count: int) -> np.ndarray:
    """``[c vec, c phi vec, c phi^2 vec, ...]`` (``count`` columns, one row per row of ``c``)."""
    c = np.atleast_2d(np.asarray(c, float))
    v = np.asarray(vec, float).reshape(-1)
    out = np.empty((c.shape[0], count))
    for k in range(count):
        out[:, k] = c @ v
        v = phi @ v
    return out


def response(phi: np.ndarray, c: np.ndarray, sos: np.ndarray, den: np.ndarray, n: int,
             inputs: list[tuple[np.ndarray, np.ndarray]] = (), x0: np.ndarray | None = None,
             c_free: np.ndarray | None = None) -> np.ndarray:
    """Outputs ``c x[k]`` of ``x[k+1] = phi x[k] + sum_q g_q v_q[k]``, ``x[0] = x0``, k < n.

    Parameters
    ----------
    phi : array
        State matrix.
    c : array
        Output row, or several rows (then one output per row, computed in one pass).
    sos, den : arrays
        All-pole sections whose poles are the eigenvalues of ``phi``, and their product
        polynomial (:func:`allpole_sos`).
    n : int
        Number of samples.
    inputs : list of (g, v)
        Input vectors and their signals (length ``n``).
    x0 : array, optional
        Initial state (free response), observed through ``c_free`` (default ``c``).
    c_free : array, optional
        Output row(s) through which the free response of ``x0`` is observed (default ``c``).

    Returns
    -------
    array
        Shape ``(n,)`` for one output row, ``(rows, n)`` otherwise.
    """
    c2 = np.atleast_2d(np.asarray(c, float))
    order = den.size - 1
    drive = np.zeros((c2.shape[0], n))
    for g, v in inputs:
        h = np.zeros((c2.shape[0], order + 1))
        h[:, 1:] = _markov(phi, c2, g, order)            # h_0 = 0: strictly causal
        for r in range(c2.shape[0]):
            num = np.convolve(den, h[r])[: order + 1]
            drive[r] += np.convolve(v, num)[:n]
    if x0 is not None:
        cf = c2 if c_free is None else np.atleast_2d(np.asarray(c_free, float))
        h = _markov(phi, cf, x0, order + 1)
        k = min(order + 1, n)
        for r in range(c2.shape[0]):
            drive[r, :k] += np.convolve(den, h[r % h.shape[0]])[:k]
    y = signal.sosfilt(sos, drive, axis=-1)
    return y[0] if np.ndim(c) == 1 else y


def simulate_zoh(structure: ModelStructure, theta: np.ndarray, u: np.ndarray, ts: float,
                 delay: float = 0.0, x0: np.ndarray | None = None) -> np.ndarray:
    """Output of the model for a zero-order-hold input, computed by filtering (module docstring).

    Parameters
    ----------
    structure : ModelStructure
        The model's orders.
    theta : numpy.ndarray
        Its parameters.
    u : array_like
        Input samples, held over each sample time.
    ts : float
        Sample time, s.
    delay : float
        Input delay, s.
    x0 : array_like, optional
        Companion-form state at the first sample (default: from rest).

    Returns
    -------
    numpy.ndarray
        The output samples, same length as ``u``.
    """
    d = discretise(structure, theta, ts, delay, derivatives=False)
    u = np.asarray(u, dtype=float)
    x0 = None if x0 is None else np.asarray(x0, dtype=float).reshape(-1)
    return response(d.phi, d.c[0], d.sos, d.den, u.size, zoh_inputs(d, u), x0)
