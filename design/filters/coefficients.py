"""The coefficient form of a learning filter (``filters.json``) and its application.

A filter is written as ``H(z) = z^advance * N(z^-1) / D(z^-1)``: ``output(k)`` uses the input
up to ``input(k + advance)``, i.e. run ``N/D`` causally on the input shifted ``advance`` samples
ahead. A non-causal zero-pole filter (:class:`~ilcdob.design.filters.noncausal.ZPKFilter`) is
converted as it is applied (:attr:`~ilcdob.design.filters.noncausal.ZPKFilter.realised`: poles that it
inverts with zero phase error replaced by their substitute, stated under ``inversion``,
docs/theory.md section 2), exactly except for its anti-causal poles ``1/(z - p)``, ``|p| > 1``,
whose product is expanded into the series ::

    prod_p 1/(z - p) = sum_{m=0}^{M} g_m z^m,   g_m = prod_p(-1/p) * c_m,   prod_p 1/(1 - z/p) = sum_m c_m z^m

truncated at ``M = ceil(ln(1/tol) / ln min|p|)``, where ``min|p|^-M`` falls below ``tol``
(1e-12): ``M`` = 22 for the ZOH sampling zero near -3.7, 2,764 for the image ``e^{10 Ts}`` of
a continuous non-minimum-phase zero at 10 rad/s sampled at 1 ms (its look-ahead of
``ln(1e12)/10`` = 2.8 s is the physics of the inversion, not an artefact). It is a finite
advance, exact to ``tol``.

Canonical form (``sos``, with ``lookahead`` when the filter has anti-causal poles)::

    output(k) = S{v}(k + advance - M),     v(j) = sum_{m=0}^{M} g_m u(j + m)

``lookahead`` is ``[g_0, ..., g_M]`` (``M = len(lookahead) - 1``; absent: ``M = 0``, ``v = u``),
the look-ahead FIR pre-stage, applied to the input ``u`` taken as zero before the trial and
continued past its end (:func:`~ilcdob.signals.extend_smoothly`); ``S`` is the cascade of the
second-order sections ``sos``, rows ``[b0, b1, b2, 1, a1, a2]`` in powers of ``z^-1``, run
forwards from rest from ``j = -M`` (the first ``v`` that sees the trial). ``advance`` is the
whole look-ahead, ``M`` samples of the pre-stage plus ``advance - M >= 0`` of the sections
(the filter's surplus of zeros over causal poles). In transfer-function form
``H(z) = z^advance * [z^-M G(z)] * S(z^-1)`` with ``G(z) = sum_m g_m z^m``: ``z^-M G(z)`` is
the causal FIR whose taps are ``lookahead`` reversed. The sections hold the filter's zeros,
its causal poles (``|p| <= 1``, the integrator at z = 1 included) and its gain, never the
roots of the series (a polynomial of degree ``M``: for ``|p|`` near 1 thousands of roots,
minutes of ``numpy.roots`` and intermediate signals 1e5 times the output); a filter with more
causal poles than zeros gets pure-delay sections (``[0, 1, 0, 1, 0, 0]``,
``[0, 0, 1, 1, 0, 0]``) so that ``advance - M`` is never negative. The sections are ordered by
:func:`order_sections` so that no intermediate signal outgrows the output (the pre-stage's
output ``v`` is ``1/|S|`` times the output, :func:`section_growth`). :func:`apply_coefficients`
and the C code of :mod:`..export.c_export` run this form, the pre-stage's sum in descending ``m``.

The closed-form filters have a dozen poles and zeros clustered between 0.8 and 1 (the loops'
slow modes and the PID integrator at z = 1); multiplied out into one direct-form pair
``num``/``den`` (``z^-1`` powers, highest first, ``den[0] = 1``; ``num`` includes the
pre-stage, ``N(z^-1) = gain prod(1 - z_i z^-1) * z^-M G(z)``, with the same ``advance``) they
lose the low-frequency response in double precision. ``num``/``den`` are therefore written
only when their frequency response agrees with the canonical form's (pre-stage and sections)
to :data:`DIRECT_FORM_RTOL` relative on the band of :func:`direct_form_grid` (four decades
below Nyquist up to Nyquist); otherwise they are left out and ``num_den_omitted`` says by
how much they disagree and where. A FIR (``den = [1]``, :mod:`..methods.fir`) has no sections: its
direct form is exact and canonical. :func:`coefficients_freqresp` evaluates any of these forms.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import signal

from ilcdob.errors import SpecError
from ilcdob.signals import as_signal, extend_smoothly
from ilcdob.statespace import simulate

from .noncausal import LOOKAHEAD_MAX, ZPKFilter, lookahead

if TYPE_CHECKING:
    import control as ct

__all__ = ["zpk_to_coefficients", "inversion_note", "order_sections", "section_growth", "order_grid",
           "apply_coefficients", "apply_lookahead", "lookahead_taps", "coefficients_freqresp",
           "state_space_to_dict", "apply_state_space", "direct_form_grid", "direct_form_disagreement",
           "DIRECT_FORM_RTOL"]

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


def direct_form_disagreement(num: Any, den: Any, sos: Any, ts: float, lookahead: Any = None) -> tuple[float, float]:
    """Largest relative difference of ``num/den`` from the canonical form on :func:`direct_form_grid`.

    Parameters
    ----------
    num, den : array_like
        Direct-form numerator and denominator, powers of ``z^-1``, highest first.
    sos : array_like
        Second-order sections, rows ``[b0, b1, b2, 1, a1, a2]``.
    ts : float
        Sample time, s.
    lookahead : array_like, optional
        The look-ahead pre-stage ``[g_0, ..., g_M]`` run before the sections (module
        docstring): the canonical form is ``z^-M G(z) S(z^-1)``, both forms with the same advance.

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
        if lookahead is not None:
            h_sos = h_sos * _lookahead_response(np.asarray(lookahead, float), zinv)
        rel = np.abs(h_nd - h_sos) / np.abs(h_sos)
    rel = np.where(np.isfinite(rel), rel, np.inf)
    i = int(np.argmax(rel))
    return float(rel[i]), float(w[i])


