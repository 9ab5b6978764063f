"""The method's filter as designed, in memory: what a design learns with before it is written to
``filters.json`` (the exact closed form, a per-trial solve, the robust-set design)."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ilcdob.errors import SpecError

from ..maps.finite_horizon import LinearMap
from .stage import CORE_PLACE, STAGE_KINDS, CParts, LawContext, Signals, Stage, register

__all__ = ["Designed", "file_core"]


def file_core(entries: dict[str, Any]) -> Stage | None:
    """The method's filter read from ``filters.json`` entries, None without one.

    Parameters
    ----------
    entries : dict
        ``L1``/``L2``, or ``law_maps``, ``F`` and ``trial_ends``.
    """
    for kls in STAGE_KINDS.values():
        if kls.place == CORE_PLACE and kls is not Designed:
            found = kls.from_dict(entries, LawContext())
            if found is not None:
                return found
    return None


@register
class Designed(Stage):
    """A method's learning filter in memory.

    Parameters
    ----------
    method : str
        The method's name.
    learn : callable
        ``learn(e, d_f) -> d_f,j`` (m, m/s^2 -> m/s^2; ``learn(e_1, d_f1, ..., e_k, d_fk)`` for a
        multi-source filter).
    entries : dict
        Its ``filters.json`` entries (empty: a method the file cannot run, e.g. a per-trial solve).
    maps : callable, optional
        ``maps(m)``: the filter over ``m`` samples of each signal as a linear map of the stacked
        signals (None: it has none; ``why_not`` says why).
    why_not : str
        Why there is no linear map (messages).
    """

    kind = "designed"
    place = CORE_PLACE

    def __init__(self, method: str, learn: Callable[..., np.ndarray], entries: dict[str, Any] | None = None,
                 maps: Callable[[int], LinearMap] | None = None, why_not: str = ""):
        self.method, self.learn, self.entries, self.maps = method, learn, dict(entries or {}), maps
        self.linear = maps is not None
        self._why_not = why_not or f"method {method!r} solves its learning signal per trial"
        self.file_form = file_core(self.entries) if self.entries else None
        self.emits_c = self.file_form is not None and self.file_form.emits_c

    def to_dict(self) -> dict[str, Any]:  # noqa: D102 - Stage.to_dict
        return dict(self.entries)

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        return (np.asarray(self.learn(*x), dtype=float),)

    def shape(self, m: int, k: int, n: int) -> tuple[int, int]:  # noqa: D102 - Stage.shape
        return m, 1

    def why_not_linear(self) -> str:  # noqa: D102 - Stage.why_not_linear
        return self._why_not

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:  # noqa: D102 - Stage.linear_map
        if self.maps is None:
            return super().linear_map(m, k, n)
        return self.maps(m)

    def c_parts(self, prefix: str) -> CParts:  # noqa: D102 - Stage.c_parts
        if self.file_form is None:
            raise SpecError(f"method {self.method!r}: no C code (its filters.json holds no learning law to run)")
        return self.file_form.c_parts(prefix)

    def __repr__(self) -> str:
        return f"<stage designed {self.method}>"
