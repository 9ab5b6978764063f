"""Balanced truncation of discrete SISO maps (ilcdob.design.filters.reduction)."""

from __future__ import annotations

import control as ct
import numpy as np

from ilcdob.design.filters.reduction import hankel_singular_values, reduced_realisation
from ilcdob.loop import freqresp


def test_balanced_truncation_error_within_its_bound(fleet):
    lp = fleet.loops[1]
    w = np.linspace(1e-3, np.pi / fleet.sample_time, 4000)
    full = freqresp(lp.G_f, w)
    for tol in (1e-5, 1e-3, 1e-2):
        red, bound = reduced_realisation(lp.G_f, tol)
        assert red.nstates < 11 and red.dt == lp.G_f.dt  # discrete, reduced (11 states minimal by minreal)
        assert np.max(np.abs(freqresp(red, w) - full)) <= bound * (1 + 1e-9)  # Enns/Glover: 2 sum(HSV)


def test_zero_tolerance_keeps_the_response(fleet):
    """tol = 0 keeps every state AB09AD finds significant: the response and the bound stay ~1e-8."""
    lp = fleet.loops[0]
    hsv = hankel_singular_values(ct.minreal(lp.G_f, verbose=False))
    red, bound = reduced_realisation(lp.G_f, 0.0)
    assert red.nstates <= hsv.size and bound <= 1e-7 * hsv[0]
    np.testing.assert_allclose(bound, 2.0 * np.sum(hsv[red.nstates:]), rtol=1e-6)
    w = np.linspace(1e-3, np.pi / fleet.sample_time, 500)
    assert np.max(np.abs(freqresp(red, w) - freqresp(lp.G_f, w))) <= bound * (1 + 1e-6)


def test_hankel_singular_values_of_a_first_order_map():
    a, b, c = 0.5, 1.0, 1.0  # G(z) = 1/(z - 0.5): Wc = Wo = 1/(1 - a^2), HSV = 1/(1 - a^2)
    sys = ct.ss([[a]], [[b]], [[c]], [[0.0]], 1.0)
    np.testing.assert_allclose(hankel_singular_values(sys), [1.0 / (1.0 - a * a)])
    hsv = hankel_singular_values(ct.ss(ct.tf([1.0, 0.3], [1.0, -0.9, 0.2], 1.0)))
    assert hsv.size == 2 and hsv[0] >= hsv[1] > 0
