"""The add-on DOB and ilcdob's loop behind a setpoint (ilcdob.vehicles.dob_loop).

The vehicle here is written with scipy alone: an airframe ``1/(s (s + a) (tau s + 1))`` sampled with
scipy's zero-order hold (``scipy.linalg.expm`` of the augmented matrix), flown by a PD loop on its
sampled state as rotorpy's SE3 loop is (``a_c = a_ff + kp (r - x) + kd (v_ref - v)``), a disturbance
added to the command that the vehicle does not log. The DOB is given a wrong airframe model: the
relation the learning relies on, ``Gd = (1 - Q) Gf / K``, holds whatever the model (ilcdob.channel_loop).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg, signal as sps

from ilcdob.errors import SpecError
from ilcdob.specs import DOBSpec, PlantSpec
from ilcdob.vehicles.closed_loop import fly_closed_loop
from ilcdob.vehicles.dob_loop import AddOnDOB, PaperLoopVehicle
from ilcdob.vehicles.interface import fly_vehicle

TS = 0.01


class LinearVehicle:
    """Three decoupled axes of ``x = v``, ``v' = a_act - drag v``, ``a_act' = (a_c + d - a_act)/lag``, sampled
    with a zero-order hold; :meth:`track` flies a PD loop on the sampled state, :meth:`step` holds a command."""

    def __init__(self, drag=0.45, lag=0.08, kp=4.0, kd=3.0, disturbance=None, ts=TS):
        a = np.array([[0.0, 1.0, 0.0], [0.0, -drag, 1.0], [0.0, 0.0, -1.0 / lag]])
        b = np.array([0.0, 0.0, 1.0 / lag])
        m = linalg.expm(np.block([[a, b[:, None]], [np.zeros((1, 4))]]) * ts)
        self.phi, self.gamma = m[:3, :3], m[:3, 3]
        self.kp, self.kd, self.ts, self.disturbance = kp, kd, ts, disturbance
        self.reset()

    def channel_gain(self, channel):
        return np.full(3, {"position": self.kp, "velocity": self.kd, "acceleration": 1.0}[channel])

    def reset(self):
        self.state = np.zeros((3, 3))  # axis x (position, velocity, actuated acceleration)
        self.k = 0
        self.commanded_acceleration = np.zeros(3)

    def position(self):
        return self.state[:, 0].copy()

    def step(self, command):
        d = np.zeros(3) if self.disturbance is None else self.disturbance[self.k]
        self.state = self.state @ self.phi.T + np.outer(np.asarray(command) + d, self.gamma)
        self.k += 1
        return np.asarray(command, float)

    def track(self, position, velocity, acceleration):
        x, v = self.state[:, 0], self.state[:, 1]
        self.commanded_acceleration = acceleration + self.kp * (position - x) + self.kd * (velocity - v)
        self.step(self.commanded_acceleration)


def _q_filter(dob: DOBSpec, u: np.ndarray) -> np.ndarray:
    """``Q{u}``: scipy's zero-order hold of ``1/(tau s + 1)^n``, from rest."""
    den = np.poly(np.full(dob.q_order, -1.0 / dob.q_time_constant)) * dob.q_time_constant ** dob.q_order
    b, a, _ = sps.cont2discrete(([1.0], den), TS, method="zoh")
    return sps.lfilter(b.ravel(), a, u)


