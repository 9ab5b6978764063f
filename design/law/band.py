"""The learning band's two stages: the trial extended and filtered before the method's filter,
filtered again and folded onto the trial after it (docs/theory.md section 6; :mod:`..filters.band`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal as sps

from ilcdob.errors import SpecError

from ..filters.band import fold_start, learning_horizon
from ..filters.entries import check_count, check_sections
from ..maps.finite_horizon import LinearMap, extension_map, fold_map, sos_map
from ..filters.c_text import DOUBLE, array_c
from .stage import CParts, LawContext, Signals, Stage, diag_maps, register

__all__ = ["BandSpec", "BandIn", "BandOut", "band_spec", "check_cutoff", "forward_backward"]


@dataclass(frozen=True)
class BandSpec:
    """The band of ``filters.json`` (key ``band``), checked.

    Attributes
    ----------
    entry : dict
        The entry as written (:meth:`~ilcdob.design.filters.band.LearningBand.to_dict`).
    sos, zi : numpy.ndarray
        One pass of F and its steady state per unit input.
    pad, end_fit : int
        Samples added at each end; samples the end's line is fitted to.
    cutoff : float or None
        F's corner, rad/s (None: not stated; the law runs without it, the C text needs it).
    order : int or None
        F's Butterworth order, when stated.
    why : str
        The band's reason, for the README.
    fold : bool
        The learning signal before ``t = 0`` folded onto the first samples (else cropped).
    rest : bool
        The output pass starts its forward filter from rest (key ``output_start``: ``"rest"``), else from the
        steady state of its first sample (``"first sample"``, files written before the key).
    """

    entry: dict[str, Any]
    sos: np.ndarray
    zi: np.ndarray
    pad: int
    end_fit: int
    cutoff: float | None
    order: int | None
    why: str
    fold: bool
    rest: bool = False


def band_spec(filters: dict[str, Any], ctx: LawContext | None = None) -> BandSpec | None:
    """The checked band of ``filters.json``, None without a filter.

    Parameters
    ----------
    filters : dict
        ``filters.json`` content (its ``band`` entry).
    ctx : LawContext, optional
        ``ctx.band``, a LearningBand, in place of the file's entry.

    Returns
    -------
    BandSpec or None

    Raises
    ------
    SpecError
        A ``band`` entry of the wrong type, shape or value, naming its key.
    """
    band = ctx.band.to_dict() if ctx is not None and ctx.band is not None else filters.get("band")
    if band is None:
        return None
    if not isinstance(band, dict):
        raise SpecError(f"`band`: got {band!r:.80}, expected a mapping (LearningBand.to_dict)")
    cutoff = band.get("cutoff_rad_s")
    if band.get("sos") is None:
        if cutoff is not None:
            raise SpecError(f"`band.sos`: missing, but `band.cutoff_rad_s` is {cutoff!r}; expected the sections of "
                            "the band's filter F (or cutoff_rad_s None: no filter)")
        return None
    sos = check_sections(band["sos"], "band.sos")
    try:
        zi = np.asarray(band.get("zi"), dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"`band.zi`: got {band.get('zi')!r:.80}, expected {sos.shape[0]} rows of 2 "
                        "numbers (scipy.signal.sosfilt_zi of `band.sos`)") from None
    if zi.shape != (sos.shape[0], 2):
        raise SpecError(f"`band.zi`: got shape {zi.shape}, expected ({sos.shape[0]}, 2) for "
                        f"{sos.shape[0]} section(s) in `band.sos` (scipy.signal.sosfilt_zi)")
    if not np.all(np.isfinite(zi)):
        raise SpecError("`band.zi`: non-finite value(s); expected finite numbers (scipy.signal.sosfilt_zi)")
    pad = check_count(band.get("pad"), "band.pad", 0)
    end_fit = check_count(band.get("end_fit"), "band.end_fit", 1)
    if cutoff is not None:
        check_cutoff(cutoff)
    if band.get("start", "crop") not in ("crop", "fold"):
        raise SpecError(f"`band.start`: got {band.get('start')!r:.80}, expected 'fold' (the part before t = 0 "
                        "added, time-reversed, to the first samples) or 'crop'")
    start = band.get("output_start", "first sample")
    if start not in ("rest", "first sample"):
        raise SpecError(f"`band.output_start`: got {start!r:.80}, expected 'rest' (the output pass of F starts from "
                        "rest) or 'first sample' (from the steady state of its first sample)")
    return BandSpec(band, sos, zi, pad, end_fit, None if cutoff is None else float(cutoff),
                    band.get("order") if isinstance(band.get("order"), int) else None,
                    str(band.get("reason") or band.get("source") or ""), band.get("start") == "fold", start == "rest")


def check_cutoff(cutoff: object) -> float:
    """The band's corner ``band.cutoff_rad_s``, checked.

    Parameters
    ----------
    cutoff : object
        The entry.

    Raises
    ------
    SpecError
        Not a finite number > 0 (rad/s).
    """
    if isinstance(cutoff, bool) or not isinstance(cutoff, (int, float)) or not (math.isfinite(cutoff) and cutoff > 0):
        raise SpecError(f"`band.cutoff_rad_s`: got {cutoff!r}, expected the corner of `band.sos`, a "
                        "frequency > 0 rad/s")
    return float(cutoff)


def forward_backward(sos: np.ndarray, zi: np.ndarray, x: np.ndarray, rest: bool = False) -> np.ndarray:
    """One zero-phase pass: ``sos`` forwards from the state ``zi x[0]`` (from rest if ``rest``), then backwards
    from ``zi y[-1]`` (what ``scipy.signal.sosfiltfilt(..., padtype=None)`` computes, ``rest`` False).

    Parameters
    ----------
    sos : numpy.ndarray
        Second-order sections.
    zi : numpy.ndarray
        Their steady state per unit input (``scipy.signal.sosfilt_zi``).
    x : numpy.ndarray
        The signal (at least one sample).
    rest : bool
        Start the forward filter from rest: the signal is zero before ``x[0]`` (the learning signal before the
        extended horizon, docs/theory.md section 6).
    """
    y, _ = sps.sosfilt(sos, x, zi=zi * (0.0 if rest else x[0]))
    y, _ = sps.sosfilt(sos, y[::-1], zi=zi * y[-1])
    return y[::-1]


def _zero_phase_map(spec: BandSpec, m: int, rest: bool = False) -> LinearMap:
    """One forward-backward pass of F over ``m`` samples (:func:`forward_backward`) as a linear map."""
    phi = sps.sosfilt(spec.sos, np.zeros(m), zi=spec.zi)[0]
    causal = sos_map(spec.sos, m, "F")

    def f(x: np.ndarray) -> np.ndarray:  # from the steady state of the first sample
        return causal(x) + phi * x[0]

    def ft(y: np.ndarray) -> np.ndarray:
        out = causal.T(y)
        out[0] += float(phi @ y)
        return out

    first, first_t = (causal, causal.T) if rest else (f, ft)
    return LinearMap(m, m, lambda x: f(first(x)[::-1])[::-1], lambda y: first_t(ft(y[::-1])[::-1]), "F")


class _Band(Stage):
    """What both halves of the band share: the spec and its ``filters.json`` entry.

    Parameters
    ----------
    spec : BandSpec
        The checked band.
    """

    keys = ("band",)

    def __init__(self, spec: BandSpec):
        self.spec = spec

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext) -> "_Band | None":  # noqa: D102
        spec = band_spec(filters, ctx)
        return None if spec is None else cls(spec)

    def to_dict(self) -> dict[str, Any]:  # noqa: D102 - Stage.to_dict
        return {"band": self.spec.entry}


@register
class BandIn(_Band):
    """``F{H{x}}`` on every signal: the trial extended by ``pad`` samples at each end (zeros
    before, the line through its last ``end_fit`` samples after), then F forwards and backwards."""

    kind = "band in"
    place = 30

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        s = self.spec
        return tuple(forward_backward(s.sos, s.zi, learning_horizon(v, 1.0, s.pad, s.end_fit)) if np.any(v)
                     else np.zeros(v.size + 2 * s.pad) for v in x)

    def shape(self, m: int, k: int, n: int) -> tuple[int, int]:  # noqa: D102 - Stage.shape
        return m + 2 * self.spec.pad, k

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:  # noqa: D102 - Stage.linear_map
        pad = self.spec.pad
        one = _zero_phase_map(self.spec, m + 2 * pad) @ extension_map(m, pad, pad, self.spec.end_fit, 1)
        return diag_maps(one, k)

    def c_parts(self, prefix: str) -> CParts:  # noqa: D102 - Stage.c_parts
        s, macro = self.spec, prefix.upper()
        cutoff = check_cutoff(s.cutoff)
        ns = s.sos.shape[0]
        what = f"Butterworth order {s.order}, " if s.order else ""
        tables = (f"\n/* F, the learning band: one pass, {ns} second-order section{'s' if ns > 1 else ''} "
                  f"({what}corner {cutoff:.6g} rad/s),\n   rows b0 b1 b2 a0 a1 a2 (a0 = 1); zi: its state "
                  "per unit input at rest (scipy.signal.sosfilt_zi). */\n"
                  + array_c(DOUBLE, f"{prefix}band_sos", s.sos) + array_c(DOUBLE, f"{prefix}band_zi", s.zi))
        helpers = _BAND_PASS_C.format(p=prefix, ns=ns) + (_HORIZON_C if s.pad else _NO_HORIZON_C).format(
            p=prefix, m=macro)
        step = (f"    {prefix}horizon(e, n, a);   /* e and df_prev are read before df_next is written */\n"
                f"    {prefix}horizon(df_prev, n, b);\n"
                f"    {prefix}band_pass(a, len, 0);\n    {prefix}band_pass(b, len, 0);\n")
        return CParts(tables, helpers, step, sections=True, loads=True)


@register
class BandOut(_Band):
    """``fold(F{y})``: F forwards and backwards over the extended learning signal, the trial's
    samples kept and the part before ``t = 0`` added time-reversed to the first ``pad``."""

    kind = "band out"
    place = 60

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        s = self.spec
        z = forward_backward(s.sos, s.zi, x[0], s.rest)
        return (fold_start(z, s.pad, n) if s.fold else z[s.pad:s.pad + n],)

    def shape(self, m: int, k: int, n: int) -> tuple[int, int]:  # noqa: D102 - Stage.shape
        return n, k

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:  # noqa: D102 - Stage.linear_map
        return fold_map(self.spec.pad, n, self.spec.fold) @ _zero_phase_map(self.spec, m, self.spec.rest)

    def c_parts(self, prefix: str) -> CParts:  # noqa: D102 - Stage.c_parts
        macro = prefix.upper()
        step = (f"    {prefix}band_pass(a, len, {int(self.spec.rest)});\n"
                f"    for (k = 0; k < n; ++k)\n        df_next[k] = a[{macro}PAD + k];\n")
        if self.spec.fold:
            step += (f"    /* fold: the part before t = 0, time-reversed, onto the first samples */\n"
                     f"    for (k = 0; k < n && k < (size_t){macro}PAD; ++k)\n"
                     f"        df_next[k] += a[{macro}PAD - 1 - k];\n")
        return CParts(step=step, stores=True)


_BAND_PASS_C = """
/* One zero-phase pass of F over x[0..n) in place, n >= 1: forwards from the state zi x[0] (from rest if
   from_rest), then backwards from zi y[n-1] (scipy.signal.sosfiltfilt with padtype=None). */
