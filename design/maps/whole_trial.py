"""The whole-trial figure of a learning law over the stated set's extreme plants (docs/theory.md section 6).

A per-frequency guarantee (:mod:`..methods.robust_set`, :mod:`..checks.theorem`) holds for signals over an infinite
horizon. A vehicle flies a trial of ``N`` samples, and near its ends a non-causal law acts on samples that do not
exist. This module flies whole trials through the loops' lifted maps (:class:`~..maps.finite_horizon.PairTrials`)
for the plants at the edge of the source's stated set and for the disturbances that meet a trial's ends, and
reports the worst ratio ``||e_j|| / ||e'_j||`` among them, with the plant and disturbance that reach it.

The plants of system j-1, ``P = (1 + Delta) P_hat`` with the stated bound ``B`` (continuous, sampled with the loop's
zero-order hold): the model itself; the gains ``Delta = +-B``; the all-pass errors ``Delta(s) = +-B (a - s)/(a + s)``
(``|Delta(jw)| = B`` at every frequency, every phase at the corner ``a``) at the worst frequency of the per-frequency
figure and at corners log-spaced over the band where loops act (:data:`CORNERS`). The disturbances (the same at both
vehicles, from rest): a gust (``1 - cos`` pulse) over the trial's last and over its first :data:`GUST_S` seconds, a
sinusoid at each worst frequency switched on at ``t = 0``, and a constant (a wind that blows all trial).

This is a figure over stated members, not a bound over every disturbance: over every disturbance a trial's ratio is
at least 1 whenever the source's relative degree exceeds the target's (a disturbance in the last samples reaches
the target's error, never the source's), so no law keeps ``rho < 1`` there; docs/theory.md section 6 gives the
argument and the measured figures.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from ilcdob.channel_loop import ChannelLoop, channel_loop
from ilcdob.errors import SpecError, UnstableLoopError
from ilcdob.loop import LoopSystem, build_loop
from ilcdob.specs import PlantSpec

from .finite_horizon import PairTrials

__all__ = ["CORNERS", "GUST_S", "INSIDE", "WholeTrialFigure", "stress_plants", "family_members", "stress_disturbances",
           "whole_trial_figure"]

#: Corners (rad/s) of the all-pass errors beside the worst frequencies, kept below a third of Nyquist.
CORNERS = (0.3, 1.0, 3.0, 10.0, 30.0)
#: Length of the gusts at the trial's ends, s (at most a quarter of the trial).
GUST_S = 3.0
#: Where a structured family's admissible range ends at a stability or margin limit (not at the bound), its member
#: is taken at this share of the limit: the limits are found on a grid, within 1 % (:func:`family_members`).
INSIDE = 0.97


@dataclass(frozen=True)
class WholeTrialFigure:
    """The worst whole-trial ratio over the stated members (module docstring).

    Attributes
    ----------
    ratio : float
        The largest ``||e_j|| / ||e'_j||`` over every plant and disturbance flown (nan if every plant was skipped).
    plant, disturbance : str
        Where it is reached.
    duration_s : float
        Trial length, s.
    ts : float
        Sample time, s.
    ratios : numpy.ndarray
        ``(plants, disturbances)`` ratios.
    plants, disturbances : list of str
        Their labels.
    skipped : list of str
        Plants left out, with why (outside the set the guarantee covers).
    """

    ratio: float
    plant: str
    disturbance: str
    duration_s: float
    ts: float
    ratios: np.ndarray = field(repr=False)
    plants: list[str] = field(default_factory=list)
    disturbances: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON fields: the worst, where, and the worst per disturbance."""
        return {"ratio": self.ratio, "worst_plant": self.plant, "worst_disturbance": self.disturbance,
                "duration_s": self.duration_s, "plants": len(self.plants),
                "worst_per_disturbance": {d: float(np.max(self.ratios[:, k])) for k, d in enumerate(self.disturbances)
                                          if self.plants},
                "skipped_plants": list(self.skipped)}


