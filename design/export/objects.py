"""A design's learning filters outside ``filters.json``: python-control objects and MATLAB files.

A filter of ``filters.json`` (:mod:`..filters.coefficients`) is ``H(z) = z^advance * S(z)``: ``S`` causal, run
on the input ``advance`` samples ahead. ``advance`` is a look-ahead (non-causal, no
python-control object holds it), so :class:`LearningFilterTF` keeps it beside the causal part:

* :attr:`LearningFilterTF.sections` - the factors of ``S`` as discrete
  ``control.TransferFunction`` s (``dt`` = the sample time): the look-ahead FIR
  ``z^-M G(z) = (g_M z^M + ... + g_0) / z^M`` when the filter has one, then each second-order
  section ``(b0 z^2 + b1 z + b2) / (z^2 + a1 z + a2)``; or the one factor ``num/den`` of a
  filter written without sections (a FIR design);
* :meth:`LearningFilterTF.to_control` - ``S`` as one ``control.StateSpace`` (the series
  connection of the factors), and ``advance``;
* :meth:`LearningFilterTF.to_tf` - ``S`` multiplied out into one ``control.TransferFunction``,
  refused (:class:`~ilcdob.errors.NumericalError`) when that form loses the response: a
  closed-form ``L1`` has a dozen poles and zeros between 0.8 and 1 and the integrator at
  ``z = 1``; its product polynomials, evaluated by python-control, are off by 21 % at 0.03
  rad/s and 1.5 % at 1 rad/s (default fleet, Ts = 0.02 s), while the factors and the state-space
  series agree with the sections to 1e-11 and 2e-10. The check is the one ``filters.json``
  applies to its own ``num``/``den`` (:data:`~ilcdob.design.filters.coefficients.DIRECT_FORM_RTOL` on
  :func:`~ilcdob.design.filters.coefficients.direct_form_grid`);
* :meth:`LearningFilterTF.freqresp` - ``H(e^{jw Ts})`` with ``z^advance``, from the factors.

:func:`filter_tf` converts one entry of ``filters.json``, :func:`filters_tf` both filters of a
``filters.json`` content, :func:`load_design` those of a design folder (read through
:func:`~ilcdob.inputs.read_json`, checked by :func:`~ilcdob.design.export.c_export.check_filters`),
and :func:`design_to_mat` writes them, with the learning band and the airframe correction, as
a MATLAB file (:mod:`ilcdob.matfile`; variables listed in :func:`design_to_mat`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import control as ct
import numpy as np

from ilcdob.errors import NumericalError, SpecError
from ilcdob.inputs import read_json
from ilcdob.matfile import check_mat_path, write_mat
from ilcdob.response import response

from .c_export import FILTER_KEYS, check_filter_entry, check_filters
from ..filters.coefficients import DIRECT_FORM_RTOL, apply_coefficients, direct_form_grid, lookahead_taps

__all__ = ["LearningFilterTF", "filter_tf", "filters_tf", "load_design", "design_to_mat", "DESIGN_FILE"]

#: The file of a design folder that holds its filters.
DESIGN_FILE = "filters.json"

#: What a design without ``L1``/``L2`` learns with instead, by method.
_NO_FILTERS = {
    "norm-optimal": "its learning is the law in lifted.npz (Riccati gains: "
                    "ilcdob.design.methods.norm_optimal.NormOptimalLaw.from_arrays; the matrices L1, L2 with --lifted)",
    "robust": "its learning signal is an SOCP solved per trial (learning_signal.csv, lifted.npz)",
    "robust-set": "its closed-form filters under `closed_form` are followed by the FIR `F` and computed on a "
                  "trial as `learning` states; use ilcdob.design.pair.design_pair(..., 'robust-set')",
}


def _sample_time(ts: object, what: str = "ts") -> float:
    if isinstance(ts, bool) or not isinstance(ts, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(ts) and ts > 0):
        raise SpecError(f"`{what}`: got {ts!r:.80}, expected the sample time, a number > 0 (s)")
    return float(ts)


@dataclass(frozen=True)
class LearningFilterTF:
    """A learning filter ``H(z) = z^advance * S(z)`` as python-control objects (module docstring).

    Build with :func:`filter_tf` (or :func:`filters_tf`, :func:`load_design`).

    Attributes
    ----------
    name : str
        The filter's key in ``filters.json`` (``"L1"``, ``"L2"``).
    ts : float
        Sample time, s.
    advance : int
        Look-ahead, samples: ``output(k)`` uses the input up to ``input(k + advance)``.
    sections : tuple of control.TransferFunction
        The factors of the causal part ``S``, each discrete with ``dt = ts`` (module docstring).
    coefficients : dict
        The ``filters.json`` entry the filter was made from (what :meth:`apply` runs).
    unit : str
        Unit of the filter's gain (``filters.json`` ``units``; ``""`` if not stated).

    Raises
    ------
    SpecError
        ``ts`` not > 0, ``advance`` not an integer >= 0, ``sections`` empty or not discrete
        transfer functions sampled at ``ts``, or ``coefficients`` not a mapping.
    """

    name: str
    ts: float
    advance: int
    sections: tuple[ct.TransferFunction, ...]
    coefficients: dict[str, Any] = field(repr=False, compare=False)
    unit: str = ""

    def __post_init__(self) -> None:
        _sample_time(self.ts, f"{self.name}: ts")
        if not isinstance(self.coefficients, Mapping):
            raise SpecError(f"`{self.name}.coefficients`: got {self.coefficients!r:.80}, expected the filters.json "
                            "entry (a mapping with `advance` and `sos` or `num`/`den`)")
        if isinstance(self.advance, bool) or not isinstance(self.advance, (int, np.integer)) or self.advance < 0:
            raise SpecError(f"`{self.name}.advance`: got {self.advance!r}, expected an integer number of samples >= 0")
        if not self.sections or not all(isinstance(s, ct.TransferFunction) and s.dt == self.ts
                                        for s in self.sections):
            raise SpecError(f"`{self.name}.sections`: expected one or more discrete control.TransferFunction with "
                            f"dt = {self.ts} s; got {[type(s).__name__ for s in self.sections]}")
        object.__setattr__(self, "advance", int(self.advance))
        object.__setattr__(self, "sections", tuple(self.sections))

    def __repr__(self) -> str:
        n_fir = 1 if self.coefficients.get("sos") and self.coefficients.get("lookahead") is not None else 0
        n_sos = len(self.sections) - n_fir
        parts = ([f"{len(self.coefficients['lookahead'])}-tap look-ahead FIR"] if n_fir else []) + \
            ([f"{n_sos} section{'s' if n_sos != 1 else ''}"] if self.coefficients.get("sos") else ["num/den"])
        unit = f" [{self.unit}]" if self.unit else ""
        return (f"<LearningFilterTF {self.name}{unit}: z^{self.advance} S(z), S with {self.order} states "
                f"({' + '.join(parts)}), Ts {self.ts:g} s>")

    @property
    def order(self) -> int:
        """Number of states of the causal part ``S`` as :meth:`to_control` realises it (minimal
        per factor: a pole and zero that cancel within one factor are not counted)."""
        return int(self._series.nstates)

    @cached_property
    def _series(self) -> ct.StateSpace:
        sys = ct.tf2ss(self.sections[0])
        for s in self.sections[1:]:
            sys = ct.series(sys, ct.tf2ss(s))
        return ct.ss(sys.A, sys.B, sys.C, sys.D, self.ts, name=self.name.replace(".", "_"))

    def to_control(self) -> tuple[ct.StateSpace, int]:
        """The causal part ``S`` as one python-control system, and the advance.

        ``H(z) = z^advance S(z)`` is not causal when ``advance > 0``: python-control (like any
        simulation from rest) cannot hold ``z^advance``, so it is returned separately. On a
        recorded trial ``x``, ``output(k) = S{x}(k + advance)``: run ``S`` over the trial and
        drop its first ``advance`` samples (``control.forced_response(S, U=x).outputs[advance:]``
        is ``output[:n - advance]``), or use :meth:`apply`, which continues the trial past its
        end for the last ``advance`` samples.

        Returns
        -------
        S : control.StateSpace
            The series connection of :attr:`sections`, ``dt = ts`` (accurate where a
            multiplied-out transfer function is not, module docstring).
        advance : int
            Look-ahead, samples.
        """
        return self._series, self.advance

    def to_tf(self) -> tuple[ct.TransferFunction, int]:
        """The causal part ``S`` multiplied out into one transfer function, and the advance.

        Returns
        -------
        S : control.TransferFunction
            The product of :attr:`sections`, ``dt = ts``.
        advance : int
            Look-ahead, samples (see :meth:`to_control`).

        Raises
        ------
        NumericalError
            The product's response differs from the factors' by more than
            :data:`~ilcdob.design.filters.coefficients.DIRECT_FORM_RTOL` relative somewhere on
            :func:`~ilcdob.design.filters.coefficients.direct_form_grid` (the message gives where): use
            :meth:`to_control` or :attr:`sections`.
        """
        tf = self.sections[0]
        for s in self.sections[1:]:
            tf = tf * s
        w = direct_form_grid(self.ts)
        with np.errstate(all="ignore"):
            rel = np.abs(response((tf,), w, self.ts, self.advance) / self.freqresp(w) - 1)
        rel = np.where(np.isfinite(rel), rel, np.inf)
        i = int(np.argmax(rel))
        if rel[i] > DIRECT_FORM_RTOL:
            raise NumericalError(
                f"{self.name}: its {len(self.sections)} factors multiplied out into one transfer function disagree "
                f"with the factors by {rel[i]:.3g} relative at w = {w[i]:.4g} rad/s (criterion {DIRECT_FORM_RTOL:g} "
                f"over {w[0]:.4g} to {w[-1]:.4g} rad/s): poles and zeros clustered near z = 1 lose their digits in "
                "polynomial coefficients; use to_control() (state space) or the factors in `sections`")
        return tf, self.advance

    def freqresp(self, w: Any) -> np.ndarray:
        """Frequency response ``H(e^{jw Ts}) = e^{jw Ts advance} S(e^{jw Ts})``, from the factors.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex response, the shape of ``w``.
        """
        return response(self.sections, w, self.ts, self.advance)

    def apply(self, x: object) -> np.ndarray:
        """Run the filter over a whole trial (:func:`~ilcdob.design.filters.coefficients.apply_coefficients`).

        Parameters
        ----------
        x : array_like
            The trial, one sample per sample time, starting at rest.

        Returns
        -------
        numpy.ndarray
            The filtered trial, same length (the trial continued smoothly past its end for the
            look-ahead).
        """
        return apply_coefficients(self.coefficients, x)


def _z_polynomials(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``num/den`` in powers of ``z^-1`` as the same ratio in powers of ``z`` (both times ``z^(L-1)``)."""
    size = max(num.size, den.size)
    return (np.concatenate([num, np.zeros(size - num.size)]), np.concatenate([den, np.zeros(size - den.size)]))


