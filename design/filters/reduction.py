"""Model reduction of stable discrete SISO maps by balanced truncation.

The robust design (:mod:`ilcdob.design.methods.robust`, docs/theory.md sections 3 and 5) enters every
plausible ``Gf_k`` through its state-space equations; a balanced truncation keeps the states
well scaled and few, and its error bound ``2 sum(discarded Hankel singular values)`` is
carried into the design's constraints, so guarantees stated for the reduced models hold for
the full ones.

``control.balred`` (python-control 0.10) hard-codes continuous time and returns a ``dt = 0``
system, so it cannot be used on discrete maps; SLICOT AB09AD is called directly through
slycot with ``dico='D'``.
"""

from __future__ import annotations

import warnings

import control as ct
import numpy as np
import scipy.linalg as sla
import slycot
from slycot.exceptions import SlycotResultWarning

__all__ = ["hankel_singular_values", "reduced_realisation"]


def hankel_singular_values(sys: ct.StateSpace) -> np.ndarray:
    """Hankel singular values of a stable discrete SISO map, largest first.

    Parameters
    ----------
    sys : control.StateSpace
        A stable discrete-time single-input single-output system.

    Returns
    -------
    numpy.ndarray
        ``sqrt(eig(Wc Wo))`` with the discrete controllability and observability Gramians,
        in decreasing order.
    """
    a, b, c = (np.asarray(m, float) for m in (sys.A, sys.B, sys.C))
    wc = sla.solve_discrete_lyapunov(a, b @ b.T)
    wo = sla.solve_discrete_lyapunov(a.T, c.T @ c)
    return np.sqrt(np.sort(np.abs(np.linalg.eigvals(wc @ wo)))[::-1])


def reduced_realisation(sys: ct.StateSpace, tol: float) -> tuple[ct.StateSpace, float]:
    """Balanced truncation of a stable discrete SISO map, and its error bound.

    States whose Hankel singular value is below ``tol`` times the largest are truncated
    (SLICOT AB09AD, square-root balance & truncate, ``dico='D'``), after a minimal
    realisation. The returned bound ``2 sum(discarded HSV)`` bounds ``||G - G_r||_inf`` and
    hence the l2 gain of the error on any finite trial from rest.

    Parameters
    ----------
    sys : control.StateSpace
        A stable discrete-time single-input single-output system.
    tol : float
        Relative Hankel singular value below which states are dropped (0 keeps every state
        of the minimal realisation; at least one state is kept).

    Returns
    -------
    (control.StateSpace, float)
        The reduced system (same sample time) and the error bound.
    """
    m = ct.minreal(sys, verbose=False)
    if m.nstates == 0:
        return m, 0.0
    hsv = hankel_singular_values(m)
    order = max(1, int(np.sum(hsv > tol * hsv[0])))
    with warnings.catch_warnings():  # AB09AD lowers nr itself to the minimal order, with a warning
        warnings.simplefilter("ignore", SlycotResultWarning)
        nr, ar, br, cr, _ = slycot.ab09ad("D", "B", "N", m.nstates, 1, 1, np.asarray(m.A, float),
                                          np.asarray(m.B, float), np.asarray(m.C, float), nr=order)
    red = ct.ss(ar[:nr, :nr], br[:nr, :], cr[:, :nr], m.D, m.dt)
    return red, float(2.0 * np.sum(hsv[nr:]))
