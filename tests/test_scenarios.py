"""The scenarios' references: the x reference as flown, and the 3-D paths of the module docstring."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ilcdob.errors import SpecError
from ilcdob.validation.scenarios import (ALTITUDE, CIRCLE_PERIOD, CIRCLE_RADIUS, CIRCLE_SPINUP, DIAMOND_EDGE_TIME,
                                         DIAMOND_HOLD, SCENARIOS, check_order, scenario)

#: Sample grid kept 3.7 ms away from every kink of the paths (spin-up end at 6 s, diamond
#: vertices at 2 + 5 k s), where the jerk jumps and a second difference straddling it is off.
T = 0.0037 + np.arange(0, 6000) * 0.01


@pytest.mark.parametrize("sid", sorted(SCENARIOS))
def test_x_column_is_the_x_reference(sid):
    sc = scenario(sid)
    pos, acc = sc.trajectory(T)
    assert pos.shape == acc.shape == (T.size, 3)
    np.testing.assert_allclose(pos[:, 0], sc.reference(T), rtol=0, atol=1e-12)
    np.testing.assert_allclose(acc[:, 0], sc.acceleration(T), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(pos[:, 2], ALTITUDE)  # 2.5 m, level flight
    np.testing.assert_array_equal(acc[:, 2], 0.0)


def test_hover_is_at_the_hover_point():
    pos, acc = scenario(1).trajectory(T)
    np.testing.assert_array_equal(pos, np.tile([0.0, 0.0, 2.5], (T.size, 1)))
    np.testing.assert_array_equal(acc, 0.0)


@pytest.mark.parametrize("sid", [2, 3])
def test_circle_has_radius_1_m_about_0_1_and_starts_at_rest_at_the_origin(sid):
    pos, acc = scenario(sid).trajectory(T)
    # every point, spin-up included, lies on the circle of radius 1 m about (0, 1 m)
    radius = np.hypot(pos[:, 0], pos[:, 1] - CIRCLE_RADIUS)
    np.testing.assert_allclose(radius, 1.0, rtol=0, atol=1e-12)
    start, _ = scenario(sid).trajectory(np.array([0.0, 1e-3]))
    np.testing.assert_allclose(start[0], [0.0, 0.0, 2.5], atol=1e-15)
    assert np.hypot(*(start[1, :2] - start[0, :2])) / 1e-3 < 1e-6  # at rest: speed ~ t^2
    # after the spin-up: uniform motion, centripetal acceleration R w^2 = 0.274 m/s^2 towards the centre
    after = T > CIRCLE_SPINUP
    w = 2 * np.pi / CIRCLE_PERIOD
    np.testing.assert_allclose(np.hypot(acc[after, 0], acc[after, 1]), CIRCLE_RADIUS * w**2, rtol=1e-12)
    towards = np.column_stack([-pos[after, 0], CIRCLE_RADIUS - pos[after, 1]])
    np.testing.assert_allclose(acc[after, :2], w**2 * towards, atol=1e-12)


def test_diamond_passes_through_its_vertices_at_the_edge_times():
    sc = scenario(4)
    vertices = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])  # module docstring
    k = np.arange(12)
    edge_times = DIAMOND_HOLD + k * DIAMOND_EDGE_TIME  # 2, 7, ..., 57 s
    pos, acc = sc.trajectory(edge_times)
    np.testing.assert_allclose(pos[:, :2], vertices[k % 4], atol=1e-12)
    np.testing.assert_allclose(acc[:, :2], 0.0, atol=1e-12)  # minimum jerk: stops at every vertex
    hold, _ = sc.trajectory(np.linspace(0, DIAMOND_HOLD, 9))
    np.testing.assert_allclose(hold[:, :2], np.tile([0.0, -1.0], (9, 1)), atol=1e-15)
    # between vertices the path is the straight edge: |x| + |y| = 1 m
    np.testing.assert_allclose(np.abs(sc.trajectory(T)[0][:, :2]).sum(axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("sid", sorted(SCENARIOS))
def test_acceleration_is_the_second_derivative_of_the_position(sid):
    # central second difference, h = 1 ms: truncation h^2/12 max|p''''| < 1e-7 m/s^2 on these
    # paths (|p''''| up to about 0.23 m/s^4 in the circle's spin-up, 360/5^4 = 0.58 on the
    # diamond; measured 1.9e-8 and 5.3e-8), round-off 4 eps 2.5 m / h^2 < 3e-9; 1e-6 m/s^2
    # against accelerations of 0.23-0.27 m/s^2
    sc = scenario(sid)
    t = T[T < sc.duration]
    h = 1e-3
    p_minus, p0, p_plus = (sc.trajectory(t + d)[0] for d in (-h, 0.0, h))
    numeric = (p_plus - 2 * p0 + p_minus) / h**2
    np.testing.assert_allclose(sc.trajectory(t)[1], numeric, rtol=0, atol=1e-6)


def test_a_replaced_x_reference_keeps_x_and_y_apart():
    # trajectory's x is always the scenario's reference: a shortened copy flies the same path
    sc = dataclasses.replace(scenario(4), duration=10.0)
    np.testing.assert_array_equal(sc.trajectory(T)[0], scenario(4).trajectory(T)[0])
    flat = dataclasses.replace(scenario(2), lateral=None)
    np.testing.assert_array_equal(flat.trajectory(T)[0][:, 1], 0.0)


def test_check_order_keeps_a_valid_order_and_names_what_is_wrong():
    names = ["UAV1", "UAV2", "UAV3"]
    assert check_order(names, ("UAV3", "UAV1")) == ["UAV3", "UAV1"]
    assert check_order(["solo"], ["solo"]) == ["solo"]  # a one-system fleet learns from itself
    with pytest.raises(SpecError, match=r"^`--order`: unknown system\(s\) 'uav1' in \['uav1', 'UAV2'\]; the fleet "
                                        r"has \['UAV1', 'UAV2', 'UAV3'\]$"):
        check_order(names, ["uav1", "UAV2"], "--order")
    with pytest.raises(SpecError, match=r"`--order`: 'UAV3', 'UAV1' given more than once"):
        check_order(names, ["UAV3", "UAV1", "UAV3", "UAV1"], "--order")
    with pytest.raises(SpecError, match=r"`order`: got \[\], expected at least two system names"):
        check_order(names, [])
    with pytest.raises(SpecError, match=r"`order`: got 3 in \['UAV1', 3\], expected system names"):
        check_order(names, ["UAV1", 3])
    with pytest.raises(SpecError, match=r"`order`: got None, expected a list of system names"):
        check_order(names, None)


def test_a_time_grid_too_long_is_refused_before_it_is_allocated():
    # 60 s at 1e-12 s: 6e13 samples (480 TB); the message names the sample time, the duration, the samples and the bound
    assert SCENARIOS[1].time(0.001).size == 60_000
    with pytest.raises(SpecError) as info:
        SCENARIOS[1].time(1e-12)
    msg = str(info.value)
    assert "scenario 1" in msg and "1e-12 s" in msg and "60 s" in msg and "6e+13 samples" in msg
    assert "5,000,000" in msg