def filter_tf(coeffs: Mapping[str, Any], ts: float, name: str = "L1", unit: str = "") -> LearningFilterTF:
    """One filter of ``filters.json`` as a :class:`LearningFilterTF`.

    Parameters
    ----------
    coeffs : mapping
        The entry (``advance``, and ``sos`` with optional ``lookahead``, or ``num``/``den``; see
        :mod:`..filters.coefficients`), checked as :func:`~ilcdob.design.export.c_export.check_filters` checks it.
    ts : float
        Sample time, s (``filters.json`` ``sample_time``).
    name : str
        The entry's key, for the object and messages.
    unit : str
        Unit of the filter's gain.

    Returns
    -------
    LearningFilterTF
        Its frequency response is :func:`~ilcdob.design.filters.coefficients.coefficients_freqresp` of ``coeffs``.

    Raises
    ------
    SpecError
        A bad sample time or entry (the message names the key, e.g. ``L1.sos``, and the value).
    """
    ts = _sample_time(ts)
    if not isinstance(name, str) or not name:
        raise SpecError(f"`name`: got {name!r:.80}, expected the filter's key in filters.json, e.g. 'L1'")
    if not isinstance(unit, str):
        raise SpecError(f"`{name}` unit: got {unit!r:.80}, expected a string such as '(m/s^2)/m'")
    check_filter_entry(coeffs, name)
    coeffs = dict(coeffs)
    factors = []
    if coeffs.get("sos"):
        g = lookahead_taps(coeffs, f"{name}.lookahead")
        if g is not None:  # z^-M G(z) = (g_M z^M + ... + g_0) / z^M
            factors.append(ct.tf(g[::-1], np.concatenate([[1.0], np.zeros(g.size - 1)]), ts))
        factors += [ct.tf(row[:3], row[3:], ts) for row in np.asarray(coeffs["sos"], dtype=float)]
    else:
        num, den = _z_polynomials(np.asarray(coeffs["num"], dtype=float), np.asarray(coeffs["den"], dtype=float))
        factors.append(ct.tf(num, den, ts))
    return LearningFilterTF(name=name, ts=ts, advance=int(coeffs["advance"]), sections=tuple(factors),
                            coefficients=coeffs, unit=unit)


