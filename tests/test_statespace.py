"""Trials of discrete state-space systems in compiled code (ilcdob/statespace.py) against the plain
recursion, and the assembled flight (validation/simulate.py) against the controller object stepped.

The reference everywhere is the recursion ``x[k+1] = A x[k] + B u[k]``, ``y[k] = C x[k] + D u[k]``
stepped sample by sample (:func:`_recursion`, what python-control's ``forced_response`` computes),
or the plant and :class:`ilcdob.controller.OuterLoopController` stepped sample by sample. Agreement
is measured relative to each signal's peak; the bound 1e-12 is the requirement (measured: 1e-15 to
9e-14 for the maps, up to 4.4e-13 for the DOB estimate of a flight, a small difference of large
signals whose own rounding in the stepped loop is that large).

Hard loops (tests/test_conditioning.py): relative degree 2 and UAV1's plant with a 43.7 ms input
delay, ``q_order`` 8, at 1 ms and 5 ms: the Q filter's 8-fold pole and M's sit ~Ts/tau from z = 1, the
PID's slow pole at 0.99989, and two delay lines of 44 states (109 states). The kernel runs the recursion
in all blocks of the trial at once from block starts given by powers of A, copying the delay lines'
states; the refinement makes the blocks' ends meet the next starts (module docstring of
ilcdob/statespace.py). Synthetic cases check what the loops do not isolate: a delay line in a scrambled
state order, a cluster of eight equal poles with slow modes near z = 1 over 1e5 samples, a model's own
step that differs from its matrices.
"""

from __future__ import annotations

import copy

import control as ct
import numpy as np
import pytest

import ilcdob
from ilcdob.controller import OuterLoopController
from ilcdob.design import simulate_map
from ilcdob.design.maps.closed_form import one_minus
from ilcdob.errors import SignalError, SpecError
from ilcdob.fleet import fleet_from_dict
from ilcdob import statespace
from ilcdob.statespace import simulate
from ilcdob.validation.simulate import simulate_flight

RTOL = 1e-12
FLEET = ilcdob.default_fleet()
HARD = {
    "a8": {"plant": {"num": [0.8, 8.0], "den": [1.0, 4.0, 0.0, 0.0]},
           "controller": {"kp": 2.0, "ki": 0.2, "kd": 2.0, "derivative_filter": 0.05, "acceleration_feedforward": True},
           "dob": {"q_order": 8, "q_time_constant": 0.15}},
    "b8": {"plant": {"num": [10.37568301], "den": [1.0, 10.32326473, 0.0, 0.0]}, "delay": 0.0437,
           "controller": {"kp": 3.0, "ki": 0.3, "kd": 2.42, "derivative_filter": 0.05,
                          "acceleration_feedforward": True},
           "dob": {"q_order": 8, "q_time_constant": 0.15}},
}


def _hard(ts: float) -> ilcdob.Fleet:
    return fleet_from_dict({"sample_time": ts, "system": [{"name": k, **copy.deepcopy(v)} for k, v in HARD.items()]})


HARD_1MS, HARD_5MS = _hard(0.001), _hard(0.005)


def _recursion(a, b, c, d, u, x0=None) -> np.ndarray:
    a, b, c, d = (np.atleast_2d(np.asarray(m, float)) for m in (a, b, c, d))
    u = np.atleast_2d(u)
    x = np.zeros(a.shape[0]) if x0 is None else np.asarray(x0, float)
    y = np.empty((c.shape[0], u.shape[1]))
    for k in range(u.shape[1]):
        y[:, k] = c @ x + d @ u[:, k]
        x = a @ x + b @ u[:, k]
    return y


def _worst(got: np.ndarray, want: np.ndarray) -> float:
    """Largest difference of each row relative to that row's peak."""
    got, want = np.atleast_2d(got), np.atleast_2d(want)
    peak = np.max(np.abs(want), axis=1)
    return float(np.max(np.max(np.abs(got - want), axis=1) / np.where(peak > 0, peak, 1.0)))


