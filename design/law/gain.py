"""The learning gain ``gamma`` in (0, 1] on the new error (1: the Theorem's law) as a stage; a choice
made when learning, not recorded in ``filters.json``."""

from __future__ import annotations

from typing import Any

import numpy as np

from ilcdob.errors import SpecError

from ..maps.finite_horizon import LinearMap
from .stage import LawContext, Signals, Stage, register

__all__ = ["Gain"]


@register
class Gain(Stage):
    """``gamma e`` on every error of the signals (the learning signals flown untouched).

    Parameters
    ----------
    gain : float
        ``gamma`` in (0, 1].

    Raises
    ------
    SpecError
        A gain outside (0, 1].
    """

    kind = "gain"
    place = 20
    emits_c = False

    def __init__(self, gain: float):
        if isinstance(gain, bool) or not isinstance(gain, (int, float)) or not 0.0 < gain <= 1.0:
            raise SpecError(f"`gain`: got {gain!r}, expected a learning gain in (0, 1]")
        self.gain = float(gain)

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext) -> "Gain | None":  # noqa: D102
        return None if ctx.gain == 1.0 else cls(ctx.gain)

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        return tuple(self.gain * v if i % 2 == 0 else v for i, v in enumerate(x))

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:  # noqa: D102 - Stage.linear_map
        scale = np.tile(np.repeat([self.gain, 1.0], m), k // 2)
        return LinearMap(k * m, k * m, lambda v: scale * v, lambda v: scale * v, "gain")

    def c_parts(self, prefix: str) -> Any:  # noqa: D102 - Stage.c_parts
        raise SpecError("the learning gain has no C code: it is chosen when learning, not in filters.json; "
                        "scale e before learn")