def _read_design(folder: str | os.PathLike) -> tuple[dict[str, Any], str]:
    """The ``filters.json`` content of a design folder (or of the file itself) and the file's name."""
    path = Path(folder)
    if path.is_dir():
        path = path / DESIGN_FILE
    data = read_json(path, DESIGN_FILE, error=SpecError, hint="give a folder written by `ilcdob design`")
    return data, str(path)


def _learning_filters(filters: Mapping[str, Any] | str | os.PathLike, source: str) -> dict[str, Any]:
    """``filters`` (a ``filters.json`` content, or a design folder to read it from) checked
    (:func:`~ilcdob.design.export.c_export.check_filters`), with both ``L1`` and ``L2``."""
    if isinstance(filters, (str, os.PathLike)):
        filters, source = _read_design(filters)
    if not isinstance(filters, Mapping) and isinstance(getattr(filters, "filters", None), Mapping):
        raise SpecError(f"{source}: got a {type(filters).__name__}; pass its `filters` (the filters.json content)")
    if isinstance(filters, Mapping) and filters and all(isinstance(v, LearningFilterTF) for v in filters.values()):
        raise SpecError(f"{source}: got the python-control filters of load_design ({', '.join(filters)}), which "
                        "leave out the learning band, the airframe correction and the limit; pass the design folder "
                        "itself (design_to_mat('folder/', 'design.mat')) or its filters.json content")
    filters = check_filters(filters, source)
    missing = [k for k in FILTER_KEYS if k not in filters]
    if missing:
        method = filters.get("method")
        why = _NO_FILTERS.get(method, "a closed-form or fir design has them")
        raise SpecError(f"{source}: no {' and '.join(missing)} filter(s) (method {method!r}): {why}; the "
                        "python-control and .mat forms exist for the designs with filters (closed-form, fir)")
    units = filters.get("units", {})
    if not isinstance(units, Mapping) or any(not isinstance(units.get(k, ""), str) for k in FILTER_KEYS):
        raise SpecError(f"{source}: `units`: got {units!r:.80}, expected a mapping such as "
                        "{'L1': '(m/s^2)/m', 'L2': '1'}")
    return filters


