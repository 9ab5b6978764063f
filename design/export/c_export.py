"""C99 code running exported learning filters, and the files of a design folder.

:func:`c_code` turns the ``L1``/``L2`` filters of ``filters.json`` (:mod:`..filters.coefficients`) into a
header and a source file with, for each filter (PREFIX: by default ``ilcdob_<from>_<to>``,
see :func:`default_c_prefix`), ::

    void PREFIX_l1_apply(const double *u, double *y, size_t n);

filtering one recorded trial exactly as :func:`~ilcdob.design.filters.coefficients.apply_coefficients`
does: the input is taken as zero before the trial, continued past its end by the
least-squares cubic through its last 16 samples
(:func:`~ilcdob.signals.extend_smoothly`), run through the look-ahead pre-stage when the
filter has one (``lookahead``, ``v(j) = sum_m g_m u(j + m)``, the sum in descending ``m``:
the smallest taps first), then through the second-order sections (or, for a FIR, the
direct form) in the operation order of ``scipy.signal.sosfilt`` (``lfilter``), and read so
that the whole filter looks ``advance`` samples ahead (:mod:`..filters.coefficients`). The loop runs over
``i = 0 .. n + advance - 1``:
``v(i - M)`` from the inputs ``u(i - M) .. u(i)``, one step of the sections, and, from
``i = advance`` on, the output ``y(i - advance)``; as ``advance >= M`` that output
overwrites no input a later step reads (``y`` may be ``u``: in place). The C code allocates
nothing: the sections' state and the cubic's coefficients live in fixed-size local arrays,
and the continuation samples past the trial's end are computed on the fly where the
pre-stage or the sections reach them, so the caller provides only the input and output
arrays. The cubic is fitted with orthogonal polynomials on the centred abscissa (Forsythe's
three-term recurrence), which solves the same least-squares problem as ``numpy.polyfit``
without its conditioning loss; the two agree to rounding.

Beside them the source has the whole learning law of the design, ::

    int PREFIX_learn(const double *e, const double *df_prev, double *df_next, size_t n,
                     double *work);

computing :func:`~ilcdob.design.law.apply_learning` (``filters.json`` keys ``band`` and
``disturbance``) ::

    d_f = fold(F{W{L1{F{H{e}}} + L2{F{H{d_f_prev}}}}})

into ``df_next``: ``H`` extends the trial by ``band.pad`` samples at each end (zeros before,
the least-squares line through its last ``band.end_fit`` samples after, fitted on the centred
abscissa: the problem ``numpy.polyfit`` of degree 1 solves), ``F`` is ``band.sos`` run
forwards from the state ``band.zi`` times the first sample, then backwards from ``band.zi``
times the last (``scipy.signal.sosfilt`` operation by operation), ``L1``/``L2`` are the apply
functions above run in place on the extended signals, ``W`` (``disturbance.W.sos``, the
airframe correction) runs forwards from rest and ``fold`` keeps the trial's ``n`` samples,
adding to its first ``pad`` the part before ``t = 0`` time-reversed (``band.start`` "fold";
"crop", of folders written before, only keeps them).
Without a band it is ``W{L1{e} + L2{d_f_prev}}``. The caller provides ``work``,
``PREFIX_LEARN_WORK(n)`` doubles (``2 (n + 2 pad)``); ``df_next`` may be ``e`` or
``df_prev``. It returns 0, or ``PREFIX_LEARN_EMPTY`` (n = 0) or ``PREFIX_LEARN_NULL`` (a
NULL pointer) without writing anything.

A robust-set design (:mod:`..methods.robust_set`, ``filters.json`` keys ``law_maps``, ``F`` and
``trial_ends``) has no ``L1``/``L2`` of its own: its ``learn`` runs, in their place, the law of
:meth:`~ilcdob.design.methods.robust_set.RobustSetDesign.apply` ::

    R{e, d_f} = (1 - Q_j){Fr{d_hat}},   d_hat = -Ginv{e + Gf{d_f}}

with ``Gf`` and ``1 - Q_j`` run as state space from rest, ``Ginv = Gd_hat_{j-1}^{-1}`` as the
apply function ``PREFIX_ginv_apply`` above, ``d_hat`` continued past the trial's end along its
Hann-weighted trend (:func:`~ilcdob.design.filters.trial_edges.end_continuation`) and the FIR ``Fr``'s
output before ``t = 0`` replaced by its matched continuation over the first samples
(:class:`~ilcdob.design.filters.trial_edges.StartMatch`, ``trial_ends.start``: the state it leaves in the
target's ``Gf_hat_j (1 - Q_j)`` times a gain table; files without it fold that output onto the first
samples); band, ``W`` and fold around it as above.
Its scratch is ``3 (n + 2 pad) + advance(Fr)`` doubles, and it uses ``cos`` (``-lm``).

With ``float_variant`` the source also has ``PREFIX_l1_apply_f`` (``float`` data,
coefficients and arithmetic) for single-precision FPUs. Its error relative to the double
version is measured when the code is written, by running the same float arithmetic in
numpy (float32) on :func:`reference_trial`, and stated in the header, ``filters.json`` and
the folder's README. The learning law has no float variant (its band and line fit run in
double only).

:func:`write_design_folder` writes ``filters.json``, ``filters.h``, ``filters.c`` and
``README.md`` of one design, each atomically.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import signal

from ilcdob.channel_loop import CHANNEL_UNITS
from ilcdob.errors import SpecError
from ilcdob.fleet import AXES
from ilcdob.names import c_comment, c_identifier
from ilcdob.signals import as_signal

from ..filters.c_text import DOUBLE, FLOAT, CType, array_c
from ..filters.entries import MAX_ADVANCE, check_filter_entry, check_sections, direct_form
from ..filters.coefficients import apply_coefficients, apply_lookahead, lookahead_taps
from ..law import LawContext, LearningLaw
from ..law.stage import OUTPUT_PLACE
from ..law.airframe import AirframePath
from ..law.band import band_spec, check_cutoff
from ..law.robust_set import RobustSetMaps

__all__ = ["CCode", "c_code", "check_filters", "check_filter_entry", "MAX_ADVANCE", "default_c_prefix",
           "check_c_prefix", "reference_trial", "emulate_c_filter", "float_error", "design_readme", "design_files", "signal_header",
           "FILTER_KEYS"]

#: The filters of ``filters.json`` that get C functions, and their lower-case C names.
FILTER_KEYS = ("L1", "L2")


_FIT_MAX = 16   # samples the continuation is fitted to (extend_smoothly's n_fit)
_FIT_DEG = 3    # its degree
_C_IDENTIFIER = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_REFERENCE_N = 2000
_REFERENCE_TEXT = ("sin(0.5 t) + 0.3 sin(2.3 t + 0.4) + 0.05 sin(11 t + 1.1), t = k Ts, "
                   f"{_REFERENCE_N} samples")


# --------------------------------------------------------------------------- names


def default_c_prefix(source: str, target: str, axis: str = "x") -> str:
    """The default prefix of a pair's C functions.

    Parameters
    ----------
    source : str
        Name of the system learned from.
    target : str
        Name of the learning system.
    axis : str
        The axis the filters are for (``filters.json``'s ``axis``): the paper's x adds nothing, y
        and z end the prefix in ``<axis>_`` so that a vehicle's three axes can share firmware.

    Returns
    -------
    str
        ``ilcdob_<source>_<target>_`` (then ``<axis>_``) in lower case, every character other
        than ``[a-z0-9_]`` replaced by ``_``.
    """
    tail = "" if axis == "x" else f"{axis}_"
    return c_identifier(f"ilcdob_{source}_{target}_{tail}".lower())


def check_c_prefix(prefix: str) -> str:
    """Return ``prefix`` if it can start C identifiers, else raise :class:`SpecError`.

    Valid: an ASCII letter followed by letters, digits and underscores (identifiers starting
    with an underscore are reserved in C). The functions are named ``<prefix>l1_apply``, so
    end the prefix with ``_`` for readable names.

    Parameters
    ----------
    prefix : str
        The prefix asked for (``--c-prefix``).

    Returns
    -------
    str
        ``prefix``, unchanged.

    Raises
    ------
    SpecError
        Not a string, or not the start of a C identifier.
    """
    if not isinstance(prefix, str) or not _C_IDENTIFIER.fullmatch(prefix):
        raise SpecError(f"`--c-prefix`: got {prefix!r}, expected the start of a C identifier: an ASCII letter "
                        "followed by letters, digits or '_' (e.g. 'uav1_uav2_')")
    return prefix


# --------------------------------------------------------------------------- numpy model of the C code


def reference_trial(ts: float, n: int = _REFERENCE_N) -> np.ndarray:
    """The test signal on which the float variant's error is measured.

    ``sin(0.5 t) + 0.3 sin(2.3 t + 0.4) + 0.05 sin(11 t + 1.1)`` at ``t = k ts``: slow,
    medium and fast content, ending mid-slope.

    Parameters
    ----------
    ts : float
        Sample time, s.
    n : int
        Number of samples (default 2000).

    Returns
    -------
    numpy.ndarray
        The trial.
    """
    t = np.arange(n) * float(ts)
    return np.sin(0.5 * t) + 0.3 * np.sin(2.3 * t + 0.4) + 0.05 * np.sin(11.0 * t + 1.1)


def _tail_samples(x: np.ndarray, count: int, dt: type) -> np.ndarray:
    """The C continuation (Forsythe fit), operation by operation in the scalar type ``dt``."""
    n = x.size
    m = min(_FIT_MAX, n)
    xs = [dt(v) for v in x[n - m:]]
    deg = min(_FIT_DEG, m - 1)
    half = dt(0.5) * dt(m - 1)
    alpha, beta, coef = [dt(0.0)] * 4, [dt(0.0)] * 4, [dt(0.0)] * 4
    p = [[dt(0.0)] * m for _ in range(deg + 1)]
    norm_prev = dt(1.0)
    for j in range(deg + 1):
        s_pp = s_tpp = s_xp = dt(0.0)
        for i in range(m):
            t = dt(i) - half
            if j == 0:
                pj = dt(1.0)
            elif j == 1:
                pj = t - alpha[0]
            else:
                pj = (t - alpha[j - 1]) * p[j - 1][i] - beta[j - 1] * p[j - 2][i]
            p[j][i] = pj
            s_pp = s_pp + pj * pj
            s_tpp = s_tpp + t * pj * pj
            s_xp = s_xp + xs[i] * pj
        alpha[j] = s_tpp / s_pp
        beta[j] = dt(0.0) if j == 0 else s_pp / norm_prev
        coef[j] = s_xp / s_pp
        norm_prev = s_pp
    t0 = dt(m) - half
    out = np.empty(count, dtype=dt)
    for q in range(count):
        t = t0 + dt(q)
        p_prev, pj, s = dt(0.0), dt(1.0), coef[0]
        for j in range(1, deg + 1):
            p_next = (t - alpha[j - 1]) * pj - beta[j - 1] * p_prev
            p_prev, pj = pj, p_next
            s = s + coef[j] * pj
        out[q] = s
    return out


def emulate_c_filter(coeffs: dict[str, Any], x: object, dtype: type = np.float32) -> np.ndarray:
    """Run the arithmetic of the C function on ``x`` in ``dtype`` (float32: the float variant).

    Parameters
    ----------
    coeffs : dict
        One filter of ``filters.json``.
    x : array_like
        A trial (rounded to ``dtype`` first, as the C caller's array would be).
    dtype : numpy.float32 or numpy.float64
        Precision of the data, coefficients and arithmetic.

    Returns
    -------
    numpy.ndarray
        The filtered trial in ``dtype``, same length as ``x``.
    """
    x = as_signal(x, "x").astype(dtype)
    if x.size == 0:
        return x
    adv = int(coeffs["advance"])
    padded = np.concatenate([x, _tail_samples(x, adv, dtype)])
    if coeffs.get("sos"):
        g = lookahead_taps(coeffs)
        if g is not None:   # the C pre-stage: a sum in descending m, in dtype
            padded = apply_lookahead(g.astype(dtype), padded)
        y = signal.sosfilt(np.asarray(coeffs["sos"], float).astype(dtype), padded)
    else:
        num, den = direct_form(coeffs)
        if num.size == 1:
            y = padded * dtype(num[0])
        else:  # den has >= 2 entries here: lfilter's transposed direct form, as the C code
            y = signal.lfilter(num.astype(dtype), den.astype(dtype), padded)
    return np.asarray(y, dtype=dtype)[adv:adv + x.size]


def float_error(coeffs: dict[str, Any], ts: float) -> float:
    """Error of the float variant of a filter's C code, measured on :func:`reference_trial`.

    Parameters
    ----------
    coeffs : dict
        One filter of ``filters.json``.
    ts : float
        Sample time, s.

    Returns
    -------
    float
        ``max |y_float - y_double| / max |y_double|``, the float arithmetic emulated by
        :func:`emulate_c_filter` and the double result by
        :func:`~ilcdob.design.filters.coefficients.apply_coefficients`.
    """
    x = reference_trial(ts)
    ref = apply_coefficients(coeffs, x)
    y32 = emulate_c_filter(coeffs, x, np.float32).astype(float)
    return float(np.max(np.abs(y32 - ref)) / np.max(np.abs(ref)))


# --------------------------------------------------------------------------- C text


def _tail_c(prefix: str, ct: CType) -> str:
    """The continuation past the trial's end (shared by the filters of one type)."""
    T, s, L = ct.name, ct.suffix, ct.lit
    return f"""\
/* Continuation of a trial past its end: the least-squares polynomial of degree
   min(3, m - 1) through its last m = min(16, n) samples (numpy.polyfit + polyval in
   ilcdob.signals.extend_smoothly), here in orthogonal polynomials on the centred
   abscissa t_i = i - (m - 1)/2, i = 0..m-1 (Forsythe's three-term recurrence). */
struct {prefix}tail{s} {{
    int {'':<{len(T) - 3}}deg;         /* polynomial degree */
    {T} t0;          /* abscissa of the first sample past the end */
    {T} alpha[4];    /* recurrence p_j+1(t) = (t - alpha_j) p_j(t) - beta_j p_j-1(t) */
    {T} beta[4];
    {T} c[4];        /* the polynomial: sum_j c_j p_j(t) */
}};

static void {prefix}tail_init{s}(struct {prefix}tail{s} *f, const {T} *u, size_t n)
{{
    {T} p[4][{_FIT_MAX}];
    {T} norm_prev = 1.0{L};
    const size_t m = n < {_FIT_MAX} ? n : {_FIT_MAX};
    const {T} *x = u + (n - m);
    const {T} half = 0.5{L} * ({T})(m - 1);
    size_t i;
    int j;

    f->deg = m > {_FIT_DEG} ? {_FIT_DEG} : (int)m - 1;
    f->t0 = ({T})m - half;
    for (j = 0; j <= f->deg; ++j) {{
        {T} s_pp = 0.0{L}, s_tpp = 0.0{L}, s_xp = 0.0{L};
        for (i = 0; i < m; ++i) {{
            const {T} t = ({T})i - half;
            {T} pj;
            if (j == 0)
                pj = 1.0{L};
            else if (j == 1)
                pj = t - f->alpha[0];
            else
                pj = (t - f->alpha[j - 1]) * p[j - 1][i] - f->beta[j - 1] * p[j - 2][i];
            p[j][i] = pj;
            s_pp = s_pp + pj * pj;
            s_tpp = s_tpp + t * pj * pj;
            s_xp = s_xp + x[i] * pj;
        }}
        f->alpha[j] = s_tpp / s_pp;
        f->beta[j] = j == 0 ? 0.0{L} : s_pp / norm_prev;
        f->c[j] = s_xp / s_pp;
        norm_prev = s_pp;
    }}
}}

/* Sample q (0, 1, ...) past the end of the trial. */
static {T} {prefix}tail_eval{s}(const struct {prefix}tail{s} *f, size_t q)
{{
    const {T} t = f->t0 + ({T})q;
    {T} p_prev = 0.0{L}, p = 1.0{L}, sum = f->c[0];
    int j;

    for (j = 1; j <= f->deg; ++j) {{
        const {T} p_next = (t - f->alpha[j - 1]) * p - f->beta[j - 1] * p_prev;
        p_prev = p;
        p = p_next;
        sum = sum + f->c[j] * p;
    }}
    return sum;
}}
"""


def signal_header(prefix: str, values: np.ndarray, ts: float) -> str:
    """A C header holding one learning signal: ``<prefix>df[<PREFIX>DF_SAMPLES]`` (m/s^2) and its sample time.

    Parameters
    ----------
    prefix : str
        Symbol prefix (:func:`check_c_prefix`).
    values : numpy.ndarray
        The samples, m/s^2 (at least one).
    ts : float
        Sample time, s (``<PREFIX>DF_TS``).

    Returns
    -------
    str
        The header's text; the literals round to exactly the given doubles.
    """
    macro = check_c_prefix(prefix).upper()
    values = np.asarray(values, float).reshape(-1)
    if not values.size:
        raise SpecError("`values`: no samples; a learning signal header needs at least one")
    return (f"/* Learning signal (m/s^2), one sample per {ts:g} s, written by ilcdob learn. */\n"
            f"#ifndef {macro}DF_H\n#define {macro}DF_H\n#define {macro}DF_SAMPLES {values.size}u\n"
            f"#define {macro}DF_TS {DOUBLE.num(ts)}\n"
            + array_c(DOUBLE, f"{prefix}df", values) + "#endif\n")


def _filter_c(prefix: str, key: str, coeffs: dict[str, Any], ct: CType) -> str:
    """Coefficient table and apply function of one filter."""
    T, s = ct.name, ct.suffix
    name = f"{prefix}{key.lower()}"
    adv = int(coeffs["advance"])
    if adv < 0:
        raise SpecError(f"`{key}.advance`: got {adv}, expected a number of samples >= 0")
    for part in ("sos", "num", "den"):
        if coeffs.get(part) is not None and not np.all(np.isfinite(np.asarray(coeffs[part], float))):
            raise SpecError(f"`{key}.{part}`: non-finite coefficient(s); expected finite numbers")
    g = lookahead_taps(coeffs, f"{key}.lookahead")
    lines = []
    if g is not None:
        ahead = g.size - 1
        lines.append(f"/* {key}: look-ahead pre-stage, {g.size} taps g_m: v(j) = sum_m g_m u(j + m), m = 0..{ahead} "
                     "(the series of the\n   anti-causal poles, |p| > 1); the sections below run on v and are read "
                     f"{adv - ahead} sample{'s' if adv - ahead != 1 else ''} ahead of it */\n")
        lines.append(array_c(ct, f"{name}_ahead{s}", g))
    if coeffs.get("sos"):
        sos = check_sections(coeffs["sos"], f"{key}.sos")
        plural = "s" if sos.shape[0] > 1 else ""
        lines.append(f"/* {key}: {sos.shape[0]} second-order section{plural} in cascade, rows "
                     "b0 b1 b2 a0 a1 a2 (a0 = 1) */\n")
        lines.append(array_c(ct, f"{name}_sos{s}", sos))
        state = f"    {T} z[{sos.shape[0]}][2] = {{{{0.0{ct.lit}}}}};\n    size_t i;\n"
        step = (f"        for (i = 0; i < {sos.shape[0]}; ++i) {{\n"
                f"            const {T} x_new = {name}_sos{s}[i][0] * x + z[i][0];\n"
                f"            z[i][0] = {name}_sos{s}[i][1] * x - {name}_sos{s}[i][4] * x_new + z[i][1];\n"
                f"            z[i][1] = {name}_sos{s}[i][2] * x - {name}_sos{s}[i][5] * x_new;\n"
                f"            x = x_new;\n"
                f"        }}\n")
    elif "num" in coeffs and "den" in coeffs:
        num, den = direct_form(coeffs)
        size = num.size
        fir = bool(np.all(den[1:] == 0.0))
        kind = f"FIR, {size} taps" if fir else f"direct form, order {size - 1}"
        lines.append(f"/* {key}: {kind} (transposed direct form, as scipy.signal.lfilter) */\n")
        lines.append(array_c(ct, f"{name}_num{s}", num))
        if not fir:
            lines.append(array_c(ct, f"{name}_den{s}", den))
        if size == 1:
            state = ""
            step = f"        x = x * {name}_num{s}[0];\n"
        else:
            feedback = "" if fir else f" - out * {name}_den{s}[i + 1]"
            feedback_last = "" if fir else f" - out * {name}_den{s}[{size - 1}]"
            state = f"    {T} z[{size - 1}] = {{0.0{ct.lit}}};\n    size_t i;\n"
            step = (f"        {{\n"
                    f"            const {T} out = z[0] + {name}_num{s}[0] * x;\n"
                    f"            for (i = 0; i + 1 < {size - 1}; ++i)\n"
                    f"                z[i] = z[i + 1] + x * {name}_num{s}[i + 1]{feedback};\n"
                    f"            z[{size - 2}] = x * {name}_num{s}[{size - 1}]{feedback_last};\n"
                    f"            x = out;\n"
                    f"        }}\n")
    else:
        why = coeffs.get("num_den_omitted", "")
        raise SpecError(f"`{key}`: neither `sos` nor `num`/`den` given" + (f" ({why})" if why else "")
                        + f"; got keys {sorted(coeffs)}")
    if g is not None:
        ahead, lit = g.size - 1, ct.lit
        body = (f"{state}    struct {prefix}tail{s} tail;\n    size_t k, m;\n\n"
                f"    if (n == 0)\n        return;\n"
                f"    {prefix}tail_init{s}(&tail, u, n);   /* before any output: y may be u */\n"
                f"    for (k = 0; k < n + {adv}; ++k) {{\n"
                f"        /* x = v(k - {ahead}) = sum_m g_m u(k - {ahead} + m), m descending (smallest taps\n"
                f"           first): the continuation past the trial's end for m >= recorded, the trial\n"
                f"           for m >= first, zero before it */\n"
                f"        const size_t recorded = k < n + {ahead} ? n + {ahead} - k : 0;\n"
                f"        const size_t first = k < {ahead} ? {ahead} - k : 0;\n"
                f"        {T} x = 0.0{lit};\n"
                f"        for (m = {ahead + 1}; m > recorded; --m)\n"
                f"            x = x + {name}_ahead{s}[m - 1] * {prefix}tail_eval{s}(&tail, k + m - 1 - {ahead} - n);\n"
                f"        for (; m > first; --m)\n"
                f"            x = x + {name}_ahead{s}[m - 1] * u[k + m - 1 - {ahead}];\n"
                f"{step}"
                f"        if (k >= {adv})\n            y[k - {adv}] = x;   /* u(k - {adv}) is read no more */\n"
                f"    }}\n")
    elif adv:
        body = (f"{state}    struct {prefix}tail{s} tail;\n    size_t k;\n\n"
                f"    if (n == 0)\n        return;\n"
                f"    {prefix}tail_init{s}(&tail, u, n);   /* before any output: y may be u */\n"
                f"    for (k = 0; k < n + {adv}; ++k) {{\n"
                f"        {T} x = k < n ? u[k] : {prefix}tail_eval{s}(&tail, k - n);\n"
                f"{step}"
                f"        if (k >= {adv})\n            y[k - {adv}] = x;\n"
                f"    }}\n")
    else:
        body = (f"{state}    size_t k;\n\n"
                f"    for (k = 0; k < n; ++k) {{\n"
                f"        {T} x = u[k];\n"
                f"{step}"
                f"        y[k] = x;\n"
                f"    }}\n")
    lines.append(f"\nvoid {name}_apply{s}(const {T} *u, {T} *y, size_t n)\n{{\n{body}}}\n")
    return "".join(lines)


def _lookahead_size(coeffs: dict[str, Any]) -> int:
    """Taps of a filter's look-ahead pre-stage (0 without one)."""
    g = coeffs.get("lookahead")
    return 0 if g is None else len(g)


def _stack_values(coeffs: dict[str, Any]) -> int:
    """Numbers held in local arrays by one apply function: filter state + continuation fit."""
    if coeffs.get("sos"):
        state = 2 * len(coeffs["sos"])
    else:
        state = max(len(coeffs["num"]), len(coeffs["den"])) - 1
    fit = 4 * _FIT_MAX + 3 * 4 + 1 if int(coeffs["advance"]) else 0   # tail_init's p, the tail struct
    return state + fit


@dataclass(frozen=True)
class _Learning:
    """The parts of the learning law beyond L1/L2, checked (:func:`_learning_parts`)."""

    sos: np.ndarray | None       # one pass of F (None: no band)
    zi: np.ndarray | None        # its steady state per unit input
    pad: int                     # samples added at each end (0 without a band)
    end_fit: int                 # samples the end line is fitted to
    cutoff: float | None         # F's corner, rad/s
    order: int | None            # F's Butterworth order, when stated
    why: str                     # the band's source and reason, for the README
    w_sos: np.ndarray | None     # the airframe correction W (None: none)
    fold: bool = False           # the learning signal before t = 0 folded onto the first samples


def _learning_parts(filters: dict[str, Any]) -> _Learning:
    """The band and airframe correction of ``filters.json`` as the law's stages read them (:mod:`..law`).

    Raises
    ------
    SpecError
        A ``band`` or ``disturbance`` entry of the wrong type, shape or value, naming its key.
    """
    spec = band_spec(filters)
    w = AirframePath.from_dict(filters, LawContext())
    w_sos = None if w is None else w.sos
    if spec is None:
        return _Learning(None, None, 0, 1, None, None, "", w_sos)
    return _Learning(spec.sos, spec.zi, spec.pad, spec.end_fit, check_cutoff(spec.cutoff), spec.order, spec.why, w_sos,
                     spec.fold)


def _robust_parts(filters: dict[str, Any]) -> RobustSetMaps | None:
    """The robust-set law's stage (``law_maps``, ``F``, ``trial_ends``), checked; None for other designs."""
    return RobustSetMaps.from_dict(filters, LawContext())


def _design_parts(filters: dict[str, Any]) -> None:
    """``method``, ``law``, ``axis``, ``limit`` and ``c`` of ``filters.json``, checked.

    Raises
    ------
    SpecError
        An entry of the wrong type or value, naming its key.
    """
    for key in ("method", "law"):
        if not isinstance(filters.get(key, ""), str):
            raise SpecError(f"`{key}`: got {filters.get(key)!r:.80}, expected a string")
    if filters.get("axis", "x") not in AXES:
        raise SpecError(f"`axis`: got {filters.get('axis')!r:.80}, expected one of {list(AXES)}")
    limit = filters.get("limit")
    if limit is not None:
        if not isinstance(limit, dict):
            raise SpecError(f"`limit`: got {limit!r:.80}, expected a mapping such as {{'acceleration_m_s2': 6.7}}")
        accel = limit.get("acceleration_m_s2")
        if accel is not None and (isinstance(accel, bool) or not isinstance(accel, (int, float))
                                  or not (math.isfinite(accel) and accel > 0)):
            raise SpecError(f"`limit.acceleration_m_s2`: got {accel!r:.80}, expected the learning vehicle's "
                            "acceleration limit, a number > 0 (m/s^2)")
    code = filters.get("c")
    if code is not None:
        if not isinstance(code, dict):
            raise SpecError(f"`c`: got {code!r:.80}, expected a mapping such as {{'prefix': 'ilcdob_uav1_uav2_'}}")
        prefix = code.get("prefix")
        if prefix is not None and not (isinstance(prefix, str) and _C_IDENTIFIER.fullmatch(prefix)):
            raise SpecError(f"`c.prefix`: got {prefix!r:.80}, expected the start of a C identifier: an ASCII letter "
                            "followed by letters, digits or '_' (e.g. 'uav1_uav2_')")


def check_filters(filters: object, source: str) -> dict[str, Any]:
    """The content of a ``filters.json`` read from a file, checked before it is used.

    Checks every entry the learning law (:func:`~ilcdob.design.law.apply_learning`) and
    the C code (:func:`c_code`) read: ``from``/``to`` names, ``sample_time`` (s), ``L1`` and
    ``L2`` (``advance`` at most :data:`MAX_ADVANCE`, finite sections or polynomials,
    look-ahead taps), ``band`` and ``disturbance``, a robust-set design's ``law_maps``,
    ``F`` and ``trial_ends``, and ``method``/``law`` (strings), ``axis``, ``limit`` (its
    ``acceleration_m_s2`` a number > 0, m/s^2, or null) and ``c`` (its ``prefix``).

    Parameters
    ----------
    filters : object
        The parsed document.
    source : str
        Where it came from, first in messages (its path).

    Returns
    -------
    dict
        ``filters``, unchanged.

    Raises
    ------
    SpecError
        An entry missing or of the wrong type, shape or value; the message names the file and
        the key.
    """
    try:
        if not isinstance(filters, dict):
            raise SpecError(f"expected a JSON object, got {type(filters).__name__}")
        for key in ("from", "to"):
            if not isinstance(filters.get(key), str):
                raise SpecError(f"`{key}`: got {filters.get(key)!r:.80}, expected the system's name")
        ts = filters.get("sample_time")
        if isinstance(ts, bool) or not isinstance(ts, (int, float)) or not (math.isfinite(ts) and ts > 0):
            raise SpecError(f"`sample_time`: got {ts!r:.80}, expected the sample time, a number > 0 (s)")
        for key in FILTER_KEYS:
            if key in filters:
                check_filter_entry(filters[key], key)
        _learning_parts(filters)
        _robust_parts(filters)
        _design_parts(filters)
    except SpecError as exc:
        raise SpecError(f"{source}: {exc}") from None
    return filters


_SECTIONS_C = """
/* Second-order sections over x[0..n) in place from the state z, forwards or (backward != 0)
   backwards, in the operation order of scipy.signal.sosfilt. */
static void {p}sections(const double (*sos)[6], size_t ns, double (*z)[2], double *x,
{indent}size_t n, int backward)
{{
    size_t k, i;

    for (k = 0; k < n; ++k) {{
        double *at = backward ? x + (n - 1 - k) : x + k;
        double v = *at;
        for (i = 0; i < ns; ++i) {{
            const double x_new = sos[i][0] * v + z[i][0];
            z[i][0] = sos[i][1] * v - sos[i][4] * x_new + z[i][1];
            z[i][1] = sos[i][2] * v - sos[i][5] * x_new;
            v = x_new;
        }}
        *at = v;
    }}
}}
"""


def _learn_c(prefix: str, law: LearningLaw) -> str:
    """``<prefix>learn`` (double only) and what it calls: each stage's tables, helpers and step in chain order
    (stages placed after :data:`~..law.stage.OUTPUT_PLACE` run on ``df_next``)."""
    macro = prefix.upper()
    parts = [s.c_parts(prefix) for s in law.stages]
    after = [p.step for s, p in zip(law.stages, parts) if s.place > OUTPUT_PLACE]
    out = ["\n/* ------------------------------------------------------------------ the learning law */\n",
           *(p.tables for p in parts)]
    if any(p.sections for p in parts):
        out.append(_SECTIONS_C.format(p=prefix, indent=" " * (13 + len(prefix))))
    out += [p.helpers for p in parts]
    load = "" if any(p.loads for p in parts) else (
        "    for (k = 0; k < n; ++k) {\n        a[k] = e[k];   /* e and df_prev are read before df_next is written */\n"
        "        b[k] = df_prev[k];\n    }\n")
    store = "" if any(p.stores for p in parts) else "    for (k = 0; k < n; ++k)\n        df_next[k] = a[k];\n"
    body = (f"    double *a, *b;\n    size_t len, k;\n\n    if (n == 0)\n        return {macro}LEARN_EMPTY;\n"
            f"    if (e == NULL || df_prev == NULL || df_next == NULL || work == NULL)\n        return {macro}LEARN_NULL;\n"
            f"    len = n + 2 * (size_t){macro}PAD;\n    a = work;\n    b = work + len;\n"
            + load + "".join(p.step for s, p in zip(law.stages, parts) if s.place <= OUTPUT_PLACE) + store
            + "".join(after) + "    return 0;\n")
    out.append(f"\nint {prefix}learn(const double *e, const double *df_prev, double *df_next, size_t n, "
               f"double *work)\n{{\n{body}}}\n")
    return "".join(out)


@dataclass(frozen=True)
class CCode:
    """The C files of one design.

    Attributes
    ----------
    prefix : str
        Prefix of every external symbol and macro (upper case for macros).
    header, source : str
        Text of ``filters.h`` and ``filters.c``.
    float_errors : dict of str -> float
        Per filter, the measured ``max |y_float - y_double| / max |y_double|`` of the float
        variant on :func:`reference_trial` (empty without the float variant).
    pad : int
        Samples the learning law adds at each end of the trial (``band.pad``; 0 without a band).
    filters : tuple of str
        The filters with an apply function of their own (``l1``, ``l2``; ``ginv`` for robust-set).
    work : str
        ``LEARN_WORK(n)`` in doubles, as a formula (default ``2 * (n + 2 * pad)``).
    """

    prefix: str
    header: str
    source: str
    float_errors: dict[str, float] = field(default_factory=dict)
    pad: int = 0
    filters: tuple[str, ...] = tuple(k.lower() for k in FILTER_KEYS)
    work: str = ""

    @property
    def info(self) -> dict[str, Any]:
        """What ``filters.json`` records about the C code (key ``c``)."""
        p, m = self.prefix, self.prefix.upper()
        out: dict[str, Any] = {"header": "filters.h", "source": "filters.c", "prefix": p,
                               "functions": [f"{p}learn", *(f"{p}{k}_apply" for k in self.filters)],
                               "learn": {"function": f"{p}learn", "computes": "ilcdob.design.law.apply_learning",
                                         "work": f"{m}LEARN_WORK(n) = {self.work or f'2 * (n + 2 * {self.pad})'} "
                                                 "doubles",
                                         "returns": f"0; {m}LEARN_EMPTY = 1 (n == 0) or {m}LEARN_NULL = 2 "
                                                    "(a NULL pointer), nothing written"}}
        if self.float_errors:
            out["float"] = {"functions": [f"{p}{k.lower()}_apply_f" for k in FILTER_KEYS],
                            "max_relative_error": self.float_errors,
                            "measured_on": _REFERENCE_TEXT + " (float32 emulation of the C arithmetic)",
                            "learn": "none: the learning law runs in double only"}
        return out


def _law_comment(macro: str, lp: _Learning, robust: list[str] | None = None) -> str:
    """The lines of the header describing what ``learn`` computes; ``robust``: the lines defining
    the robust-set law ``R``, which then replaces ``L1{.} + L2{.}``."""
    def core(x: str, y: str) -> str:
        return f"R{{{x}, {y}}}" if robust is not None else f"L1{{{x}}} + L2{{{y}}}"

    if lp.sos is not None:
        order = f"order {lp.order} " if lp.order else ""
        ends = "fold" if lp.fold else "crop"
        inner = core("F{H{e}}", "F{H{d_f}}")
        lines = [f"    d_next = {ends}(F{{W{{{inner}}}}})" if lp.w_sos is not None else f"    d_next = {ends}(F{{{inner}}})",
                 "exactly as ilcdob.design.law.apply_learning does (to rounding), where",
                 *(robust or []),
                 f"  F  is the learning band: a Butterworth {order}low-pass with corner {lp.cutoff:.6g} rad/s",
                 f"     ({macro}BAND_CUTOFF), run forwards from its steady state at the first sample, then",
                 "     backwards from its steady state at the last (zero phase);",
                 f"  H  extends the trial by {macro}PAD samples at each end: zeros before, after the end",
                 f"     the least-squares line through its last {macro}END_FIT samples;"]
        if lp.w_sos is not None:
            lines.append("  W  is the airframe correction (the disturbance acts on the airframe), from rest;")
        lines += ["  R  runs on the extended signals;" if robust is not None else
                  "  L1, L2 run as the functions below, on the extended signals;",
                  "  fold keeps the trial's n samples and adds, time-reversed, the learning signal computed"
                  f" before t = 0 to the first {macro}PAD of them." if lp.fold else "  crop keeps the trial's n samples."]
    else:
        lines = [f"    d_next = W{{{core('e', 'd_f')}}}" if lp.w_sos is not None else f"    d_next = {core('e', 'd_f')}",
                 "exactly as ilcdob.design.law.apply_learning does (to rounding)"
                 + (", where" if robust is not None else ":"), *(robust or []),
                 f"no learning band (no filter, {macro}BAND_CUTOFF 0.0): "
                 + ("R" if robust is not None else "L1 and L2") + " act on the trial as recorded"
                 + (";" if lp.w_sos is not None else ".")]
        if lp.w_sos is not None:
            lines.append("W is the airframe correction (the disturbance acts on the airframe), from rest.")
    return "".join(f" * {line}\n" for line in lines)


def _law_macros(filters: dict[str, Any], macro: str, lp: _Learning) -> tuple[str, str]:
    """The header's band macros, then the stages' macros, and the stages' notes (:class:`~..law.stage.CParts`)."""
    parts = [s.c_parts(macro.lower()) for s in LearningLaw.from_dict(filters).stages]
    if lp.sos is not None:
        macros = (f"#define {macro}BAND_CUTOFF {lp.cutoff!r} /* rad/s, corner of the learning band F */\n"
                  f"#define {macro}PAD {lp.pad} /* samples added at each end of the trial */\n"
                  f"#define {macro}END_FIT {lp.end_fit} /* samples the line continuing the trial is fitted to */\n")
    else:
        macros = (f"#define {macro}BAND_CUTOFF 0.0 /* no learning band: the law acts on the trial as recorded */\n"
                  f"#define {macro}PAD 0 /* no band: nothing added to the trial */\n")
    return macros + "".join(p.macros for p in parts), "".join(p.note for p in parts)


def _header(title: str, macro: str, prefix: str, law: str, limit_note: str, apply_text: str, macros: str,
            declarations: str) -> str:
    """``filters.h`` of a design: how to call ``learn`` (``law``: :func:`_law_comment`), ``apply_text`` on the
    other functions (comment lines, each starting `` * ``), the include guard, ``macros`` (before the
    ``LEARN_*`` codes) and ``declarations`` after ``learn``'s, in ``extern "C"`` for C++."""
    guard = f"{macro}FILTERS_H"
    return f"""\
/* {title}, written by `ilcdob design`.
 *
 * Between two flights, the learning signal d_next of the next vehicle is computed from the
 * previous vehicle's recorded trial, its tracking error e (m) and the learning signal it
 * flew, d_f (m/s^2; zeros if none), n samples each, every {macro}SAMPLE_TIME seconds from
 * the start of the trial, by one call:
 *
 *     static double work[{macro}LEARN_WORK(N_MAX)];      (scratch, N_MAX >= n)
 *     if ({prefix}learn(e, d_f, d_next, n, work) != 0) {{ n == 0 or a NULL pointer }}
 *
 * then d_next (m/s^2) is fed forward on the next flight, sample k at time k Ts. It is
{law} * work holds {macro}LEARN_WORK(n) doubles and overlaps none of e, d_f, d_next; d_next
 * may be e or d_f (both are read before d_next is written). learn returns 0, or without
 * writing anything {macro}LEARN_EMPTY (n == 0) or {macro}LEARN_NULL (a NULL pointer).
{limit_note} *
{apply_text} */
#ifndef {guard}
#define {guard}

#include <stddef.h>

{macros}#define {macro}LEARN_EMPTY 1 /* learn: n == 0 */
#define {macro}LEARN_NULL 2 /* learn: a NULL pointer */

#ifdef __cplusplus
extern "C" {{
#endif

/* The learning law: previous vehicle's trial (e in m, df_prev in m/s^2) -> df_next (m/s^2). */
int {prefix}learn(const double *e, const double *df_prev, double *df_next, size_t n, double *work);
{declarations}
#ifdef __cplusplus
}}
#endif

#endif /* {guard} */
"""


def c_code(filters: dict[str, Any], prefix: str | None = None, float_variant: bool = False) -> CCode:
    """``filters.h`` and ``filters.c`` for the learning law and the ``L1``/``L2`` filters of a design.

    Parameters
    ----------
    filters : dict
        ``filters.json`` content with ``from``, ``to``, ``method``, ``sample_time``, ``L1``, ``L2``
        and optionally ``band`` and ``disturbance`` (module docstring).
    prefix : str, optional
        Symbol prefix (default :func:`default_c_prefix` of the pair), checked by :func:`check_c_prefix`.
    float_variant : bool
        Also emit ``<prefix>l1_apply_f``/``l2_apply_f`` in ``float`` (the learning law has no
        float variant).

    Returns
    -------
    CCode

    Raises
    ------
    SpecError
        A missing key, a bad prefix, or a filter, ``band`` or ``disturbance.W`` entry of the
        wrong shape or value (the message names the key).
    """
    rp = _robust_parts(filters)
    missing = [k for k in ("from", "to", "method", "sample_time", *(FILTER_KEYS if rp is None else ()))
               if k not in filters]
    if missing:
        raise SpecError(f"filters: missing key(s) {missing} for the C code; method "
                        f"{filters.get('method')!r} has no L1/L2 filters (closed-form and fir have them; robust-set "
                        "has its `law_maps`)")
    prefix = check_c_prefix(default_c_prefix(str(filters["from"]), str(filters["to"]), str(filters.get("axis", "x")))
                            if prefix is None else prefix)
    lp = _learning_parts(filters)
    if rp is not None:
        if float_variant:
            raise SpecError("float variant: a robust-set design has no L1/L2 functions to give in float, and its "
                            "learning law runs in double only; leave out --c-float")
        return _robust_c_code(filters, prefix, lp, rp)
    macro = prefix.upper()
    pair = c_comment(f"{filters['from']} -> {filters['to']}")
    ts = float(filters["sample_time"])
    types = [DOUBLE, FLOAT] if float_variant else [DOUBLE]
    errors = {k: float_error(filters[k], ts) for k in FILTER_KEYS} if float_variant else {}

    decls = []
    for ct in types:
        for k in FILTER_KEYS:
            decls.append(f"void {prefix}{k.lower()}_apply{ct.suffix}(const {ct.name} *u, {ct.name} *y, size_t n);")
    adv = {k: int(filters[k]["advance"]) for k in FILTER_KEYS}
    taps = {k: _lookahead_size(filters[k]) for k in FILTER_KEYS}
    stack = max([_stack_values(filters[k]) for k in FILTER_KEYS]
                + [2 * s.shape[0] for s in (lp.sos, lp.w_sos) if s is not None])
    float_note = ""
    if float_variant:
        float_note = (
            " *\n * float variant (*_apply_f: float data, coefficients and arithmetic): measured\n"
            " *   max |y_float - y_double| / max |y_double| = "
            + ", ".join(f"{errors[k]:.2e} ({k})" for k in FILTER_KEYS)
            + f"\n *   on {_REFERENCE_TEXT}\n *   (float32 emulation of this arithmetic when the file was written).\n"
            f" *   The learning law ({prefix}learn) has no float variant: it runs in double only.\n")
    band_macros, limit_note = _law_macros(filters, macro, lp)
    apply_text = f"""\
 * The filters alone: {prefix}l1_apply and {prefix}l2_apply each filter one whole
 * recorded trial of n samples (n >= 1; n = 0 does nothing)
 * exactly as ilcdob.design.filters.coefficients.apply_coefficients does: the filter looks
 * {macro}L1_ADVANCE (L2: {macro}L2_ADVANCE) samples ahead, the input is taken as zero
 * before the trial and continued past its end by the least-squares cubic through its last
 * 16 samples. A filter with anti-causal poles (|p| > 1) first runs the input through a
 * look-ahead FIR of {macro}L1_LOOKAHEAD_TAPS (L2: {macro}L2_LOOKAHEAD_TAPS) taps, the series of
 * those poles, v(j) = sum_m g_m u(j + m); its taps - 1 samples are part of the advance, and
 * its second-order sections run on v (0 taps: no FIR, the sections run on u).
 * y must hold n values and may be u (in place). With a band or W their sum is
 * not the learning signal: use learn. No allocation: the filter
 * state and the cubic live in local arrays of at most {stack} numbers ({8 * stack} bytes in
 * double, {4 * stack} in float) plus a few scalars. Compile with -ffp-contract=off (no fused multiply-add)
 * to reproduce the Python arithmetic operation by operation; contraction changes the
 * results only at the level of rounding.
{float_note}"""
    macros = f"""\
#define {macro}SAMPLE_TIME {ts!r} /* s */
#define {macro}L1_ADVANCE {adv['L1']} /* samples of look-ahead of L1 */
#define {macro}L2_ADVANCE {adv['L2']} /* samples of look-ahead of L2 */
#define {macro}L1_LOOKAHEAD_TAPS {taps['L1']} /* taps of L1's look-ahead FIR (0: none) */
#define {macro}L2_LOOKAHEAD_TAPS {taps['L2']} /* taps of L2's look-ahead FIR (0: none) */
{band_macros}#define {macro}LEARN_WORK(n) (2 * ((n) + 2 * {macro}PAD)) /* doubles of scratch for learn */
"""
    declarations = f"""\
/* L1: previous vehicle's tracking error (m) -> learning signal (m/s^2). */
{decls[0]}
/* L2: previous vehicle's learning signal (m/s^2) -> learning signal (m/s^2). */
{decls[1]}
"""
    if float_variant:
        declarations += f"/* The same in float, see the error stated above. */\n{decls[2]}\n{decls[3]}\n"
    header = _header(f"Learning filters {pair} (method {c_comment(filters['method'])})", macro, prefix,
                     _law_comment(macro, lp), limit_note, apply_text, macros, declarations)
    parts = [f"/* Learning filters {pair}: see filters.h. Written by `ilcdob design`. */\n"
             '#include "filters.h"\n']
    for ct in types:
        if any(adv.values()):
            parts.append("\n" + _tail_c(prefix, ct))
        for k in FILTER_KEYS:
            parts.append("\n" + _filter_c(prefix, k, filters[k], ct))
    parts.append(_learn_c(prefix, LearningLaw.from_dict(filters)))
    return CCode(prefix=prefix, header=header, source="".join(parts), float_errors=errors, pad=lp.pad)


def _robust_c_code(filters: dict[str, Any], prefix: str, lp: _Learning, rp: RobustSetMaps) -> CCode:
    """``filters.h`` and ``filters.c`` of a robust-set design: ``learn`` and ``ginv_apply`` (:func:`c_code`)."""
    macro = prefix.upper()
    pair = c_comment(f"{filters['from']} -> {filters['to']}")
    src, tgt = c_comment(str(filters["from"])), c_comment(str(filters["to"]))
    ts = float(filters["sample_time"])
    ginv_adv, ginv_taps = int(rp.ginv["advance"]), _lookahead_size(rp.ginv)
    band_macros, limit_note = _law_macros(filters, macro, lp)
    guarantee = filters.get("rho_guaranteed")
    robust = [
        "  R{e, d_f} = (1 - Q){Fr{d_hat}},  d_hat = -Ginv{e + Gf{d_f}}: the robust-set law",
        "     (ilcdob.design.methods.robust_set.RobustSetDesign.apply); Gf = Gf_hat and Ginv = Gd_hat^-1",
        f"     of {src}'s model (Ginv: {prefix}ginv_apply below, non-causal), Q of {tgt}; Fr the",
        f"     robustness FIR of {macro}F_TAPS taps looking {macro}F_ADVANCE samples ahead; d_hat is",
        "     continued past the end along its trend (the Hann-weighted least-squares line through",
        f"     the 2 {macro}F_ADVANCE samples before its last {macro}FADE, blended into over those)",
        "     and Fr's output before t = 0 is added, time-reversed, to the first samples"
        + (f"; per frequency |e_j| <= {guarantee:.4g} |e'_j| for every plant of the Delta set"
           if isinstance(guarantee, (int, float)) else "") + ";"]
    work = f"3 * (n + 2 * {lp.pad}) + {rp.advance}"
    apply_text = f"""\
 * {prefix}ginv_apply runs Ginv alone over a whole trial of n samples (y may be u), as
 * ilcdob.design.filters.coefficients.apply_coefficients does: it looks {macro}GINV_ADVANCE samples ahead, the
 * input taken as zero before the trial and continued past its end by the least-squares
 * cubic through its last 16 samples. Uses cos() of the C math library (link with -lm).
 * Compile with -ffp-contract=off to reproduce the Python arithmetic operation by operation;
 * contraction changes the results only at the level of rounding.
"""
    macros = f"""\
#define {macro}SAMPLE_TIME {ts!r} /* s */
#define {macro}F_TAPS {rp.h.size} /* taps of the robustness FIR */
#define {macro}F_ADVANCE {rp.advance} /* samples of look-ahead of the robustness FIR */
#define {macro}FADE {rp.fade} /* samples at the trial's end blended into the trend */
#define {macro}GINV_ADVANCE {ginv_adv} /* samples of look-ahead of Ginv */
#define {macro}GINV_LOOKAHEAD_TAPS {ginv_taps} /* taps of Ginv's look-ahead FIR (0: none) */
{band_macros}#define {macro}LEARN_WORK(n) ({work.replace("n + ", "(n) + ")}) /* doubles of scratch for learn */
"""
    declarations = f"""\
/* Ginv = Gd_hat^-1 of the previous vehicle's model: tracking error (m) -> disturbance (m/s^2), sign as Gd^-1. */
void {prefix}ginv_apply(const double *u, double *y, size_t n);
"""
    header = _header(f"Robust-set learning law {pair}", macro, prefix, _law_comment(macro, lp, robust), limit_note,
                     apply_text, macros, declarations)
    parts = [f"/* Robust-set learning law {pair}: see filters.h. Written by `ilcdob design`. */\n"
             '#include <math.h>\n#include "filters.h"\n']
    if ginv_adv:
        parts.append("\n" + _tail_c(prefix, DOUBLE))
    parts.append("\n" + _filter_c(prefix, "Ginv", rp.ginv, DOUBLE))
    parts.append(_learn_c(prefix, LearningLaw.from_dict(filters)))
    return CCode(prefix=prefix, header=header, source="".join(parts), pad=lp.pad, filters=("ginv",), work=work)


# --------------------------------------------------------------------------- design folder


_FILE_TEXT = {
    "filters.json": "the design: method, pair, sample time and, for closed-form and fir, the filters L1 and L2 "
                    "(`advance` samples of look-ahead in all; second-order sections `sos`, rows "
                    "[b0, b1, b2, 1, a1, a2] in powers of z^-1, run after the look-ahead FIR `lookahead` = "
                    "[g_0, ..., g_M] where the filter has anti-causal poles: output(k) = S{v}(k + advance - M), "
                    "v(j) = sum_m g_m u(j + m); or FIR taps `num`; direct-form `num`/`den` (the look-ahead FIR "
                    "multiplied in, same `advance`) only where they reproduce the sections, else "
                    "`num_den_omitted` says why)",
    "filters.h": "C99 declarations of the function computing the learning signal from a recorded trial (`learn`: "
                 "the design's law within the learning band, with the airframe correction when there is one) and "
                 "of the functions running its filters alone (L1 and L2; robust-set: Ginv), with the sample time, "
                 "the band and the look-ahead of each filter",
    "filters.c": "their implementation (no allocation; compile it with your firmware or ground tool)",
    "filters.mat": "the same law for MATLAB (scipy.io.savemat, version 5): L1 and L2 as sections, the learning band, "
                   "the airframe correction and the limit, each variable described in its `description` "
                   "(ilcdob.design_to_mat)",
    "lifted.npz": "numpy arrays: for norm-optimal its law d_f,j = L1 e_j-1 + L2 d_f,j-1 as Riccati gains "
                  "(ilcdob.design.methods.norm_optimal.NormOptimalLaw.from_arrays(numpy.load(...)).apply(e, d_f)) and, "
                  "with --lifted, the N x N matrices L1, L2; for robust the learning signal d_f, the predicted "
                  "improvement ratios and errors",
    "learning_signal.csv": "the learning signal d_f,j (m/s^2) computed from the given trial of the previous "
                           "vehicle, to feed forward on the next flight",
    "bode.png": "Bode plots (magnitude in dB, phase in degrees, against rad/s up to Nyquist) of the pair's "
                "closed-form filters L1 and L2, its error propagation Te1 and Te2 under a stated model error, and "
                "Omega (disturbance -> DOB estimate) of both vehicles, with the learning band marked",
    "reference_terms.csv": "exact-reference law: the previous vehicle's model reference error e_ref_source (m), "
                           "removed from its error before L1, and the correction (in the learning signal's unit, "
                           "m/s^2 on ilcdob's loop) added to the learning signal, for the given trial's reference",
    "README.md": "this file",
}


def _band_readme(filters: dict[str, Any], lp: _Learning) -> list[str]:
    """README sentences on the band and the airframe correction that ``learn`` applies."""
    out = []
    if lp.sos is not None:
        order = f"of order {lp.order} " if lp.order else ""
        out.append(f"The learning band F is a zero-phase Butterworth low-pass {order}with corner {lp.cutoff:.4g} rad/s"
                   + (f" ({lp.why})" if lp.why else "") + f"; the trial is extended by {lp.pad} samples at each end "
                   f"(zeros before, the least-squares line through its last {lp.end_fit} samples after).")
        if (filters.get("band") or {}).get("request") == "auto":
            out.append("The corner was chosen when this folder was written; the Python design chooses it per trial "
                       "(`--bandwidth auto`): for another trial run `ilcdob design --trial` again, or state the "
                       "corner with `--bandwidth`.")
    else:
        out.append("No learning band (no filter): L1 and L2 act on the trial as recorded.")
    if lp.w_sos is not None:
        out.append("W is the airframe correction (the disturbance acts on the airframe), run after L1 + L2.")
    out += [p.readme for p in (s.c_parts("") for s in LearningLaw.from_dict(filters).stages) if p.readme]
    return out


def _inversion_readme(filters: dict[str, Any]) -> list[str]:
    """README lines stating the zero-phase substitutes of ``filters.json`` (``inversion``)."""
    lines = []
    for key in FILTER_KEYS:
        note = filters[key].get("inversion")
        if not note:
            continue
        poles = ", ".join(f"{re:.6g}" + (f"{im:+.4g}j" if im else "") for re, im in note["poles"])
        looks = ", ".join("on the unit circle" if n is None else f"{n} samples" for n in note["exact_lookahead_samples"])
        below = note["error_below_rad_s"]
        lines += ["", f"{key} inverts the plant zero(s) {poles} of {filters['from']}'s model with zero phase error "
                  f"(ZPETC; exactly they would look ahead {looks}): relative error of the filter below 1e-6 up to "
                  f"{below['1e-06']:.4g} rad/s, below 1e-4 up to {below['0.0001']:.4g} rad/s, below 1e-2 up to "
                  f"{below['0.01']:.4g} rad/s; with exact models the learning falls short by that fraction, it does not overshoot."]
    return lines


def _structure_readme(filters: dict[str, Any]) -> list[str]:
    """README lines giving each filter's look-ahead and how it is run (pre-stage, sections)."""
    ts = float(filters["sample_time"])
    lines = []
    for key in FILTER_KEYS:
        f = filters[key]
        adv = int(f["advance"])
        look = f"{key} looks ahead {adv} sample{'s' if adv != 1 else ''} ({adv * ts:.4g} s)"
        if f.get("sos"):
            ns, taps = len(f["sos"]), _lookahead_size(f)
            sections = f"{ns} second-order section{'s' if ns != 1 else ''}"
            if taps:
                ahead = taps - 1
                lines.append(f"- {look}: a look-ahead FIR of {taps} taps (`lookahead` in `filters.json`, "
                             f"v(j) = sum_m g_m u(j + m), m = 0..{ahead}: the series of its anti-causal poles "
                             f"|p| > 1, the stable inversion's backward part cut where its terms fall below 1e-12) "
                             f"looks {ahead} samples ahead, then {sections} run on v, read {adv - ahead} "
                             f"sample{'s' if adv - ahead != 1 else ''} ahead.")
            else:
                lines.append(f"- {look}: {sections}.")
        elif "num" in f:
            kind = (f"a FIR of {len(f['num'])} taps" if list(f.get("den", [1.0])) == [1.0]
                    else f"a direct form of order {max(len(f['num']), len(f['den'])) - 1}")
            lines.append(f"- {look}: {kind}.")
    return lines


def _robust_readme(filters: dict[str, Any], prefix: str) -> list[str]:
    """README lines defining the robust-set law ``R`` that ``learn`` runs."""
    fir, guarantee = filters["F"], filters.get("rho_guaranteed")
    ginv = filters["law_maps"]["inverse_gd"]
    return [f"R is the robust-set law: R{{e, d_f}} = (1 - Q_j){{Fr{{d_hat}}}} with d_hat = -Ginv{{e + Gf{{d_f}}}} "
            f"the disturbance reconstructed by {filters['from']}'s model (Gf = Gf_hat, Ginv = Gd_hat^-1, "
            f"`law_maps` in `filters.json`), Q_j the Q of {filters['to']}'s DOB and Fr the robustness FIR of "
            f"{len(fir['num'])} taps looking {fir['advance']} samples ahead (`F`). d_hat is continued past the "
            f"trial's end along its trend (`trial_ends`) and Fr's output before t = 0 is folded onto the first "
            "samples."
            + (f" Per frequency it guarantees |e_j| <= {guarantee:.4g} |e'_j| for every plant of the Delta set "
               f"({filters.get('guaranteed_over', 'see filters.json')})." if isinstance(guarantee, (int, float))
               else ""),
            "", f"`{prefix}ginv_apply` runs Ginv alone (it looks ahead {ginv['advance']} samples; the trial is "
            "continued past its end by a cubic, as `ilcdob.design.filters.coefficients.apply_coefficients` does). "
            "The code uses "
            "`cos()` of the C math library (link with `-lm`)."]


def _signal_units(filters: dict[str, Any]) -> tuple[str, str, list[str]]:
    """Units of the source's and the target's learning signal, and the README lines saying where each enters
    (a pair with a vehicle on its own controller: ``channel`` and ``source_channel`` in ``filters.json``)."""
    if "channel" not in filters:
        return "m/s^2", "m/s^2", []
    ch_tgt, ch_src = filters["channel"], filters.get("source_channel", "acceleration")
    words = {"position": "an offset of its position setpoint (m)", "velocity": "a velocity feed-forward (m/s)",
             "acceleration": "an acceleration feed-forward (m/s^2)"}
    return CHANNEL_UNITS[ch_src], CHANNEL_UNITS[ch_tgt], [
        "", f"Here d_f is the learning signal on each vehicle's channel: on {filters['from']} {words[ch_src]}, on "
        f"{filters['to']} {words[ch_tgt]} added to the setpoint its own controller tracks. A vehicle flying "
        "ilcdob's PID + DOB learns on its acceleration feed-forward: its d_f here is the acceleration added to its "
        "command, the opposite of the paper's d_f added to the DOB estimate."]


def design_readme(filters: dict[str, Any], files: Sequence[str], code: CCode | None = None) -> str:
    """The ``README.md`` of a design folder holding ``files``.

    Parameters
    ----------
    filters : dict
        ``filters.json`` content.
    files : sequence of str
        Names of the files in the folder (described in this order).
    code : CCode, optional
        The C code written, for its function names and float figures.

    Returns
    -------
    str
        The README text (Markdown).
    """
    src, tgt, ts = filters["from"], filters["to"], float(filters["sample_time"])
    u_src, u_tgt, channels = _signal_units(filters)
    lines = [f"# Learning design {src} -> {tgt} ({filters['method']})", "",
             f"Written by `ilcdob design`. Sample time Ts = {ts:g} s. Vehicle {tgt} learns from the previous "
             f"vehicle {src}: d_f,j = L1{{e_j-1}} + L2{{d_f,j-1}}"
             + (", through the learning band and corrections below." if code is not None else "."),
             *channels, "", "## Files", ""]
    lines += [f"- `{name}`: {_FILE_TEXT.get(name, '')}" for name in files]
    lines += ["", "## Between two flights", ""]
    if code is not None:
        p, m = code.prefix, code.prefix.upper()
        lp = _learning_parts(filters)
        law = "L1{F{H{e}}} + L2{F{H{d_f}}}" if lp.sos is not None else "L1{e} + L2{d_f}"
        if lp.w_sos is not None:
            law = f"W{{{law}}}"
        if lp.sos is not None:
            law = f"crop(F{{{law}}})"
        robust = "law_maps" in filters
        if robust:
            law = law.replace("L1{F{H{e}}} + L2{F{H{d_f}}}", "R{F{H{e}}, F{H{d_f}}}").replace("L1{e} + L2{d_f}",
                                                                                            "R{e, d_f}")
        lines += [f"After a flight of {src}, take its recorded tracking error e (m) and the learning signal it "
                  f"flew, d_f ({u_src}; zeros if none), n samples every {ts:g} s from the start of the trial. Then",
                  "",
                  "```c",
                  '#include "filters.h"',
                  f"static double work[{m}LEARN_WORK(N_MAX)];   /* scratch, N_MAX >= n */",
                  "/* e, d_f: the recorded trial; d_next: n doubles (may be e or d_f) */",
                  f"if ({p}learn(e, d_f, d_next, n, work) != 0) {{ /* n == 0 or a NULL pointer */ }}",
                  "```",
                  "",
                  f"and feed `d_next` forward ({u_tgt}) on the next flight of {tgt}, sample k at time k Ts. "
                  f"`{p}learn` computes d_next = {law} over the whole trial at once, exactly as "
                  "`ilcdob.design.law.apply_learning` does in Python (to rounding); no allocation, "
                  f"`work` holds `{m}LEARN_WORK(n)` = {code.work or f'2 * (n + 2 * {lp.pad})'} doubles.",
                  "", *_band_readme(filters, lp), ""]
        if robust:
            lines += _robust_readme(filters, p)
        else:
            lines += [f"The filters alone are `{p}l1_apply` and `{p}l2_apply` (they look ahead "
                      f"{filters['L1']['advance']} (L1) and {filters['L2']['advance']} (L2) samples; the trial is "
                      "continued past its end by a cubic, as "
                      "`ilcdob.design.filters.coefficients.apply_coefficients` does)"
                      + ("; with the band or W their sum is not the learning signal." if lp.sos is not None
                         or lp.w_sos is not None else "; their sum is what `learn` returns."),
                      "", *_structure_readme(filters)]
            lines += _inversion_readme(filters)
        if filters.get("law") == "exact-reference":
            lines += ["", f"Learning law exact-reference (`ilcdob.design.law.laws`): pass `e - e_ref_source` instead "
                      f"of `e` to `{p}learn` and add `correction` to `d_next`, both from `reference_terms.csv` "
                      "(they depend on the reference trajectory: run `ilcdob design --law exact-reference` again "
                      "for another trajectory). `learning_signal.csv` already includes both."]
        if code.float_errors:
            lines += ["", "The float variant (`*_apply_f`, L1 and L2 only; `learn` runs in double) differs from "
                      "the double one by at most "
                      + ", ".join(f"{v:.2e} ({k})" for k, v in code.float_errors.items())
                      + f" of the output's maximum, measured on {_REFERENCE_TEXT}."]
    elif "learning_signal.csv" in files:
        lines += [f"`learning_signal.csv` is the learning signal of {tgt} for the trial given with `--trial`: "
                  f"feed it forward on the next flight of {tgt}. For another trial of {src}, run "
                  "`ilcdob design` again with that trial (columns time (s), error (m), learning (m/s^2))."]
    else:
        lines += [f"Method {filters['method']} has no filters to run on board: give a trial of {src} with "
                  "`--trial` to get the learning signal."]
    return "\n".join(lines) + "\n"


def design_files(filters: dict[str, Any], others: Sequence[str] = (), prefix: str | None = None,
                 float_variant: bool = False) -> tuple[dict[str, Any], dict[str, Any]]:
    """The files of a design folder: ``filters.json``, ``filters.h``/``filters.c`` (when the design
    has L1/L2 or law maps) and ``README.md``.

    Parameters
    ----------
    filters : dict
        ``filters.json`` content; not modified.
    others : sequence of str
        Other files of the folder (``filters.mat``, ``lifted.npz``, ``learning_signal.csv``), for the README.
    prefix : str, optional
        C symbol prefix (default :func:`default_c_prefix`).
    float_variant : bool
        Also emit the float functions.

    Returns
    -------
    tuple of (dict, dict)
        The content map (file name -> text or JSON document), and the ``filters.json``
        content: ``filters`` plus, with C code, key ``c`` (:attr:`CCode.info`).
    """
    data = dict(filters)
    files: dict[str, Any] = {}
    code = None
    if all(k in filters for k in FILTER_KEYS) or "law_maps" in filters:
        code = c_code(filters, prefix, float_variant)
        data["c"] = code.info
        files = {"filters.h": code.header, "filters.c": code.source}
    names = ["filters.json", *files, *others, "README.md"]
    files["README.md"] = design_readme(data, names, code)
    files["filters.json"] = data
    return files, data
