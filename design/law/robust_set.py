"""The robust-set law as a stage: ``(1 - Q_j){F{d_hat}}``, ``d_hat = -Gd_hat_{j-1}^{-1}{e + Gf_hat_{j-1}{d_f}}``,
from the maps ``filters.json`` records (docs/theory.md sections 3 and 6; :mod:`..methods.robust_set`)."""

from __future__ import annotations

from typing import Any

import control as ct
import numpy as np

from ilcdob.errors import SpecError

from ..filters.c_text import DOUBLE, array_c, state_space_c
from ..filters.entries import check_count, check_filter_entry, check_state_space
from ..filters.coefficients import apply_coefficients, apply_state_space, state_space_to_dict, zpk_to_coefficients
from ..maps.closed_form import LearningFilters, inverse_gd_filter, one_minus
from ..maps.finite_horizon import LinearMap, causal_map, fir_map, identity_map, trend_map
from ..filters.trial_edges import StartMatch, fir_on_trial
from .filters import coefficients_map
from .stage import CORE_PLACE, CParts, LawContext, Signals, Stage, hstack_maps, register

__all__ = ["RobustSetMaps", "state_space_map", "robust_set_maps"]


def state_space_map(ss: tuple[np.ndarray, ...], m: int, name: str) -> LinearMap:
    """A checked state-space entry run from rest over ``m`` samples as a linear map.

    Parameters
    ----------
    ss : tuple of numpy.ndarray
        ``(A, B, C, D)`` (:func:`~..filters.entries.check_state_space`).
    m : int
        Samples.
    name : str
        Its name.
    """
    a, b, c, d = ss
    if b.size == 0:
        return LinearMap(m, m, lambda x: d[0] * x, lambda y: d[0] * y, name)
    return causal_map(ct.ss(a, b.reshape(-1, 1), c.reshape(1, -1), d.reshape(1, 1), True), m, name)