@pytest.mark.parametrize("channel", ["position", "acceleration"])
def test_the_disturbance_reaches_the_position_as_one_minus_q_times_the_learning_signals_map(channel):
    """A disturbance ``d`` and the learning signal ``u = -(1 - Q){d}/K`` move the vehicle with the add-on DOB
    by exactly opposite amounts (``Gd = (1 - Q) Gf / K``), although the DOB's airframe model is 30 % off in
    gain, drag and lag: agreement to 1e-9 of the motion over a whole 20 s trial."""
    n = 2000
    t = np.arange(n) * TS
    d = np.zeros((n, 3))
    d[:, 0] = 0.8 * np.sin(1.1 * t) + 0.4 * np.sign(np.sin(0.3 * t))
    model = PlantSpec(num=[0.7], den=list(np.polymul([1.0, 0.3, 0.0], [0.05, 1.0])))
    dob = DOBSpec(3, 0.1)

    def fly(dist, learning):
        vehicle = AddOnDOB(LinearVehicle(disturbance=dist), {"x": model}, dob, channel)
        return fly_closed_loop(vehicle, np.zeros((n, 3)), learning=learning, channel=channel)

    y_d = fly(d, None).y_meas[:, 0]
    k = LinearVehicle().channel_gain(channel)[0]
    y_u = fly(None, {"x": -(d[:, 0] - _q_filter(dob, d[:, 0])) / k}).y_meas[:, 0]
    assert np.max(np.abs(y_d)) > 1e-3
    np.testing.assert_allclose(y_u, -y_d, rtol=0, atol=1e-9 * np.max(np.abs(y_d)))


def test_the_dob_removes_a_constant_disturbance_that_the_vehicles_loop_alone_leaves():
    """A PD loop leaves ``d / kp`` of a constant disturbance (0.1 m here); with the DOB (even on a wrong model)
    the error decays to below 1e-6 m by the end of a 20 s trial."""
    n = 2000
    d = np.zeros((n, 3))
    d[:, 0] = 0.4
    model = PlantSpec(num=[0.7], den=list(np.polymul([1.0, 0.3, 0.0], [0.05, 1.0])))
    alone = fly_closed_loop(LinearVehicle(disturbance=d), np.zeros((n, 3)))
    with_dob = fly_closed_loop(AddOnDOB(LinearVehicle(disturbance=d), {"x": model}, DOBSpec(3, 0.1)),
                               np.zeros((n, 3)))
    assert abs(alone.y_meas[-1, 0] - 0.4 / 4.0) < 1e-6
    assert abs(with_dob.y_meas[-1, 0]) < 1e-6


def test_paper_loop_vehicle_flies_fly_vehicles_loop_with_the_learning_signal_as_minus_d_f():
    """ilcdob's PID + DOB behind the setpoint interface: a learning signal on its acceleration channel flies
    exactly what :func:`fly_vehicle` flies with ``d_f = -u`` (to 1e-12 of the motion)."""
    import ilcdob

    fleet = ilcdob.default_fleet()
    loop = fleet.loop("UAV1")
    n = 500
    t = np.arange(n) * loop.ts
    r = np.zeros((n, 3))
    r[:, 0] = 0.2 * np.sin(0.7 * t)
    u = np.zeros((n, 3))
    u[:, 0] = 0.3 * np.cos(1.9 * t)
    loops = {ax: loop for ax in "xyz"}
    lin = LinearVehicle(ts=loop.ts)
    a = fly_closed_loop(PaperLoopVehicle(lin, loops), r, learning=u, channel="acceleration")
    b = fly_vehicle(lin, loops, r, learning=-u)
    np.testing.assert_allclose(a.y_meas, b.y_meas, rtol=0, atol=1e-12 * np.max(np.abs(b.y_meas)))
    with pytest.raises(SpecError, match="acceleration channel only"):
        PaperLoopVehicle(lin, loops).channel_gain("position")


def test_bad_add_on_dobs_name_what_is_wrong():
    model = PlantSpec(num=[1.0], den=[0.05, 1.05, 0.45, 0.0])
    with pytest.raises(SpecError, match="`dob.q_order`: got 2, below the relative degree 3"):
        AddOnDOB(LinearVehicle(), {"x": model}, DOBSpec(2, 0.1))
    with pytest.raises(SpecError, match="`airframes`: got axes \\['w'\\]"):
        AddOnDOB(LinearVehicle(), {"w": model}, DOBSpec(3, 0.1))
    with pytest.raises(SpecError, match="reports commanded_acceleration"):
        AddOnDOB(object(), {"x": model}, DOBSpec(3, 0.1))
    with pytest.raises(SpecError, match="`dob`: got tuple"):
        AddOnDOB(LinearVehicle(), {"x": model}, (3, 0.1))
