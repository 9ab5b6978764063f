"""Nominal norm-optimal design: known answers and the closed-form limit."""

from __future__ import annotations

import numpy as np
import pytest

from ilcdob.design import closed_form_filters, simulate_map
from ilcdob.design.norm_optimal import NormOptimalDesigner, NormOptimalOptions, norm_optimal_learning
from ilcdob.errors import SpecError
from ilcdob.validation.simulate import rmse, simulate_flight


def _hover(fleet, n):
    t = np.arange(n) * fleet.sample_time
    return np.zeros(n), np.sin(0.9425 * t) + 0.3 * np.sin(2.7 * t)


@pytest.mark.parametrize("lam, mu", [(1e-6, 0.0), (1e-4, 1e-3), (0.0, 1e-2)])
def test_riccati_equals_the_dense_normal_equations(fleet, lam, mu):
    target = fleet.loops[2]
    n = 250
    _, d = _hover(fleet, n)
    e0 = -simulate_map(target.G_d, d)
    des = NormOptimalDesigner(target, n, NormOptimalOptions(lam, mu))
    dense = des.solution_matrix() @ e0  # (Gf'Gf + lam I + mu D'D)^-1 Gf' e0, numpy solve
    np.testing.assert_allclose(des.solve(e0), dense, rtol=0, atol=1e-8 * np.max(np.abs(dense)))
    # optimality: any perturbation raises the cost
    rng = np.random.default_rng(0)
    base = des.cost(e0, dense)
    for _ in range(3):
        assert des.cost(e0, dense + 1e-3 * rng.standard_normal(n)) > base


def test_limit_equals_the_closed_form(fleet):
    a, b = fleet.loops[0], fleet.loops[1]
    n = 3000
    r, d = _hover(fleet, n)
    fa, fb = simulate_flight(a, r, d), simulate_flight(b, r, d)
    df_no = norm_optimal_learning(a, b, fa.e, fa.d_f, NormOptimalOptions(1e-10, 1e-10))
    df_cf = closed_form_filters(a, b).apply(fa.e, fa.d_f)
    # identical away from the trial end (finite-horizon end effects of both)
    assert rmse((df_no - df_cf)[:-50]) < 1e-3 * rmse(df_cf)
    assert rmse(simulate_flight(b, r, d, d_f=df_no).e) < 1e-5 * rmse(fb.e)


def test_regularisation_trades_error_for_effort(fleet):
    a, b = fleet.loops[0], fleet.loops[1]
    n = 1500
    r, d = _hover(fleet, n)
    fa, fb = simulate_flight(a, r, d), simulate_flight(b, r, d)
    light = norm_optimal_learning(a, b, fa.e, fa.d_f, NormOptimalOptions(1e-8, 1e-8))
    heavy = norm_optimal_learning(a, b, fa.e, fa.d_f, NormOptimalOptions(1e-1, 1.0))
    assert rmse(heavy) < rmse(light)
    e_light = rmse(simulate_flight(b, r, d, d_f=light).e)
    e_heavy = rmse(simulate_flight(b, r, d, d_f=heavy).e)
    assert e_light < e_heavy < rmse(fb.e)


def test_lifted_matrices_reproduce_the_solution(fleet):
    a, b = fleet.loops[0], fleet.loops[1]
    n = 400
    r, d = _hover(fleet, n)
    df_a = 0.1 * np.sin(np.arange(n) * 0.02 * 1.3)
    fa, fb = simulate_flight(a, r, d, d_f=df_a), simulate_flight(b, r, d)
    opts = NormOptimalOptions(1e-8, 1e-8)
    l1, l2 = NormOptimalDesigner(b, n, opts).lifted_matrices(a)
    df_lift = l1 @ fa.e + l2 @ fa.d_f
    assert rmse(simulate_flight(b, r, d, d_f=df_lift).e) < 1e-3 * rmse(fb.e)


def test_bad_options():
    with pytest.raises(SpecError, match="lam"):
        NormOptimalOptions(lam=-1.0)
    with pytest.raises(SpecError, match="weight"):
        NormOptimalOptions(weight=0.0)