def stress_plants(model: PlantSpec, bound: float, corners: list[float]) -> list[tuple[str, PlantSpec]]:
    """The stated set's extreme members: the model, the gains ``1 +- B``, the all-pass errors ``+-B`` at ``corners``.

    Parameters
    ----------
    model : PlantSpec
        ``P_hat``, continuous.
    bound : float
        The stated bound ``B`` (>= 0).
    corners : list of float
        All-pass corners, rad/s (> 0).

    Returns
    -------
    list of (str, PlantSpec)
        Label and plant.

    Raises
    ------
    SpecError
        A negative or non-finite bound, or a corner <= 0.
    """
    if not (np.isfinite(bound) and bound >= 0):
        raise SpecError(f"`bound`: got {bound!r}, expected a stated model-error bound >= 0")
    if any(not (np.isfinite(a) and a > 0) for a in corners):
        raise SpecError(f"`corners`: got {list(corners)}, expected all-pass corners > 0 rad/s")
    num, den = np.asarray(model.num, float), np.asarray(model.den, float)
    out = [("model", model)]
    if bound == 0:
        return out
    for sign in (1.0, -1.0):
        out.append((f"gain {1 + sign * bound:g}", PlantSpec(tuple(num * (1 + sign * bound)), model.den, model.delay)))
    for a in corners:
        for sign in (1.0, -1.0):  # 1 + s B (a - s)/(a + s) = ((1 - s B) s + (1 + s B) a)/(s + a)
            b = sign * bound
            out.append((f"all-pass {'+' if sign > 0 else '-'}{bound:g} at {a:.3g} rad/s",
                        PlantSpec(tuple(np.polymul(num, [1 - b, (1 + b) * a])), tuple(np.polymul(den, [1.0, a])),
                                  model.delay)))
    return out


def family_members(model: PlantSpec, bound: float, taus: list[float], lo: np.ndarray,
                   hi: np.ndarray) -> list[tuple[str, PlantSpec]]:
    """A structured family's extreme members: the model, and per error shape (the gain ``Delta = r``, the
    high-pass errors ``Delta(s) = r s tau/(s tau + 1)``) the two ends of its admissible ``r``.

    ``r`` runs over ``[max(-B, lo), min(B, hi)]``; an end set by ``lo`` or ``hi`` (a stability or margin limit) is
    taken at :data:`INSIDE` of it, inside the set the guarantee covers.

    Parameters
    ----------
    model : PlantSpec
        ``P_hat``, continuous.
    bound : float
        The family's ``|r| <= B`` (> 0).
    taus : list of float
        High-pass time constants, s (> 0).
    lo, hi : numpy.ndarray
        ``1 + len(taus)`` admissible limits, the gain's first
        (:func:`~ilcdob.design.sets.value_set.admissible_range`).

    Returns
    -------
    list of (str, PlantSpec)
        Label and plant.

    Raises
    ------
    SpecError
        A bound <= 0, a time constant <= 0, or limits of another length.
    """
    if not (np.isfinite(bound) and bound > 0):
        raise SpecError(f"`bound`: got {bound!r}, expected a family bound > 0")
    if any(not (np.isfinite(t) and t > 0) for t in taus):
        raise SpecError(f"`taus`: got {list(taus)}, expected high-pass time constants > 0 s")
    lo, hi = np.asarray(lo, float).reshape(-1), np.asarray(hi, float).reshape(-1)
    if lo.size != len(taus) + 1 or hi.size != lo.size:
        raise SpecError(f"`lo`, `hi`: got {lo.size} and {hi.size} limits, expected {len(taus) + 1} (the gain's, then "
                        "one per time constant)")
    num, den = np.asarray(model.num, float), np.asarray(model.den, float)
    out = [("model", model)]
    for k, tau in enumerate([None, *taus]):
        for r in (-bound if lo[k] <= -bound else INSIDE * lo[k], bound if hi[k] >= bound else INSIDE * hi[k]):
            if tau is None:
                out.append((f"gain {1 + r:.4g}", PlantSpec(tuple(num * (1 + r)), model.den, model.delay)))
            else:  # 1 + r s tau/(s tau + 1) = ((1 + r) tau s + 1)/(tau s + 1)
                out.append((f"high-pass {r:+.4g} at tau {tau:.3g} s",
                            PlantSpec(tuple(np.polymul(num, [(1 + r) * tau, 1.0])), tuple(np.polymul(den, [tau, 1.0])),
                                      model.delay)))
    return out


