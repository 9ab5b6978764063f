"""Initial estimates for continuous-time fits: state-variable-filter instrumental variables.

Simplified refined instrumental variables for continuous-time models (SRIVC; P. Young,
"Refined instrumental variable estimation", 2011; Garnier, Wang, Young, 2008), with the
fixed integrators imposed structurally. The model ``s^K A(s) y = B(s) u`` is linear in the
parameters once both sides are passed through a stable prefilter ``s^k / L(s)``:

    y_f^(N) = -sum_i a_i y_f^(K+i) + sum_j b_j u_f^(j)

The first pass uses ``L(s) = (s + lam)^N``; every further pass uses the current estimate of
``A(s)`` (stabilised, integrators replaced by ``(s + lam)``) and, as instruments, the
filtered noise-free output simulated from the current model: the estimate converges to the
output-error optimum in a few passes, which makes it a good starting point for the
output-error refinement in :mod:`ilcdob.identification.tfest`.
"""

from __future__ import annotations

import numpy as np

from ilcdob.uncertainty import ModelStructure

from .oe import Discretisation, discretise, response, simulate_zoh

__all__ = ["srivc", "delayed"]


def delayed(u: np.ndarray, delay_samples: float) -> np.ndarray:
    """A signal delayed by a (fractional) number of samples, by linear interpolation.

    Parameters
    ----------
    u : numpy.ndarray
        The signal.
    delay_samples : float
        Delay, samples (may be fractional).

    Returns
    -------
    numpy.ndarray
        ``u(k - delay_samples)``, zero before the start, same length.
    """
    if delay_samples == 0:       # interpolation at the samples themselves: the signal (a copy)
        return np.array(u, dtype=float)
    n = u.size
    k = np.arange(n) - delay_samples
    return np.interp(k, np.arange(n), u, left=0.0)


def _bank(lpoly: np.ndarray, ts: float) -> Discretisation:
    """The sampled companion realisation of ``1/L(s)`` whose states give the filter bank."""
    n = lpoly.size - 1
    return discretise(ModelStructure(n, 0, 0), np.concatenate([lpoly[1:] / lpoly[0], [1.0]]), ts, 0.0,
                      derivatives=False)


def _filter_bank(x: np.ndarray, lpoly: np.ndarray, d: Discretisation, orders: range, hold: str) -> list[np.ndarray]:
    """``s^k / L(s)`` applied to samples of ``x``: ``hold="zoh"`` for the piecewise-constant
    input; ``"foh"`` for the sampled continuous output, approximated by holding the mean of
    consecutive samples (the trapezoid over each step: an O(ts^2) difference from the exact
    first-order hold, ample for an initial estimate). All orders come from the states of one
    companion realisation of ``1/L(s)`` (``d``, :func:`_bank`; :func:`~ilcdob.identification.oe.response`)."""
    n = lpoly.size - 1
    lead = lpoly[0]
    v = x if hold == "zoh" else 0.5 * (x + np.concatenate([x[1:], x[-1:]]))
    rows = n if max(orders) >= n else max(orders) + 1
    states = np.atleast_2d(response(d.phi, np.eye(n)[:rows], d.sos, d.den, x.size, [(d.g0, v)])) / lead
    out = []
    for k in orders:
        if k < n:
            out.append(states[k])
        else:  # s^n / L = (1 - sum_{j<n} l_j s^j / L) / lead
            out.append(x / lead - (lpoly[1:][::-1] / lead) @ states)
    return out


def _stable_prefilter(theta: np.ndarray, structure: ModelStructure, lam: float) -> np.ndarray:
    den, _ = structure.split(theta)
    free = den[: structure.n_free_poles + 1]
    roots = np.roots(free) if structure.n_free_poles else np.zeros(0)
    roots = np.where(roots.real > -1e-3 * lam, -np.abs(roots.real) - 1e-3 * lam + 1j * roots.imag, roots)
    roots = np.concatenate([roots, np.full(structure.n_integrators, -lam)])
    return np.real(np.poly(roots))


def srivc(structure: ModelStructure, experiments: list[tuple[np.ndarray, np.ndarray]], ts: float,
          delay: float = 0.0, lam: float | None = None, iterations: int = 8, tol: float = 1e-6) -> np.ndarray:
    """SRIVC estimate of ``theta`` from experiments ``[(u, y), ...]`` sampled at ``ts``.

    Parameters
    ----------
    structure : ModelStructure
    experiments : list of (u, y)
        Input and output samples of each experiment (same length within one experiment).
    ts : float
        Sample time, s.
    delay : float
        Known input delay, s (applied to ``u`` by interpolation).
    lam : float, optional
        Initial prefilter pole (rad/s); default ``0.5 / (10 ts)``... a tenth of Nyquist/5.
    iterations : int
        Refinement passes after the first.
    tol : float
        Stop when a pass changes ``theta`` by less than this, relative (an initial estimate
        needs no more: the output-error fit refines it).
    """
    n_tot = structure.n_poles
    k_int = structure.n_integrators
    lam = float(lam) if lam is not None else 0.1 * np.pi / ts / 5
    lpoly = np.real(np.poly(np.full(n_tot, -lam)))
    data = [(delayed(np.asarray(u, float), delay / ts), np.asarray(y, float)) for u, y in experiments]
    theta = None
    free_orders = [k_int + i for i in range(structure.n_free_poles - 1, -1, -1)]
    for it in range(iterations + 1):
        m_zp = 0.0
        m_zy = 0.0
        bank = _bank(lpoly, ts)
        for u, y in data:
            yf = _filter_bank(y, lpoly, bank, range(n_tot + 1), "foh")
            uf = _filter_bank(u, lpoly, bank, range(structure.n_zeros + 1), "zoh")
            skip = min(u.size // 4, int(np.ceil(6.0 / (lam * ts))))
            # regressors as rows (parameters x samples)
            u_rows = [uf[j][skip:] for j in range(structure.n_zeros, -1, -1)]
            phi = np.vstack([-yf[k][skip:] for k in free_orders] + u_rows)
            if theta is None:
                zeta = phi
            else:
                xh = simulate_zoh(structure, theta, u, ts)
                xf = _filter_bank(xh, lpoly, bank, range(n_tot + 1), "foh")
                zeta = np.vstack([-xf[k][skip:] for k in free_orders] + u_rows)
            m_zp = m_zp + zeta @ phi.T
            m_zy = m_zy + zeta @ yf[n_tot][skip:]
        if not (np.all(np.isfinite(m_zp)) and np.all(np.isfinite(m_zy))):
            raise ValueError("SRIVC diverged (non-finite filtered signals)")
        scale = np.sqrt(np.abs(np.diag(m_zp)))
        scale[scale == 0] = 1.0
        new = np.linalg.lstsq(m_zp / np.outer(scale, scale), m_zy / scale, rcond=None)[0] / scale
        if theta is not None and np.linalg.norm(new - theta) <= tol * np.linalg.norm(theta):
            theta = new
            break
        theta = new
        lpoly = _stable_prefilter(theta, structure, lam)
    return theta
