"""Nominal norm-optimal design: known answers, the closed-form limit, the compact law and its size."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.design import closed_form_filters, simulate_map
from ilcdob.design.norm_optimal import (
    NormOptimalDesigner,
    NormOptimalLaw,
    NormOptimalOptions,
    check_norm_optimal_size,
    norm_optimal_bytes,
    norm_optimal_learning,
)
from ilcdob.design.pair import design_pair
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


def _loop_reference(target, n, opts, e0):
    """The per-sample Riccati recursion and passes the compiled form replaced (gains, pivots, d_f)."""
    gf = target.nominal.G_f
    a, b, c, d = (np.asarray(m, float) for m in (gf.A, gf.B, gf.C, gf.D))
    nx = a.shape[0]
    abar = np.zeros((nx + 1, nx + 1))
    abar[:nx, :nx] = a
    bbar, cz, d = np.append(b[:, 0], 1.0), np.append(c[0], 0.0), float(d.ravel()[0])
    sel = np.eye(nx + 1)[-1]
    w = opts.weight
    q = w * np.outer(cz, cz) + opts.mu * np.outer(sel, sel)
    s, r = w * cz * d - opts.mu * sel, w * d**2 + opts.lam + opts.mu
    p, gains, pivots = np.zeros((nx + 1, nx + 1)), np.empty((n, nx + 1)), np.empty(n)
    for t in range(n - 1, -1, -1):
        pb = p @ bbar
        pivots[t] = r + bbar @ pb
        huz = s + abar.T @ pb
        gains[t] = huz / pivots[t]
        p = q + abar.T @ p @ abar - np.outer(huz, gains[t])
        p = 0.5 * (p + p.T)
    pvec, kff = np.zeros(nx + 1), np.empty(n)
    for t in range(n - 1, -1, -1):
        r_t = -w * e0[t] * d
        kff[t] = (r_t + bbar @ pvec) / pivots[t]
        pvec = -w * e0[t] * cz + (abar - np.outer(bbar, gains[t])).T @ pvec - gains[t] * r_t
    z, u = np.zeros(nx + 1), np.empty(n)
    for t in range(n):
        u[t] = -gains[t] @ z - kff[t]
        z = abar @ z + bbar * u[t]
    return gains, pivots, u


@pytest.mark.parametrize("lam, mu, tol", [(1e-8, 1e-8, 1e-11), (1e-6, 1e-5, 1e-12)])
def test_compiled_recursion_equals_the_per_sample_loop(fleet, lam, mu, tol):
    target, n = fleet.loops[1], 1500
    _, d = _hover(fleet, n)
    e0 = -simulate_map(target.G_d, d)
    opts = NormOptimalOptions(lam, mu)
    gains, pivots, u = _loop_reference(target, n, opts, e0)
    des = NormOptimalDesigner(target, n, opts)
    # the gains to 1e-12 (measured 1.5e-13); the learning signal to the problem's own floor: at the default
    # weights the loop itself moves by 2.5e-12 when e0 moves by one unit in the last place (measured 3.6e-12)
    assert np.max(np.abs(des.gains - gains)) <= 1e-12 * np.max(np.abs(gains))
    np.testing.assert_allclose(des.pivots, pivots, rtol=1e-12, atol=0)
    assert np.max(np.abs(des.solve(e0) - u)) <= tol * np.max(np.abs(u))


def _trial(n):
    t = np.arange(n) * 0.02
    return 0.01 * np.sin(0.9 * t) + 1e-3 * np.random.default_rng(0).standard_normal(n), 0.1 * np.sin(1.3 * t)


def test_compact_law_equals_the_lifted_matrices(fleet):
    a, b = fleet.loops[0], fleet.loops[1]
    n = 200
    e, df = _trial(n)
    # where the dense lifted matrices are themselves accurate (their inverse is a Cholesky of normal
    # equations of condition 1 / regularisation): equal to 1e-10 of the peak (measured 6e-13)
    des = NormOptimalDesigner(b, n, NormOptimalOptions(1e-4, 1e-3))
    l1, l2 = des.lifted_matrices(a, 1e-8)
    law = des.law(a, 1e-8)
    ref = l1 @ e + l2 @ df
    assert np.max(np.abs(law.apply(e, df) - ref)) <= 1e-10 * np.max(np.abs(ref))
    # what lifted.npz carries reproduces it exactly, and is O(N)
    again = NormOptimalLaw.from_arrays(law.to_arrays())
    np.testing.assert_array_equal(again.apply(e, df), law.apply(e, df))
    assert law.nbytes < 100 * 8 * n and law.gains.shape == (n, 12)
    # default weights and regularisation: the dense matrices carry their own rounding (measured 4e-9)
    des = NormOptimalDesigner(b, n)
    l1, l2 = des.lifted_matrices(a)
    ref = l1 @ e + l2 @ df
    assert np.max(np.abs(des.law(a).apply(e, df) - ref)) <= 1e-7 * np.max(np.abs(ref))


def test_long_trial_design_is_compact(fleet):
    n = 50000
    tracemalloc.start()
    try:
        design = design_pair(fleet, "UAV1", "UAV2", "norm-optimal", n=n)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    arrays = design.lifted
    assert "L1" not in arrays and arrays["gains"].shape == (n, 12) and arrays["inverse_gains"].shape == (n - 1, 12)
    # measured 16.4 MB (41 numbers per sample); the size check's estimate bounds it, two lifted matrices
    # alone would take 40 GB
    assert peak < norm_optimal_bytes(n, 11) < 40e6
    assert design.order == f"Riccati gains over {n} samples"


def test_size_check_counts_what_is_built(capsys, tmp_path):
    with pytest.raises(SpecError, match=r"`n`: got 20000 samples; the lifted 20000 x 20000 matrices L1, L2 "
                                        r"\(lifted=True\) take 25.6 GB .* limit is 6.4 GB \(10000 samples\): "
                                        r"omit lifted=True \(the design's compact form, Riccati gains, takes 10.2 MB"):
        check_norm_optimal_size(20000, 11, True)
    check_norm_optimal_size(20000, 11)  # the compact form: 10 MB
    with pytest.raises(SpecError, match=r"`n`: got 100000000 samples; the norm-optimal design \(Riccati gains, "
                                        r"11 states\) would take 51.2 GB"):
        check_norm_optimal_size(10**8, 11)
    out = tmp_path / "d"
    assert main(["--quiet", "design", "--from", "UAV1", "--to", "UAV2", "--method", "norm-optimal", "--lifted",
                 "--n", "12000", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "`--n`: got 12000" in err and "9.22 GB" in err and "omit --lifted" in err and not out.exists()


def test_design_folder_holds_the_compact_law(fleet, tmp_path):
    out = tmp_path / "no"
    assert main(["--quiet", "design", "--from", "UAV1", "--to", "UAV2", "--method", "norm-optimal", "--n", "300",
                 "--out", str(out)]) == 0
    with np.load(out / "lifted.npz") as arrays:
        assert "L1" not in arrays.files
        law = NormOptimalLaw.from_arrays(arrays)
    e, df = _trial(300)
    l1, l2 = NormOptimalDesigner(fleet.loop("UAV2"), 300).lifted_matrices(fleet.loop("UAV1"))
    ref = l1 @ e + l2 @ df
    assert np.max(np.abs(law.apply(e, df) - ref)) <= 1e-7 * np.max(np.abs(ref))
    with pytest.raises(SpecError, match=r"x.npz: no norm-optimal law in it \(missing \['n'"):
        NormOptimalLaw.from_arrays({"L1": l1}, "x.npz")
