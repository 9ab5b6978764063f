"""The learning vehicle's acceleration limit as the law's last stage (:mod:`..limit`): a learning
signal beyond it is clipped (with a warning) or refused, in Python and in the C ``learn``."""

from __future__ import annotations

import math
from typing import Any

from ilcdob.errors import SpecError
from ilcdob.specs import LimitSpec

from ..finite_horizon import LinearMap, identity_map
from ..limit import LIMIT_POLICIES, enforce_limit
from .stage import CParts, LawContext, Signals, Stage, register

__all__ = ["Limit"]


@register
class Limit(Stage):
    """``clip(d_f, -a_max, a_max)`` (policy ``"clip"``) or a refusal (``"refuse"``) beyond the limit.

    Its linear map is the identity: the law where the signal stays inside the limit (the
    whole-trial check is of the law without clipping). Its C clips ``d_next`` in place and returns
    ``LEARN_CLIPPED``, or (``"refuse"``) leaves it and returns ``LEARN_BEYOND_LIMIT``.

    Parameters
    ----------
    limits : LimitSpec
        The learning vehicle's limit (``max_acceleration``, m/s^2).
    policy : {"clip", "refuse"}
        What to do beyond it.
    what : str
        What the signal is, for the messages.
    band_text : str
        The learning band used, for the messages.
    """

    kind = "limit"
    place = 80
    keys = ("limit",)

    def __init__(self, limits: LimitSpec, policy: str = "clip", what: str = "learning signal", band_text: str = ""):
        if policy not in LIMIT_POLICIES:
            raise SpecError(f"`on_limit`: got {policy!r}, expected one of {list(LIMIT_POLICIES)}")
        self.limits, self.policy, self.what, self.band_text = limits, policy, what, band_text

    @staticmethod
    def entry(limits: LimitSpec, policy: str) -> dict[str, Any]:
        """The ``limit`` entry of ``filters.json`` for a vehicle's limit and the policy.

        Parameters
        ----------
        limits : LimitSpec
            The learning vehicle's limit.
        policy : {"clip", "refuse"}
            What to do beyond it.
        """
        return {"acceleration_m_s2": limits.max_acceleration, "from": limits.describe(), "on_limit": policy}

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext) -> "Limit | None":  # noqa: D102
        if ctx.on_limit == "off":
            return None
        band = ctx.band.describe() if ctx.band is not None else _band_text(filters.get("band"))
        if ctx.limits is not None:
            return cls(ctx.limits, ctx.on_limit or "clip", ctx.what, band)
        entry = filters.get("limit")
        if entry is None:
            return None
        if not isinstance(entry, dict):
            raise SpecError(f"`limit`: got {entry!r:.80}, expected a mapping such as {{'acceleration_m_s2': 6.7}}")
        accel = entry.get("acceleration_m_s2")
        if accel is None:
            return None
        if isinstance(accel, bool) or not isinstance(accel, (int, float)) or not (math.isfinite(accel) and accel > 0):
            raise SpecError(f"`limit.acceleration_m_s2`: got {accel!r:.80}, expected the learning vehicle's "
                            "acceleration limit, a number > 0 (m/s^2)")
        policy = ctx.on_limit or entry.get("on_limit", "clip")
        if policy not in LIMIT_POLICIES:
            raise SpecError(f"`limit.on_limit`: got {policy!r:.80}, expected one of {list(LIMIT_POLICIES)}")
        return cls(LimitSpec(acceleration=float(accel)), policy, ctx.what, band)

    def to_dict(self) -> dict[str, Any]:  # noqa: D102 - Stage.to_dict
        return {"limit": self.entry(self.limits, self.policy)}

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        d_f, notes["limit"] = enforce_limit(x[0], self.limits, self.policy, self.what, self.band_text)
        return (d_f,)

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:  # noqa: D102 - Stage.linear_map
        return identity_map(m, "inside the limit")

    def c_parts(self, prefix: str) -> CParts:  # noqa: D102 - Stage.c_parts
        macro, limit = prefix.upper(), self.limits.max_acceleration
        clip = self.policy == "clip"
        code = f"{macro}LEARN_CLIPPED" if clip else f"{macro}LEARN_BEYOND_LIMIT"
        step = ("    {\n        size_t beyond = 0;\n\n        for (k = 0; k < n; ++k)\n"
                f"            if (df_next[k] > {macro}ACCELERATION_LIMIT || df_next[k] < -{macro}ACCELERATION_LIMIT) {{\n"
                "                ++beyond;\n"
                + (f"                df_next[k] = df_next[k] > 0.0 ? {macro}ACCELERATION_LIMIT : "
                   f"-{macro}ACCELERATION_LIMIT;\n" if clip else "")
                + f"            }}\n        if (beyond)\n            return {code};\n    }}\n")
        macros = (f"#define {macro}ACCELERATION_LIMIT {limit!r} /* m/s^2, of the learning vehicle: |d_next| must "
                  "stay below it */\n"
                  + (f"#define {macro}LEARN_CLIPPED 3 /* learn: d_next clipped to the acceleration limit */\n" if clip
                     else f"#define {macro}LEARN_BEYOND_LIMIT 4 /* learn: d_next beyond the acceleration limit, not "
                          "to be flown */\n"))
        action = ("clips d_next to it and returns " + code if clip else
                  "leaves d_next as computed and returns " + code + " (do not fly it)")
        note = (f" * Beyond the learning vehicle's acceleration limit ({macro}ACCELERATION_LIMIT, filters.json\n"
                f" * `limit`, on_limit {self.policy!r}) learn {action};\n"
                " * an exact-reference correction, added after learn, is not checked.\n")
        readme = (f"Beyond the acceleration limit ({limit:.4g} m/s^2, `limit` in `filters.json`, on_limit "
                  f"'{self.policy}') `learn` " + ("clips `d_next` to it and returns `LEARN_CLIPPED`." if clip else
                                                  "returns `LEARN_BEYOND_LIMIT` (do not fly `d_next`)."))
        return CParts(step=step, macros=macros, note=note, readme=readme)


def _band_text(entry: object) -> str:
    """One line on the band of a ``filters.json`` entry, for the limit's messages."""
    if not isinstance(entry, dict):
        return ""
    cutoff = entry.get("cutoff_rad_s")
    if isinstance(cutoff, (int, float)) and not isinstance(cutoff, bool):
        return f"{cutoff:.4g} rad/s ({entry.get('source', '')}; {entry.get('reason', '')})"
    return f"off: {entry.get('reason', '')}" if entry.get("reason") else "off"