@register
class RobustSetMaps(Stage):
    """The robust-set law from ``law_maps``, ``F`` and ``trial_ends`` of ``filters.json``.

    Parameters
    ----------
    entries : dict
        The three entries as written.
    h : numpy.ndarray
        The robustness FIR's taps.
    advance, fade : int
        Its look-ahead and the samples at the trial's end blended into the trend.
    ginv : dict
        ``Gd_hat_{j-1}^{-1}`` in coefficient form.
    gf, omq : tuple of numpy.ndarray
        ``Gf_hat_{j-1}`` and ``1 - Q_j`` as ``(A, B, C, D)``.
    start : StartMatch or None
        ``trial_ends.start``: ``F``'s output before ``t = 0`` continued over the first samples
        (:class:`~..filters.trial_edges.StartMatch`); absent (files written before it), folded onto them.
    """

    kind = "robust-set maps"
    place = CORE_PLACE
    keys = ("law_maps", "F", "trial_ends")

    def __init__(self, entries: dict[str, Any], h: np.ndarray, advance: int, fade: int, ginv: dict[str, Any],
                 gf: tuple[np.ndarray, ...], omq: tuple[np.ndarray, ...], start: StartMatch | None = None):
        self.entries, self.h, self.advance, self.fade = entries, h, advance, fade
        self.ginv, self.gf, self.omq, self.start = ginv, gf, omq, start

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext) -> "RobustSetMaps | None":  # noqa: D102
        maps = filters.get("law_maps")
        if maps is None:
            return None
        if not isinstance(maps, dict):
            raise SpecError(f"`law_maps`: got {maps!r:.80}, expected a mapping with source_gf, inverse_gd, "
                            "one_minus_q")
        fir, ends = filters.get("F"), filters.get("trial_ends")
        if not isinstance(fir, dict):
            raise SpecError(f"`F`: got {fir!r:.80}, expected the robustness FIR {{'num': [...], 'advance': samples}}")
        check_filter_entry({**fir, "den": [1.0]}, "F")
        h = np.asarray(fir["num"], dtype=float)
        if h.ndim != 1 or not h.size:
            raise SpecError(f"`F.num`: got {h.size} taps of shape {h.shape}, expected a list of at least one tap")
        if not isinstance(ends, dict):
            raise SpecError(f"`trial_ends`: got {ends!r:.80}, expected a mapping with `fade_samples`")
        fade = check_count(ends.get("fade_samples"), "trial_ends.fade_samples", 0)
        start = None if ends.get("start") is None else StartMatch.from_dict(ends["start"])
        check_filter_entry(maps.get("inverse_gd"), "law_maps.inverse_gd")
        return cls({k: filters[k] for k in cls.keys}, h, int(fir["advance"]), fade, maps["inverse_gd"],
                   check_state_space(maps.get("source_gf"), "law_maps.source_gf"),
                   check_state_space(maps.get("one_minus_q"), "law_maps.one_minus_q"), start)

    def to_dict(self) -> dict[str, Any]:  # noqa: D102 - Stage.to_dict
        return dict(self.entries)

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:  # noqa: D102 - Stage.apply
        maps = self.entries["law_maps"]
        e, df = x
        e_virtual = e + apply_state_space(maps["source_gf"], df) if np.any(df) else e
        d_hat = -apply_coefficients(self.ginv, e_virtual)
        return (apply_state_space(maps["one_minus_q"], fir_on_trial(d_hat, self.h, self.advance, self.fade,
                                                                             self.start)),)

    def shape(self, m: int, k: int, n: int) -> tuple[int, int]:  # noqa: D102 - Stage.shape
        return m, 1

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:  # noqa: D102 - Stage.linear_map
        a = self.advance
        steps = [-coefficients_map(self.ginv, m)]
        if a:
            steps.append(trend_map(m, a, self.fade))
        steps.append(fir_map(self.h, a, m, n_in=m + a, start=self.start))
        steps.append(state_space_map(self.omq, m, "1 - Q_j"))
        out = steps[0]
        for s in steps[1:]:
            out = s @ out
        eye = identity_map(m)
        return out @ hstack_maps([eye, state_space_map(self.gf, m, "Gf_hat_{j-1}")], "e + Gf d_f")

    def c_parts(self, prefix: str) -> CParts:  # noqa: D102 - Stage.c_parts
        return CParts(tables=_robust_c(prefix, self), step=f"    {prefix}rs_core(a, b, len, work + 2 * len);\n")


