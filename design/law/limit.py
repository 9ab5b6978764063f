"""A learning signal a vehicle can fly: the acceleration limit of the learning vehicle.

The learning signal is fed forward as a commanded acceleration (m/s^2). A multirotor makes
horizontal acceleration by tilting, so it can fly at most ``g tan(tilt limit)``
(:class:`ilcdob.specs.LimitSpec`). A learning signal beyond that holds the vehicle at its
tilt limit for as long as it lasts: the feedback loop loses its authority and the flight
ends far off the reference. The usual cause is sensor noise through the plant inverse of the
learning filters (a learning band too wide, :mod:`ilcdob.design.filters.band`).

:func:`enforce_limit` checks a learning signal against the limit and, by policy, clips it
with a :class:`LearningLimitWarning` naming the peak, the limit, the samples beyond it and
the likely cause, or refuses it with :class:`LearningLimitError`.

:class:`Limit` is the limit as the law's last stage (docs/theory.md section 6): in Python and in
the C ``learn`` a learning signal beyond it is clipped (with a warning) or refused.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ilcdob.errors import LearningLimitError, LearningLimitWarning, SpecError
from ilcdob.signals import as_signal
from ilcdob.specs import LimitSpec

from ..maps.finite_horizon import LinearMap, identity_map
from .stage import CParts, LawContext, Signals, Stage, register

__all__ = ["LimitReport", "LearningLimitError", "LearningLimitWarning", "enforce_limit", "LIMIT_POLICIES", "Limit"]

#: What to do with a learning signal beyond the limit: clip it (with a warning) or refuse it.
LIMIT_POLICIES = ("clip", "refuse")


@dataclass(frozen=True)
class LimitReport:
    """A learning signal against the learning vehicle's acceleration limit.

    Attributes
    ----------
    limit : float
        The limit, m/s^2.
    limit_text : str
        The limit and where it comes from (:meth:`ilcdob.specs.LimitSpec.describe`).
    peak : float
        Peak ``|d_f|`` before any clipping, m/s^2.
    rms : float
        RMS of ``d_f`` before clipping, m/s^2.
    beyond : int
        Samples beyond the limit.
    clipped : bool
        The signal handed back was clipped to the limit.
    """

    limit: float
    limit_text: str
    peak: float
    rms: float
    beyond: int
    clipped: bool

    def to_dict(self) -> dict[str, object]:
        """The report as JSON values (m/s^2)."""
        return {"limit_m_s2": self.limit, "limit": self.limit_text, "peak_m_s2": self.peak, "rms_m_s2": self.rms,
                "samples_beyond": self.beyond, "clipped": self.clipped}


def enforce_limit(d_f: object, limits: LimitSpec | None, policy: str = "clip", what: str = "learning signal",
                  band_text: str = "") -> tuple[np.ndarray, LimitReport | None]:
    """Check ``d_f`` against the acceleration limit; clip (with a warning) or refuse it beyond.

    Parameters
    ----------
    d_f : array, m/s^2
        The learning signal.
    limits : LimitSpec or None
        The learning vehicle's limits (None: nothing to check; ``d_f`` is returned as is).
    policy : {"clip", "refuse"}
        Beyond the limit: clip to ``[-limit, limit]`` with a :class:`LearningLimitWarning`,
        or raise :class:`LearningLimitError`.
    what : str
        What the signal is (e.g. ``"learning signal of UAV2 from UAV1"``), for the messages.
    band_text : str
        The learning band used (:meth:`ilcdob.design.filters.band.LearningBand.describe`), for the
        messages.

    Returns
    -------
    (numpy.ndarray, LimitReport or None)
        The signal (clipped if it had to be) and the report.

    Raises
    ------
    LearningLimitError
        ``policy="refuse"`` and the signal exceeds the limit.
    SpecError
        Unknown policy.
    """
    if policy not in LIMIT_POLICIES:
        raise SpecError(f"`on_limit`: got {policy!r}, expected one of {list(LIMIT_POLICIES)}")
    d_f = as_signal(d_f, "d_f")
    if limits is None:
        return d_f, None
    lim = limits.max_acceleration
    peak = float(np.max(np.abs(d_f), initial=0.0))
    beyond = int(np.sum(np.abs(d_f) > lim))
    report = LimitReport(lim, limits.describe(), peak, float(np.sqrt(np.mean(d_f ** 2))) if d_f.size else 0.0,
                         beyond, False)
    if not beyond:
        return d_f, report
    msg = (f"{what}: peaks at {peak:.4g} m/s^2 (RMS {report.rms:.3g}), beyond the acceleration limit "
           f"{report.limit_text} on {beyond} of {d_f.size} samples; likely cause: "
           + _likely_cause(np.flatnonzero(np.abs(d_f) > lim), d_f.size, band_text))
    if policy == "refuse":
        raise LearningLimitError(msg + "; refused (--on-limit refuse)")
    warnings.warn(msg + "; clipped to the limit (--on-limit refuse to stop instead)", LearningLimitWarning,
                  stacklevel=2)
    return np.clip(d_f, -lim, lim), LimitReport(lim, report.limit_text, peak, report.rms, beyond, True)


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


#: Where every sample beyond the limit lies within this share of a trial's first (or last) samples (at least
#: three, on trials of 100 samples or more), the limit's message names the trial's start (end) as the cause.
EDGE_SHARE = 0.01


def _likely_cause(beyond: np.ndarray, n: int, band_text: str) -> str:
    """The cause the limit's message names for the samples ``beyond`` it (indices) of an ``n``-sample signal."""
    edge = max(3, int(EDGE_SHARE * n))
    if n >= 100 and beyond.max() < edge:
        return (f"the trial's start (all in its first {edge} samples): its error is not at rest at t = 0, a step "
                "that the plant inverse of the learning filter turns into a spike; start the recording with the "
                "vehicle at rest on its path, or cut the first samples (--start)")
    if n >= 100 and beyond.min() >= n - edge:
        return (f"the trial's end (all in its last {edge} samples): its error has not settled when the recording "
                "stops; record past the end of the manoeuvre, or cut the last samples (--stop)")
    return (f"sensor noise through the plant inverse of the learning filter (learning band {band_text or 'not stated'}"
            "): lower the band (--bandwidth RAD_S), give the sensor noise, or check the trial for spikes and steps")


def _band_text(entry: object) -> str:
    """One line on the band of a ``filters.json`` entry, for the limit's messages."""
    if not isinstance(entry, dict):
        return ""
    cutoff = entry.get("cutoff_rad_s")
    if isinstance(cutoff, (int, float)) and not isinstance(cutoff, bool):
        return f"{cutoff:.4g} rad/s ({entry.get('source', '')}; {entry.get('reason', '')})"
    return f"off: {entry.get('reason', '')}" if entry.get("reason") else "off"