def _inputs(n: int, ts: float, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * ts
    return {"noise": rng.standard_normal(n), "step": np.ones(n), "sine": np.sin(2 * np.pi * 0.3 * t)}


def test_maps_of_the_built_in_fleet_are_the_recursion():
    for lp in FLEET.loops:
        for name, sys_ in (("G_d", lp.G_d), ("G_f", lp.G_f), ("G_r", lp.G_r), ("Omega", lp.Omega),
                           ("G_d_no_dob", lp.G_d_no_dob), ("1 - Q", one_minus(lp.Q))):
            for kind, u in _inputs(3000, lp.ts).items():
                want = _recursion(sys_.A, sys_.B, sys_.C, sys_.D, u)[0]
                assert _worst(simulate_map(sys_, u), want) <= RTOL, (lp.name, name, kind)
    # and simulate_map is python-control's forced response, as it was computed before
    u = _inputs(3000, FLEET.sample_time)["noise"]
    old = np.asarray(ct.forced_response(FLEET.loops[0].G_f, U=u).outputs, float).ravel()
    assert _worst(simulate_map(FLEET.loops[0].G_f, u), old) <= RTOL


@pytest.mark.parametrize("fleet, name, which", [(HARD_1MS, "a8", "G_d"), (HARD_1MS, "a8", "G_f"),
                                                (HARD_1MS, "a8", "1-Q"), (HARD_5MS, "b8", "G_d"),
                                                (HARD_5MS, "b8", "G_f")])
def test_maps_of_hard_loops_are_the_recursion(fleet, name, which):
    lp = fleet.loop(name)
    sys_ = one_minus(lp.Q) if which == "1-Q" else getattr(lp, which)
    for kind, u in _inputs(20000, lp.ts).items():
        want = _recursion(sys_.A, sys_.B, sys_.C, sys_.D, u)[0]
        assert _worst(simulate_map(sys_, u), want) <= RTOL, kind


def test_long_trials_carry_the_state_exactly_across_chunks(monkeypatch):
    # 1e5 samples at 1 ms in 25 chunks of 4096; a state rounded at each chunk's start drifted to 1e-11 (step
    # input into the slow modes); the DC gain of the 0.99989 pole keeps an error from fading
    monkeypatch.setattr(statespace, "CHUNK_ENTRIES", 1 << 13)
    sys_ = HARD_1MS.loop("a8").G_f
    u = np.ones(100_000)
    u[50_000:] = -0.5
    assert _worst(simulate_map(sys_, u), _recursion(sys_.A, sys_.B, sys_.C, sys_.D, u)[0]) <= RTOL


@pytest.fixture
def runs(monkeypatch):
    """The runs of the block recursion, counted (one per chunk when the block starts from the matrix powers
    are right: the refinement then applies its correction in closed form); the per-sample loop, the last
    resort, must not run."""
    count: list[int] = []
    run = statespace._Blocks.run

    def counted(self, *args):
        count.append(1)
        return run(self, *args)

    def no_fallback(*args):
        raise AssertionError("the block recursion did not settle: the per-sample loop ran")

    monkeypatch.setattr(statespace._Blocks, "run", counted)
    monkeypatch.setattr(statespace, "_plain", no_fallback)
    return count


def _delay_loop(seed: int, line: int = 30):
    """A 4-state core closed through a delay line of ``line`` states (``x_i[k + 1] = x_(i-1)[k]``), the states
    in a scrambled order; two inputs, two outputs, the second reading the middle of the line."""
    rng = np.random.default_rng(seed)
    core, n = 4, 4 + line
    a, b, c, d = np.zeros((n, n)), np.zeros((n, 2)), np.zeros((2, n)), rng.standard_normal((2, 2))
    a[:core, :core] = 0.9 * np.linalg.qr(rng.standard_normal((core, core)))[0]
    a[:core, n - 1] = 0.05 * rng.standard_normal(core)  # the line's end drives the core
    a[core, :core] = rng.standard_normal(core)  # the line's start: the core and the second input
    b[:core, 0], b[core, 1] = rng.standard_normal(core), 1.0
    for i in range(core + 1, n):
        a[i, i - 1] = 1.0
    c[0, :core], c[1, core + line // 2] = rng.standard_normal(core), 1.0
    perm = rng.permutation(n)
    return a[perm][:, perm], b[perm], c[:, perm], d, rng


def test_delay_lines_are_copied_not_multiplied(runs):
    a, b, c, d, rng = _delay_loop(4)
    form = statespace._blocks(a, b, c, d, 64)
    # 29 states copy another; the product multiplies the 2 inputs, the 5 other states and the 2 copied
    # states that the others or the outputs read (the line's end and middle), not all 34
    assert form.g == 5 and form.k == 2 + 5 + 2
    u, x0 = rng.standard_normal((2, 20_000)), rng.standard_normal(a.shape[0])
    assert _worst(simulate(a, b, c, d, u, x0), _recursion(a, b, c, d, u, x0)) <= RTOL
    # the same system with its states in the reverse order, as a check of where each copy comes from
    flip = np.arange(a.shape[0])[::-1]
    af, bf, cf = a[flip][:, flip], b[flip], c[:, flip]
    assert _worst(simulate(af, bf, cf, d, u, x0[flip]), _recursion(a, b, c, d, u, x0)) <= RTOL
    assert len(runs) == 2  # one run of the recursion each


def _cluster_system(seed: int):
    """An 8-fold pole at 0.993 (a Q filter's cascade of first-order lags), driving a slow pole at 0.99989
    and a lightly damped pair at radius 0.9995, in a dense random basis (11 states)."""
    rng = np.random.default_rng(seed)
    t = np.zeros((11, 11))
    for i in range(8):
        t[i, i] = 0.993
        if i:
            t[i, i - 1] = 0.007
    t[8, 8], t[8, 7], t[9, 8] = 0.99989, 1.1e-4, 0.01
    t[9:, 9:] = 0.9995 * np.array([[np.cos(0.003), -np.sin(0.003)], [np.sin(0.003), np.cos(0.003)]])
    q = np.linalg.qr(rng.standard_normal((11, 11)))[0]
    return q @ t @ q.T, q[:, :1].copy(), rng.standard_normal((1, 11)) @ q.T, np.array([[0.5]]), rng


def test_repeated_poles_and_slow_modes_over_a_long_trial(runs):
    a, b, c, d, rng = _cluster_system(7)
    n = 100_000
    u = np.where(np.arange(n) < n // 2, 1.0, -0.5) + 0.1 * rng.standard_normal(n)
    x0 = rng.standard_normal(11)
    assert _worst(simulate(a, b, c, d, u, x0), _recursion(a, b, c, d, u, x0)) <= RTOL
    assert len(runs) == 1
    # a model whose own step differs from the matrices by 1e-9 (as an interconnection's rounded products
    # do, more): the result is the model's recursion, which the matrices' misses by far more than 1e-12
    a_model = a * (1.0 + 1e-9 * rng.standard_normal(a.shape))

    def step(x, w):
        return a_model @ x + b @ w, c @ x + d @ w

    want = _recursion(a_model, b, c, d, u[:20_000], x0)
    assert _worst(_recursion(a, b, c, d, u[:20_000], x0), want) > 100 * RTOL
    assert _worst(simulate(a, b, c, d, u[:20_000], x0, evaluate=step), want) <= RTOL
    # the correction after the first run (block starts from the matrices) exceeds REFINE_RTOL of the states
    # there: the recursion runs once more from the corrected starts
    assert len(runs) == 1 + 2


def test_the_model_step_runs_for_all_blocks_at_once(runs):
    # b8 at 2 ms: 65 states, two delay lines of 22; 1e5 samples; the step is called for all blocks at
    # once: L calls (L < sqrt(N)), the i-th with samples i, L + i, 2 L + i, ... (one per block), not with
    # runs of consecutive samples
    sys_ = _hard(0.002).loop("b8").G_f
    a, b, c, d = (np.asarray(m, float) for m in (sys_.A, sys_.B, sys_.C, sys_.D))
    assert a.shape == (65, 65)
    u = _inputs(100_000, 0.002, 3)["noise"]
    calls = []

    def step(x, w):
        calls.append(np.array(w[0]))
        return a @ x + b @ w, c @ x + d @ w

    want = _recursion(a, b, c, d, u)
    assert _worst(simulate(a, b, c, d, u), want) <= RTOL
    assert _worst(simulate(a, b, c, d, u, evaluate=step), want) <= RTOL
    span = len(calls)
    assert len(runs) == 2 and 1 < span <= np.sqrt(u.size)
    np.testing.assert_array_equal(calls[0], u[::span])
    np.testing.assert_array_equal(calls[-1][:-1], u[span - 1::span][:calls[-1].size - 1])


def test_large_systems_with_delay_lines():
    sys_ = HARD_1MS.loop("b8").G_d  # 109 states: two delay lines of 44
    assert sys_.nstates == 109
    u = _inputs(3000, 0.001)["noise"]
    assert _worst(simulate_map(sys_, u), _recursion(sys_.A, sys_.B, sys_.C, sys_.D, u)[0]) <= RTOL


def test_initial_state_several_inputs_and_outputs():
    # a stable 6-state system with two complex pairs (2 x 2 Schur blocks), 3 inputs, 2 outputs, from a
    # nonzero state, over 3 chunks
    rng = np.random.default_rng(3)
    blocks = [np.array([[0.95, 0.2], [-0.2, 0.95]]), np.array([[0.3, -0.8], [0.8, 0.3]]), np.diag([0.999, -0.7])]
    t = np.zeros((6, 6))
    for i, blk in enumerate(blocks):
        t[2 * i:2 * i + 2, 2 * i:2 * i + 2] = blk
    q = np.linalg.qr(rng.standard_normal((6, 6)))[0]
    a = q @ (t + np.triu(rng.standard_normal((6, 6)) * 0.1, 2)) @ q.T
    b, c, d = rng.standard_normal((6, 3)), rng.standard_normal((2, 6)), rng.standard_normal((2, 3))
    u, x0 = rng.standard_normal((3, 30_000)), rng.standard_normal(6)
    assert _worst(simulate(a, b, c, d, u, x0), _recursion(a, b, c, d, u, x0)) <= RTOL


def test_edge_sizes():
    a, b, c, d = [[0.5]], [[1.0]], [[1.0]], [[2.0]]
    assert simulate(a, b, c, d, np.zeros((1, 0))).shape == (1, 0)
    np.testing.assert_array_equal(simulate(a, b, c, d, [3.0]), [[6.0]])
    np.testing.assert_array_equal(simulate(a, b, c, d, [3.0], x0=[1.0]), [[7.0]])
    # no states: a static gain
    np.testing.assert_array_equal(simulate(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[2.0]], [1.0, -1.0]),
                                  [[2.0, -2.0]])


def test_bad_input_is_named():
    a, b, c, d = [[0.5]], [[1.0]], [[1.0]], [[0.0]]
    with pytest.raises(SpecError, match="`a`: got shape \\(1, 2\\)"):
        simulate([[0.5, 0.1]], b, c, d, [1.0])
    with pytest.raises(SpecError, match="`b`: got shape"):
        simulate(a, b, c, d, np.ones((2, 3)))  # two inputs, B has one column
    with pytest.raises(SpecError, match="`c`: got shape"):
        simulate(a, b, [[1.0, 2.0]], d, [1.0])
    with pytest.raises(SpecError, match="`a`: has non-finite"):
        simulate([[np.nan]], b, c, d, [1.0])
    with pytest.raises(SignalError, match="`u`: non-finite value inf at sample 2 of input 0"):
        simulate(a, b, c, d, [1.0, 0.0, np.inf])
    with pytest.raises(SignalError, match="`x0`"):
        simulate(a, b, c, d, [1.0], x0=[1.0, 2.0])
    with pytest.raises(SpecError, match="`evaluate`"):
        simulate(a, b, c, d, [1.0], evaluate="step")
    lp = FLEET.loops[0]
    with pytest.raises(SpecError, match="`sys`: got a system with 3 input"):
        simulate_map(lp.closed_loop, np.ones(4))
    with pytest.raises(SignalError, match="`u`: non-finite"):
        simulate_map(lp.G_f, [0.0, np.nan])
    with pytest.raises(SpecError, match="`stepped`"):
        simulate_flight(lp, np.zeros(4), np.zeros(4), stepped="yes")


def _law_inputs(n: int, dob: bool, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    v = np.cumsum(rng.standard_normal((4, n)), axis=1) * np.array([[0.1], [0.1], [0.01], [0.01]])
    if not dob:
        v[3] = 0.0
    return v


@pytest.mark.parametrize("lp", [FLEET.loop("UAV1"), HARD_1MS.loop("a8")], ids=["UAV1", "a8@1ms"])
@pytest.mark.parametrize("dob", [True, False])
def test_the_law_in_matrices_is_the_controller_stepping(lp, dob):
    n = 4000
    v = _law_inputs(n, dob, 5)
    ctl = OuterLoopController(lp, dob=dob)
    stepped = np.zeros((2, n))
    for k in range(n):
        stepped[0, k] = ctl.step(v[0, k], v[1, k], feedforward=v[2, k], learning=v[3, k])
        stepped[1, k] = ctl.d_hat
    law = OuterLoopController(lp, dob=dob).state_space()
    assert law.inputs == ("r", "y_m", "a_ff", "d_f") and law.outputs == ("u2", "d_hat") and law.dob is dob
    # the matrices (their entries are rounded products of the blocks'), and the law's own step
    assert _worst(_recursion(law.a, law.b, law.c, law.d, v), stepped) <= 1e-10
    assert _worst(simulate(law.a, law.b, law.c, law.d, v, evaluate=law.evaluate), stepped) <= RTOL
    if not dob:
        assert not np.any(law.c[1]) and not np.any(law.d[1]) and not np.any(law.d[:, 3])


def _flights(lp, n: int, seed: int):
    # a white disturbance: the DOB estimate is then small beside M{y_m} and Q{u2}, its difference, and
    # shows their rounding most (the matrices' products alone, without the law's own step: up to 1e-12)
    rng = np.random.default_rng(seed)
    t = np.arange(n) * lp.ts
    r = np.sin(0.5 * t)
    common = {"a_ref": -0.25 * np.sin(0.5 * t), "sensor_noise": 1e-3 * rng.standard_normal(n)}
    d = 0.3 * rng.standard_normal(n)
    for mode, df in (("dob", 0.1 * np.cos(2.0 * t)), ("no_dob", None)):
        yield mode, (simulate_flight(lp, r, d, d_f=df, mode=mode, **common),
                     simulate_flight(lp, r, d, d_f=df, mode=mode, stepped=True, **common))


@pytest.mark.parametrize("lp, n", [(FLEET.loop("UAV1"), 3000), (FLEET.loop("UAV2"), 3000), (FLEET.loop("UAV3"), 3000),
                                   (HARD_1MS.loop("a8"), 20000), (HARD_1MS.loop("b8"), 4000)],
                         ids=["UAV1", "UAV2", "UAV3", "a8@1ms", "b8@1ms"])
def test_flight_is_the_controller_stepped(lp, n):
    # both modes, with sensor noise, acceleration feed-forward (on in every one of these controllers) and
    # a learning signal; the assembled loop against the plant and the controller object stepped
    assert lp.spec.controller.acceleration_feedforward
    for mode, (new, old) in _flights(lp, n, 11):
        assert new.system == old.system and new.mode == old.mode == mode
        np.testing.assert_array_equal(new.t, old.t)
        for sig in ("y", "e", "u2", "y_meas", "e_meas", "d_hat"):
            got, want = getattr(new, sig), getattr(old, sig)
            assert got.shape == want.shape == (n,), sig
            if mode == "no_dob" and sig == "d_hat":
                assert not np.any(got) and not np.any(want)
                continue
            assert _worst(got, want) <= RTOL, (mode, sig, _worst(got, want))
        for sig in ("r", "d", "d_f"):
            np.testing.assert_array_equal(getattr(new, sig), getattr(old, sig))