def filters_tf(filters: Mapping[str, Any], source: str = "<memory>") -> dict[str, LearningFilterTF]:
    """Both learning filters of a ``filters.json`` content (e.g. ``PairDesign.filters``).

    Parameters
    ----------
    filters : mapping
        The content, with ``sample_time``, ``L1`` and ``L2`` (closed-form and fir designs).
    source : str
        Where it came from, first in messages.

    Returns
    -------
    dict of str to LearningFilterTF
        ``{"L1": ..., "L2": ...}``.

    Raises
    ------
    SpecError
        An entry missing or invalid (:func:`~ilcdob.design.export.c_export.check_filters`), or a
        method without ``L1``/``L2`` (the message says what it learns with instead).
    """
    filters = _learning_filters(filters, source)
    units = filters.get("units", {})
    return {k: filter_tf(filters[k], filters["sample_time"], k, units.get(k, "")) for k in FILTER_KEYS}


def load_design(folder: str | os.PathLike) -> dict[str, LearningFilterTF]:
    """The learning filters of a design folder written by ``ilcdob design``.

    Parameters
    ----------
    folder : str or os.PathLike
        The design folder (its :data:`DESIGN_FILE` is read), or that file itself.

    Returns
    -------
    dict of str to LearningFilterTF
        ``{"L1": ..., "L2": ...}`` (:func:`filters_tf`).

    Raises
    ------
    SpecError
        The file is missing, unreadable, not JSON, or holds an invalid or missing entry (the
        message names the file and the key).
    """
    return filters_tf(*_read_design(folder))


