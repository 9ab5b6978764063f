"""Frequency responses on the unit circle (ilcdob.response), and the filter objects that report theirs through it.

The reference values are computed here with numpy alone (``z = e^{jw Ts}``, polynomials evaluated by
``numpy.polyval``), not by the code under test. Every filter object's ``freqresp`` must be the shared
function's value to the bit: one implementation, no copies that could drift apart.
"""

from __future__ import annotations

import numpy as np
import pytest

from ilcdob.design.maps.closed_form import closed_form_filters
from ilcdob.design.methods.fir import FIRFilter
from ilcdob.design.export.objects import filter_tf
from ilcdob.loop import freqresp
from ilcdob.response import fir_matrix, fir_response, response, unit_circle

TS = 0.01
W = np.geomspace(0.05, np.pi / TS, 257)


def _poly_z(num, den):
    """``num(z)/den(z)`` (coefficients in powers of z, highest first) as a callable of z, by numpy."""
    return lambda z: np.polyval(num, z) / np.polyval(den, z)


def test_unit_circle_keeps_the_shape_and_lies_on_the_circle():
    w = np.linspace(0.0, np.pi / TS, 12).reshape(3, 4)
    wf, z = unit_circle(w.tolist(), TS)
    assert wf.dtype == float and wf.shape == z.shape == (3, 4)
    np.testing.assert_allclose(np.abs(z), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.angle(z[0, :2]), [0.0, w[0, 1] * TS], rtol=1e-14)


def test_response_is_the_product_of_the_factors_times_the_advance():
    f1, f2 = _poly_z([1.0, -0.5], [1.0, -0.9]), _poly_z([0.3, 0.1, 0.05], [1.0, 0.2, 0.0])
    z = np.exp(1j * W * TS)
    want = z**3 * f1(z) * f2(z)
    np.testing.assert_allclose(response((f1, f2), W, TS, advance=3), want, rtol=1e-13)
    np.testing.assert_allclose(response((f1,), W, TS), f1(z), rtol=1e-15)
    # an advance of 0 is the factor 1 + 0j: the same finite values
    np.testing.assert_array_equal(response((f1,), W, TS, advance=0), response((f1,), W, TS))
    assert response((), W, TS, advance=2).shape == W.shape
    with pytest.raises(ValueError, match="no factor and no advance"):
        response((), W, TS)


def test_fir_response_is_z_to_the_advance_times_the_taps_polynomial():
    h = np.random.default_rng(0).standard_normal(41)
    z = np.exp(1j * W * TS)
    want = z**7 * np.polyval(h[::-1], 1 / z)
    np.testing.assert_allclose(fir_response(h, W, TS, 7), want, rtol=1e-11)
    np.testing.assert_array_equal(fir_response(h, W, TS, 7), fir_matrix(W, h.size, 7, TS) @ h)
    w2 = W[:256].reshape(16, 16)
    np.testing.assert_array_equal(fir_response(h, w2, TS, 7), fir_response(h, W[:256], TS, 7).reshape(16, 16))


def test_every_filter_object_reports_the_shared_response(fleet):
    w = np.geomspace(0.05, np.pi / fleet.sample_time, 200)
    ts = fleet.sample_time
    loop = fleet.loops[0]
    np.testing.assert_array_equal(freqresp(loop.G_d, w), response((loop.G_d,), w, ts))
    lf = closed_form_filters(fleet.loops[0], fleet.loops[1])
    np.testing.assert_array_equal(lf.L1.freqresp(w), response((lf.L1,), w, ts))
    tf = filter_tf({"advance": 2, "num": [0.5, 0.3, 0.2], "den": [1.0]}, TS, "L2")
    np.testing.assert_array_equal(tf.freqresp(W), response(tf.sections, W, TS, 2))
    fir = FIRFilter(np.array([0.5, 0.3, 0.2]), 2, TS)
    np.testing.assert_array_equal(fir.freqresp(W), fir_response(fir.h, W, TS, 2))
    # the FIR, the num/den filter and numpy agree on the same filter
    z = np.exp(1j * W * TS)
    np.testing.assert_allclose(fir.freqresp(W), z**2 * np.polyval([0.2, 0.3, 0.5], 1 / z), rtol=1e-13)
    np.testing.assert_allclose(tf.freqresp(W), fir.freqresp(W), rtol=1e-13)