static void {p}band_pass(double *x, size_t n, int from_rest)
{{
    const double x0 = from_rest ? 0.0 : x[0];
    double z[{ns}][2];
    size_t i;

    for (i = 0; i < {ns}; ++i) {{
        z[i][0] = {p}band_zi[i][0] * x0;
        z[i][1] = {p}band_zi[i][1] * x0;
    }}
    {p}sections({p}band_sos, {ns}, z, x, n, 0);
    for (i = 0; i < {ns}; ++i) {{
        z[i][0] = {p}band_zi[i][0] * x[n - 1];
        z[i][1] = {p}band_zi[i][1] * x[n - 1];
    }}
    {p}sections({p}band_sos, {ns}, z, x, n, 1);
}}
"""

_HORIZON_C = """
/* H: x[0..n), n >= 1, extended by PAD = {m}PAD samples at each end into
   h[0..n + 2 PAD): zeros before; after the end the least-squares line through the last
   m = min(END_FIT, n) samples, END_FIT = {m}END_FIT (numpy.polyfit of degree 1 in
   ilcdob.design.filters.band.learning_horizon; m = 1: the last sample), here on the centred abscissa
   t_i = i - (m - 1)/2, i = 0..m-1: mean + slope t. */
static void {p}horizon(const double *x, size_t n, double *h)
{{
    const size_t m = n < {m}END_FIT ? n : {m}END_FIT;
    const double *u = x + (n - m);
    const double half = 0.5 * (double)(m - 1);
    double s_x = 0.0, s_tt = 0.0, s_tx = 0.0, mean, slope = 0.0;
    size_t i;

    for (i = 0; i < m; ++i) {{
        const double t = (double)i - half;
        s_x = s_x + u[i];
        s_tt = s_tt + t * t;
        s_tx = s_tx + t * u[i];
    }}
    mean = s_x / (double)m;
    if (m > 1)
        slope = s_tx / s_tt;
    for (i = 0; i < {m}PAD; ++i)
        h[i] = 0.0;
    for (i = 0; i < n; ++i)
        h[{m}PAD + i] = x[i];
    for (i = 0; i < {m}PAD; ++i)
        h[{m}PAD + n + i] = mean + slope * ((double)(m + i) - half);
}}
"""

_NO_HORIZON_C = """
/* H with {m}PAD = 0: the trial as it is. */
static void {p}horizon(const double *x, size_t n, double *h)
{{
    size_t i;

    for (i = 0; i < n; ++i)
        h[i] = x[i];
}}
"""
