"""Nominal norm-optimal design: known answers, the closed-form limit, the compact law and its size."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.design import closed_form_filters, simulate_map
from ilcdob.design.methods.norm_optimal import (
                                                NormOptimalDesigner,
                                                NormOptimalLaw,
                                                NormOptimalOptions,
                                                check_norm_optimal_size,
                                                norm_optimal_bytes,
                                                norm_optimal_learning,
                                                )
from ilcdob.design.methods import NormOptimal
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


def _reference_gains(target, n, opts, dtype=np.float64):
    """Gains and pivots of the per-sample Riccati recursion the compiled form replaced, in ``dtype``."""
    gf = target.nominal.G_f
    a, b, c, d = (np.asarray(m, dtype) for m in (gf.A, gf.B, gf.C, gf.D))
    nx = a.shape[0]
    abar = np.zeros((nx + 1, nx + 1), dtype)
    abar[:nx, :nx] = a
    bbar, cz, d = np.append(b[:, 0], dtype(1)), np.append(c[0], dtype(0)), d.ravel()[0]
    sel = np.eye(nx + 1, dtype=dtype)[-1]
    w, lam, mu = dtype(opts.weight), dtype(opts.lam), dtype(opts.mu)
    q = w * np.outer(cz, cz) + mu * np.outer(sel, sel)
    s, r = w * cz * d - mu * sel, w * d * d + lam + mu
    p, gains, pivots = np.zeros((nx + 1, nx + 1), dtype), np.empty((n, nx + 1), dtype), np.empty(n, dtype)
    for t in range(n - 1, -1, -1):
        pb = p @ bbar
        pivots[t] = r + bbar @ pb
        huz = s + abar.T @ pb
        gains[t] = huz / pivots[t]
        p = q + abar.T @ p @ abar - np.outer(huz, gains[t])
        p = (p + p.T) / 2
    return gains, pivots


def _reference_passes(target, gains, pivots, opts, e0, dtype=np.float64):
    """The per-sample backward and forward passes with the given gains, in ``dtype``: ``d_f``."""
    gf = target.nominal.G_f
    a, b, c, d = (np.asarray(m, dtype) for m in (gf.A, gf.B, gf.C, gf.D))
    nx, n = a.shape[0], e0.size
    abar = np.zeros((nx + 1, nx + 1), dtype)
    abar[:nx, :nx] = a
    bbar, cz, d = np.append(b[:, 0], dtype(1)), np.append(c[0], dtype(0)), d.ravel()[0]
    gains, pivots, e, w = np.asarray(gains, dtype), np.asarray(pivots, dtype), np.asarray(e0, dtype), dtype(opts.weight)
    pvec, kff = np.zeros(nx + 1, dtype), np.empty(n, dtype)
    for t in range(n - 1, -1, -1):
        r_t = -w * e[t] * d
        kff[t] = (r_t + bbar @ pvec) / pivots[t]
        pvec = -w * e[t] * cz + (abar - np.outer(bbar, gains[t])).T @ pvec - gains[t] * r_t
    z, u = np.zeros(nx + 1, dtype), np.empty(n, dtype)
    for t in range(n):
        u[t] = -(gains[t] @ z) - kff[t]
        z = abar @ z + bbar * u[t]
    return u


def _peak_relative(x, ref):
    return float(np.max(np.abs(np.asarray(x, np.longdouble) - ref)) / np.max(np.abs(ref)))


@pytest.mark.parametrize("mode", ["off", "required"])  # CasADi's virtual machine; native code (ilcdob/native.py)
@pytest.mark.parametrize("lam, mu, tol", [(1e-8, 1e-8, 1e-11), (1e-6, 1e-5, 1e-12)])
def test_compiled_recursion_equals_the_per_sample_loop(fleet, lam, mu, tol, mode, monkeypatch, request):
    if mode == "required":
        request.getfixturevalue("cc")  # skipped without a C compiler
    monkeypatch.setenv("ILCDOB_NATIVE", mode)
    target, n = fleet.loops[1], 1500
    _, d = _hover(fleet, n)
    e0 = -simulate_map(target.G_d, d)
    opts = NormOptimalOptions(lam, mu)
    gains, pivots = _reference_gains(target, n, opts)
    u = _reference_passes(target, gains, pivots, opts, e0)
    des = NormOptimalDesigner(target, n, opts)
    got = des.solve(e0)
    # the gains to 1e-12 (measured 1.5e-13); the learning signal to the problem's own floor: at the default
    # weights the loop itself moves by 2.5e-12 when e0 moves by one unit in the last place (measured 4.4e-12)
    assert np.max(np.abs(des.gains - gains)) <= 1e-12 * np.max(np.abs(gains))
    np.testing.assert_allclose(des.pivots, pivots, rtol=1e-12, atol=0)
    assert np.max(np.abs(got - u)) <= tol * np.max(np.abs(u))
    # against the exact optimum: the same recursion in 80-bit arithmetic. The gains to a few roundings
    # (measured 2.9e-16 to 4.7e-16). The learning signal within 1e-12 of its peak where the problem allows:
    # at the default weights (a closed-loop pole at 1 - 1e-8) the exact gains merely rounded to float64 move
    # it by 7e-13 (the floor of any method storing float64 gains) and rounding the passes' states adds as
    # much again, so the tolerance is 8 floors there (measured: compiled 3.3e-12, the loop 2.9e-12; at
    # lam, mu = 1e-6, 1e-5 floor 3.5e-14, compiled 1.8e-13, the loop 2.6e-13)
    if np.finfo(np.longdouble).eps > 1e-18:
        pytest.skip("numpy's longdouble is no wider than float64 here: no 80-bit reference")
    ld = np.longdouble
    exact_gains, exact_pivots = _reference_gains(target, n, opts, ld)
    exact = _reference_passes(target, exact_gains, exact_pivots, opts, e0, ld)
    assert _peak_relative(des.gains, exact_gains) <= 1e-14
    assert _peak_relative(des.pivots, exact_pivots) <= 1e-14
    floor = _peak_relative(_reference_passes(target, exact_gains.astype(float), exact_pivots.astype(float), opts,
                                             e0, ld), exact)
    assert _peak_relative(got, exact) <= max(1e-12, 8 * floor)


def test_recursions_skip_the_systems_zero_entries(fleet, monkeypatch):
    from ilcdob.design.methods import norm_optimal as no

    rng = np.random.default_rng(3)
    a = np.diag(rng.uniform(0.3, 0.9, 6)) + np.triu(rng.uniform(-0.2, 0.2, (6, 6)), 1)
    a[:, 2] = 0.0  # a state nothing reads: a row of A' without entries
    b, c = np.array([1.0, 0.0, 0.5, 0.0, -0.3, 0.0]), np.array([0.0, 0.2, 0.0, 1.0, 0.0, 0.4])
    systems = {"fleet": no._state_space(fleet.loops[1].nominal.G_f), "feedthrough": (a, b, c, 0.7)}
    n = 700
    u = np.sin(0.05 * np.arange(n)) + 0.1 * rng.standard_normal(n)
    results = {}
    for name in ("sparse", "dense"):
        if name == "dense":  # every entry a symbol, as the functions were built before
            monkeypatch.setattr(no, "_pattern", lambda sys: (sys[0].shape[0], tuple(range(sys[0].size)),
                                                             tuple(range(sys[1].size)), tuple(range(sys[2].size)),
                                                             True))
        for key, sys in systems.items():
            gains, pivots = no._lq_gains(sys, 1.0, 1e-6, 1e-5, n)
            results[name, key] = (gains, pivots, no._lq_solve(sys, gains, pivots, -u, -sys[3] * u),
                                  no._simulate(sys, u))
        monkeypatch.undo()
    for key, sys in systems.items():
        # leaving out the products with zero changes no sum: the same numbers bit for bit
        for sparse, dense in zip(results["sparse", key], results["dense", key]):
            np.testing.assert_array_equal(sparse, dense)
    np.testing.assert_allclose(results["sparse", "feedthrough"][3],
                               simulate_map(_ss(a, b, c, 0.7), u), rtol=0, atol=1e-13)
    # the fleet's A has 65 nonzero entries of 121, c one of 11: about 40 % fewer instructions per sample
    sparse, dense = no._pattern(systems["fleet"]), (11, tuple(range(121)), tuple(range(11)), tuple(range(11)), True)
    for kind in ("gains", "backward", "forward", "simulate"):
        assert (no._base(kind, sparse, no._UNROLL[kind]).n_instructions()
                < 0.7 * no._base(kind, dense, no._UNROLL[kind]).n_instructions())


def _ss(a, b, c, d):
    import control as ct

    return ct.ss(a, b.reshape(-1, 1), c.reshape(1, -1), [[d]], True)


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
        design = design_pair(fleet, "UAV1", "UAV2", NormOptimal(n=n))
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
