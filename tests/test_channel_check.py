"""The exact worst case of learning between channel vehicles (ilcdob.design.checks.channel).

Held to a construction without ilcdob code: the channel map's 3-sigma bound from analytic gradients of
``G(jw) = B(jw)/A(jw) e^{-jw tau}`` (ilcdob differentiates numerically), the Theorem's ratio
``e_j/e'_j = 1 - Gf_j L1 Gd_{j-1}/Gd_j`` written from the maps with the learner's maps also in error, and
its maximum over the disc of ``Delta`` found by brute force on its boundary; whole trials of plants drawn
inside the set, simulated with scipy.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal as sps

from ilcdob.design.checks.channel import channel_check
from ilcdob.design.filters.band import LearningBand
from ilcdob.design.maps.channel_filters import channel_filters
from ilcdob.design.pair import design_channel_pair
from ilcdob.errors import SpecError
from ilcdob.specs import DOBSpec, IdentificationSpec, PlantSpec
from ilcdob.channel_loop import channel_loop
from lti_truth import alias_radius

TS = 0.01
# a position loop's channel map B/A (3 poles, 1 zero) and its fit's parameters (a2, a1, a0, b1, b0, delay)
A, B, TAU = np.array([1.0, 10.7, 33.2, 43.3]), np.array([8.0, 43.3]), 0.012
THETA = np.concatenate([A[1:], B, [TAU]])
_SD = np.abs(THETA) * np.array([0.01, 0.015, 0.012, 0.02, 0.01, 0.05])
_CORR = 0.3 ** np.abs(np.subtract.outer(np.arange(6), np.arange(6)))
COV = np.outer(_SD, _SD) * _CORR  # a positive definite covariance with correlated parameters
IDENT = IdentificationSpec(3, 1, 0, tuple(THETA[:-1]), tuple(map(tuple, COV)), delay_estimated=True)
OTHER = PlantSpec(num=[2.0, 30.0], den=[0.1, 1.4, 5.0, 8.0])


def _bound(w: np.ndarray) -> np.ndarray:
    """3 sigma of ``|dG|/|G|`` from the analytic gradient (module docstring)."""
    s = 1j * w
    a, b = np.polyval(A, s), np.polyval(B, s)
    g = b / a * np.exp(-s * TAU)
    grads = [-g * s ** 2 / a, -g * s / a, -g / a, s * g / b, g / b, -s * g]
    jac = np.array(grads)
    var = np.einsum("iw,ij,jw->w", jac.real, COV, jac.real) + np.einsum("iw,ij,jw->w", jac.imag, COV, jac.imag)
    return 3.0 * np.sqrt(var) / np.abs(g)


def _disc_max(f, radius):
    """``max |f(Delta)|`` over ``|Delta| = radius`` (the maximum of ``|1 - F (1 + Delta)|`` lies on the boundary):
    7200 points, then refined on the best one's neighbourhood."""
    th = np.linspace(0.0, 2 * np.pi, 7200, endpoint=False)[None, :]
    best = th[0, np.argmax(np.abs(f(radius[:, None] * np.exp(1j * th))), axis=1)]
    fine = best[:, None] + np.linspace(-1e-3, 1e-3, 2001)[None, :]
    return np.max(np.abs(f(radius[:, None] * np.exp(1j * fine))), axis=1)


def _loops(dob: bool = False):
    src = channel_loop("src", TS, "position", PlantSpec(num=list(B), den=list(A), delay=TAU), 6.0,
                       identification=IDENT)
    extra = {"airframe": PlantSpec(num=[1.0], den=[0.05, 1.05, 0.3, 0.0]), "dob": DOBSpec(3, 0.1)} if dob else {}
    tgt = channel_loop("tgt", TS, "acceleration", OTHER, 1.0, **extra)
    return src, tgt


@pytest.mark.parametrize("band", [None, 3.0])
def test_the_worst_case_is_the_theorems_ratio_maximised_over_the_identified_disc(band):
    """The check's worst case agrees with the brute-force maximum of ``|1 - Gf_j L1 Gd_{j-1} / Gd_j|`` over the
    source's 3-sigma disc (learner's maps 20 % and 30 degrees off: they cancel) to 1e-6 relative, with and without
    a learning band (its gain ``|H|^4`` written here from the Butterworth formula)."""
    src, tgt = _loops()
    w = np.geomspace(0.05, 0.9 * np.pi / TS, 60)
    lb = None if band is None else LearningBand(TS, band, 4, "stated")
    check = channel_check(src, tgt, band=lb, w=w)
    np.testing.assert_allclose(check.bound, _bound(w), rtol=1e-6)
    f = np.ones(w.size) if lb is None else (1.0 / (1.0 + (np.tan(w * TS / 2) / np.tan(band * TS / 2)) ** 8)) ** 2
    assert channel_filters(src, tgt).L1.substituted.size == 0  # every zero inverted exactly: F is the band's alone
    gd_j = 1.7 * np.exp(1j * 0.5)  # the learner's true maps over its model's: any common factor
    theorem = lambda delta: 1 - (gd_j * tgt.channel_gain) * f[:, None] / (tgt.channel_gain * gd_j) * (1 + delta)
    np.testing.assert_allclose(check.worst, _disc_max(theorem, _bound(w)), rtol=1e-6)
    assert check.holds == bool(np.all(check.worst <= 1 + 1e-9))


