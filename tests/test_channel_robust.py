"""The robust per-trial SOCP between vehicles on their own controller, over their sampled channel maps.

Each hypothesis of the design is a pair of true channel maps (one drawn for the source, one for the target).
Here the source's trial and the target's learning flight are simulated with python-control on one such pair,
from the maps' continuous transfer functions: the SOCP's promise ``||e_k|| <= rho ||e0_k||`` is checked on the
whole trial by a simulator that shares nothing with the design's own predicted errors.
"""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from ilcdob.design.methods import Robust
from ilcdob.design.methods.robust import RobustOptions
from ilcdob.design.pair import design_channel_pair, design_pair
from ilcdob.design.sets.delta import channel_delta_set
from ilcdob.errors import SpecError
from ilcdob.fleet import fleet_from_dict

TS = 0.01  # s

#: Two unlike vehicles: a position-channel one (K = 4, relative degree 3) and an acceleration-channel one with a
#: lightly damped pair (damping 0.25 at 2.2 rad/s).
SYSTEMS = [{"name": "a", "channel": "position", "channel_gain": 4.0,
            "channel_map": {"num": [4.0], "den": [0.1, 1.0, 3.0, 4.0]}},
           {"name": "c", "channel": "acceleration", "channel_map": {"num": [1.0], "den": [0.2, 1.0, 1.2, 4.8]}}]


def _fly(loop, t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Position of a sampled vehicle's true map (its continuous ``disturbance_map``, ZOH) driven by ``u`` (m/s^2)."""
    m = loop.disturbance_map
    return ct.forced_response(ct.c2d(ct.ss(ct.tf(list(m.num), list(m.den))), TS, "zoh"), t, u).outputs


@pytest.mark.parametrize("source, target", [("a", "c"), ("c", "a")])
def test_the_socp_keeps_its_promise_on_every_hypothesis(source, target):
    """For every pair of drawn maps the design carries (bound 0.2: gain and high-pass errors), the target flown
    with that pair's truth has ``||e|| <= rho ||e0||`` over the whole 20 s trial (rho 0.6, 1e-3 for the
    solver's tolerance), and in fact <= 0.1 (the acceptance's iteration-1 figure; measured 0.047-0.065: the
    SOCP minimises the worst hypothesis's error, the improvement constraint is not active here)."""
    flt = fleet_from_dict({"sample_time": TS, "system": SYSTEMS})
    rng = np.random.default_rng(4)
    deltas = {n: channel_delta_set(flt.loop(n), 4, rng, bound=0.2) for n in (source, target)}
    rho = 0.6
    design = design_pair(flt, source, target, Robust(RobustOptions(rho=rho), deltas=deltas), band=None)
    assert design.filters["models"] == 5 and design.filters["units"] == {"learning": {"a": "m", "c": "m/s^2"}[target]}
    t = np.arange(0.0, 20.0, TS)
    d = 0.3 + 0.5 * np.sin(0.94 * t) + 0.2 * np.sin(1.41 * t + 0.5)  # m/s^2, the paper's disturbance
    pairs = [(flt.loop(source), flt.loop(target))] + list(zip(deltas[source].loops, deltas[target].loops))
    for k, (src, tgt) in enumerate(pairs):
        e_src = -_fly(src, t, d)
        u = design.learn(e_src, np.zeros_like(t))
        e0 = -_fly(tgt, t, d)
        e = e0 - tgt.channel_gain * _fly(tgt, t, u)
        ratio = np.linalg.norm(e) / np.linalg.norm(e0)
        assert ratio <= min(rho + 1e-3, 0.1), (k, ratio)


def test_robust_refuses_a_mixed_pair_and_a_vehicle_without_an_uncertainty_set():
    paper = {"name": "p", "plant": {"num": [1.0], "den": [0.1, 1.0, 0.0, 0.0]},
             "controller": {"kp": 3.0, "ki": 0.3, "kd": 2.42, "derivative_filter": 0.05},
             "dob": {"q_order": 3, "q_time_constant": 0.15}}
    flt = fleet_from_dict({"sample_time": TS, "system": [*SYSTEMS, paper]})
    with pytest.raises(SpecError, match="'robust' between a vehicle on its own controller and ilcdob's"):
        design_channel_pair(flt.loop("a"), flt.loop("p"), method="robust")
    with pytest.raises(SpecError, match="no identification"):
        design_pair(flt, "a", "c", "robust")  # inline maps: no covariance, no bound given
    with pytest.raises(SpecError, match="'closed-form' or 'robust'"):
        design_pair(flt, "a", "c", "fir")
