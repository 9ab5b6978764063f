"""The learning-signal map of a vehicle inverted over one trial, by least squares (docs/theory.md section 6).

A learning law that acts on the reconstructed disturbance with a non-causal filter ``F``
(:mod:`..methods.robust_set`) is, over an infinite horizon, ``e_j = (1 - F) e'_j``. On a trial of ``N``
samples it is not: near the trial's ends ``F`` reaches past the samples that exist, and the
worst disturbance of a whole trial can make the error larger than without learning. Asking
instead for the *error* the learning signal should produce makes the finite trial exact.
With ``y`` the target's predicted error without learning (its model's ``Gd`` applied to the
reconstructed disturbance) and ``F_N`` the finite section of ``F`` (zero outside the trial),
the learning signal is the ``u`` whose effect on the error, through the lifted map ``Gf_N`` of
the target's model, comes nearest to ``-F_N y``::

    u = argmin ||Gf_N u + F_N y||^2 + lam ||u||^2

``Gf_N u`` is then the orthogonal projection of ``-F_N y`` onto the errors the target can be
given (up to ``lam``), so with exact models ``e_j = P (I - F_N) e'_j`` on the trial with ``P`` a
projection: ``||e_j|| <= ||I - F_N|| ||e'_j|| <= max_w |1 - F(w)| ||e'_j||`` for every
disturbance, the norm of a finite section of a convolution being at most the peak of its
frequency response (``sqrt(2)`` times it when ``y`` is extended before ``t = 0`` as an odd
function, as robust-set does so that ``F``'s output starts near 0: the extension at most doubles
the energy ``F`` sees). Over an infinite horizon the law is the same as before.

``lam`` is ``ridge`` times the mean diagonal of ``Gf_N^T Gf_N``. It must lie below the squared
gain of ``Gf`` wherever the error has content (``|Gf|`` falls to ~1e-5 of its peak at Nyquist on
the built-in fleet: ``ridge = 1e-9`` raised the whole-trial figure from 0.15 to 0.37 on UAV1 ->
UAV2), and above the exponentially small singular values a non-minimum-phase zero of ``Gf``
gives the lifted map (inputs growing as ``z^k`` toward the end). The default 1e-12 does both.

Cost: the matrices are dense, ``2 x 8 N^2`` bytes and ``N^3/3`` operations to factor (about
1 s at ``N`` = 3000); :data:`MAX_TRIAL_SAMPLES` bounds ``N``.
"""

from __future__ import annotations

from collections import OrderedDict

import control as ct
import numpy as np
from scipy.linalg import cho_factor, cho_solve

from ilcdob.lifted import lifted_operator, markov_parameters

__all__ = ["TrialInverse", "trial_inverse", "MAX_TRIAL_SAMPLES", "RIDGE"]

#: Longest trial (samples) the least-squares inverse is built for: two dense 8000 x 8000 matrices
#: take 1 GB and factor in about 20 s on 2 cores.
MAX_TRIAL_SAMPLES = 8000
#: Default ``ridge`` (module docstring).
RIDGE = 1e-12


class TrialInverse:
    """Regularised least-squares inverse of a causal map over ``n`` samples (module docstring).

    Parameters
    ----------
    sys : control.StateSpace
        Discrete SISO map (the target model's ``G_f``).
    n : int
        Samples of the trial (<= :data:`MAX_TRIAL_SAMPLES`).
    ridge : float
        ``lam`` relative to the mean diagonal of ``G_N^T G_N``.
    """

    def __init__(self, sys: ct.StateSpace, n: int, ridge: float = RIDGE):
        g = lifted_operator(markov_parameters(sys, n))
        a = g.T @ g
        a[np.diag_indices(n)] += ridge * np.trace(a) / n
        self.n = n
        self._g = g
        self._factor = cho_factor(a, overwrite_a=True, check_finite=False)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``argmin ||G_N u - b||^2 + lam ||u||^2``.

        Parameters
        ----------
        b : numpy.ndarray
            The output asked for, ``n`` samples.

        Returns
        -------
        numpy.ndarray
            The input ``u``, ``n`` samples.
        """
        return cho_solve(self._factor, self._g.T @ b, check_finite=False)

    def adjoint(self, u: np.ndarray) -> np.ndarray:
        """The adjoint of :meth:`solve`, ``G_N (G_N^T G_N + lam I)^{-1} u``.

        Parameters
        ----------
        u : numpy.ndarray
            ``n`` samples.

        Returns
        -------
        numpy.ndarray
            ``n`` samples.
        """
        return self._g @ cho_solve(self._factor, u, check_finite=False)

    def __call__(self, b: np.ndarray) -> np.ndarray:
        return self.solve(b)


_CACHE: OrderedDict[tuple, TrialInverse] = OrderedDict()
_CACHE_SIZE = 4  # trials of a few lengths (the scenarios of a campaign) per process


def trial_inverse(sys: ct.StateSpace, n: int, key: object, ridge: float = RIDGE) -> TrialInverse:
    """:class:`TrialInverse` of ``sys`` over ``n`` samples, built once per ``(key, n, ridge)``.

    Parameters
    ----------
    sys : control.StateSpace
        Discrete SISO map.
    n : int
        Samples of the trial.
    key : hashable
        Identifies ``sys`` (e.g. the loop's specification and sample time).
    ridge : float
        As in :class:`TrialInverse`.

    Returns
    -------
    TrialInverse
    """
    k = (key, int(n), float(ridge))
    if k in _CACHE:
        _CACHE.move_to_end(k)
    else:
        _CACHE[k] = TrialInverse(sys, int(n), ridge)
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return _CACHE[k]