def _robust_c(prefix: str, rp: "RobustSetMaps") -> str:
    """The robust-set law's maps and ``<prefix>rs_core`` (``(1 - Q_j){F{d_hat}}`` on a signal pair)."""
    macro = prefix.upper()
    out = [state_space_c(prefix, "gf", "Gf_hat of the source's model (learning signal -> error)", rp.gf),
           state_space_c(prefix, "omq", "1 - Q of the target (the part of a disturbance its DOB leaves)", rp.omq),
           f"\n/* F, the robustness filter: FIR of {rp.h.size} taps, out(k) = sum_i h_i in(k + {macro}F_ADVANCE - i). */\n",
           array_c(DOUBLE, f"{prefix}rs_h", rp.h)]
    if rp.advance and rp.start is not None:
        st = rp.start
        out += [f"\n/* The start's continuation (ilcdob.design.filters.trial_edges.StartMatch): the state x0 of\n"
                f"   H = Gf_hat_j (1 - Q_j) ({st.b.size} states, x(k + 1) = A x(k) + B p(k) from rest) after F's\n"
                f"   output p before t = 0; gain x0 is added to the first {st.span} samples. */\n",
                array_c(DOUBLE, f"{prefix}rs_sa", st.a), array_c(DOUBLE, f"{prefix}rs_sb", st.b),
                array_c(DOUBLE, f"{prefix}rs_sg", st.gain)]
    if rp.advance:
        out.append(f"""
/* d[0..n) continued {macro}F_ADVANCE samples past its end into d[n..n + F_ADVANCE) along its trend
   (ilcdob.design.filters.trial_edges.end_continuation): the least-squares line through the FIT =
   min(2 F_ADVANCE, n - m) samples before the last m = min({macro}FADE, n), weighted by the Hann
   window w_i = 0.5 - 0.5 cos(2 pi (i + 1)/(FIT + 1)) (numpy.hanning(FIT + 2)[1:-1]), on the
   centred abscissa; the last m samples blended into it, d + f_k (line - d)... exactly
   line + f_k (d - line), f_k = 0.5 (1 + cos(pi (k + 1)/(m + 1))). One sample: a constant; none: zero. */
static void {prefix}rs_trend(double *d, size_t n)
{{
    const double pi = 3.14159265358979323846;
    const size_t m = n < {macro}FADE ? n : {macro}FADE;
    const size_t fit = 2 * (size_t){macro}F_ADVANCE < n - m ? 2 * (size_t){macro}F_ADVANCE : n - m;
    double mean = 0.0, slope = 0.0, centre = 0.0;
    size_t i;

    if (fit >= 2) {{
        const double *x = d + (n - m - fit);
        const double half = 0.5 * (double)(fit - 1);
        double s_w = 0.0, s_wt = 0.0, s_wx = 0.0, s_wtt = 0.0, s_wtx = 0.0, t_bar;
        for (i = 0; i < fit; ++i) {{
            const double w = 0.5 - 0.5 * cos(2.0 * pi * (double)(i + 1) / (double)(fit + 1));
            const double t = (double)i - half;
            s_w = s_w + w;
            s_wt = s_wt + w * t;
            s_wx = s_wx + w * x[i];
        }}
        t_bar = s_wt / s_w;
        mean = s_wx / s_w;
        for (i = 0; i < fit; ++i) {{
            const double w = 0.5 - 0.5 * cos(2.0 * pi * (double)(i + 1) / (double)(fit + 1));
            const double t = (double)i - half - t_bar;
            s_wtt = s_wtt + w * t * t;
            s_wtx = s_wtx + w * t * (x[i] - mean);
        }}
        slope = s_wtx / s_wtt;
        centre = (double)(n - m - fit) + half + t_bar;
    }} else if (fit == 1) {{
        mean = d[n - m - 1];
    }}
    for (i = 0; i < m; ++i) {{
        const size_t k = n - m + i;
        const double line = mean + slope * ((double)k - centre);
        const double f = 0.5 * (1.0 + cos(pi * (double)(i + 1) / (double)(m + 1)));
        d[k] = line + f * (d[k] - line);
    }}
    for (i = 0; i < {macro}F_ADVANCE; ++i)
        d[n + i] = mean + slope * ((double)(n + i) - centre);
}}
""")
    out.append(f"""
/* Sample i of F's output over d[0..len), zero outside: sum_j h_j d(i - j) (numpy.convolve). */
static double {prefix}rs_conv(const double *d, size_t len, size_t i)
{{
    const size_t first = i + 1 > len ? i + 1 - len : 0;
    const size_t last = i < {rp.h.size - 1} ? i : {rp.h.size - 1};
    double sum = 0.0;
    size_t j;

    for (j = first; j <= last; ++j)
        sum = sum + {prefix}rs_h[j] * d[i - j];
    return sum;
}}

/* The robust-set law on a signal pair of len >= 1 samples (the trial, or the band's extended
   horizon): a = e, b = d_f of the source in; a = (1 - Q_j){{F{{d_hat}}}} out, with
   d_hat = -Ginv{{e + Gf{{d_f}}}} (ilcdob.design.methods.robust_set.RobustSetDesign.apply). b is
   overwritten; d holds len + {macro}F_ADVANCE doubles. */
static void {prefix}rs_core(double *a, double *b, size_t len, double *d)
{{
    size_t k;

    {prefix}gf_run(b, len);
    for (k = 0; k < len; ++k)
        a[k] = a[k] + b[k];
    {prefix}ginv_apply(a, d, len);
    for (k = 0; k < len; ++k)
        d[k] = -d[k];
""" + (_start_c(prefix, rp) if rp.advance and rp.start is not None else f"""\
    {prefix}rs_trend(d, len);
    for (k = 0; k < len; ++k) {{
        a[k] = {prefix}rs_conv(d, len + {macro}F_ADVANCE, {macro}F_ADVANCE + k);
        if (k < {macro}F_ADVANCE)   /* F's output before t = 0, folded onto the first samples */
            a[k] = a[k] + {prefix}rs_conv(d, len + {macro}F_ADVANCE, {macro}F_ADVANCE - 1 - k);
    }}
""" if rp.advance else f"""\
    for (k = 0; k < len; ++k)
        a[k] = {prefix}rs_conv(d, len, k);
""") + f"""\
    {prefix}omq_run(a, len);
}}
""")
    return "".join(out)


