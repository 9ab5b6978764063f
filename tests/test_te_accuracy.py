"""Accuracy of :meth:`LearningFilters.te_responses` (the Theorem's error propagation, paper Sec. III).

Under a small model error ``Te1 = Gd_j Gd_{j-1}^-1 - Gf_j L1`` is a difference of two nearly equal
terms (about -250 dB at 1e-3 rad/s for a 10 % gain error on the built-in fleet, against terms
near +8 dB). The reference here evaluates it as written in 50-digit arithmetic (mpmath), from
each loop's blocks P, C, Q, M at ``z = e^{j w Ts}``: their state-space matrices (``A - I`` of
the delta form, ``B``, ``C``, ``D``), whose double values are taken as exact. ``L1`` is the
Theorem's ``-(1 - Q_j) Gd_hat_{j-1}^-1`` times the ratio of the filter as applied to its
zero-pole form (the poles inverted with zero phase error), both in 50 digits. Transfer-function
coefficients in double precision would not do: rounding them splits the plant's double pole at
z = 1 by +-4e-8, a relative error of 4e-6 in P at 1e-3 rad/s.
"""

from __future__ import annotations

from dataclasses import replace

import mpmath as mp
import numpy as np
import pytest

import ilcdob
from ilcdob import build_loop
from ilcdob.design import closed_form_filters
from ilcdob.design.checks.figure import with_gain_error
from ilcdob.errors import SpecError

#: A relative-degree-2 plant (double integrator) at Ts = 0.01 s: its sampling zero at z = -1 is
#: inverted with zero phase error in L1 of D1 -> D2 (a filter as applied that differs from its formula).
SUBSTITUTED_FLEET = {"sample_time": 0.01, "system": [
    {"name": "D1", "plant": {"num": [1.0], "den": [1.0, 0.0, 0.0]},
     "controller": {"kp": 3.0, "ki": 0.3, "kd": 2.4, "derivative_filter": 0.05},
     "dob": {"q_order": 3, "q_time_constant": 0.15}},
    {"name": "D2", "plant": {"num": [1.0], "den": [0.1, 1.0, 0.0]},
     "controller": {"kp": 1.2, "ki": 0.12, "kd": 1.53, "derivative_filter": 0.05},
     "dob": {"q_order": 3, "q_time_constant": 0.2}}]}

RTOL = 1e-6


def _grid(ts: float) -> np.ndarray:
    return np.geomspace(1e-3, 0.9 * np.pi / ts, 30)


def _true_loop(loop, plant_gain: float = 1.1, pid_gain: float = 1.0, kd_gain: float = 1.0):
    """``loop``'s system flown with a plant ``plant_gain`` times its model and PID gains scaled."""
    model = loop.spec.nominal_plant
    pid = loop.spec.controller
    pid = replace(pid, kp=pid.kp * pid_gain, ki=pid.ki * pid_gain, kd=pid.kd * pid_gain * kd_gain)
    plant = replace(model, num=tuple(np.asarray(model.num) * plant_gain))
    return build_loop(replace(loop.spec, plant=plant, model=model, controller=pid), loop.ts)


def _mp_block(blk, w: np.ndarray) -> list:
    """``c ((z - 1) I - (A - I))^-1 b + d`` in 50 digits."""
    n = blk.a_minus_i.shape[0]
    a = mp.matrix(blk.a_minus_i.tolist()) if n else None
    b = mp.matrix([float(x) for x in np.asarray(blk.sys.B, float)[:, 0]]) if n else None
    c = [mp.mpf(float(x)) for x in np.asarray(blk.sys.C, float).reshape(-1)]
    d = mp.mpf(float(np.asarray(blk.sys.D, float)[0, 0]))
    out = []
    for wi in w:
        zm1 = mp.expm1(1j * mp.mpf(float(wi)) * mp.mpf(blk.ts))
        x = mp.lu_solve(zm1 * mp.eye(n) - a, b) if n else []
        out.append(mp.fsum(c[i] * x[i] for i in range(n)) + d)
    return out


def _mp_zpk(f, w: np.ndarray) -> list:
    out = []
    for wi in w:
        z = mp.exp(1j * mp.mpf(float(wi)) * mp.mpf(f.ts))
        v = mp.mpf(float(f.gain))
        for r in f.zeros:
            v *= z - mp.mpc(complex(r))
        for p in f.poles:
            v /= z - mp.mpc(complex(p))
        out.append(v)
    return out