def _lookahead_response(g: np.ndarray, zinv: np.ndarray) -> np.ndarray:
    """``z^-M G(z) = sum_m g_m z^(m - M)`` at the points ``zinv = z^-1`` (Horner in ``z^-1``)."""
    return np.polyval(g, zinv)


def section_growth(sos: np.ndarray, ts: float, lookahead: Any = None) -> float:
    """Largest steady-state size of an intermediate signal of a section cascade, relative to
    its output: ``max_k max_w |H_1(w) ... H_k(w)| / |H(w)|`` on :func:`order_grid`.

    Parameters
    ----------
    sos : numpy.ndarray
        Second-order sections in cascade order.
    ts : float
        Sample time, s.
    lookahead : array_like, optional
        The look-ahead pre-stage run before the sections (module docstring): its output is
        counted as the first intermediate signal (``1/|S(w)|`` times the output).

    Returns
    -------
    float
        The ratio (1 when no intermediate exceeds the output at any frequency).
    """
    h = _section_responses(np.asarray(sos, float), ts)
    if lookahead is not None:
        zinv = np.exp(-1j * order_grid(ts) * ts)
        h = np.vstack([_lookahead_response(np.asarray(lookahead, float), zinv), h])
    part = np.cumprod(h, axis=0)
    return float(np.max(np.abs(part) / np.abs(part[-1])))


