"""Short reprs and notebook tables of the result objects (ilcdob.display)."""

from __future__ import annotations

import numpy as np

import ilcdob
from ilcdob.design.pair import design_pair
from ilcdob.identification import FitOptions, tfest
from ilcdob.identification.oe import simulate_zoh
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure
from ilcdob.validation.compare import CompareOptions, compare_designs
from ilcdob.validation.reproduce import reproduce


def _check(obj, *needles: str) -> None:
    text = repr(obj)
    assert "\n" not in text and len(text) < 300, text  # one short line, not a dump of arrays
    for needle in needles:
        assert needle in text, (needle, text)
    html = obj._repr_html_()
    assert html.startswith("<table>") and html.endswith("</table>") and "<td>" in html


def test_reprs_name_what_matters(fleet):
    _check(fleet, "UAV1, UAV2, UAV3", "0.02 s")
    _check(design_pair(fleet, "UAV1", "UAV2"), "closed-form", "UAV1 -> UAV2", "SOS")
    res = reproduce(fleet, [1], 1)
    m = res.scenarios[0].systems["UAV2"].metrics()
    _check(res, "1 scenario(s)", "law paper")
    assert f"{1e3 * m['rmse_dob']:.4g}" in res._repr_html_()  # the table holds the RMSE in mm
    _check(compare_designs(fleet, 1, ["closed-form"], CompareOptions(samples=1, duration=5.0)), "scenario 1",
           "closed-form")


def test_tfestimate_repr_and_table():
    rng = np.random.default_rng(0)
    u = np.repeat(rng.standard_normal(100), 30)
    y = simulate_zoh(ModelStructure(2), np.array([3.0, 2.0, 2.0]), u, 0.02) + 0.001 * rng.standard_normal(u.size)
    est = tfest(FlightData(np.arange(u.size) * 0.02, {"u": u, "y": y}, source="t"), "u", "y", ModelStructure(2),
                FitOptions())
    _check(est, "G(s) =", "fit 99", "converged")
    html = est._repr_html_()
    assert "a1" in html and "a0" in html and "b0" in html and "1 sigma" in html
