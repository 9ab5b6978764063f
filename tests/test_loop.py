"""The loop of one system: maps against the block formulas and the block-diagram simulation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ilcdob import DOBSpec, PIDSpec, PlantSpec, SpecError, UnstableLoopError, build_loop, freqresp
from ilcdob.design import simulate_map
from ilcdob.validation.simulate import simulate_flight

W = np.logspace(-2, np.log10(150), 60)


@pytest.mark.parametrize("i", [0, 1, 2])
def test_maps_match_block_formulas(fleet, i):
    lp = fleet.loops[i]
    p, c, q, m = (freqresp(s, W) for s in (lp.P, lp.C, lp.Q, lp.M))
    d = 1 - q + p * (m + c)  # docs/theory.md section 1
    for got, want in [(lp.G_r, p * c / d), (lp.G_d, p * (1 - q) / d), (lp.G_f, -p / d),
                      (lp.Omega, (m + q * c) * p / d), (lp.G_d_no_dob, p / (1 + p * c)),
                      (lp.G_r_no_dob, p * c / (1 + p * c))]:
        np.testing.assert_allclose(freqresp(got, W), want, rtol=1e-6)


def test_maps_match_block_diagram_simulation(fleet):
    lp = fleet.loops[2]
    rng = np.random.default_rng(4)
    n = 1500
    t = np.arange(n) * lp.ts
    r = np.sin(0.4 * t) + 0.2 * rng.standard_normal(n)
    d = np.cos(1.3 * t) + 0.3 * rng.standard_normal(n)
    df = 0.5 * np.sin(2.1 * t)
    fl = simulate_flight(lp, r, d, d_f=df)
    y_maps = simulate_map(lp.G_r, r) + simulate_map(lp.G_d, d) + simulate_map(lp.G_f, df)
    dhat_maps = (simulate_map(lp.closed_loop[2, 0], r) + simulate_map(lp.Omega, d)
                 + simulate_map(lp.closed_loop[2, 2], df))
    scale = np.max(np.abs(fl.y))
    np.testing.assert_allclose(fl.y, y_maps, atol=1e-9 * scale)
    np.testing.assert_allclose(fl.d_hat, dhat_maps, atol=1e-8 * np.max(np.abs(fl.d_hat)))
    plain = simulate_flight(lp, r, d, mode="no_dob")
    y_plain = simulate_map(lp.G_r_no_dob, r) + simulate_map(lp.G_d_no_dob, d)
    np.testing.assert_allclose(plain.y, y_plain, atol=1e-9 * np.max(np.abs(plain.y)))


def test_acceleration_feedforward_enters_like_minus_learning_signal(fleet):
    lp = fleet.loops[0]
    t = np.arange(800) * lp.ts
    r, a = np.sin(0.5 * t), -0.25 * np.sin(0.5 * t)
    with_ff = simulate_flight(lp, r, np.zeros_like(t), a_ref=a)
    as_df = simulate_flight(lp, r, np.zeros_like(t), d_f=-a)
    np.testing.assert_allclose(with_ff.y, as_df.y, atol=1e-12)


def test_unstable_loop_is_a_clear_error(fleet):
    spec = replace(fleet.systems[0], controller=PIDSpec(300.0, 0.3, 0.1, 0.05))
    with pytest.raises(UnstableLoopError) as info:
        build_loop(spec, 0.02)
    msg = str(info.value)
    assert "'UAV1'" in msg and "|z|=" in msg


@pytest.mark.filterwarnings("ignore::RuntimeWarning", "ignore::scipy.signal.BadCoefficients")
@pytest.mark.parametrize("plant, controller", [
    # the plant's zero-order hold overflows: a pole at s = +1e5 rad/s grows by e^2000 in one sample
    (PlantSpec([1.0], [1.0, -1e5, 0.0, 0.0]), None),
    # huge plant gain and kp: the interconnection's products (1e100 * 1e100 * 1e100) overflow, or, with some
    # SciPy versions, already the plant's zero-order hold
    (PlantSpec([1e100], [0.1, 1.0, 0.0, 0.0]), PIDSpec(1e100, 0.3, 2.4, 0.05)),
    # huge gains with a normal plant: every block discretises, the interconnection's products overflow
    (None, PIDSpec(1e308, 1e308, 1e308, 0.05)),
])
def test_overflowing_loop_is_a_spec_error_naming_the_system(fleet, plant, controller):
    # whichever step overflows first (a block's discretisation or the interconnection), the SpecError
    # names the system and says the numbers overflowed
    spec = fleet.systems[0]
    spec = replace(spec, plant=plant or spec.plant, model=None, controller=controller or spec.controller)
    with pytest.raises(SpecError) as info:
        build_loop(spec, 0.02)
    msg = str(info.value)
    assert msg.startswith("system 'UAV1': ") and "non-finite" in msg and "overflow" in msg


@pytest.mark.parametrize("tau", [1e300, 1e-300])
def test_q_time_constant_out_of_range_is_a_spec_error_naming_the_system(fleet, tau):
    # Q's matrices hold (Ts/tau)^k / k! and M's gain 1/tau^q_order: these overflowed (OverflowError, an
    # internal error) instead of being refused as the input they come from
    with pytest.raises(SpecError) as info:
        build_loop(replace(fleet.systems[0], dob=DOBSpec(3, tau)), 0.02)
    msg = str(info.value)
    assert msg.startswith("system 'UAV1': `dob.q_time_constant`: got ") and "2e-08 to 20000 s" in msg


def test_closed_loop_delta_form_matches_the_loop(fleet):
    # A - I of the interconnection, assembled from the blocks' delta forms, is the loop's A - I (to rounding)
    for lp in fleet.loops:
        n = lp.closed_loop.nstates
        np.testing.assert_allclose(lp.closed_loop_a_minus_i + np.eye(n), lp.closed_loop.A, rtol=0, atol=1e-15)
        np.testing.assert_allclose(np.sort_complex(lp.poles()), np.sort_complex(np.linalg.eigvals(lp.closed_loop.A)),
                                   rtol=0, atol=1e-9)


def test_shared_delay_line_gives_exact_poles_at_zero(fleet):
    # plant and Q branch both delayed by 0.0437 s at 5 ms (8 samples + a fraction: 9 states each): the
    # difference of the two lines contributes 9 poles at z = 0 exactly; the rest are the loop's other poles
    spec = replace(fleet.systems[0], plant=PlantSpec(fleet.systems[0].plant.num, fleet.systems[0].plant.den, 0.0437))
    lp = build_loop(spec, 0.005)
    assert lp.blocks["P"].delay_states == lp.blocks["Q"].delay_states == 9
    poles = lp.poles()
    assert poles.size == lp.closed_loop.nstates and np.sum(poles == 0) == 9
    full = np.linalg.eigvals(lp.closed_loop_a_minus_i) + 1
    big = np.sort_complex(full[np.abs(full) > 0.2])
    # (to 2e-8: the near-double pole of Q and M at 0.967 is that sensitive to rounding, ~sqrt(eps))
    np.testing.assert_allclose(big, np.sort_complex(poles[np.abs(poles) > 0.2]), rtol=0, atol=1e-7)


@pytest.mark.parametrize("ts, q_order", [(0.005, 8), (0.001, 6), (0.001, 8)])
def test_fast_sampling_high_order_is_not_a_false_alarm(fleet, ts, q_order):
    # reported as unstable with |z| = 1.0005-1.02 when Q and M were realised from polynomials; the
    # exact largest pole (120-digit characteristic polynomial) is the PID's slow pole
    exact = {0.005: 0.99943828, 0.001: 0.99988762}
    spec = replace(fleet.systems[0], dob=DOBSpec(q_order, 0.15))
    lp = build_loop(spec, ts)
    assert abs(np.max(np.abs(lp.poles())) - exact[ts]) < 1e-4
    # the 2 q_order poles of Q and M sit about Ts/tau inside the circle
    h = ts / 0.15
    near = lp.poles()[np.abs(lp.poles() - np.exp(-h)) < 0.5 * h]
    assert near.size >= q_order and np.all(np.abs(near) < 1 - 0.5 * h)


def test_unstable_loop_is_still_caught_at_fast_sampling(fleet):
    spec = replace(fleet.systems[0], controller=PIDSpec(300.0, 0.3, 0.1, 0.05), dob=DOBSpec(8, 0.15))
    with pytest.raises(UnstableLoopError, match="'UAV1'.*\\|z\\|="):
        build_loop(spec, 0.001)
