"""The method's filter as ``filters.json`` writes it: ``L1{e} + L2{d_f}`` in coefficient form
(closed-form and FIR designs; paper Sec. III, docs/theory.md section 2)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import signal as sps

from ..filters.entries import check_filter_entry
from ..filters.coefficients import apply_coefficients, lookahead_taps
from ..maps.finite_horizon import LinearMap, crop_map, extension_map, sos_map
from .stage import CORE_PLACE, CParts, LawContext, Signals, Stage, hstack_maps, register

__all__ = ["FilterPair", "coefficients_map"]

_CUBIC_FIT = 16  # samples the continuation past the end is fitted to (ilcdob.signals.extend_smoothly)


def _lfilter_map(b: np.ndarray, a: np.ndarray, m: int, name: str) -> LinearMap:
    """``scipy.signal.lfilter(b, a, .)`` from rest over ``m`` samples as a linear map."""
    return LinearMap(m, m, lambda x: sps.lfilter(b, a, x), lambda y: sps.lfilter(b, a, y[::-1])[::-1], name)


def coefficients_map(coeffs: dict[str, Any], m: int) -> LinearMap:
    """:func:`~..filters.coefficients.apply_coefficients` of one filter over ``m`` samples as a linear map.

    The trial continued past its end by the cubic through its last 16 samples (``advance + 8``
    samples), the look-ahead pre-stage (when given) and the sections (or ``num``/``den``) run
    from rest, the output read ``advance`` samples ahead.

    Parameters
    ----------
    coeffs : dict
        One filter of ``filters.json``.
    m : int
        Samples of the input.
    """
    adv = int(coeffs["advance"])
    out = extension_map(m, 0, adv + 8, _CUBIC_FIT, 3)
    size = out.n_out
    if coeffs.get("sos"):
        g = lookahead_taps(coeffs)
        if g is not None:
            out = _lfilter_map(g[::-1], np.ones(1), size, "look-ahead") @ out
        out = sos_map(np.asarray(coeffs["sos"], float), size, "sections") @ out
    else:
        out = _lfilter_map(np.asarray(coeffs["num"], float), np.asarray(coeffs["den"], float), size, "num/den") @ out
    return crop_map(size, adv, m) @ out


@register
class FilterPair(Stage):
    """``L1{e} + L2{d_f}`` from the coefficient entries ``L1`` and ``L2``
    (:func:`~..filters.coefficients.apply_coefficients`).

    Parameters
    ----------
    l1, l2 : dict
        The two filters of ``filters.json``, checked (:func:`~..filters.entries.check_filter_entry`).
    """

    kind = "L1/L2"
    place = CORE_PLACE
    keys = ("L1", "L2")

    def __init__(self, l1: dict[str, Any], l2: dict[str, Any]):
        self.l1, self.l2 = l1, l2

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext) -> "FilterPair | None":  # noqa: D102
        if "L1" not in filters or "L2" not in filters:
            return None
        for key in cls.keys:
            check_filter_entry(filters[key], key)
        return cls(filters["L1"], filters["L2"])

    def to_dict(self) -> dict[str, Any]:  # noqa: D102 - Stage.to_dict
        return {"L1": self.l1, "L2": self.l2}

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        return (apply_coefficients(self.l1, x[0]) + apply_coefficients(self.l2, x[1]),)

    def shape(self, m: int, k: int, n: int) -> tuple[int, int]:  # noqa: D102 - Stage.shape
        return m, 1

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:  # noqa: D102 - Stage.linear_map
        return hstack_maps([coefficients_map(self.l1, m), coefficients_map(self.l2, m)], "L1/L2")

    def c_parts(self, prefix: str) -> CParts:  # noqa: D102 - Stage.c_parts
        return CParts(step=f"    {prefix}l1_apply(a, a, len);\n    {prefix}l2_apply(b, b, len);\n"
                           f"    for (k = 0; k < len; ++k)\n        a[k] = a[k] + b[k];\n")