def _matrix(value: Any, cols: int) -> np.ndarray:
    return np.asarray(value, dtype=float).reshape(-1, cols) if value is not None else np.zeros((0, cols))


def _row(value: Any) -> np.ndarray:
    return np.asarray(value, dtype=float).reshape(-1) if value is not None else np.zeros(0)


def _filter_variables(filters: Mapping[str, Any], key: str) -> tuple[dict[str, Any], dict[str, str]]:
    c = filters[key]
    unit = filters.get("units", {}).get(key, "")
    sos = c.get("sos") or None
    direct = "num" in c and "den" in c
    omitted = c.get("num_den_omitted") or "not written"
    values = {f"{key}_advance": int(c["advance"]), f"{key}_sos": _matrix(sos, 6),
              f"{key}_lookahead": _row(c.get("lookahead") if sos else None),
              f"{key}_num": _row(c["num"] if direct else None), f"{key}_den": _row(c["den"] if direct else None),
              f"{key}_unit": unit}
    notes = {f"{key}_advance": f"look-ahead of {key}, samples: {key}(z) = z^advance S(z), output(k) uses the input "
                               "up to input(k + advance)",
             f"{key}_sos": f"second-order sections of S, rows [b0 b1 b2 1 a1 a2] in powers of z^-1 (sosfilt), gain "
                           f"in {key}_unit" + ("" if sos else "; empty: the filter is num/den"),
             f"{key}_lookahead": "look-ahead FIR taps g_0..g_M run before the sections: v(j) = sum_m g_m u(j + m), "
                                 "M = numel - 1 (part of advance); empty: none (v = u)",
             f"{key}_num": "numerator of S, powers of z^-1 (filter(num, den, ...)), look-ahead FIR included"
                           + ("" if direct else f"; empty: {omitted}"),
             f"{key}_den": "denominator of S, powers of z^-1, den(1) = 1" + ("" if direct else "; empty: see num"),
             f"{key}_unit": f"unit of {key}'s gain ('' if not stated)"}
    return values, notes