def order_grid(ts: float) -> np.ndarray:
    """Frequencies on which section orderings are judged (as :func:`direct_form_grid`, coarser).

    Parameters
    ----------
    ts : float
        Sample time, s.

    Returns
    -------
    numpy.ndarray
        400 log-spaced points from four decades below Nyquist to Nyquist, rad/s.
    """
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
        A filter with :attr:`~ilcdob.design.filters.noncausal.ZPKFilter.substituted` poles.

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
        first = over[0] if over.size else w.size   # first frequency over the level
        below[f"{level:g}"] = float(w[first - 1]) if first else 0.0
    return {"method": "zero-phase-error substitute (z^-1 - p)/(1 - p)^2 for poles in the left half of the z-plane "
                      f"(sampling zeros) whose exact inverse would look ahead more than {LOOKAHEAD_MAX} samples or "
                      "that lie on the unit circle",
            "poles": [[float(p.real), float(p.imag)] for p in f.substituted],
            "exact_lookahead_samples": [lookahead(p) if abs(p) > 1 + 1e-8 else None for p in f.substituted],
            "error_below_rad_s": below}


def _lookahead_series(pu: np.ndarray, tol: float) -> np.ndarray:
    """``[g_0, ..., g_M]``: ``prod_p 1/(z - p) = sum_m g_m z^m`` truncated where ``min|p|^-M < tol``."""
    m = int(math.ceil(-math.log(tol) / math.log(float(np.min(np.abs(pu))))))
    # prod 1/(1 - z/p) = sum_m c_m z^m: the impulse response of prod 1/(1 - w/p) in a variable w
    impulse = np.zeros(m + 1)
    impulse[0] = 1.0
    c = signal.lfilter([1.0], np.real(np.poly(1.0 / pu)), impulse)
    return float(np.real(np.prod(-1.0 / pu))) * c


