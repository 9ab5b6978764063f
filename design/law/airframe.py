"""The airframe correction W as a stage: a disturbance acting on the airframe (or as wind through
its drag) reaches the learning vehicle through W (docs/theory.md section 6; :mod:`..maps.flown`)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import signal as sps

from ilcdob.errors import SpecError

from ..filters.c_text import DOUBLE, array_c
from ..filters.entries import check_sections
from ..maps.finite_horizon import LinearMap, sos_map
from .stage import CParts, LawContext, Signals, Stage, register

__all__ = ["AirframePath"]


@register
class AirframePath(Stage):
    """``W{y}``: second-order sections run forwards from rest over the learning signal.

    Parameters
    ----------
    entry : dict
        The ``disturbance`` entry of ``filters.json`` (``at``, ``W.sos``).
    sos : numpy.ndarray
        W's sections ``[b0, b1, b2, 1, a1, a2]``.
    """

    kind = "airframe path"
    place = 50
    keys = ("disturbance",)

    def __init__(self, entry: dict[str, Any], sos: np.ndarray):
        self.entry, self.sos = entry, sos

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext) -> "AirframePath | None":  # noqa: D102
        dist = filters.get("disturbance")
        if dist is None:
            return None
        if not isinstance(dist, dict):
            raise SpecError(f"`disturbance`: got {dist!r:.80}, expected a mapping such as {{'at': 'command'}}")
        if dist.get("W") is None:
            if dist.get("at", "command") in ("airframe", "wind"):
                raise SpecError(f"`disturbance.W`: missing, but `disturbance.at` is {dist.get('at')!r}; expected the "
                                "airframe correction {'sos': [[b0, b1, b2, 1, a1, a2], ...]}")
            return None
        w = dist["W"]
        if not isinstance(w, dict) or w.get("sos") is None:
            raise SpecError(f"`disturbance.W`: got {w!r:.80}, expected {{'sos': [[b0, b1, b2, 1, a1, a2], ...]}}")
        return cls(dist, check_sections(w["sos"], "disturbance.W.sos"))

    def to_dict(self) -> dict[str, Any]:  # noqa: D102 - Stage.to_dict
        return {"disturbance": self.entry}

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        return (sps.sosfilt(self.sos, x[0]),)

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:  # noqa: D102 - Stage.linear_map
        return sos_map(self.sos, m, "W")

    def c_parts(self, prefix: str) -> CParts:  # noqa: D102 - Stage.c_parts
        nw = self.sos.shape[0]
        tables = (f"\n/* W, the airframe correction: {nw} second-order section{'s' if nw > 1 else ''} run "
                  "forwards from rest,\n   rows b0 b1 b2 a0 a1 a2 (a0 = 1). */\n" + array_c(DOUBLE, f"{prefix}w_sos", self.sos))
        helpers = f"""
/* W over x[0..n) in place, from rest. */
static void {prefix}w_pass(double *x, size_t n)
{{
    double z[{nw}][2] = {{{{0.0}}}};

    {prefix}sections({prefix}w_sos, {nw}, z, x, n, 0);
}}
"""
        return CParts(tables, helpers, f"    {prefix}w_pass(a, len);\n", sections=True)
