"""The closed-form learning filters in lifted (matrix) form, regularised.

``L1 = -T(1 - Q_j) Gd_{j-1}^+`` and ``L2 = L1 T(Gf_{j-1})`` over an N-sample trial, where
``Gd^+`` is the Tikhonov-regularised inverse of the lifted ``Gd_{j-1}`` after shifting out
its relative degree ``m`` (docs/theory.md section 3)::

    Gd^+ = Z (H_s^T H_s + alpha I)^{-1} H_s^T S,   alpha = regularisation * sigma_max(H_s)^2

``S`` drops the first ``m`` error samples (they do not depend on the input), ``Z`` pads the
last ``m`` inputs with zeros. The lifted ``Gd`` of a non-minimum-phase ZOH plant is
ill-conditioned (its smallest singular value decays like ``|z_nmp|^-N``), hence the
regularisation and the reported conditioning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve, svdvals

from ilcdob.errors import SpecError
from ilcdob.lifted import lifted_operator, markov_parameters, relative_degree
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal

from .closed_form import one_minus

__all__ = ["LiftedLearningFilters", "lifted_filters", "regularised_inverse"]


@dataclass(frozen=True)
class LiftedLearningFilters:
    """Lifted learning matrices for one pair.

    Attributes
    ----------
    L1, L2 : numpy.ndarray
        N x N matrices: ``d_f,j = L1 e_{j-1} + L2 d_f,{j-1}``.
    shift : int
        Relative degree of ``Gd_{j-1}`` in samples, shifted out before inverting.
    condition_number : float
        ``sigma_max / sigma_min`` of the shifted lifted ``Gd_{j-1}``.
    regularised_condition : float
        Condition number of the regularised normal matrix ``H_s^T H_s + alpha I``.
    regularisation : float
        Relative Tikhonov weight (alpha / sigma_max^2).
    """

    L1: np.ndarray
    L2: np.ndarray
    shift: int
    condition_number: float
    regularised_condition: float
    regularisation: float

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """Learning signal of system j, ``d_f,j = L1 e_{j-1} + L2 d_f,{j-1}`` (the Theorem, lifted).

        Parameters
        ----------
        e_prev : array_like
            Tracking error of system j-1, m, N samples.
        df_prev : array_like
            Learning signal system j-1 flew with, m/s^2 (zeros if none), N samples.

        Returns
        -------
        numpy.ndarray
            ``d_f,j``, m/s^2, N samples.
        """
        n = self.L1.shape[0]
        e = as_signal(e_prev, "e_prev", n)
        df = as_signal(df_prev, "df_prev", n)
        return self.L1 @ e + self.L2 @ df


def regularised_inverse(h: np.ndarray, regularisation: float = 1e-12) -> tuple[np.ndarray, int, np.ndarray]:
    """Tikhonov inverse ``Gd^+`` (N x N) of the lifted map with Markov parameters ``h``.

    See the module docstring (docs/theory.md section 3): the relative degree is shifted out,
    then the regularised normal equations are solved by Cholesky.

    Parameters
    ----------
    h : numpy.ndarray
        Markov parameters of the map over the trial (N samples).
    regularisation : float
        Relative Tikhonov weight ``alpha / sigma_max^2``, > 0.

    Returns
    -------
    pinv : numpy.ndarray
        ``Gd^+``, N x N.
    shift : int
        The relative degree ``m`` shifted out.
    singular_values : numpy.ndarray
        Singular values of the shifted lifted operator, largest first.

    Raises
    ------
    SpecError
        ``regularisation`` not > 0.
    """
    if not regularisation > 0:
        raise SpecError(f"`regularisation`: got {regularisation!r}, expected a number > 0")
    n = h.size
    m = relative_degree(h)
    hs = lifted_operator(h[m:])
    sv = svdvals(hs)
    alpha = regularisation * sv[0] ** 2
    normal = hs.T @ hs + alpha * np.eye(n - m)
    inv = cho_solve(cho_factor(normal), hs.T)  # (n-m) x (n-m)
    pinv = np.zeros((n, n))
    pinv[: n - m, m:] = inv
    return pinv, m, sv


def lifted_filters(prev: LoopSystem, nxt: LoopSystem, n: int,
                   regularisation: float = 1e-12) -> LiftedLearningFilters:
    """Lifted, regularised form of the closed-form filters over ``n`` samples.

    Parameters
    ----------
    prev, nxt : LoopSystem
        System j-1 (its model is used) and system j.
    n : int
        Trial length in samples. Cost: O(n^3) (dense SVD and Cholesky); n of a few
        thousand takes seconds.
    regularisation : float
        Relative Tikhonov weight, > 0.

    Returns
    -------
    LiftedLearningFilters
        The N x N matrices ``L1``, ``L2`` and their conditioning.
    """
    src = prev.nominal
    gd_pinv, m, sv = regularised_inverse(markov_parameters(src.G_d, n), regularisation)
    alpha = regularisation * sv[0] ** 2
    t_1mq = lifted_operator(markov_parameters(one_minus(nxt.Q), n))
    l1 = -t_1mq @ gd_pinv
    l2 = l1 @ lifted_operator(markov_parameters(src.G_f, n))
    return LiftedLearningFilters(
        L1=l1, L2=l2, shift=m,
        condition_number=float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"),
        regularised_condition=float((sv[0] ** 2 + alpha) / (sv[-1] ** 2 + alpha)),
        regularisation=float(regularisation),
    )
