"""Nominal norm-optimal learning design (docs/theory.md section 3), solved in O(N).

For system j learning from system j-1 with the predicted error without learning ``e0``
(from j-1's flight: ``e0 = -Gd_j {d_rec}``, ``d_rec`` the disturbance reconstructed from
j-1's data with its model), choose the learning signal ``d_f`` to minimise::

    J = sum_t  w (e0_t - y_t)^2 + lam d_f,t^2 + mu (d_f,t - d_f,t-1)^2,    y = Gf_j {d_f}

This is a finite-horizon linear-quadratic tracking problem. With the state of ``Gf_j``
augmented by the previous input (for the difference penalty), the backward Riccati
recursion gives time-varying gains once per system (cost O(N n^3), n the order of Gf_j),
and each trial costs one backward pass for the affine term and one forward pass
(O(N n^2)): no N x N matrix is formed. The same optimum, written as the linear system
``(Gf' W Gf + lam I + mu Diff' Diff) d_f = Gf' W e0``, is what a dense QP would solve in
O(N^3). Its solution map, composed with the reconstruction, is the pair of lifted learning
matrices (:meth:`NormOptimalDesigner.lifted_matrices`); as ``lam, mu -> 0`` with exact models
it reproduces the closed-form filters of the Theorem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.lifted import lifted_operator, markov_parameters
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal

from .closed_form import reconstruct_disturbance, simulate_map

__all__ = ["NormOptimalOptions", "NormOptimalDesigner", "norm_optimal_learning"]


@dataclass(frozen=True)
class NormOptimalOptions:
    """Weights of the norm-optimal cost.

    Attributes
    ----------
    lam : float
        Weight of ``||d_f||^2`` (>= 0), (m/(m/s^2))^2.
    mu : float
        Weight of ``||Diff d_f||^2`` (>= 0); ``lam + mu`` must be > 0 unless Gf has a
        direct feedthrough.
    weight : float
        Error weight ``w`` (> 0).
    """

    lam: float = 1e-8
    mu: float = 1e-8
    weight: float = 1.0

    def __post_init__(self) -> None:
        for name in ("lam", "mu"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise SpecError(f"`{name}`: got {v!r}, expected a finite number >= 0")
        if not (math.isfinite(self.weight) and self.weight > 0):
            raise SpecError(f"`weight`: got {self.weight!r}, expected a number > 0")


class NormOptimalDesigner:
    """Riccati solution of the nominal norm-optimal problem for one target loop.

    Parameters
    ----------
    target : LoopSystem
        System j; its nominal (model) ``G_f`` is used.
    n : int
        Trial length, samples (>= 2).
    options : NormOptimalOptions, optional
        Weights of the cost (default ``NormOptimalOptions()``).

    Notes
    -----
    The backward Riccati recursion for the gains runs once, here (O(N n^3)); each
    :meth:`solve` then costs O(N n^2) (module docstring; docs/theory.md section 3).
    """

    def __init__(self, target: LoopSystem, n: int, options: NormOptimalOptions | None = None) -> None:
        if n < 2:
            raise SpecError(f"`n`: got {n}, expected a trial length >= 2 samples")
        self.target, self.n = target, int(n)
        self.options = opts = options or NormOptimalOptions()
        gf = target.nominal.G_f
        a, b, c, d = (np.asarray(m, float) for m in (gf.A, gf.B, gf.C, gf.D))
        nx = a.shape[0]
        w, lam, mu = opts.weight, opts.lam, opts.mu
        # augmented state z = [x; u_prev]
        self._abar = np.zeros((nx + 1, nx + 1))
        self._abar[:nx, :nx] = a
        self._bbar = np.concatenate([b[:, 0], [1.0]])
        self._cz = np.concatenate([c[0], [0.0]])
        self._d = float(d.ravel()[0])
        sel = np.zeros(nx + 1)
        sel[-1] = 1.0
        q = w * np.outer(self._cz, self._cz) + mu * np.outer(sel, sel)
        s = w * self._cz * self._d - mu * sel
        r = w * self._d**2 + lam + mu
        if r <= 0:
            raise SpecError("`lam` + `mu` must be > 0 (Gf has no direct feedthrough)")
        # backward Riccati for the gains (independent of the trial)
        p = np.zeros((nx + 1, nx + 1))
        self._gain = np.empty((self.n, nx + 1))       # K_t
        self._huu = np.empty(self.n)                  # H_uu,t
        self._closed = np.empty((self.n, nx + 1, nx + 1))  # (A - B K_t)' for the affine recursion
        abar, bbar = self._abar, self._bbar
        for t in range(self.n - 1, -1, -1):
            pb = p @ bbar
            huu = r + bbar @ pb
            huz = s + abar.T @ pb            # (S + A' P B) as a vector
            k = huz / huu
            p = q + abar.T @ p @ abar - np.outer(huz, k)
            p = 0.5 * (p + p.T)
            self._gain[t], self._huu[t] = k, huu
            self._closed[t] = (abar - np.outer(bbar, k)).T

    def solve(self, e0: object) -> np.ndarray:
        """Optimal learning signal for a predicted error without learning.

        Parameters
        ----------
        e0 : array_like
            Predicted error of system j without learning, m, ``n`` samples.

        Returns
        -------
        numpy.ndarray
            The minimiser ``d_f`` of ``J`` (module docstring), m/s^2, ``n`` samples.
        """
        e0 = as_signal(e0, "e0", self.n)
        w = self.options.weight
        nz = self._abar.shape[0]
        # affine term: p_t = q_t + (A - B K_t)' p_{t+1} - K_t' r_t, with q_t = -w e0_t Cz, r_t = -w e0_t D
        pvec = np.zeros(nz)
        kff = np.empty(self.n)
        for t in range(self.n - 1, -1, -1):
            r_t = -w * e0[t] * self._d
            h_u = r_t + self._bbar @ pvec
            kff[t] = h_u / self._huu[t]
            pvec = -w * e0[t] * self._cz + self._closed[t] @ pvec - self._gain[t] * r_t
        z = np.zeros(nz)
        u = np.empty(self.n)
        for t in range(self.n):
            u[t] = -self._gain[t] @ z - kff[t]
            z = self._abar @ z + self._bbar * u[t]
        return u

    def cost(self, e0: np.ndarray, d_f: np.ndarray) -> float:
        """Value of the cost ``J`` for a given learning signal (for checks).

        Parameters
        ----------
        e0 : numpy.ndarray
            Predicted error without learning, m.
        d_f : numpy.ndarray
            Learning signal, m/s^2, same length.

        Returns
        -------
        float
            ``J`` (module docstring).
        """
        o = self.options
        y = simulate_map(self.target.nominal.G_f, d_f)
        du = np.diff(np.concatenate([[0.0], d_f]))
        return float(o.weight * np.sum((e0 - y) ** 2) + o.lam * np.sum(d_f**2) + o.mu * np.sum(du**2))

    def solution_matrix(self) -> np.ndarray:
        """The N x N map ``e0 -> d_f``: ``(Gf' W Gf + lam I + mu Diff' Diff)^{-1} Gf' W`` (dense, O(N^3))."""
        o = self.options
        gf = lifted_operator(markov_parameters(self.target.nominal.G_f, self.n))
        diff = np.eye(self.n) - np.eye(self.n, k=-1)
        h = o.weight * gf.T @ gf + o.lam * np.eye(self.n) + o.mu * diff.T @ diff
        return np.linalg.solve(h, o.weight * gf.T)

    def lifted_matrices(self, source: LoopSystem, regularisation: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
        """Lifted learning matrices ``(L1, L2)``: ``d_f,j = L1 e_{j-1} + L2 d_f,{j-1}``.

        ``L1 = F Gd_j Gd_{j-1}^+`` (``e0 = -Gd_j d_rec``, ``d_rec = -Gd_{j-1}^+ e'``) with ``F`` the
        solution matrix and ``Gd_{j-1}^+`` the
        regularised inverse of :func:`~ilcdob.design.lifted_filters.regularised_inverse`;
        ``L2 = L1 Gf_{j-1}``. Dense, O(N^3): for export and checks at moderate N.

        Parameters
        ----------
        source : LoopSystem
            System j-1 (its model is used).
        regularisation : float
            Relative Tikhonov weight of the inverse of ``Gd_{j-1}``, > 0.

        Returns
        -------
        L1, L2 : numpy.ndarray
            N x N learning matrices.
        """
        from .lifted_filters import regularised_inverse

        src = source.nominal
        n = self.n
        gd_prev_inv, _, _ = regularised_inverse(markov_parameters(src.G_d, n), regularisation)
        gd_j = lifted_operator(markov_parameters(self.target.nominal.G_d, n))
        l1 = self.solution_matrix() @ (gd_j @ gd_prev_inv)
        l2 = l1 @ lifted_operator(markov_parameters(src.G_f, n))
        return l1, l2


def norm_optimal_learning(source: LoopSystem, target: LoopSystem, e_prev: object, df_prev: object,
                          options: NormOptimalOptions | None = None) -> np.ndarray:
    """Learning signal of ``target`` from a flight of ``source`` (nominal norm-optimal design).

    ``e0 = -Gd_j{d_rec}``, ``d_rec = reconstruct_disturbance(source, e_prev, df_prev)``; then the
    Riccati solution of :class:`NormOptimalDesigner`.

    Parameters
    ----------
    source : LoopSystem
        System j-1, which flew (its model is used for the reconstruction).
    target : LoopSystem
        System j, the learning system (its model's ``G_d`` and ``G_f`` are used).
    e_prev : array_like
        Tracking error of system j-1 over the trial, m.
    df_prev : array_like
        Learning signal system j-1 flew with, m/s^2 (zeros if none), same length.
    options : NormOptimalOptions, optional
        Weights of the cost.

    Returns
    -------
    numpy.ndarray
        ``d_f,j``, m/s^2, same length as ``e_prev``.
    """
    e_prev = as_signal(e_prev, "e_prev")
    d_rec = reconstruct_disturbance(source, e_prev, df_prev)
    e0 = -simulate_map(target.nominal.G_d, d_rec)
    return NormOptimalDesigner(target, e_prev.size, options).solve(e0)
