"""Export of learning filters: coefficient form, C header, application from coefficients.

A filter is written as ``H(z) = z^advance * N(z^-1) / D(z^-1)`` with ``N``, ``D`` in powers of
``z^-1``, highest first (``D[0] = 1``): ``output(k)`` uses ``input(k + advance)``, i.e. run
``N/D`` causally on the input shifted ``advance`` samples ahead. A non-causal zero-pole
filter (:class:`~ilcdob.design.noncausal.ZPKFilter`) is converted exactly except for its
anti-causal poles ``1/(z - p)``, ``|p| > 1``, which are expanded into the series
``-(1/p) sum_m (z/p)^m`` truncated where ``|p|^-m`` falls below ``tol`` (about 22 terms for
the ZOH sampling zero at -3.6): a finite advance, exact to ``tol``.

Precision: the closed-form filters have a dozen poles and zeros clustered between 0.8 and 1
(the loop's slow modes and the PID integrator). Expanded into one direct-form polynomial
pair they lose accuracy at low frequency in double precision (about 1 % at 0.3 rad/s for
the built-in fleet): implement them from ``sos`` (second-order sections of the same filter,
``[b0, b1, b2, 1, a1, a2]`` rows, ``z^-1`` powers), which the export always includes and
which :func:`apply_coefficients` prefers. ``num``/``den`` are kept for tools that want them.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import signal

from ilcdob.atomic import write_text_atomic
from ilcdob.errors import SpecError

from .noncausal import ZPKFilter, as_signal, extend_smoothly

__all__ = ["zpk_to_coefficients", "apply_coefficients", "c_header"]


def zpk_to_coefficients(f: ZPKFilter, tol: float = 1e-12) -> dict[str, object]:
    """``{"num", "den", "advance"}`` of a (non-causal) zero-pole filter, see module docstring."""
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
    sos = signal.zpk2sos(all_zeros, np.concatenate([pc, np.zeros(max(n_extra, 0))]), sos_gain)
    return {"num": [float(v) for v in gain * num], "den": [float(v) for v in den], "advance": int(advance),
            "sos": sos.tolist()}


def apply_coefficients(coeffs: dict, x: object) -> np.ndarray:
    """Run ``z^advance N/D`` over a whole trial (input continued smoothly past its end)."""
    x = as_signal(x, "x")
    adv = int(coeffs["advance"])
    padded = extend_smoothly(x, adv + 8)
    if coeffs.get("sos"):
        y = signal.sosfilt(np.asarray(coeffs["sos"], float), padded)
    else:
        num, den = np.asarray(coeffs["num"], float), np.asarray(coeffs["den"], float)
        if den.size == 0 or den[0] == 0:
            raise SpecError(f"`den`: leading coefficient must be non-zero, got {list(den)}")
        y = signal.lfilter(num, den, padded)
    return y[adv:adv + x.size]


def _c_array(name: str, values) -> str:
    body = ", ".join(f"{float(v):.17g}" for v in values)
    return f"static const double {name}[{len(values)}] = {{{body}}};"


def c_header(design: dict, guard: str = "ILCDOB_LEARNING_FILTERS_H") -> str:
    """A C header with the coefficients of ``filters.json`` (``L1``, ``L2``)."""
    lines = [f"/* Learning filters {design['from']} -> {design['to']}, method {design['method']}, written by ilcdob.",
             " * y(k) = sum_i num[i] u(k + advance - i) - sum_{i>=1} den[i] y(k - i), den[0] = 1;",
             " * L1 filters the previous system's error (m), L2 its learning signal (m/s^2); output in m/s^2. */",
             f"#ifndef {guard}", f"#define {guard}", "",
             f"#define ILCDOB_SAMPLE_TIME {float(design['sample_time']):.17g} /* s */"]
    for key in ("L1", "L2"):
        f = design[key]
        lines += [f"#define ILCDOB_{key}_ADVANCE {int(f['advance'])}",
                  _c_array(f"ilcdob_{key.lower()}_num", f["num"]),
                  _c_array(f"ilcdob_{key.lower()}_den", f["den"])]
        if f.get("sos"):
            rows = ", ".join("{" + ", ".join(f"{float(v):.17g}" for v in row) + "}" for row in f["sos"])
            lines += [f"/* {key} as second-order sections (preferred): rows b0 b1 b2 a0 a1 a2 */",
                      f"#define ILCDOB_{key}_N_SOS {len(f['sos'])}",
                      f"static const double ilcdob_{key.lower()}_sos[{len(f['sos'])}][6] = {{{rows}}};"]
    lines += ["", f"#endif /* {guard} */", ""]
    return "\n".join(lines)


def write_c_header(path: str | Path, design: dict) -> None:
    """Write :func:`c_header` atomically."""
    write_text_atomic(path, c_header(design))