def _start_c(prefix: str, rp: "RobustSetMaps") -> str:
    """``rs_core``'s trend, FIR and start continuation (:class:`~..filters.trial_edges.StartMatch`) in C."""
    macro, ns, span = prefix.upper(), rp.start.b.size, rp.start.span
    return f"""\
    {prefix}rs_trend(d, len);
    {{
        double x[{ns}] = {{0.0}}, t[{ns}];
        size_t i, j;

        for (k = 0; k < {macro}F_ADVANCE; ++k) {{   /* F's output before t = 0 drives H from rest */
            const double p = {prefix}rs_conv(d, len + {macro}F_ADVANCE, k);
            for (i = 0; i < {ns}; ++i) {{
                double v = {prefix}rs_sb[i] * p;
                for (j = 0; j < {ns}; ++j)
                    v = v + {prefix}rs_sa[i][j] * x[j];
                t[i] = v;
            }}
            for (i = 0; i < {ns}; ++i)
                x[i] = t[i];
        }}
        for (k = 0; k < len; ++k) {{
            a[k] = {prefix}rs_conv(d, len + {macro}F_ADVANCE, {macro}F_ADVANCE + k);
            if (k < {span}) {{
                for (j = 0; j < {ns}; ++j)
                    a[k] = a[k] + {prefix}rs_sg[k][j] * x[j];
            }}
        }}
    }}
"""


def robust_set_maps(lf: LearningFilters) -> dict[str, Any]:
    """The maps a robust-set design's learning law runs on a trial (``filters.json`` key ``law_maps``).

    Parameters
    ----------
    lf : LearningFilters
        The closed-form filters of the design (:attr:`~ilcdob.design.methods.robust_set.RobustSetDesign.filters`), whose
        loops give the maps.

    Returns
    -------
    dict
        ``source_gf``: ``Gf_hat_{j-1}`` of the source's model (state space, from rest);
        ``inverse_gd``: ``Gd_hat_{j-1}^{-1}`` in coefficient form (:func:`zpk_to_coefficients`, a
        non-causal filter); ``one_minus_q``: ``1 - Q_j`` of the target (state space); ``rule``.
    """
    return {"source_gf": state_space_to_dict(lf.source.nominal.G_f),
            "inverse_gd": zpk_to_coefficients(inverse_gd_filter(lf.source, model=True)),
            "one_minus_q": state_space_to_dict(one_minus(lf.target.Q)),
            "rule": "on a trial (e, d_f_prev): e' = e + source_gf{d_f_prev} (state space from rest), d_hat = "
                    "-inverse_gd{e'} (coefficient form, continued past the end by the cubic), F on d_hat as "
                    "`trial_ends` says, then one_minus_q (state space from rest)"}
