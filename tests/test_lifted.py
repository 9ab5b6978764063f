"""Lifted operators: Toeplitz from Markov parameters, relative degree, matrix-free products."""

from __future__ import annotations

import control as ct
import numpy as np

from ilcdob.design import simulate_map
from ilcdob.lifted import lifted_operator, markov_parameters, relative_degree, toeplitz_matvec, toeplitz_rmatvec


def test_lifted_operator_equals_simulation(fleet):
    gf = fleet.loops[0].G_f
    n = 300
    x = np.random.default_rng(1).standard_normal(n)
    t = lifted_operator(markov_parameters(gf, n))
    np.testing.assert_allclose(t @ x, simulate_map(gf, x), atol=1e-12 * np.max(np.abs(t @ x)))
    assert np.allclose(np.triu(t, 1), 0)


def test_relative_degree_of_a_delay():
    sys = ct.ss(ct.tf([1.0], [1.0, -0.5, 0.0, 0.0], 0.02))  # 1/(z^3 - 0.5 z^2) = z^-3/(1 - 0.5 z^-1)
    assert relative_degree(markov_parameters(sys, 20)) == 3


def test_fft_products_match_dense(fleet):
    n = 3000
    h = markov_parameters(fleet.loops[1].G_d, n)
    rng = np.random.default_rng(2)
    x, y = rng.standard_normal(n), rng.standard_normal(n)
    t = lifted_operator(h)
    scale = np.max(np.abs(t @ x))
    np.testing.assert_allclose(toeplitz_matvec(h, x), t @ x, atol=1e-10 * scale)
    np.testing.assert_allclose(toeplitz_rmatvec(h, y), t.T @ y, atol=1e-10 * np.max(np.abs(t.T @ y)))