def test_a_paper_loop_source_is_checked_through_its_plants_disc():
    """ilcdob's PID + DOB (the built-in UAV1 with a stated 20 % bound) teaching a vehicle with the add-on DOB: the
    worst case is the brute-force maximum of ``|1 - F Gd/Gd_hat|`` with ``Gd = P (1 - Q)/(1 - Q + P (M + C))`` and
    ``P = P_hat (1 + Delta)`` over the stated set's disc on the sampled plant, the blocks' responses from
    python-control, to 1e-6 relative."""
    import control as ct

    import ilcdob

    loop = ilcdob.default_fleet().loop("UAV1")
    _, tgt = _loops(dob=True)
    tgt = channel_loop("tgt", loop.ts, "acceleration", OTHER, 1.0, airframe=tgt.airframe, dob=tgt.dob)
    w = np.geomspace(0.05, 0.9 * np.pi / loop.ts, 40)
    check = channel_check(loop, tgt, w=w, bound=0.2)
    p, m, c, q = (np.asarray(ct.frequency_response(b, w).complex).ravel() for b in (loop.P, loop.M, loop.C, loop.Q))

    def gd(pp):
        return pp * (1 - q[:, None]) / (1 - q[:, None] + pp * (m[:, None] + c[:, None]))

    theorem = lambda delta: 1 - gd(p[:, None] * (1 + delta)) / gd(p[:, None] + 0 * delta)
    model = loop.spec.nominal_plant  # the stated continuous 0.2 on the sampled plant (the aliases' sum)
    np.testing.assert_allclose(check.worst, _disc_max(theorem, alias_radius(model.num, model.den, model.delay,
                                                                            loop.ts, w, 0.2)), rtol=1e-6)
    assert check.bound_source == "stated bound"


def test_whole_trials_of_plants_inside_the_set_are_no_worse_than_the_check_says():
    """Twelve pairs of true channel maps drawn from the fit's covariance and inside its 3-sigma set (both vehicles'
    in error), a 20 s hover trial from rest in a disturbance of steps and sines, simulated with scipy (ZOH, the
    delay a modified z-transform by a half-sample sum): learning from the source's whole trial leaves the target
    no more than the check's worst ratio plus 0.01 (the trial's ends) of its error without learning."""
    src, tgt = _loops()
    check = channel_check(src, tgt)
    rng = np.random.default_rng(3)
    n = 2000
    t = np.arange(n) * TS
    d = 0.6 * np.sin(0.8 * t) + 0.3 * np.sin(2.1 * t + 0.5) + 0.4 * (t > 6.0)
    w = check.w

    def sim(num, den, delay, u):
        # the delay is a whole sample plus a fraction: shift by the whole, interpolate the held input for the rest
        k, frac = divmod(delay / TS, 1.0)
        held = np.concatenate([np.zeros(int(k)), u])[:u.size]
        prev = np.concatenate([[0.0], held[:-1]])
        b0, a0, _ = sps.cont2discrete((num, den), TS, method="zoh")
        y_now = sps.dlsim((b0.ravel(), a0, TS), held)[1].ravel()
        y_prev = sps.dlsim((b0.ravel(), a0, TS), prev)[1].ravel()
        return (1 - frac) * y_now + frac * y_prev if frac > 1e-12 else y_now

    kept, ratios = 0, []
    while kept < 12:
        x = rng.multivariate_normal(THETA, COV)
        den, num, delay = np.concatenate([[1.0], x[:3]]), x[3:5], max(x[5], 0.0)
        g = np.polyval(num, 1j * w) / np.polyval(den, 1j * w) * np.exp(-1j * w * delay)
        g0 = np.polyval(B, 1j * w) / np.polyval(A, 1j * w) * np.exp(-1j * w * TAU)
        if np.any(np.abs(g / g0 - 1) > check.bound):
            continue
        kept += 1
        e_src = -sim(num / 6.0, den, delay, d)  # the source's true Gd = G_ch / K
        u = design_channel_pair(src, tgt, band=None).learning(e_src, np.zeros(n)).d_f
        true_tgt = (1.1 * np.asarray(OTHER.num), OTHER.den)  # the learner's map 10 % off: it cancels
        e_no = -sim(*true_tgt, 0.0, d)
        e = -sim(*true_tgt, 0.0, d + u)
        ratios.append(np.sqrt(np.mean(e ** 2) / np.mean(e_no ** 2)))
    assert max(ratios) <= check.worst_ratio + 0.01, (max(ratios), check.worst_ratio)
    assert check.holds and check.worst_ratio < 1


def test_bad_checks_name_what_is_wrong():
    src, tgt = _loops()
    bare = channel_loop("bare", TS, "position", PlantSpec(num=list(B), den=list(A), delay=TAU), 6.0)
    with pytest.raises(SpecError, match="vehicle 'bare': its channel map has no identification"):
        channel_check(bare, tgt)
    with pytest.raises(SpecError, match="`bound`: got 1.5"):
        channel_check(src, tgt, bound=1.5)
    with pytest.raises(SpecError, match="`w`: expected frequencies"):
        channel_check(src, tgt, w=[1.0, 400.0])
    with pytest.raises(SpecError, match="`scale`: got 0"):
        channel_check(src, tgt, scale=0)