def design_to_mat(filters: Mapping[str, Any] | str | os.PathLike, path: str | os.PathLike,
                  source: str = "design") -> Path:
    """Write a design's learning law (``filters.json`` content) as a ``.mat`` file.

    Variables (numbers as doubles; ``description`` lists each with its meaning and unit):

    * ``sample_time`` (s); ``source_system``, ``target_system``, ``method``, ``law``, ``axis`` (text);
    * for ``K`` in ``L1``, ``L2``: ``K_advance`` (samples), ``K_sos`` (rows
      ``[b0 b1 b2 1 a1 a2]``, powers of ``z^-1``; 0 x 6 when the filter is ``num``/``den``),
      ``K_lookahead`` (taps ``g_0..g_M``; empty: none), ``K_num``/``K_den`` (powers of
      ``z^-1``; empty when ``filters.json`` left them out), ``K_unit``; the filter is
      ``K(z) = z^K_advance S(z)`` (:mod:`..filters.coefficients`);
    * the learning band ``F``: ``band_sos`` (0 x 6: none), ``band_zi``, ``band_pad`` and
      ``band_end_fit`` (samples), ``band_cutoff_rad_s`` (NaN: none), ``band_start``;
    * the airframe correction ``W``: ``W_sos`` (0 x 6: the disturbance acts at the command);
    * ``limit_acceleration_m_s2`` (NaN: no limit stated);
    * ``learning_law``: the law these variables compute
      (:func:`~ilcdob.design.law.apply_learning`).

    Parameters
    ----------
    filters : mapping or str or os.PathLike
        The ``filters.json`` content (e.g. ``PairDesign.filters``) of a closed-form or fir design, or the
        folder ``ilcdob design`` wrote (or its ``filters.json``); checked by
        :func:`~ilcdob.design.export.c_export.check_filters`. Not :func:`load_design`'s python-control
        filters: they leave out the band, the airframe correction and the limit.
    path : str or os.PathLike
        The file, ending in ``.mat`` (written atomically, :func:`ilcdob.matfile.write_mat`).
    source : str
        Where ``filters`` came from, first in messages.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    SpecError
        A bad path, an invalid entry, a method without ``L1``/``L2``, or an invalid ``limit``.
    """
    check_mat_path(path, "design")
    filters = _learning_filters(filters, source)
    for key in ("method", "law", "axis"):
        if not isinstance(filters.get(key, ""), str):
            raise SpecError(f"{source}: `{key}`: got {filters.get(key)!r:.80}, expected a string")
    values: dict[str, Any] = {"sample_time": float(filters["sample_time"]), "source_system": filters["from"],
                              "target_system": filters["to"], "method": filters.get("method", ""),
                              "law": filters.get("law", "paper"), "axis": filters.get("axis", "x")}
    notes = {"sample_time": "sample time, s", "source_system": "system learned from (j-1)",
             "target_system": "system that learns (j)", "method": "design method", "law": "learning law",
             "axis": "axis designed (x, y or z)"}
    for key in FILTER_KEYS:
        v, n = _filter_variables(filters, key)
        values.update(v)
        notes.update(n)
    band = filters.get("band") or {}
    has_band = band.get("sos") is not None
    values.update({"band_sos": _matrix(band.get("sos"), 6), "band_zi": _matrix(band.get("zi"), 2),
                   "band_pad": int(band.get("pad", 0)) if has_band else 0,
                   "band_end_fit": int(band.get("end_fit", 1)) if has_band else 0,
                   "band_cutoff_rad_s": float(band["cutoff_rad_s"]) if has_band else float("nan"),
                   "band_start": str(band.get("start", "crop")) if has_band else "",
                   "band_output_start": str(band.get("output_start", "first sample")) if has_band else ""})
    notes.update({"band_sos": "learning band F, second-order sections run forwards then backwards (zero phase); "
                              "empty: no band (F = 1)",
                  "band_zi": "steady state of band_sos per unit input (sosfilt_zi), the start of each pass (but "
                             "band_output_start)",
                  "band_pad": "samples H adds before and after the trial (zeros before, a line after)",
                  "band_end_fit": "last samples of the trial the line after it is fitted to",
                  "band_cutoff_rad_s": "corner of F, rad/s (NaN: no band)",
                  "band_start": "'fold': the part before t = 0 is added, time-reversed, to the first band_pad "
                                "samples; 'crop': dropped; '': no band",
                  "band_output_start": "'rest': the pass of F on the learning signal starts its forward filter from "
                                       "rest; 'first sample': from band_zi times its first sample; '': no band"})
    w_sos = (filters.get("disturbance") or {}).get("W", {}) or {}
    values["W_sos"] = _matrix(w_sos.get("sos"), 6)
    notes["W_sos"] = ("airframe correction W, second-order sections run forwards from rest; empty: the disturbance "
                      "acts at the command (W = 1)")
    limit = filters.get("limit")
    accel = float("nan")
    if limit is not None:
        accel = limit.get("acceleration_m_s2") if isinstance(limit, Mapping) else None
        if isinstance(accel, bool) or not isinstance(accel, (int, float)) or not (math.isfinite(accel) and accel > 0):
            raise SpecError(f"{source}: `limit.acceleration_m_s2`: got {accel!r:.80}, expected the learning vehicle's "
                            "acceleration limit, a number > 0 (m/s^2)")
    values["limit_acceleration_m_s2"] = float(accel)
    notes["limit_acceleration_m_s2"] = "learning vehicle's acceleration limit, m/s^2 (NaN: none stated)"
    law = ("d_f = fold(F{W{L1{F{H{e}}} + L2{F{H{d_f_prev}}}}})" if has_band else "d_f = W{L1{e} + L2{d_f_prev}}")
    if values["law"] == "exact-reference":
        law += ("; exact-reference: e is the error minus the source's reference error e_ref_source, and the "
                "correction is added to d_f (reference_terms.csv of the design folder)")
    values["learning_law"] = law + ": e (m) the source's error, d_f_prev (m/s^2) the learning signal it flew"
    notes["learning_law"] = "the learning law these variables compute (ilcdob.design.law.apply_learning)"
    return write_mat(path, values, notes, "design")