def _mp_maps(loop, w: np.ndarray) -> tuple[list, list]:
    """``Gd = P (1 - Q)/D`` and ``Gf = -P/D``, ``D = 1 - Q + P (M + C)``, in 50 digits."""
    p, c, q, m = (_mp_block(loop.blocks[k], w) for k in ("P", "C", "Q", "M"))
    den = [1 - qi + pi * (mi + ci) for pi, ci, qi, mi in zip(p, c, q, m)]
    return [pi * (1 - qi) / di for pi, qi, di in zip(p, q, den)], [-pi / di for pi, di in zip(p, den)]


def reference_te(lf, source_true, target_true, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Te1 = Gd_j/Gd_{j-1} - Gf_j L1`` and ``Te2 = Te1 Gf_{j-1}`` as written, in 50 digits."""
    with mp.workdps(50):
        gd_j, gf_j = _mp_maps(target_true, w)
        gd_p, gf_p = _mp_maps(source_true, w)
        gd_hat, _ = _mp_maps(lf.source, w)
        q_hat_j = _mp_block(lf.target.blocks["Q"], w)
        applied = [a / b for a, b in zip(_mp_zpk(lf.L1.realised, w), _mp_zpk(lf.L1, w))]
        te1 = [gj / gp + fj * (1 - qj) / gh * s
               for gj, gp, fj, qj, gh, s in zip(gd_j, gd_p, gf_j, q_hat_j, gd_hat, applied)]
        te2 = [t * f for t, f in zip(te1, gf_p)]
        return np.array([complex(t) for t in te1]), np.array([complex(t) for t in te2])


@pytest.fixture(scope="module")
def uav_pair():
    fleet = ilcdob.default_fleet()
    a, b = fleet.loop("UAV1"), fleet.loop("UAV2")
    return a, b, closed_form_filters(a, b)


@pytest.fixture(scope="module")
def substituted_pair():
    fleet = ilcdob.fleet.fleet_from_dict(SUBSTITUTED_FLEET, source="substituted")
    a, b = fleet.loops
    lf = closed_form_filters(a, b)
    assert lf.L1.substituted.size  # the case this fleet is for
    return a, b, lf


def _assert_close(got: np.ndarray, want: np.ndarray, w: np.ndarray, what: str) -> None:
    err = np.abs(got / want - 1)
    i = int(np.argmax(err))
    assert err[i] <= RTOL, f"{what}: relative error {err[i]:.3g} at {w[i]:.4g} rad/s (|want| {abs(want[i]):.3g})"


@pytest.mark.parametrize("case", ["plants 10 % stronger", "and target PID 5 % stronger",
                                  "and source derivative gain 5 % stronger"])
def test_te_matches_a_50_digit_evaluation_under_model_error(uav_pair, case):
    a, b, lf = uav_pair
    w = _grid(a.ts)
    source_true = _true_loop(a, kd_gain=1.05 if "source" in case else 1.0)
    target_true = _true_loop(b, pid_gain=1.05 if "target" in case else 1.0)
    want1, want2 = reference_te(lf, source_true, target_true, w)
    te1, te2 = lf.te_responses(w, source_true, target_true)
    _assert_close(te1, want1, w, f"Te1 ({case})")
    _assert_close(te2, want2, w, f"Te2 ({case})")
    if case == "plants 10 % stronger":  # the cancellation this is about: Te1 is tiny at low frequency
        assert abs(want1[0]) < 1e-11 and abs(want1[w.searchsorted(0.01)]) < 1e-8


@pytest.mark.parametrize("plant_gain", [1.0, 1.1])
def test_te_matches_a_50_digit_evaluation_with_a_substituted_pole(substituted_pair, plant_gain):
    a, b, lf = substituted_pair
    w = _grid(a.ts)
    source_true, target_true = with_gain_error(a, plant_gain), with_gain_error(b, plant_gain)
    want1, want2 = reference_te(lf, source_true, target_true, w)
    te1, te2 = lf.te_responses(w, source_true, target_true)
    _assert_close(te1, want1, w, f"Te1 (plant gain {plant_gain})")
    _assert_close(te2, want2, w, f"Te2 (plant gain {plant_gain})")


def test_te_vanishes_exactly_with_exact_models(uav_pair):
    a, b, lf = uav_pair
    w = _grid(a.ts)
    rebuilt = build_loop(a.spec, a.ts), build_loop(b.spec, b.ts)  # equal blocks, other objects
    for te1, te2 in (lf.te_responses(w), lf.te_responses(w, a, b), lf.te_responses(w, *rebuilt)):
        assert np.all(te1 == 0) and np.all(te2 == 0)


def test_true_loop_at_another_sample_time_is_refused(uav_pair):
    a, b, lf = uav_pair
    with pytest.raises(SpecError, match=r"`source_true`.*0\.01 s.*0\.02 s"):
        lf.te_responses(_grid(a.ts), build_loop(a.spec, 0.01), b)
