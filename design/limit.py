"""A learning signal a vehicle can fly: the acceleration limit of the learning vehicle.

The learning signal is fed forward as a commanded acceleration (m/s^2). A multirotor makes
horizontal acceleration by tilting, so it can fly at most ``g tan(tilt limit)``
(:class:`ilcdob.specs.LimitSpec`). A learning signal beyond that holds the vehicle at its
tilt limit for as long as it lasts: the feedback loop loses its authority and the flight
ends far off the reference. The usual cause is sensor noise through the plant inverse of the
learning filters (a learning band too wide, :mod:`ilcdob.design.band`).

:func:`enforce_limit` checks a learning signal against the limit and, by policy, clips it
with a :class:`LearningLimitWarning` naming the peak, the limit, the samples beyond it and
the likely cause, or refuses it with :class:`LearningLimitError`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ilcdob.errors import LearningLimitError, LearningLimitWarning, SpecError
from ilcdob.signals import as_signal
from ilcdob.specs import LimitSpec

__all__ = ["LimitReport", "LearningLimitError", "LearningLimitWarning", "enforce_limit", "LIMIT_POLICIES"]

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
        The learning band used (:meth:`ilcdob.design.band.LearningBand.describe`), for the
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
           f"{report.limit_text} on {beyond} of {d_f.size} samples; likely cause: sensor noise through the plant "
           f"inverse of the learning filter (learning band {band_text or 'unknown'}): lower the band "
           "(--bandwidth RAD_S), give the sensor noise, or check the trial for spikes and steps")
    if policy == "refuse":
        raise LearningLimitError(msg + "; refused (--on-limit refuse)")
    warnings.warn(msg + "; clipped to the limit (--on-limit refuse to stop instead)", LearningLimitWarning,
                  stacklevel=2)
    return np.clip(d_f, -lim, lim), LimitReport(lim, report.limit_text, peak, report.rms, beyond, True)
