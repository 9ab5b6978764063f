"""Closed-form learning filters (the Theorem, Case I) and their lifted form."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ilcdob import PlantSpec, build_loop, freqresp
from ilcdob.design import closed_form_filters, lifted_filters
from ilcdob.validation.simulate import rmse, simulate_flight

W = np.logspace(-1.5, np.log10(150), 50)


def _hover_case(src, tgt, n=3000):
    t = np.arange(n) * src.ts
    d = np.sin(0.9425 * t) + 0.3 * np.sin(3.1 * t)
    r = np.zeros(n)
    f_src = simulate_flight(src, r, d)
    f_tgt = simulate_flight(tgt, r, d)
    return r, d, f_src, f_tgt


def test_l1_l2_equal_the_theorem_from_the_closed_loop_maps(fleet):
    a, b = fleet.loops[0], fleet.loops[2]
    lf = closed_form_filters(a, b)
    gd_j, gf_j, gd_p, gf_p = (freqresp(s, W) for s in (b.G_d, b.G_f, a.G_d, a.G_f))
    l1 = gd_j / (gf_j * gd_p)  # (Gf_j Gd_{j-1})^{-1} Gd_j
    np.testing.assert_allclose(lf.l1_response(W), l1, rtol=1e-5)
    np.testing.assert_allclose(lf.l2_response(W), l1 * gf_p, rtol=1e-5)


@pytest.mark.parametrize("pair", [(0, 1), (1, 2), (2, 0), (0, 2)])
def test_case_one_exact_models_cancel_the_disturbance(fleet, pair):
    src, tgt = (fleet.loops[i] for i in pair)
    r, d, f_src, f_tgt = _hover_case(src, tgt)
    df = closed_form_filters(src, tgt).apply(f_src.e, f_src.d_f)
    learned = simulate_flight(tgt, r, d, d_f=df)
    # Case I: e_j = 0 up to trial-boundary effects; the paper reports convergence in 1 iteration
    assert rmse(learned.e) < 1e-6 * rmse(f_tgt.e)


def test_learning_from_a_learning_flight_uses_l2(fleet):
    a, b, c = fleet.loops
    r, d, f_a, _ = _hover_case(a, b)
    df_b = closed_form_filters(a, b).apply(f_a.e, f_a.d_f)
    f_b = simulate_flight(b, r, d, d_f=df_b)
    df_c = closed_form_filters(b, c).apply(f_b.e, f_b.d_f)
    f_c = simulate_flight(c, r, d, d_f=df_c)
    no_learning = simulate_flight(c, r, d)
    assert rmse(f_c.e) < 1e-6 * rmse(no_learning.e)
    # without the L2 term (treating B's error as if it flew no learning signal) it fails
    wrong = closed_form_filters(b, c).apply(f_b.e, np.zeros_like(f_b.e))
    assert rmse(simulate_flight(c, r, d, d_f=wrong).e) > 0.5 * rmse(no_learning.e)


@pytest.mark.parametrize("delay", [0.0, 0.04, 0.03])
def test_non_minimum_phase_and_delayed_plants_are_inverted_stably(fleet, delay):
    spec = fleet.systems[0]
    plant = PlantSpec(spec.plant.num, spec.plant.den, delay)
    src = build_loop(replace(spec, plant=plant, name="delayed"), 0.02)
    tgt = fleet.loops[1]
    assert np.any(np.abs(src.P.zeros()) > 1)  # ZOH sampling zero: NMP discrete plant
    lf = closed_form_filters(src, tgt)
    assert lf.L1.anticausal_poles.size >= 1
    r, d, f_src, f_tgt = _hover_case(src, tgt)
    df = lf.apply(f_src.e, f_src.d_f)
    assert np.max(np.abs(df)) < 5.0  # bounded: no blow-up from the unstable inverse
    learned = simulate_flight(tgt, r, d, d_f=df)
    # limited by the last few samples, where the advance of the inverse needs the error
    # beyond the trial (continued by extrapolation)
    assert rmse(learned.e) < 1e-4 * rmse(f_tgt.e)


def test_naive_causal_inverse_would_blow_up(fleet):
    # the reason for stable inversion: the same zeros/poles run causally diverge
    from scipy import signal

    src, tgt = fleet.loops[0], fleet.loops[1]
    lf = closed_form_filters(src, tgt)
    _, _, f_src, _ = _hover_case(src, tgt, 300)  # 3.55^300 ~ 1e165 stays finite
    k = len(lf.L1.zeros) - len(lf.L1.poles)
    sos = signal.zpk2sos(lf.L1.zeros, np.concatenate([lf.L1.poles, np.zeros(k)]), lf.L1.gain)
    naive = signal.sosfilt(sos, f_src.e)
    assert np.max(np.abs(naive)) > 1e100
    assert np.max(np.abs(lf.apply(f_src.e, f_src.d_f))) < 5.0


def test_lifted_form_matches_closed_form_and_reports_conditioning(fleet):
    a, b = fleet.loops[0], fleet.loops[1]
    n = 750
    r, d, f_a, f_b = _hover_case(a, b, n)
    lifted = lifted_filters(a, b, n)
    assert lifted.shift == 1
    assert lifted.condition_number > 1e8  # NMP + double zero at DC: badly conditioned
    assert np.isfinite(lifted.regularised_condition) and lifted.regularised_condition < 1e13
    df_lift = lifted.apply(f_a.e, f_a.d_f)
    e_lift = simulate_flight(b, r, d, d_f=df_lift).e
    e_cf = simulate_flight(b, r, d, d_f=closed_form_filters(a, b).apply(f_a.e, f_a.d_f)).e
    assert rmse(e_lift) < 1e-4 * rmse(f_b.e)
    assert rmse(e_cf) < 1e-4 * rmse(f_b.e)
    # L2 in lifted form: a learning signal flown by A is accounted for
    df_a = 0.2 * np.sin(np.arange(n) * 0.02 * 1.7)
    f_a2 = simulate_flight(a, r, d, d_f=df_a)
    e2 = simulate_flight(b, r, d, d_f=lifted.apply(f_a2.e, f_a2.d_f)).e
    assert rmse(e2) < 1e-4 * rmse(f_b.e)