def _delay_sections(d: int) -> np.ndarray:
    """Sections of a pure delay of ``d`` samples: ``z^-2`` rows, then one ``z^-1`` row if ``d`` is odd."""
    rows = [[0.0, 0.0, 1.0, 1.0, 0.0, 0.0]] * (d // 2) + [[0.0, 1.0, 0.0, 1.0, 0.0, 0.0]] * (d % 2)
    return np.array(rows, dtype=float).reshape(-1, 6)


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
        ``{"advance": int, "sos": [[b0, b1, b2, 1, a1, a2], ...]}``, with anti-causal poles
        ``"lookahead": [g_0, ..., g_M]``, plus either ``"num"``, ``"den"`` (when they agree
        with the canonical form to :data:`DIRECT_FORM_RTOL`) or ``"num_den_omitted"`` (a
        sentence giving the disagreement), and ``"inversion"`` when poles were substituted.
    """
    exact = f
    f = f.realised
    pc, pu = f.causal_poles, f.anticausal_poles
    # zpk2sos pads the shorter of zeros and poles with roots at the origin: its sections are
    # z^-(len(zeros) - len(pc)) times the causal part prod(z - z_i)/prod(z - p_c)
    surplus = len(f.zeros) - len(pc)
    delay = max(-surplus, 0)
    sos = signal.zpk2sos(f.zeros, pc, f.gain)
    if delay:
        sos = np.vstack([sos, _delay_sections(delay)])
    sos = order_sections(sos, f.ts)
    g = _lookahead_series(pu, tol) if len(pu) else None
    m = g.size - 1 if g is not None else 0
    out: dict[str, Any] = {"advance": int(max(surplus, 0) + m), "sos": sos.tolist()}
    if g is not None:
        out["lookahead"] = [float(v) for v in g]
    if exact.substituted.size:
        out["inversion"] = inversion_note(exact)
    # the same filter multiplied out, z^-M G(z) included (module docstring)
    num = f.gain * (np.real(np.poly(f.zeros)) if len(f.zeros) else np.array([1.0]))
    den = np.real(np.poly(pc)) if len(pc) else np.array([1.0])
    if g is not None:
        num = np.convolve(num, g[::-1])
    num = np.concatenate([np.zeros(delay), num])
    rel, w = direct_form_disagreement(num, den, sos, f.ts, g)
    if rel <= DIRECT_FORM_RTOL:
        out["num"], out["den"] = [float(v) for v in num], [float(v) for v in den]
    else:
        grid = direct_form_grid(f.ts)
        out["num_den_omitted"] = (f"direct-form polynomials disagree with the sections by {rel:.3g} relative at "
                                  f"w = {w:.4g} rad/s (criterion {DIRECT_FORM_RTOL:g} over {grid[0]:.4g} to "
                                  f"{grid[-1]:.4g} rad/s); use sos")
    return out


def lookahead_taps(coeffs: dict[str, Any], key: str = "lookahead") -> np.ndarray | None:
    """The look-ahead pre-stage ``[g_0, ..., g_M]`` of a filter of ``filters.json``, checked.

    Parameters
    ----------
    coeffs : dict
        One filter of ``filters.json``.
    key : str
        The name of the entry, for error messages (``"L1.lookahead"``).

    Returns
    -------
    numpy.ndarray or None
        The taps (None when the filter has no pre-stage).

    Raises
    ------
    SpecError
        Not a non-empty list of finite numbers, given without ``sos``, or longer than
        ``advance + 1`` (the look-ahead ``M`` is part of ``advance``).
    """
    value = coeffs.get("lookahead")
    if value is None:
        return None
    try:
        g = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"`{key}`: got {value!r:.80}, expected a list of numbers [g_0, ..., g_M]") from None
    if g.ndim != 1 or g.size == 0 or not np.all(np.isfinite(g)):
        raise SpecError(f"`{key}`: got {g.size} value(s) of shape {g.shape}, expected a non-empty list of finite "
                        "numbers [g_0, ..., g_M]")
    if not coeffs.get("sos"):
        raise SpecError(f"`{key}`: a look-ahead pre-stage runs before second-order sections, but `sos` is missing "
                        "(num/den already include it)")
    adv = coeffs.get("advance")
    if isinstance(adv, (int, np.integer)) and not isinstance(adv, bool) and g.size - 1 > adv:
        raise SpecError(f"`{key}`: {g.size} taps look ahead {g.size - 1} samples, more than `advance` = {adv}; "
                        "expected advance >= len(lookahead) - 1")
    return g


def apply_lookahead(g: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The look-ahead pre-stage in causal form: ``w(i) = v(i - M) = sum_m g_m x(i - M + m)``.

    ``x`` is taken as zero before its start; the sum runs in descending ``m``, the smallest
    taps first (the order of the C code, so that a float32 ``x`` and ``g`` reproduce its
    float arithmetic; ascending, the float error of a closed-form L1 was 8.3e-6 instead of 4.6e-6).

    Parameters
    ----------
    g : numpy.ndarray
        The taps ``[g_0, ..., g_M]`` (their dtype is the arithmetic's).
    x : numpy.ndarray
        The input, already continued past its end.

    Returns
    -------
    numpy.ndarray
        ``w``, the length of ``x``.
    """
    m = g.size - 1
    xp = np.concatenate([np.zeros(m, dtype=x.dtype), x])
    acc = np.zeros(x.size, dtype=np.result_type(g, x))
    for i in range(g.size - 1, -1, -1):
        acc = acc + g[i] * xp[i:i + x.size]
    return acc


def coefficients_freqresp(coeffs: dict[str, Any], w: Any, ts: float) -> np.ndarray:
    """Frequency response of a filter of ``filters.json`` as written (module docstring).

    ``e^{jw Ts advance} * e^{-jw Ts M} G(e^{jw Ts}) * S(e^{-jw Ts})`` from ``sos`` (and
    ``lookahead``), or ``e^{jw Ts advance} N/D`` from ``num``/``den`` without sections.

    Parameters
    ----------
    coeffs : dict
        One filter of ``filters.json``.
    w : array_like
        Frequencies, rad/s.
    ts : float
        Sample time, s.

    Returns
    -------
    numpy.ndarray
        Complex response, the shape of ``w``.
    """
    w = np.asarray(w, dtype=float)
    zinv = np.exp(-1j * w * ts)
    if coeffs.get("sos"):
        _, h = signal.sosfreqz(np.asarray(coeffs["sos"], float), worN=w.ravel() * ts)
        h = h.reshape(w.shape)
        g = lookahead_taps(coeffs)
        if g is not None:
            h = h * _lookahead_response(g, zinv)
    elif "num" in coeffs and "den" in coeffs:
        h = (np.polyval(np.asarray(coeffs["num"], float)[::-1], zinv)
             / np.polyval(np.asarray(coeffs["den"], float)[::-1], zinv))
    else:
        raise SpecError(f"filter coefficients: neither `sos` nor `num`/`den` given; got keys {sorted(coeffs)}")
    return h * np.exp(1j * w * ts * int(coeffs["advance"]))


def apply_coefficients(coeffs: dict[str, Any], x: object) -> np.ndarray:
    """Run a filter of ``filters.json`` over a whole trial (input continued smoothly past its end).

    ``output(k) = S{v}(k + advance - M)`` with the look-ahead pre-stage ``v`` (module
    docstring), or ``z^advance N/D`` from ``num``/``den`` when there are no sections.

    Parameters
    ----------
    coeffs : dict
        A filter of ``filters.json``: ``advance`` and ``sos`` (preferred when present; with
        ``lookahead`` when the filter has one) or ``num``/``den``.
    x : array_like
        The trial, one sample per sample time, starting at rest.

    Returns
    -------
    numpy.ndarray
        The filtered trial, same length as ``x``. The input is continued past its end by
        :func:`~ilcdob.signals.extend_smoothly` (``advance + 8`` samples: the look-ahead
        needs ``advance``) and taken as zero before its start.
    """
    x = as_signal(x, "x")
    if "advance" not in coeffs:
        raise SpecError(f"filter coefficients: missing key `advance`; got keys {sorted(coeffs)}")
    adv = int(coeffs["advance"])
    if adv < 0:
        raise SpecError(f"`advance`: got {adv}, expected a number of samples >= 0")
    g = lookahead_taps(coeffs)
    padded = extend_smoothly(x, adv + 8)
    if coeffs.get("sos"):
        sos = np.asarray(coeffs["sos"], float)
        if sos.ndim != 2 or sos.shape[1] != 6 or not np.all(sos[:, 3] == 1.0):
            raise SpecError(f"`sos`: expected rows [b0, b1, b2, 1, a1, a2], got an array of shape {sos.shape}")
        if g is not None:
            padded = apply_lookahead(g, padded)
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


def state_space_to_dict(sys: ct.StateSpace) -> dict[str, Any]:
    """A discrete SISO state-space system as ``filters.json`` records it: ``{"A", "B", "C", "D"}``.

    Parameters
    ----------
    sys : control.StateSpace
        Discrete-time, one input and one output.

    Returns
    -------
    dict
        ``A`` (n x n), ``B`` (n x 1), ``C`` (1 x n) as nested lists, ``D`` a number; run by
        :func:`apply_state_space`.
    """
    return {"A": np.asarray(sys.A, float).tolist(), "B": np.asarray(sys.B, float).tolist(),
            "C": np.asarray(sys.C, float).tolist(), "D": float(np.asarray(sys.D, float).reshape(-1)[0])}


def apply_state_space(ss: dict[str, Any], x: object) -> np.ndarray:
    """Run a state-space entry of ``filters.json`` causally over a trial, from rest.

    ``s(k + 1) = A s(k) + B u(k)``, ``y(k) = C s(k) + D u(k)``, ``s(0) = 0``, by the compiled kernel
    :func:`ilcdob.statespace.simulate` (as :func:`~..maps.closed_form.simulate_map` runs the design's maps).

    Parameters
    ----------
    ss : dict
        ``{"A", "B", "C", "D"}`` (:func:`state_space_to_dict`).
    x : array_like
        The input trial.

    Returns
    -------
    numpy.ndarray
        The output, same length as ``x``.
    """
    x = as_signal(x, "x")
    if x.size == 0:
        return x
    a = np.asarray(ss["A"], float)
    b, c = (np.asarray(ss[k], float).reshape(-1) for k in ("B", "C"))
    return simulate(a.reshape(b.size, b.size), b, c, float(ss["D"]), x).reshape(-1)
