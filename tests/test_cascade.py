"""The check that tells a cascaded position controller (PX4's, ArduPilot's shape) from a single loop on data
(ilcdob.validation.channel_id.check_channel_gain).

The vehicles are written with scipy alone: an airframe ``x' = v``, ``v' = a - drag v``, ``a' = (a_c + d - a)/lag``
sampled with a zero-order hold (``scipy.linalg.expm``), 0.5 mm of white position noise. The cascade flies, on its
sampled state, ``v_sp = kpp (r - x) + v_ff`` and ``a_c = kpv (v_sp - v) + kiv integral(v_sp - v) + a_ff``: the
velocity integral cancels a constant force, so its disturbance map is not ``P (1 - T)`` of any single loop, and
its position channel reaches the command through ``kpp (kpv + kiv/s)``, no constant ``K``. The single loop flies
``a_c = kp (r - x) + kd (v_ref - v) + a_ff`` (rotorpy's SE3 shape). The fits are judged against
these vehicles, not against ilcdob's maps.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg

from ilcdob.validation.channel_id import check_channel_gain, identify_channel

TS = 0.01
NOISE = 5e-4  # m


class Airframe:
    """Three decoupled axes of the airframe (module docstring), a command disturbance ``d(t)`` (m/s^2)."""

    def __init__(self, drag: float, lag: float, seed: int, disturbance=None):
        a = np.array([[0.0, 1.0, 0.0], [0.0, -drag, 1.0], [0.0, 0.0, -1.0 / lag]])
        b = np.array([0.0, 0.0, 1.0 / lag])
        m = linalg.expm(np.block([[a, b[:, None]], [np.zeros((1, 4))]]) * TS)
        self.phi, self.gamma, self.ts = m[:3, :3], m[:3, 3], TS
        self.rng, self.disturbance = np.random.default_rng(seed), disturbance
        self.reset()

    def reset(self):
        self.state = np.zeros((3, 3))  # per axis: position, velocity, actuated acceleration
        self.k = 0
        self.commanded_acceleration = np.zeros(3)
        self.integral = np.zeros(3)

    def position(self):
        return self.state[:, 0] + NOISE * self.rng.standard_normal(3)

    def _fly(self, command):
        d = np.zeros(3) if self.disturbance is None else self.disturbance(self.k * TS)
        self.commanded_acceleration = command
        self.state = self.state @ self.phi.T + np.outer(command + d, self.gamma)
        self.k += 1


class Cascade(Airframe):
    """PX4's shape: a position P over a velocity PI, the acceleration feed-forward after it."""

    def __init__(self, kpp, kpv, kiv, drag=0.4, lag=0.06, seed=0, disturbance=None):
        super().__init__(drag, lag, seed, disturbance)
        self.kpp, self.kpv, self.kiv = kpp, kpv, kiv

    def channel_gain(self, channel):
        if channel != "acceleration":
            raise ValueError("a cascade has a constant K on the acceleration channel only")
        return np.ones(3)

    def track(self, position, velocity, acceleration):
        x, v = self.position(), self.state[:, 1]
        v_err = self.kpp * (position - x) + velocity - v
        self.integral = self.integral + v_err * TS
        self._fly(self.kpv * v_err + self.kiv * self.integral + acceleration)


class SingleLoop(Airframe):
    """rotorpy's SE3 shape: one PD loop on position and velocity."""

    def __init__(self, kp, kd, drag=0.4, lag=0.06, seed=0, disturbance=None):
        super().__init__(drag, lag, seed, disturbance)
        self.kp, self.kd = kp, kd

    def channel_gain(self, channel):
        return np.full(3, {"position": self.kp, "velocity": self.kd, "acceleration": 1.0}[channel])

    def track(self, position, velocity, acceleration):
        x, v = self.position(), self.state[:, 1]
        self._fly(self.kp * (position - x) + self.kd * (velocity - v) + acceleration)


#: Two cascades with different gains and airframes (a PX4-like default and a stiff, fast one).
CASCADES = {"px4-like": dict(kpp=0.95, kpv=1.8, kiv=0.4, drag=0.35, lag=0.08),
            "stiff": dict(kpp=1.6, kpv=3.5, kiv=1.5, drag=0.6, lag=0.04)}


@pytest.mark.slow  # four 30 s identifications per case, about 90 s each on 2 cores
@pytest.mark.parametrize("kind", ["single loop", "cascade"])
def test_the_gain_check_tells_a_cascade_from_a_single_loop(kind):
    """The position channel's fit over the acceleration channel's: for the single PD loop a constant ``kp``
    within the fits' 3-sigma bounds across the chirp band; for the cascade no constant ``K`` (here its
    steady-state candidate ``kpp kpv``) comes within them: its velocity integral makes ``K`` grow without bound
    below ``kiv / kpv`` rad/s."""
    if kind == "single loop":
        def make(name, seed, cmd=None, wind=None):
            return SingleLoop(4.0, 3.0, seed=seed)
        gain = 4.0
    else:
        def make(name, seed, cmd=None, wind=None):
            return Cascade(**CASCADES["px4-like"], seed=seed)
        gain = CASCADES["px4-like"]["kpp"] * CASCADES["px4-like"]["kpv"]
    fits = {ch: identify_channel(make, "v", TS, ch, "x", 30.0) for ch in ("position", "acceleration")}
    check = check_channel_gain(fits["position"], fits["acceleration"], gain)
    assert check.holds == (kind == "single loop"), check
    if kind == "cascade":
        assert np.max(check.mismatch) > 0.3  # far beyond any fit's uncertainty: not a near miss


def test_the_python_route_fixes_a_cascades_zero_at_the_origin():
    """`identify_channel(..., zero_at_origin=True)` on the PX4-like cascade's acceleration channel: the chosen map
    has its zero at s = 0 exactly, held out >= 95 %, and its loop integrates; on the single PD loop (no integral)
    every candidate's data refuse the zero and the identification says so."""
    from ilcdob.channel_loop import channel_loop
    from ilcdob.errors import SpecError

    fit = identify_channel(lambda name, seed: Cascade(**CASCADES["px4-like"], seed=seed), "v", TS, "acceleration",
                           "x", 30.0, zero_at_origin=True)
    assert fit.plant.num[-1] == 0.0 and fit.fit_validation >= 95.0, (fit.plant, fit.fit_validation)
    assert channel_loop("v", TS, "acceleration", fit.plant, identification=fit.identification).integrates
    with pytest.raises(SpecError, match="does not integrate"):
        identify_channel(lambda name, seed: SingleLoop(4.0, 3.0, seed=seed), "v", TS, "acceleration", "x", 30.0,
                         zero_at_origin=True)
