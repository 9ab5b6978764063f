"""The entries of ``filters.json`` checked: counts, second-order sections, filters and state space.

Every stage of the learning law (:mod:`..law`) and the C code (:mod:`..export.c_export`) read their
coefficients through these checks, so a hand-edited or truncated ``filters.json`` is refused
with a message naming the key, the value and what is valid.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ilcdob.errors import SpecError

from .coefficients import lookahead_taps

__all__ = ["MAX_ADVANCE", "MAX_STATES", "check_count", "check_sections", "check_filter_entry", "check_state_space",
           "direct_form"]

#: Most samples of look-ahead (``advance``) a filter of ``filters.json`` may state: 1000 s at
#: 1 kHz, far beyond any learning filter, and small enough to allocate.
MAX_ADVANCE = 1_000_000

#: Most states of a state-space map of ``filters.json`` (``law_maps``): a loop map of a dozen
#: blocks has a few dozen.
MAX_STATES = 512


def direct_form(coeffs: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """``num``, ``den`` normalised by ``den[0]`` and padded to one length (as ``lfilter`` does).

    Parameters
    ----------
    coeffs : dict
        A filter with ``num`` and ``den``.

    Raises
    ------
    SpecError
        Empty polynomials or ``den[0] == 0``.
    """
    num, den = np.asarray(coeffs["num"], float), np.asarray(coeffs["den"], float)
    if num.size == 0 or den.size == 0 or den[0] == 0:
        raise SpecError(f"`num`/`den`: expected non-empty polynomials with den[0] != 0, got {num.size} "
                        f"numerator and {den.size} denominator coefficients, den[0] = {den[:1].tolist()}")
    size = max(num.size, den.size)
    num = np.concatenate([num, np.zeros(size - num.size)]) / den[0]
    den = np.concatenate([den, np.zeros(size - den.size)]) / den[0]
    return num, den


def check_sections(value: object, key: str) -> np.ndarray:
    """``value`` as finite second-order sections ``[b0, b1, b2, 1, a1, a2]``.

    Parameters
    ----------
    value : object
        The entry.
    key : str
        Its name, first in messages.

    Raises
    ------
    SpecError
        Not finite rows of six numbers with ``a0 = 1``.
    """
    try:
        sos = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"`{key}`: got {value!r:.80}, expected rows [b0, b1, b2, 1, a1, a2] of numbers") from None
    if sos.ndim != 2 or sos.shape[0] < 1 or sos.shape[1] != 6:
        raise SpecError(f"`{key}`: got an array of shape {sos.shape}, expected at least one row "
                        "[b0, b1, b2, 1, a1, a2] (shape (sections, 6))")
    if not np.all(np.isfinite(sos)):
        raise SpecError(f"`{key}`: non-finite coefficient(s); expected finite numbers")
    if not np.all(sos[:, 3] == 1.0):
        raise SpecError(f"`{key}`: got a0 = {sos[:, 3].tolist()}, expected rows [b0, b1, b2, 1, a1, a2] (a0 = 1)")
    return sos


def check_count(value: object, key: str, least: int) -> int:
    """``value`` as an integer number of samples ``>= least``.

    Parameters
    ----------
    value : object
        The entry.
    key : str
        Its name, first in messages.
    least : int
        The smallest valid count.

    Raises
    ------
    SpecError
        Not an integer (booleans refused) or below ``least``.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise SpecError(f"`{key}`: got {value!r}, expected an integer number of samples >= {least}")
    return int(value)


def check_filter_entry(coeffs: object, key: str) -> None:
    """One filter of ``filters.json`` checked: ``advance``, then ``sos`` (and ``lookahead``) or ``num``/``den``.

    Parameters
    ----------
    coeffs : object
        The entry (``filters["L1"]``, ...).
    key : str
        Its name, first in messages.

    Raises
    ------
    SpecError
        Not a mapping, ``advance`` not an integer in ``[0, MAX_ADVANCE]``, sections or
        polynomials that are not finite numbers of the right shape, or bad look-ahead taps.
    """
    if not isinstance(coeffs, dict):
        raise SpecError(f"`{key}`: got {coeffs!r:.80}, expected a mapping with `advance` and `sos` or `num`/`den`")
    adv = check_count(coeffs.get("advance"), f"{key}.advance", 0)
    if adv > MAX_ADVANCE:
        raise SpecError(f"`{key}.advance`: got {adv} samples, expected at most {MAX_ADVANCE} (a look-ahead of "
                        "a few hundred samples is already long)")
    if coeffs.get("sos"):
        check_sections(coeffs["sos"], f"{key}.sos")
    else:
        try:
            num, den = (np.asarray(coeffs.get(part), dtype=float) for part in ("num", "den"))
        except (TypeError, ValueError):
            raise SpecError(f"`{key}.num`/`{key}.den`: expected lists of numbers (or `sos`)") from None
        if num.ndim != 1 or den.ndim != 1 or not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
            raise SpecError(f"`{key}.num`/`{key}.den`: expected lists of finite numbers (or `sos`)")
        direct_form(coeffs)
    lookahead_taps(coeffs, f"{key}.lookahead")


def check_state_space(value: object, key: str) -> tuple[np.ndarray, ...]:
    """A state-space entry ``{"A", "B", "C", "D"}`` as finite arrays of consistent shape.

    Parameters
    ----------
    value : object
        The entry.
    key : str
        Its name, first in messages.

    Returns
    -------
    tuple of numpy.ndarray
        ``A`` (n x n), ``B``, ``C`` (n values each), ``D`` (one value).

    Raises
    ------
    SpecError
        Missing matrices, inconsistent shapes, more than :data:`MAX_STATES` states, non-finite values.
    """
    if not isinstance(value, dict) or any(k not in value for k in "ABCD"):
        raise SpecError(f"`{key}`: got {value!r:.80}, expected a mapping with A (n x n), B, C (n numbers) and D")
    try:
        a, b, c, d = (np.asarray(value[k], dtype=float) for k in "ABCD")
    except (TypeError, ValueError):
        raise SpecError(f"`{key}`: A, B, C and D must be numbers (nested lists)") from None
    ns = b.size
    if a.shape not in ((ns, ns), (0,), (1, 0)) or c.size != ns or d.size != 1 or ns > MAX_STATES:
        raise SpecError(f"`{key}`: got A of shape {a.shape}, {b.size} B, {c.size} C and {d.size} D values; expected "
                        f"A of n x n, n B and n C values (n <= {MAX_STATES}) and one D")
    if not all(np.all(np.isfinite(x)) for x in (a, b, c, d)):
        raise SpecError(f"`{key}`: non-finite value(s); expected finite numbers")
    return a.reshape(ns, ns), b.reshape(-1), c.reshape(-1), d.reshape(-1)
