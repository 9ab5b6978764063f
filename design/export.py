"""Export of learning filters: coefficient form and application from coefficients.

A filter is written as ``H(z) = z^advance * N(z^-1) / D(z^-1)``: ``output(k)`` uses
``input(k + advance)``, i.e. run ``N/D`` causally on the input shifted ``advance`` samples
ahead. A non-causal zero-pole filter (:class:`~ilcdob.design.noncausal.ZPKFilter`) is
converted as it is applied (:attr:`~ilcdob.design.noncausal.ZPKFilter.realised`: poles
whose exact inverse would look ahead more than 64 samples replaced by their zero-phase-error
substitute, stated under ``inversion``, docs/theory.md section 2), exactly except for its
anti-causal poles ``1/(z - p)``, ``|p| > 1``, which are expanded into the series
``-(1/p) sum_m (z/p)^m`` truncated where ``|p|^-m`` falls below ``tol`` (about 22 terms for
the ZOH sampling zero at -3.6, at most 64 by the look-ahead bound): a finite advance, exact
to ``tol``. The sections are ordered by :func:`order_sections` so that no intermediate
signal outgrows the output.

Canonical form: second-order sections. ``sos`` rows are ``[b0, b1, b2, 1, a1, a2]`` in
powers of ``z^-1``, cascaded; :func:`apply_coefficients` and the C code of
:mod:`.c_export` run them. The closed-form filters have a dozen poles and zeros clustered
between 0.8 and 1 (the loops' slow modes and the PID integrator at z = 1); multiplied out
into one direct-form pair ``num``/``den`` (``z^-1`` powers, highest first, ``den[0] = 1``)
they lose the low-frequency response in double precision. ``num``/``den`` are therefore
written only when their frequency response agrees with the sections' to
:data:`DIRECT_FORM_RTOL` relative on the band of :func:`direct_form_grid` (four decades
below Nyquist up to Nyquist); otherwise they are left out and ``num_den_omitted`` says by
how much they disagree and where. A FIR (``den = [1]``, :mod:`.fir`) has no sections: its
direct form is exact and canonical.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal

from ilcdob.errors import SpecError
from ilcdob.signals import as_signal, extend_smoothly

from .band import learning_horizon
from .noncausal import LOOKAHEAD_MAX, ZPKFilter, lookahead

__all__ = ["zpk_to_coefficients", "inversion_note", "order_sections", "section_growth", "order_grid", "apply_coefficients", "apply_learning", "direct_form_grid",
           "direct_form_disagreement", "DIRECT_FORM_RTOL"]

#: Largest relative disagreement of ``num``/``den`` with ``sos`` for ``num``/``den`` to be written.
DIRECT_FORM_RTOL = 1e-6

_BAND_DECADES = 4     # the check band starts this many decades below Nyquist
_GRID_POINTS = 2048   # log-spaced points over the band, and as many linearly spaced


def direct_form_grid(ts: float) -> np.ndarray:
    """Frequencies (rad/s) on which ``num``/``den`` are checked against the sections.

    The union of 2048 log-spaced points from ``1e-4 * pi / ts`` to Nyquist ``pi / ts`` and
    2048 linearly spaced points up to Nyquist: dense at low frequency, where clustered poles
    make the direct form lose accuracy, and over the whole band. ``w = 0`` is excluded (the
    PID integrator puts a pole of L1 at z = 1).

    Parameters
    ----------
    ts : float
        Sample time, s.

    Returns
    -------
    numpy.ndarray
        Sorted unique frequencies, rad/s.
    """
    wn = math.pi / ts
    return np.unique(np.concatenate([np.geomspace(wn * 10.0 ** -_BAND_DECADES, wn, _GRID_POINTS),
                                     np.linspace(wn / _GRID_POINTS, wn, _GRID_POINTS)]))


def direct_form_disagreement(num: Any, den: Any, sos: Any, ts: float) -> tuple[float, float]:
    """Largest relative difference of ``num/den`` from ``sos`` on :func:`direct_form_grid`.

    Parameters
    ----------
    num, den : array_like
        Direct-form numerator and denominator, powers of ``z^-1``, highest first.
    sos : array_like
        Second-order sections, rows ``[b0, b1, b2, 1, a1, a2]``.
    ts : float
        Sample time, s.

    Returns
    -------
    rel : float
        ``max |H_nd - H_sos| / |H_sos|`` (``inf`` if the direct form overflows or divides by 0).
    w : float
        Frequency of that maximum, rad/s.
    """
    w = direct_form_grid(ts)
    zinv = np.exp(-1j * w * ts)
    with np.errstate(all="ignore"):
        h_nd = np.polyval(np.asarray(num, float)[::-1], zinv) / np.polyval(np.asarray(den, float)[::-1], zinv)
        _, h_sos = signal.sosfreqz(np.asarray(sos, float), worN=w * ts)
        rel = np.abs(h_nd - h_sos) / np.abs(h_sos)
    rel = np.where(np.isfinite(rel), rel, np.inf)
    i = int(np.argmax(rel))
    return float(rel[i]), float(w[i])


def section_growth(sos: np.ndarray, ts: float) -> float:
    """Largest steady-state size of an intermediate signal of a section cascade, relative to
    its output: ``max_k max_w |H_1(w) ... H_k(w)| / |H(w)|`` on :func:`order_grid`.

    Parameters
    ----------
    sos : numpy.ndarray
        Second-order sections in cascade order.
    ts : float
        Sample time, s.

    Returns
    -------
    float
        The ratio (1 when no intermediate exceeds the output at any frequency).
    """
    h = _section_responses(np.asarray(sos, float), ts)
    part = np.cumprod(h, axis=0)
    return float(np.max(np.abs(part) / np.abs(part[-1])))


def order_grid(ts: float) -> np.ndarray:
    """Frequencies on which section orderings are judged: 400 log-spaced points from four
    decades below Nyquist to Nyquist, rad/s (as :func:`direct_form_grid`, coarser)."""
    wn = math.pi / ts
    return np.geomspace(wn * 10.0 ** -_BAND_DECADES, wn, 400)


def _section_responses(sos: np.ndarray, ts: float) -> np.ndarray:
    z = np.exp(-1j * order_grid(ts) * ts)
    num = sos[:, [0]] + sos[:, [1]] * z + sos[:, [2]] * z ** 2
    den = sos[:, [3]] + sos[:, [4]] * z + sos[:, [5]] * z ** 2
    return num / den


def order_sections(sos: np.ndarray, ts: float) -> np.ndarray:
    """Order a section cascade so that its intermediate signals stay near the output's size.

    ``scipy.signal.zpk2sos`` orders sections by pole radius. A learning filter pairs an
    inverse plant (gain ~1e5 towards Nyquist) with poles clustered near ``z = 1``; in that order
    the partial cascades of a closed-form L1 reached 3.7e6 times the output at low frequency,
    and the rounding they carried, amplified by the later sections' high-frequency gain, cost
    the output 1e-3 of its size. Greedily appending the section that keeps
    ``max_w |partial(w)| / |H(w)|`` smallest (:func:`section_growth`) brought the same filter
    to 1.4 and its output to rounding level. The product, hence the filter, is unchanged.

    Parameters
    ----------
    sos : numpy.ndarray
        Second-order sections, rows ``[b0, b1, b2, 1, a1, a2]``.
    ts : float
        Sample time, s.

    Returns
    -------
    numpy.ndarray
        The same rows, reordered.
    """
    sos = np.asarray(sos, float)
    h = _section_responses(sos, ts)
    total = np.abs(np.prod(h, axis=0))
    part = np.ones(h.shape[1], dtype=complex)
    remaining, order = list(range(sos.shape[0])), []
    while remaining:
        best = min(remaining, key=lambda i: float(np.max(np.abs(part * h[i]) / total)))
        order.append(best)
        remaining.remove(best)
        part = part * h[best]
    return sos[order]


def inversion_note(f: ZPKFilter) -> dict[str, Any]:
    """What a filter's zero-phase substitutes cost (:mod:`.noncausal`, look-ahead bound).

    Parameters
    ----------
    f : ZPKFilter
        A filter with :attr:`~ilcdob.design.noncausal.ZPKFilter.substituted` poles.

    Returns
    -------
    dict
        ``method``, the substituted ``poles`` (``[re, im]``), the ``exact_lookahead_samples``
        each would have needed, and ``error_below_rad_s``: the highest frequency up to which
        the relative error ``|applied/exact - 1|`` stays below 1e-6, 1e-4 and 1e-2.
    """
    w = np.linspace(0.0, math.pi / f.ts, 20001)[1:]
    err = f.approximation_error(w)
    below = {}
    for level in (1e-6, 1e-4, 1e-2):
        over = np.flatnonzero(err > level)
        below[f"{level:g}"] = float(w[over[0] - 1]) if over.size and over[0] > 0 else (0.0 if over.size else float(w[-1]))
    return {"method": "zero-phase-error substitute (z^-1 - p)/(1 - p)^2 for poles whose exact inverse would look "
                      f"ahead more than {LOOKAHEAD_MAX} samples or that lie on the unit circle",
            "poles": [[float(p.real), float(p.imag)] for p in f.substituted],
            "exact_lookahead_samples": [lookahead(p) if abs(p) > 1 + 1e-8 else None for p in f.substituted],
            "error_below_rad_s": below}


def zpk_to_coefficients(f: ZPKFilter, tol: float = 1e-12) -> dict[str, Any]:
    """Coefficient form of a (non-causal) zero-pole filter, see module docstring.

    Parameters
    ----------
    f : ZPKFilter
        The filter.
    tol : float
        Truncation of the series of the anti-causal poles (relative size of the last term).

    Returns
    -------
    dict
        ``{"advance": int, "sos": [[b0, b1, b2, 1, a1, a2], ...]}`` plus either
        ``"num"``, ``"den"`` (when they agree with ``sos`` to :data:`DIRECT_FORM_RTOL`) or
        ``"num_den_omitted"`` (a sentence giving the disagreement).
    """
    exact = f
    f = f.realised
    pc, pu = f.causal_poles, f.anticausal_poles
    num = np.real(np.poly(f.zeros)) if len(f.zeros) else np.array([1.0])   # in z^-1 after shift
    den = np.real(np.poly(pc)) if len(pc) else np.array([1.0])
    advance = len(f.zeros) - len(pc)
    gain = f.gain
    if len(pu):
        slowest = float(np.min(np.abs(pu)))
        m = int(math.ceil(-math.log(tol) / math.log(slowest)))
        # prod 1/(1 - z/p) = sum_m c_m z^m: coefficients of the reversed-time causal filter
        impulse = np.zeros(m + 1)
        impulse[0] = 1.0
        c = signal.lfilter([1.0], np.real(np.poly(1.0 / pu)), impulse)
        gain *= float(np.real(np.prod(-1.0 / pu)))
        num = np.convolve(num, c[::-1])  # z^m sum_i c_{m-i} z^-i
        advance += m
    if advance < 0:
        num = np.concatenate([np.zeros(-advance), num])
        advance = 0
    # the same filter in second-order sections: zeros = filter zeros + roots of the series
    # sum_m c_m z^m = c_M prod(z - r_i) (radius |p|: well separated)
    all_zeros, sos_gain = f.zeros, gain
    if len(pu):
        all_zeros = np.concatenate([f.zeros, np.roots(c[::-1])])
        sos_gain = gain * c[-1]
    n_extra = len(all_zeros) - len(pc)
    sos = order_sections(signal.zpk2sos(all_zeros, np.concatenate([pc, np.zeros(max(n_extra, 0))]), sos_gain), f.ts)
    out: dict[str, Any] = {"advance": int(advance), "sos": sos.tolist()}
    if exact.substituted.size:
        out["inversion"] = inversion_note(exact)
    num = gain * num
    rel, w = direct_form_disagreement(num, den, sos, f.ts)
    if rel <= DIRECT_FORM_RTOL:
        out["num"], out["den"] = [float(v) for v in num], [float(v) for v in den]
    else:
        grid = direct_form_grid(f.ts)
        out["num_den_omitted"] = (f"direct-form polynomials disagree with the sections by {rel:.3g} relative at "
                                  f"w = {w:.4g} rad/s (criterion {DIRECT_FORM_RTOL:g} over {grid[0]:.4g} to "
                                  f"{grid[-1]:.4g} rad/s); use sos")
    return out


def apply_coefficients(coeffs: dict[str, Any], x: object) -> np.ndarray:
    """Run ``z^advance N/D`` over a whole trial (input continued smoothly past its end).

    Parameters
    ----------
    coeffs : dict
        A filter of ``filters.json``: ``advance`` and ``sos`` (preferred when present) or
        ``num``/``den``.
    x : array_like
        The trial, one sample per sample time, starting at rest.

    Returns
    -------
    numpy.ndarray
        The filtered trial, same length as ``x``. The input is continued past its end by
        :func:`~ilcdob.signals.extend_smoothly` (the advance needs it) and taken
        as zero before its start.
    """
    x = as_signal(x, "x")
    if "advance" not in coeffs:
        raise SpecError(f"filter coefficients: missing key `advance`; got keys {sorted(coeffs)}")
    adv = int(coeffs["advance"])
    if adv < 0:
        raise SpecError(f"`advance`: got {adv}, expected a number of samples >= 0")
    padded = extend_smoothly(x, adv + 8)
    if coeffs.get("sos"):
        sos = np.asarray(coeffs["sos"], float)
        if sos.ndim != 2 or sos.shape[1] != 6 or not np.all(sos[:, 3] == 1.0):
            raise SpecError(f"`sos`: expected rows [b0, b1, b2, 1, a1, a2], got an array of shape {sos.shape}")
        y = signal.sosfilt(sos, padded)
    elif "num" in coeffs and "den" in coeffs:
        num, den = np.asarray(coeffs["num"], float), np.asarray(coeffs["den"], float)
        if den.size == 0 or den[0] == 0:
            raise SpecError(f"`den`: leading coefficient must be non-zero, got {list(den)}")
        y = signal.lfilter(num, den, padded)
    else:
        why = coeffs.get("num_den_omitted", "")
        raise SpecError("filter coefficients: neither `sos` nor `num`/`den` given"
                        + (f" ({why})" if why else "") + f"; got keys {sorted(coeffs)}")
    return y[adv:adv + x.size]



def _forward_backward(sos: np.ndarray, zi: np.ndarray, x: np.ndarray) -> np.ndarray:
    """One zero-phase pass: ``sos`` forwards from the state ``zi x[0]``, then backwards from
    ``zi y[-1]`` (what ``scipy.signal.sosfiltfilt(..., padtype=None)`` computes)."""
    y, _ = signal.sosfilt(sos, x, zi=zi * x[0])
    y, _ = signal.sosfilt(sos, y[::-1], zi=zi * y[-1])
    return y[::-1]


def apply_learning(filters: dict[str, Any], e_prev: object, df_prev: object) -> np.ndarray:
    """The learning law of a ``filters.json`` computed from its coefficients alone.

    What the C function ``<prefix>learn`` runs (:mod:`.c_export`), in numpy::

        d_f = crop(F{W{L1{F{H{e}}} + L2{F{H{d_f_prev}}}}})

    ``H`` extends the trial by ``band.pad`` samples (zeros before, the least-squares line
    through its last ``band.end_fit`` samples after), ``F`` is ``band.sos`` run forwards then
    backwards from the steady state ``band.zi`` times the first sample of each pass, ``W``
    is ``disturbance.W.sos`` run forwards from rest, ``L1``/``L2`` run as
    :func:`apply_coefficients`; ``crop`` keeps the trial's samples. Without a band (no
    ``band.sos``) it is ``W{L1{e} + L2{d_f_prev}}``.

    Parameters
    ----------
    filters : dict
        ``filters.json`` content with ``L1`` and ``L2`` (closed-form and FIR designs).
    e_prev : array, m
        The previous vehicle's tracking error (for ``exact-reference``: with its reference
        error removed).
    df_prev : array, m/s^2
        The learning signal it flew (zeros if none).

    Returns
    -------
    numpy.ndarray
        The learning signal, m/s^2 (for ``exact-reference``: before the reference correction).
    """
    missing = [k for k in ("L1", "L2") if k not in filters]
    if missing:
        raise SpecError(f"filters: missing key(s) {missing}; method {filters.get('method')!r} has no L1/L2 filters")
    e = as_signal(e_prev, "e_prev")
    df = as_signal(df_prev, "df_prev", e.size)
    band = filters.get("band") or {}
    w_sos = (filters.get("disturbance") or {}).get("W", {}).get("sos")
    if band.get("sos") is None:
        y = apply_coefficients(filters["L1"], e) + apply_coefficients(filters["L2"], df)
        return signal.sosfilt(np.asarray(w_sos, float), y) if w_sos is not None else y
    sos, zi = np.asarray(band["sos"], float), np.asarray(band["zi"], float)
    pad, n_fit, ts = int(band["pad"]), int(band["end_fit"]), float(filters["sample_time"])
    x1 = _forward_backward(sos, zi, learning_horizon(e, ts, pad, n_fit))
    x2 = _forward_backward(sos, zi, learning_horizon(df, ts, pad, n_fit))
    y = apply_coefficients(filters["L1"], x1) + apply_coefficients(filters["L2"], x2)
    if w_sos is not None:
        y = signal.sosfilt(np.asarray(w_sos, float), y)
    return _forward_backward(sos, zi, y)[pad:pad + e.size]