def stress_disturbances(n: int, ts: float, w_worst: list[float]) -> list[tuple[str, np.ndarray]]:
    """Gusts over the trial's last and first :data:`GUST_S` seconds, sinusoids at ``w_worst`` from ``t = 0``,
    a constant.

    Parameters
    ----------
    n : int
        Samples of the trial.
    ts : float
        Sample time, s.
    w_worst : list of float
        Frequencies of the sinusoids, rad/s.

    Returns
    -------
    list of (str, numpy.ndarray)
        Label and disturbance (unit peak, m/s^2).
    """
    t = np.arange(n) * ts
    k = max(2, min(int(round(GUST_S / ts)), n // 4))
    pulse = 0.5 * (1 - np.cos(2 * np.pi * np.arange(k) / (k - 1)))
    end, start = np.zeros(n), np.zeros(n)
    end[n - k:], start[:k] = pulse, pulse
    out = [(f"gust over the last {k * ts:.3g} s", end), (f"gust over the first {k * ts:.3g} s", start)]
    out += [(f"sin({w:.4g} t) from t = 0", np.sin(w * t)) for w in w_worst]
    out.append(("constant", np.ones(n)))
    return out


def _true_loops(source: LoopSystem | ChannelLoop) -> tuple[PlantSpec, Callable[[PlantSpec], Any]]:
    """The map the stated set perturbs (the plant model; a vehicle on its own controller: its channel map
    ``G_ch``) and the source's loop rebuilt around a true one of it."""
    if isinstance(source, ChannelLoop):
        return source.channel_plant(), lambda plant: channel_loop(
            source.name, source.ts, source.channel, plant, source.channel_gain, source.airframe, source.dob,
            source.identification, source.reference_map)
    spec = source.nominal.spec
    model = spec.model or spec.plant
    return model, lambda plant: build_loop(replace(spec, plant=plant, model=model), source.ts)


def whole_trial_figure(law: Callable[[np.ndarray], np.ndarray], source: LoopSystem | ChannelLoop,
                       target: LoopSystem | ChannelLoop,
                       bound: float, w_worst: list[float], duration_s: float,
                       keep: Callable[[LoopSystem], str] | None = None,
                       members: list[tuple[str, PlantSpec]] | None = None) -> WholeTrialFigure:
    """Fly whole trials of ``law`` for the stated set's extreme plants of the source (module docstring).

    Parameters
    ----------
    law : callable
        ``e'_{j-1} -> d_f,j`` over a trial of ``round(duration_s / Ts)`` samples (e.g. a :class:`LinearMap`).
    source, target : LoopSystem or ChannelLoop
        Systems j-1 and j; their models are used (the target's plant does not enter the ratio per frequency). For a
        vehicle on its own controller the stated set perturbs its channel map ``G_ch``.
    bound : float
        The source's stated bound ``B`` on ``|Delta(jw)|``.
    w_worst : list of float
        Worst frequencies of the per-frequency figure, rad/s: the all-pass corners and sinusoids there.
    duration_s : float
        Trial length, s.
    keep : callable, optional
        ``true source loop -> reason`` ("" keeps the plant): the plants a guarantee covers (e.g. a stability margin).
    members : list of (str, PlantSpec), optional
        The source's plants to fly in place of :func:`stress_plants` of ``bound`` (e.g. :func:`family_members`).

    Returns
    -------
    WholeTrialFigure

    Raises
    ------
    SpecError
        A trial shorter than 10 samples.
    """
    ts = source.ts
    n = int(round(duration_s / ts))
    if n < 10:
        raise SpecError(f"`duration_s`: got {duration_s!r} s, expected a trial of at least 10 samples of {ts:g} s")
    nyq = np.pi / ts
    w_worst = [float(w) for w in w_worst if 0 < w < nyq]
    corners = sorted({*w_worst, *(a for a in CORNERS if a < nyq / 3)})
    model, true_loop = _true_loops(source)
    base = PairTrials(source.nominal, target.nominal, n)  # the target's maps, shared by every plant
    disturbances = stress_disturbances(n, ts, w_worst)
    rows, labels, skipped = [], [], []
    for label, plant in stress_plants(model, bound, corners) if members is None else members:
        try:
            loop = true_loop(plant)
        except UnstableLoopError:
            skipped.append(f"{label}: the source's DOB loop is unstable with it")
            continue
        why = keep(loop) if keep is not None else ""
        if why:
            skipped.append(f"{label}: {why}")
            continue
        trials = base.with_source(loop)
        rows.append([trials.ratio(law, d) for _, d in disturbances])
        labels.append(label)
    ratios = np.asarray(rows, float).reshape(len(labels), len(disturbances))
    if not labels:
        return WholeTrialFigure(float("nan"), "", "", n * ts, ts, ratios, [], [d for d, _ in disturbances], skipped)
    i, k = np.unravel_index(int(np.argmax(ratios)), ratios.shape)
    return WholeTrialFigure(float(ratios[i, k]), labels[i], disturbances[k][0], n * ts, ts, ratios, labels,
                            [d for d, _ in disturbances], skipped)
