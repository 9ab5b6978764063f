"""The two reference terms of the ``exact-reference`` law as stages (docs/theory.md section 6;
:mod:`.laws`): the source's reference error removed before learning, the target's own reference
correction added after. Their signals are not in ``filters.json`` (``reference_terms.csv``)."""

from __future__ import annotations

from typing import Any

from ilcdob.errors import SpecError

from .stage import LawContext, Signals, Stage, register

__all__ = ["ReferenceIn", "ReferenceOut"]


class _Reference(Stage):
    """Both halves: the pair's :class:`~.laws.ReferenceTerms` (``LawContext.reference``)."""

    keys = ("reference_terms",)
    linear = False
    emits_c = False

    def __init__(self, terms: Any):
        self.terms = terms

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext) -> "_Reference | None":  # noqa: D102
        return None if ctx.reference is None else cls(ctx.reference)

    def to_dict(self) -> dict[str, Any]:  # noqa: D102 - Stage.to_dict
        return {"reference_terms": self.terms.to_dict()}

    def why_not_linear(self) -> str:  # noqa: D102 - Stage.why_not_linear
        return "the exact-reference law is affine in the error; only the paper's law is linear in it"

    def c_parts(self, prefix: str) -> Any:  # noqa: D102 - Stage.c_parts
        raise SpecError("the exact-reference terms have no C code: subtract reference_terms.csv's e_ref_source from "
                        "e before learn and add its correction to d_next")


@register
class ReferenceIn(_Reference):
    """``e - e_ref,{j-1}``: the error of the source with its reference term removed."""

    kind = "reference in"
    place = 10

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        return (self.terms.error_in(x[0]), *x[1:])


@register
class ReferenceOut(_Reference):
    """``d_f + Gf_hat_j^{-1}{e_ref,j}``: the target's reference correction added."""

    kind = "reference out"
    place = 70

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        return (self.terms.signal_out(x[0]),)
