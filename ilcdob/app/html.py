"""One self-contained HTML report from the output folders of ilcdob: ``ilcdob report``.

``ilcdob report DIR [DIR ...] --out report.html`` reads every ``DIR`` and writes one HTML
file that opens offline: figures are embedded as base64 PNG ``data:`` URIs, the style sheet
is inline, and the page refers to no external URL. Each section is rendered when its input
is among the folders; the sections none of the folders feeds are left out and named once,
below the table of contents. No number in the report is made up or defaulted, every one is
read from an input file or computed from the fleet those files name. Fields are shown with
human labels and units (``share_improved`` 1 as "improved" 100 %, RMSE in mm, as the CLI's
text tables), the JSON key in the column's tooltip.

Inputs, detected by file name in each folder
--------------------------------------------
``results.json`` (``ilcdob reproduce``, see :meth:`ReproductionResult.to_dict`)
    ``{"plant": "linear" | "nonlinear" | "rotorpy", "law": LAW, "fleet": PATH, "sample_time": s, "iterations": n,
    "scenarios": [{"id", "title", "order": [names], "systems": {name: {"rmse_no_dob",
    "rmse_dob", "rmse_learning": [n], "rmse_dhat_dob", "rmse_dhat_learning": [n]}}}]}``,
    RMSE in m and m/s^2 (``law``: the learning law of :mod:`ilcdob.design.law.laws`, shown with
    the results; absent in files written before laws existed), with the figures written beside it (``rmse_bars.png``,
    ``error_s<N>.png``, ``disturbance_s<N>.png``, ``bode_loops.png``, ``bode_learning.png``,
    ``bode_te.png``, ``identified_models.png``). Sections: the fleet and its identified
    models, the Bode figures, RMSE table and bars, error and disturbance-estimate time series
    per scenario (one section per plant), and the Theorem check.
``results.json`` with ``"controller": "own"`` (``ilcdob reproduce --plant rotorpy --controller own``)
    Vehicles on their own controllers (:meth:`ChannelReproduction.to_dict`): settings, vehicles,
    identification, learning ratios per scenario, channel, disturbance and law, the acceptance rows and
    ``learning.png``: one section.
``compare.json`` (``ilcdob compare``) and ``campaign.json`` (``ilcdob campaign``)
    Rendered generically, so their schemas can evolve: scalars at the top level become a
    key/value table, and every *method table* found anywhere in the document becomes an
    HTML table, rows = methods, columns = the rows' numeric (and boolean, then short text)
    fields, nested dicts flattened with dotted names (``ratio.median``). A method table is

    * a dict of dicts, each inner dict holding a number (or null) directly, e.g.
      ``{"methods": {"closed-form": {"median": 0.02, "p95": 0.05, "worst": 0.09,
      "share_improved": 1.0}, "robust": {...}}}`` -- rows named by the keys; or
    * a list of such dicts, e.g.
      ``{"rows": [{"method": "fir", "pair": "UAV1 -> UAV2", "ratio": 0.03}, ...]}`` --
      rows named by ``method``, ``name``, ``label`` or ``id`` (plus ``source -> target`` or
      ``from -> to`` when present), else by position.

    The campaign's statistics are expected per method as ``median``, ``p95``, ``worst`` and
    ``share_improved`` of the ratio ``||e_j|| / ||e'_j||`` (< 1: learning improved), but any
    numeric field is shown. Lists of numbers (frequency grids, samples) are not tabulated;
    the report says how many values it left out.
    A row with a text field ``error`` (a design that ``ilcdob compare`` could not make) holds
    no result: it is shown with that reason instead of its empty values. The figure written
    beside each file (``compare_ratios.png``, ``campaign_ratios.png``) is embedded below its
    tables.

Beside ``results.json``, ``ilcdob reproduce`` writes the report's other inputs
(:func:`report_files`): ``fleet.json`` (the fleet table with its identified models and
uncertainty) and ``theorem.json`` + ``theorem.png`` (the Theorem check). The report reads
these files and computes nothing.

The report trusts nothing it reads. A folder's ``manifest.json`` lists the SHA-256 of every
file of its run: a folder holding a file that is missing, changed or not listed there (files
from different runs, edited files) is refused, naming the file
(:func:`ilcdob.app.output.verify_manifest`); a folder without any manifest (written before
manifests existed) is rendered with its provenance stated as unknown. The fields of
``results.json``, ``fleet.json`` and ``theorem.json`` that the report uses, the other numbers
their writer puts there (a Theorem pair's ``worst_w``, a scenario's ``duration_s``, ...), and
the numeric settings and method tables of ``compare.json`` and ``campaign.json``, are type-checked
when read, and a file that is not standard JSON is refused, each error naming the file and
the key. Every value is HTML-escaped (:func:`ilcdob.names.html_text`) where it is rendered.
"""

from __future__ import annotations

import base64
import io
import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilcdob.errors import IlcdobError
from ilcdob.inputs import read_bytes, read_text
from ilcdob.display import polynomial_text
from ilcdob.names import html_text, quoted

from .output import MANIFEST, ManifestError, verify_manifest

if TYPE_CHECKING:
    from ilcdob.fleet import Fleet

__all__ = ["ReportError", "ReportOptions", "ReportInputs", "JsonInput", "JsonTable", "KNOWN_FILES",
           "discover_inputs", "json_tables", "build_report", "report_files", "THEOREM_SAMPLES"]

#: Sampled plants per Delta set of the Theorem check written by :func:`report_files` (as ``ilcdob check``
#: draws them, seed 0). The check reads each set's bound, which does not depend on the samples, so
#: :func:`report_files` draws none (:func:`ilcdob.design.checks.theorem.bound_delta_sets`).
THEOREM_SAMPLES = 8

#: File name -> the command that writes it.
KNOWN_FILES: dict[str, str] = {
    "results.json": "ilcdob reproduce [--plant linear|nonlinear|rotorpy] --out DIR",
    "compare.json": "ilcdob compare --out DIR",
    "campaign.json": "ilcdob campaign --samples N --out DIR",
}
PLANTS = ("linear", "nonlinear", "rotorpy")
_PLANT_TITLE = {"linear": "Linear plant (exact models, simulation)",
                "nonlinear": "Nonlinear plant (6-DOF quadrotors flown with identified models)",
                "rotorpy": "Rotorpy plant (a third-party multirotor simulator flown with identified models)"}
_LABEL_KEYS = ("method", "name", "label", "id", "key")
_PAIR_KEYS = (("source", "target"), ("from", "to"))
_MAX_TEXT = 60

_BODE_NOTE = (" Magnitude in dB and phase in degrees, wrapped to (-180, 180], against frequency in rad/s up to "
              "Nyquist (grey line); curves that coincide (within 1 %, 0.09 dB) are drawn once, their legend entry "
              "naming them all.")
_BODE_FIGURES = {
    "bode_loops.png": "Bode plots of G_r and G_d of every system (dotted: G_d without DOB)." + _BODE_NOTE,
    "bode_learning.png": "Bode plots of the learning filters L1 and L2 of every pair flown (L1 depends on the "
                         "pair's source only when every Q is the same, and L2 = (1 - Q_j)/(1 - Q_j-1) is then 1)."
                         + _BODE_NOTE,
    "bode_te.png": "Te1, Te2 (error propagation with learning under the model error stated in the "
                   "figure) and Omega (disturbance -> DOB estimate; with exact models about Q, so the same for "
                   "every system with the same Q)."
                   + _BODE_NOTE,
}


class ReportError(IlcdobError, ValueError):
    """A report input folder is missing, empty of known files, or holds an unreadable file."""


@dataclass(frozen=True)
class ReportOptions:
    """Settings of :func:`build_report`.

    Attributes
    ----------
    title : str
        Page title and top heading.
    """

    title: str = "ilcdob report: learning among systems with mismatched dynamics"

    def __post_init__(self) -> None:
        if not isinstance(self.title, str) or not self.title.strip():
            raise ReportError(f"`title`: got {self.title!r}, expected a non-empty string")


@dataclass(frozen=True)
class JsonInput:
    """One JSON input file found by :func:`discover_inputs`.

    Attributes
    ----------
    folder : Path
        The report input folder.
    path : Path
        The file (``folder / name``).
    data : object
        Its parsed JSON.
    """

    folder: Path
    path: Path
    data: Any


@dataclass(frozen=True)
class ReportInputs:
    """The known files found in the report's folders, in the order the folders were given.

    Attributes
    ----------
    folders : tuple of Path
    results, compare, campaign : tuple of JsonInput
        Parsed ``results.json``, ``compare.json`` and ``campaign.json`` files.
    provenance : tuple of str
        Per folder, what wrote it (:func:`check_folder`).
    own : tuple of JsonInput
        Parsed ``results.json`` files of vehicles on their own controllers (``"controller": "own"``).
    """

    folders: tuple[Path, ...]
    results: tuple[JsonInput, ...] = ()
    compare: tuple[JsonInput, ...] = ()
    campaign: tuple[JsonInput, ...] = ()
    provenance: tuple[str, ...] = ()
    own: tuple[JsonInput, ...] = ()


@dataclass(frozen=True)
class JsonTable:
    """A method table found in a JSON document (see the module docstring).

    Attributes
    ----------
    path : str
        Where in the document, e.g. ``methods`` or ``pairs[0].methods``.
    columns : tuple of str
        Column names (dotted for nested fields), numeric columns first.
    rows : tuple of (str, dict)
        Row label and its values by column.
    omitted : int
        Numbers in lists that were left out of the table.
    failed : tuple of (str, str)
        Rows that hold no result: row label and the reason, from the row's text field ``error``
        (e.g. a design of ``ilcdob compare`` that could not be made). Their values stay in ``rows``.
    """

    path: str
    columns: tuple[str, ...]
    rows: tuple[tuple[str, dict[str, Any]], ...]
    omitted: int = 0
    failed: tuple[tuple[str, str], ...] = ()


# ---------------------------------------------------------------------------------------------
# inputs

#: File name -> the command that writes it, for "regenerate it with ..." (the known files and the other inputs).
_MADE_BY = {**KNOWN_FILES, "fleet.json": KNOWN_FILES["results.json"], "theorem.json": KNOWN_FILES["results.json"]}
#: Deepest nesting of objects and lists a JSON input may have (ilcdob writes at most 6 levels).
_MAX_DEPTH = 64


def _finite(text: str) -> float:
    """A JSON number as a float; ValueError when it overflows to an infinity (``1e999``)."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text[:40]} is out of range")
    return value


def _not_json(name: str) -> Any:
    """``parse_constant`` of :func:`json.loads`: ``NaN`` and ``Infinity`` are not standard JSON."""
    raise ValueError(f"{name} is not a number of standard JSON")


def _depth(data: Any) -> int:
    """Nesting depth of objects and lists in ``data`` (counting stops past :data:`_MAX_DEPTH`)."""
    deepest, stack = 0, [(data, 1)]
    while stack:
        value, level = stack.pop()
        if isinstance(value, (dict, list)):
            deepest = max(deepest, level)
            if level > _MAX_DEPTH:
                break
            stack.extend((v, level + 1) for v in (value.values() if isinstance(value, dict) else value))
    return deepest


def _regenerate(path: Path) -> str:
    return f"regenerate it with `{_MADE_BY.get(path.name, KNOWN_FILES['results.json'])}`"


def _read_json(path: Path) -> Any:
    """The parsed standard JSON of ``path``; ReportError naming the file when it is not that."""
    try:
        text = read_text(path, "result file", error=ReportError, hint=_regenerate(path))  # regular file, size cap
    except OSError as exc:
        raise ReportError(f"{path}: cannot read ({exc.strerror})") from exc
    except UnicodeDecodeError as exc:
        raise ReportError(f"{path}: not a UTF-8 text file (byte {exc.object[exc.start]:#04x} at offset {exc.start}); "
                          f"{_regenerate(path)}") from exc
    try:
        data = json.loads(text, parse_float=_finite, parse_constant=_not_json)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, a non-standard number, a huge integer
        raise ReportError(f"{path}: not valid JSON ({str(exc)[:200]}); {_regenerate(path)}") from None
    if _depth(data) > _MAX_DEPTH:
        raise ReportError(f"{path}: objects and lists nested more than {_MAX_DEPTH} levels deep, which ilcdob never "
                          f"writes; {_regenerate(path)}")
    return data


def _is_real(v: Any) -> bool:
    """A finite JSON number (not a boolean)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(v)
    except OverflowError:  # an integer beyond the float range
        return False


def _key(where: str, key: str) -> str:
    """``where.key``, with ``key`` quoted when it is not plain printable text."""
    plain = key.isprintable() and key.isascii() and len(key) <= 64 and not any(c in key for c in '."[]')
    return f"{where}.{key}" if plain and key else f"{where}[{quoted(key)}]"


@dataclass(frozen=True)
class _Schema:
    """Type checks of the fields of one JSON input that the report uses; each failure a ReportError
    naming the file, the key, the value and what the file's writer puts there."""

    path: Path

    def fail(self, key: str, value: Any, expected: str) -> ReportError:
        return ReportError(f"{self.path}: key \"{key}\": got {quoted(value)}, expected {expected}; "
                           f"{_regenerate(self.path)}")

    def obj(self, value: Any, key: str | None = None) -> dict:
        if not isinstance(value, dict):
            if key is None:
                raise ReportError(f"{self.path}: expected a JSON object, got a JSON {type(value).__name__}; "
                                  f"{_regenerate(self.path)}")
            raise self.fail(key, value, "an object")
        return value

    def seq(self, value: Any, key: str, what: str) -> list:
        if not isinstance(value, list):
            raise self.fail(key, value, f"a list of {what}")
        return value

    def text(self, value: Any, key: str, null: bool = False) -> None:
        if not (isinstance(value, str) or (null and value is None)):
            raise self.fail(key, value, "a text" + (" or null" if null else ""))

    def texts(self, value: Any, key: str) -> list:
        for item in self.seq(value, key, "texts"):
            if not isinstance(item, str):
                raise self.fail(key, value, "a list of texts")
        return value

    def flag(self, value: Any, key: str, null: bool = False) -> None:
        if not (isinstance(value, bool) or (null and value is None)):
            raise self.fail(key, value, "true or false" + (" or null" if null else ""))

    def real(self, value: Any, key: str, null: bool = False, positive: bool = False) -> None:
        if not ((_is_real(value) and (value > 0 or not positive)) or (null and value is None)):
            raise self.fail(key, value, ("a number > 0" if positive else "a number") + (" or null" if null else ""))

    def reals(self, value: Any, key: str, null: bool = False) -> None:
        for item in self.seq(value, key, "numbers"):
            if not (_is_real(item) or (null and item is None)):
                raise self.fail(key, value, "a list of numbers" + (" (or nulls)" if null else ""))

    def integer(self, value: Any, key: str, least: int | None = None) -> None:
        if isinstance(value, bool) or not isinstance(value, int) or (least is not None and value < least):
            raise self.fail(key, value, "an integer" + (f" >= {least}" if least is not None else ""))


def _check_results(path: Path, data: Any) -> None:
    """The fields of ``results.json`` that the report reads (module docstring), typed as its writer writes them."""
    s = _Schema(path)
    s.obj(data)
    plant = data.get("plant")
    if plant not in PLANTS:
        raise ReportError(f"{path}: key \"plant\" is {quoted(plant)}, expected one of {list(PLANTS)}; "
                          f"{_regenerate(path)}")
    if data.get("law") is not None:
        s.text(data["law"], "law")
    if "sample_time" in data:
        s.real(data["sample_time"], "sample_time", null=True, positive=True)
    if "sensor_noise_std_m" in data:
        s.real(data["sensor_noise_std_m"], "sensor_noise_std_m", null=True)
    longest = 0
    for i, sc in enumerate(s.seq(data.get("scenarios"), "scenarios", "scenario objects")):
        where = f"scenarios[{i}]"
        s.obj(sc, where)
        s.integer(sc.get("id"), f"{where}.id", least=0)
        if "title" in sc:
            s.text(sc["title"], f"{where}.title")
        if "duration_s" in sc:
            s.real(sc["duration_s"], f"{where}.duration_s", null=True, positive=True)
        systems = s.obj(sc.get("systems"), f"{where}.systems")
        if sc.get("order") is not None:
            order = s.texts(sc["order"], f"{where}.order")
            if any(name not in systems for name in order):
                raise s.fail(f"{where}.order", order, f"names of {where}.systems ({sorted(systems)})")
        for name, m in systems.items():
            key = _key(f"{where}.systems", name)
            s.obj(m, key)
            for field_ in ("rmse_no_dob", "rmse_dob", "rmse_dhat_dob"):
                if field_ in m:
                    s.real(m[field_], f"{key}.{field_}", null=True)
            for field_ in ("rmse_learning", "rmse_dhat_learning", "peak_d_f_learning"):
                if field_ in m:
                    s.reals(m[field_], f"{key}.{field_}", null=True)
                    if field_ != "peak_d_f_learning":
                        longest = max(longest, len(m[field_]))
    if data.get("iterations") is not None:
        s.integer(data["iterations"], "iterations", least=0)
        if data["iterations"] != longest:
            raise s.fail("iterations", data["iterations"], f"the number of learning iterations the file holds "
                         f"({longest}: its longest rmse_learning list)")


def _check_own_results(path: Path, data: Any) -> None:
    """The fields of an own-controller ``results.json`` the report reads
    (:meth:`ilcdob.validation.channel_reproduction.ChannelReproduction.to_dict`), typed as its writer writes them."""
    s = _Schema(path)
    settings = s.obj(data.get("settings"), "settings")
    for i, v in enumerate(s.seq(settings.get("vehicles"), "settings.vehicles", "vehicle objects")):
        where = f"settings.vehicles[{i}]"
        s.text(s.obj(v, where).get("name"), f"{where}.name")
        for key in ("mass_kg", "arm_m"):
            s.real(v.get(key), f"{where}.{key}", null=True, positive=True)  # null: written before they were
    for key in ("sample_time", "sensor_noise_std", "trial_s"):
        s.real(settings.get(key), f"settings.{key}")
    for ch, per in s.obj(data.get("identification"), "identification").items():
        for name, axes in s.obj(per, _key("identification", ch)).items():
            for ax, fit in s.obj(axes, _key(f"identification.{ch}", name)).items():
                where = _key(f"identification.{ch}.{name}", ax)
                s.real(s.obj(fit, where).get("held_out_fit_percent"), f"{where}.held_out_fit_percent")
                s.real(fit.get("airframe_fit_percent"), f"{where}.airframe_fit_percent", null=True)
    for i, r in enumerate(s.seq(data.get("runs"), "runs", "run objects")):
        where = f"runs[{i}]"
        s.integer(s.obj(r, where).get("scenario"), f"{where}.scenario", least=0)
        for key in ("channel", "disturbance", "law"):
            s.text(r.get(key), f"{where}.{key}")
        order = s.texts(r.get("order"), f"{where}.order")
        base, ratios = s.obj(r.get("rmse_no_learning"), f"{where}.rmse_no_learning"), s.obj(r.get("ratios"),
                                                                                               f"{where}.ratios")
        for name in order:
            s.real(base.get(name), _key(f"{where}.rmse_no_learning", name))
            s.reals(ratios.get(name), _key(f"{where}.ratios", name))
    for i, row in enumerate(s.seq(data.get("acceptance"), "acceptance", "acceptance rows")):
        where = f"acceptance[{i}]"
        s.text(s.obj(row, where).get("what"), f"{where}.what")
        s.real(row.get("value"), f"{where}.value")
        s.real(row.get("limit"), f"{where}.limit")
        s.flag(row.get("passed"), f"{where}.passed")


def _check_fleet_table(path: Path, data: Any) -> None:
    """``fleet.json`` (:func:`report_files`): source, sample time, a header and rows of texts."""
    s = _Schema(path)
    s.obj(data)
    s.text(data.get("source"), "source")
    s.real(data.get("sample_time"), "sample_time", positive=True)
    header = s.texts(data.get("header"), "header")
    for i, row in enumerate(s.seq(data.get("rows"), "rows", "rows")):
        if not (isinstance(row, list) and len(row) == len(header) and all(isinstance(c, str) for c in row)):
            raise s.fail(f"rows[{i}]", row, f"a list of {len(header)} texts (one per header column)")


def _check_theorem(path: Path, data: Any) -> None:
    """``theorem.json`` (:func:`report_files`): ``missing``, or the sample count, seed and the pairs of each order."""
    s = _Schema(path)
    s.obj(data)
    if "missing" in data:
        s.text(data["missing"], "missing")
        return
    s.integer(data.get("samples"), "samples", least=1)
    s.integer(data.get("seed"), "seed")
    for i, o in enumerate(s.seq(data.get("orders"), "orders", "order objects")):
        where = f"orders[{i}]"
        s.obj(o, where)
        s.texts(o.get("order"), f"{where}.order")
        s.text(o.get("table"), f"{where}.table")
        for j, c in enumerate(s.seq(o.get("pairs"), f"{where}.pairs", "pair objects")):
            key = f"{where}.pairs[{j}]"
            s.obj(c, key)
            s.text(c.get("source"), f"{key}.source")
            s.text(c.get("target"), f"{key}.target")
            s.flag(c.get("holds_everywhere"), f"{key}.holds_everywhere")
            for field_ in ("min_margin", "worst_w"):
                s.real(c.get(field_), f"{key}.{field_}", null=True)
            s.text(c.get("delta_source"), f"{key}.delta_source", null=True)
            band = c.get("failing_band")
            if band is not None and not (isinstance(band, list) and len(band) == 2 and all(map(_is_real, band))):
                raise s.fail(f"{key}.failing_band", band, "null or [low, high] in rad/s")
            for field_ in ("band_rad_s", "exact_worst_ratio", "exact_worst_w_rad_s"):
                s.real(c.get(field_), f"{key}.{field_}", null=True)
            s.text(c.get("verdict"), f"{key}.verdict", null=True)
            s.flag(c.get("agrees"), f"{key}.agrees", null=True)
            s.text(c.get("statement"), f"{key}.statement", null=True)


#: The numeric fields of a method's row in ``compare.json`` and ``campaign.json`` (number or null).
_METHOD_NUMBERS = ("rmse_nominal", "ratio_nominal", "rmse_worst", "ratio_worst", "ratio_median", "improved_share",
                   "design_time_s", "median", "p95", "worst", "share_improved")


#: The numeric settings at the top level of ``compare.json`` and ``campaign.json`` (number or null).
_SETTING_NUMBERS = ("scenario", "samples", "seed", "scale", "robust_models", "rho", "duration", "runs_per_method",
                    "rejected_plants", "resumed_samples", "workers", "wall_time_s", "sample_time_s", "sample_cpu_s")


def _check_method_table(s: _Schema, table: Any, key: str) -> None:
    for name, row in s.obj(table, key).items():
        where = _key(key, name)
        s.obj(row, where)
        for field_ in _METHOD_NUMBERS:
            if field_ in row:
                s.real(row[field_], f"{where}.{field_}", null=True)
        for field_ in ("runs", "failed"):
            if field_ in row:
                s.integer(row[field_], f"{where}.{field_}", least=0)
        if "ratios" in row:
            s.reals(row["ratios"], f"{where}.ratios", null=True)
        for field_ in ("method", "order", "error"):
            if field_ in row:
                s.text(row[field_], f"{where}.{field_}", null=True)


def _check_methods(path: Path, data: Any) -> None:
    """``compare.json`` / ``campaign.json``: an object whose numeric settings (:data:`_SETTING_NUMBERS`) are
    numbers and whose ``methods`` (and each campaign scenario's ``methods``) map method names to rows with
    numeric fields, typed as their writers write them."""
    s = _Schema(path)
    s.obj(data)
    for field_ in _SETTING_NUMBERS:
        if field_ in data:
            s.real(data[field_], field_, null=True)
    if "rmse_without_learning" in data:  # compare's
        for name, value in s.obj(data["rmse_without_learning"], "rmse_without_learning").items():
            s.real(value, _key("rmse_without_learning", name), null=True)
    if "methods" in data:
        _check_method_table(s, data["methods"], "methods")
    if isinstance(data.get("scenarios"), dict):  # the campaign's (compare's scenario is a number)
        for name, sc in s.obj(data["scenarios"], "scenarios").items():
            where = _key("scenarios", name)
            _check_method_table(s, s.obj(sc, where).get("methods"), f"{where}.methods")


def _read_checked(path: Path, check: Any) -> Any:
    """``path``'s JSON after ``check(path, data)`` (one of the ``_check_*`` functions)."""
    data = _read_json(path)
    check(path, data)
    return data


def discover_inputs(dirs: list[str | Path]) -> ReportInputs:
    """Find, verify and parse the known files (:data:`KNOWN_FILES`) in every folder of ``dirs``.

    Each folder is checked against its ``manifest.json`` (:func:`check_folder`) before any of
    its files is read.

    Parameters
    ----------
    dirs : list of str or Path
        The report's input folders.

    Returns
    -------
    ReportInputs

    Raises
    ------
    ReportError
        No folder given; a folder that does not exist or is a file; a folder with none of
        the known files; a folder whose files do not match its manifest; a known file that is
        not valid JSON; a ``results.json``, ``compare.json`` or ``campaign.json`` whose fields
        the report reads have the wrong type (the message names the file and the key).
    """
    if not dirs:
        raise ReportError("`dirs`: got no folder; pass at least one output folder of "
                          + ", ".join(f"`{c.split(' ')[0]} {c.split(' ')[1]}`" for c in KNOWN_FILES.values()))
    found: dict[str, list[JsonInput]] = {name: [] for name in (*KNOWN_FILES, "own")}
    folders, provenance = [], []
    expected = ", ".join(KNOWN_FILES)
    for d in dirs:
        folder = Path(d)
        if not folder.exists():
            raise ReportError(f"report input {str(d)!r}: no such folder; expected an output folder holding "
                              f"one of {expected}")
        if not folder.is_dir():
            hint = f"; pass its folder {str(folder.parent)!r}" if folder.name in KNOWN_FILES else ""
            raise ReportError(f"report input {str(d)!r}: is a file, expected a folder holding one of {expected}{hint}")
        present = [name for name in KNOWN_FILES if (folder / name).is_file()]
        if not present:
            held = sorted(p.name for p in folder.iterdir())
            shown = ", ".join(held[:8]) + (" ..." if len(held) > 8 else "") if held else "nothing"
            raise ReportError(
                f"report input {str(d)!r}: none of {expected} found (it holds {shown}); pass a folder written by "
                + ", ".join(f"`{c}`" for c in KNOWN_FILES.values()))
        provenance.append(check_folder(folder))
        for name in present:
            path = folder / name
            data = _read_json(path)
            own = name == "results.json" and isinstance(data, dict) and data.get("controller") == "own"
            (_check_own_results if own else _check_results if name == "results.json" else _check_methods)(path, data)
            found["own" if own else name].append(JsonInput(folder, path, data))
        folders.append(folder)
    return ReportInputs(tuple(folders), tuple(found["results.json"]), tuple(found["compare.json"]),
                        tuple(found["campaign.json"]), tuple(provenance), tuple(found["own"]))


def check_folder(folder: Path) -> str:
    """Check that an output folder holds exactly the files of one run; returns a provenance sentence.

    Parameters
    ----------
    folder : Path
        An output folder.

    Returns
    -------
    str
        The command, version, time and run of the folder's ``manifest.json``, or that it has none
        (written before manifests existed: provenance unknown, nothing to check against).

    Raises
    ------
    ReportError
        The folder does not match its manifest (:func:`ilcdob.app.output.verify_manifest`): a
        listed file is missing or differs from what that run wrote, a file is not listed, or the
        manifest is malformed; the message names the file.
    """
    try:
        manifest = verify_manifest(folder)
    except ManifestError as exc:
        raise ReportError(str(exc)) from exc
    if manifest is None:
        return (f"{folder}: no {MANIFEST} (written by an earlier version of ilcdob): provenance unknown, its files "
                "are not verified")
    args = " ".join(manifest.get("arguments") or [])
    return (f"{folder}: `ilcdob {args or manifest.get('command', '')}`, ilcdob {manifest.get('version')}, "
            f"{manifest.get('created_utc')}, run {str(manifest.get('run_id'))[:8]}")


# ---------------------------------------------------------------------------------------------
# generic JSON tables

def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_table(rows: list[Any]) -> bool:
    """Rows of a method table: dicts, each with a number or null directly, one number at least."""
    return (bool(rows) and all(isinstance(r, dict) for r in rows)
            and all(any(_is_number(x) or x is None for x in r.values()) for r in rows)
            and any(_is_number(x) for r in rows for x in r.values()))


def _flatten(row: dict, prefix: str = "", depth: int = 0) -> tuple[dict[str, Any], int]:
    out: dict[str, Any] = {}
    omitted = 0
    for k, v in row.items():
        key = f"{prefix}{k}"
        if v is None or isinstance(v, (bool, int, float)):
            out[key] = v
        elif isinstance(v, str):
            if len(v) <= _MAX_TEXT:
                out[key] = v
        elif isinstance(v, dict) and depth < 2:
            sub, n = _flatten(v, key + ".", depth + 1)
            out.update(sub)
            omitted += n
        elif isinstance(v, list):
            omitted += sum(1 for x in v if _is_number(x))
    return out, omitted


def _row_label(row: dict, index: int) -> tuple[str, set[str]]:
    parts, used = [], set()
    for key in _LABEL_KEYS:
        if isinstance(row.get(key), (str, int)) and not isinstance(row.get(key), bool):
            parts.append(str(row[key]))
            used.add(key)
            break
    for a, b in _PAIR_KEYS:
        if isinstance(row.get(a), str) and isinstance(row.get(b), str):
            parts.append(f"{row[a]} -> {row[b]}")
            used |= {a, b}
            break
    return (" ".join(parts) if parts else f"#{index}"), used


def _make_table(path: str, rows: list[tuple[str, dict, set[str]]]) -> JsonTable:
    flat, omitted, failed = [], 0, []
    for label, row, used in rows:
        reason = row.get("error")
        if isinstance(reason, str) and reason.strip():
            failed.append((label, reason.strip()))
            used = used | {"error"}
        values, n = _flatten({k: v for k, v in row.items() if k not in used})
        flat.append((label, values))
        omitted += n
    numeric: list[str] = []
    other: list[str] = []
    for _, values in flat:
        for k, v in values.items():
            if _is_number(v) or isinstance(v, bool) or v is None:
                if k not in numeric:
                    numeric.append(k)
    for _, values in flat:
        for k, v in values.items():
            if isinstance(v, str) and k not in numeric and k not in other:
                other.append(k)
    # a column that only ever holds null carries nothing
    numeric = [k for k in numeric if any(values.get(k) is not None for _, values in flat)]
    return JsonTable(path, tuple(numeric + other), tuple(flat), omitted, tuple(failed))


def _join(path: str, key: Any) -> str:
    return f"{path}[{key}]" if isinstance(key, int) else (f"{path}.{key}" if path else str(key))


def json_tables(data: Any, path: str = "") -> list[JsonTable]:
    """Every method table of a JSON document (see the module docstring), in document order.

    Parameters
    ----------
    data : object
        Parsed JSON (``compare.json``, ``campaign.json``).
    path : str
        Location prefix for the tables' ``path``.

    Returns
    -------
    list of JsonTable
    """
    if isinstance(data, dict):
        if _is_table(list(data.values())):
            return [_make_table(path, [(str(k), v, {f for f in _LABEL_KEYS if v.get(f) == k})
                                       for k, v in data.items()])]
        out = []
        for k, v in data.items():
            if isinstance(v, (dict, list)):
                out += json_tables(v, _join(path, k))
        return out
    if isinstance(data, list):
        if _is_table(data):
            rows = []
            for i, v in enumerate(data):
                label, used = _row_label(v, i)
                rows.append((label, v, used))
            return [_make_table(path, rows)]
        out = []
        for i, v in enumerate(data):
            if isinstance(v, (dict, list)):
                out += json_tables(v, _join(path, i))
        return out
    return []


# ---------------------------------------------------------------------------------------------
# HTML pieces

def _fmt(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "NaN" if math.isnan(v) else (("inf" if v > 0 else "-inf") if math.isinf(v) else f"{v:.4g}")
    return str(v)


#: Human labels of the fields of ``compare.json`` and ``campaign.json`` (as the CLI's text tables
#: name them, with units); other fields get :func:`_label`'s generic form.
_LABELS = {
    "scenario": "scenario", "source": "learns from (j-1)", "target": "learning system (j)", "samples": "samples",
    "delta_set": "Delta set", "law": "learning law", "method": "method", "order": "order",
    "design_time_s": "design time (s)", "rmse_nominal": "RMSE nominal (mm)", "ratio_nominal": "ratio nominal",
    "rmse_worst": "RMSE worst (mm)", "ratio_worst": "ratio worst", "ratio_median": "ratio median",
    "improved_share": "improved", "share_improved": "improved", "seed": "seed", "uncertainty": "uncertainty",
    "scale": "uncertainty scale", "robust_models": "robust design models", "rho": "rho (robust guarantee)",
    "duration": "trial duration (s)", "runs_per_method": "runs per method", "rejected_plants": "rejected plants",
    "resumed_samples": "resumed samples", "workers": "worker processes", "wall_time_s": "wall time (s)",
    "sample_time_s": "time per sample (s)", "sample_cpu_s": "CPU per sample (s)", "ratio": "ratio",
    "runs": "runs", "failed": "failed runs", "median": "median", "p95": "95th percentile", "worst": "worst",
}
#: Fields that are shares in [0, 1], shown in % ("improved 100 %").
_SHARES = ("improved_share", "share_improved")
#: Fields in m shown in mm (the CLI's compare table does the same).
_MILLIMETRES = ("rmse_nominal", "rmse_worst")
#: Unit suffixes of field names -> the unit shown in the label.
_UNIT_SUFFIXES = (("_rad_s", "rad/s"), ("_m_s2", "m/s^2"), ("_mm", "mm"), ("_s", "s"), ("_m", "m"))


def _label(key: str) -> str:
    """A JSON field as a column label: :data:`_LABELS`, else words with the unit of its suffix
    (``settle_time_s`` -> ``settle time (s)``); dotted names label each part (``ratio.median``)."""
    if key in _LABELS:
        return _LABELS[key]
    if "." in key:
        return " ".join(_label(part) for part in key.split("."))
    for suffix, unit in _UNIT_SUFFIXES:
        if key.endswith(suffix) and len(key) > len(suffix):
            return f"{key[:-len(suffix)].replace('_', ' ')} ({unit})"
    return key.replace("_", " ")


def _cell(key: str, value: Any) -> str:
    """A field's value as shown: shares in %, RMSE in mm, nothing (null) as ``-``, else :func:`_fmt`."""
    last = key.rsplit(".", 1)[-1]
    if value is None:
        return "-"
    if _is_real(value) and last in _SHARES:
        return f"{100 * value:.4g} %"
    if _is_real(value) and last in _MILLIMETRES:
        return f"{1e3 * value:.4g}"
    return _fmt(value)


def _table(header: list[str], rows: list[list[str]], cls: str = "") -> str:
    """An HTML table; cells are escaped here."""
    head = "".join(f"<th>{html_text(h)}</th>" for h in header)
    body = "\n".join("<tr>" + "".join(f"<td>{html_text(c)}</td>" for c in r) + "</tr>" for r in rows)
    c = f' class="{cls}"' if cls else ""
    return f"<table{c}><thead><tr>{head}</tr></thead>\n<tbody>\n{body}\n</tbody></table>"


#: Largest figure the report embeds, pixels (the commands write about 1 megapixel).
_MAX_PIXELS = 40_000_000


def _png_uri(data: bytes, path: Path, made_by: str) -> str:
    """``data:`` URI of the figure ``path`` (its bytes ``data``), re-encoded as a 256-colour palette PNG (line
    plots look the same; the report shrinks about 2.5x); ReportError naming the file when it does not decode."""
    from PIL import Image

    buf = io.BytesIO()
    try:
        with Image.open(io.BytesIO(data)) as img:
            if img.width * img.height > _MAX_PIXELS:
                raise ReportError(f"{path}: a figure of {img.width} x {img.height} pixels, more than the "
                                  f"{_MAX_PIXELS} the commands ever write; regenerate the folder with "
                                  f"`{KNOWN_FILES[made_by]}`")
            img.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(buf, "PNG", optimize=True)
    except ReportError:
        raise
    except (OSError, ValueError, SyntaxError, EOFError, Image.DecompressionBombError) as exc:
        raise ReportError(f"{path}: not a readable PNG figure ({str(exc)[:120]}); regenerate the folder with "
                          f"`{KNOWN_FILES[made_by]}`") from exc
    small = buf.getvalue()
    return "data:image/png;base64," + base64.b64encode(small if len(small) < len(data) else data).decode("ascii")


#: Largest figure embedded, bytes (ilcdob's PNGs are a few hundred kB).
MAX_FIGURE_BYTES = 32 * 2**20


def _file_figure(folder: Path, name: str, caption: str, made_by: str = "results.json") -> str:
    """The PNG ``folder / name`` as an embedded figure with ``caption`` (a note when it is absent);
    ``made_by``: the known file whose command writes it (named when the file is not a PNG)."""
    path = folder / name
    if not path.is_file():
        return f'<p class="missing">Figure {html_text(name)} is not in {html_text(str(folder))} (it was written ' \
               "without figures, or by an older version): not shown.</p>"
    data = read_bytes(path, "figure", limit=MAX_FIGURE_BYTES, error=ReportError)  # regular file, size cap
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        raise ReportError(f"{path}: not a PNG file; regenerate the folder with `{KNOWN_FILES[made_by]}`")
    return (f'<figure><img src="{html_text(_png_uri(data, path, made_by))}" alt="{html_text(name)}">'
            f"<figcaption>{html_text(f'{caption} ({path})')}</figcaption></figure>")


def _missing(what: str, expected: str) -> str:
    return f'<p class="missing"><strong>No input:</strong> {html_text(what)} Expected {html_text(expected)}.</p>'


# ---------------------------------------------------------------------------------------------
# sections

@dataclass
class _Section:
    """One section: id, heading, HTML body, and which inputs fed it (empty: no input)."""

    sid: str
    heading: str
    body: str
    sources: list[str] = field(default_factory=list)
    expected: str = ""


def _fleet_table(fleet: Fleet) -> dict[str, Any]:
    """The fleet table of the report (``fleet.json``): models, controllers, identification, |Delta|."""
    from ilcdob.validation.figures import identified_bounds

    ts = fleet.sample_time
    w = np.logspace(-2, np.log10(0.999 * np.pi / ts), 300)
    bounds = identified_bounds(fleet, np.concatenate([[1.0, 10.0], w]))
    rows = []
    for s in fleet.systems:
        model = s.nominal_plant
        ident = s.identification
        c = s.controller
        row = [s.name, f"({polynomial_text(model.num, 4)}) / ({polynomial_text(model.den, 4)})", f"{model.delay:.4g}",
               f"{c.kp:.4g} / {c.ki:.4g} / {c.kd:.4g}", f"{s.dob.q_order}, {s.dob.q_time_constant:.4g}",
               "exact (model = plant)" if s.model is None else "differs from the true plant"]
        if ident is not None:
            sd = np.sqrt(np.diag(np.asarray(ident.covariance)))
            pars = ", ".join(f"{v:.4g} ± {e:.2g}" for v, e in zip(ident.parameters, sd))
            b = bounds[s.name][1]
            row += [f"{ident.fit_estimation:.2f}", f"{ident.fit_validation:.2f}", pars,
                    f"{100 * b[0]:.3g}", f"{100 * b[1]:.3g}", f"{100 * np.max(b[2:]):.3g}"]
        else:
            row += ["not identified"] + ["-"] * 5
        rows.append(row)
    header = ["system", "model P_hat(s)", "delay (s)", "PID kp / ki / kd", "Q order, time constant (s)",
              "model vs plant", "fit estimation (%)", "fit held-out (%)", "parameters (1 sigma)",
              "|Delta| 3 sigma at 1 rad/s (%)", "at 10 rad/s (%)", f"max to Nyquist {np.pi / ts:.3g} rad/s (%)"]
    return {"source": fleet.source, "sample_time": ts, "header": header, "rows": rows}


def _fleet_html(table: dict[str, Any]) -> str:
    return (f"<p>Fleet {html_text(table['source'])}: {len(table['rows'])} systems, sample time "
            f"{html_text(format(table['sample_time'], 'g'))} s. Fit in % "
            "(MATLAB definition) on estimation and held-out flights; parameters as in "
            "<code>IdentificationSpec</code> (free denominator then numerator coefficients) with 1-sigma "
            "uncertainty; |Delta| is the 3-sigma multiplicative uncertainty of the identified model from its "
            "parameter covariance.</p>\n" + _table(table["header"], table["rows"], "wide"))


def _rmse_table(data: dict) -> str:
    n = int(data.get("iterations") or max((len(m.get(k, [])) for sc in data["scenarios"] for m in sc["systems"].values()
                                            for k in ("rmse_learning", "rmse_dhat_learning")), default=0))
    header = (["scenario", "system", "no DOB (mm)", "only DOB (mm)"] + [f"learning {i + 1} (mm)" for i in range(n)]
              + [f"learning {n} / DOB", "d est. DOB (m/s^2)"] + [f"d est. learning {i + 1} (m/s^2)" for i in range(n)])
    rows = []
    for sc in data["scenarios"]:
        order = sc.get("order") or list(sc["systems"])
        for name in order:
            m = sc["systems"][name]
            learn = list(m.get("rmse_learning", []))
            dl = list(m.get("rmse_dhat_learning", []))
            mm = lambda v: "-" if v is None else f"{1e3 * v:.4g}"  # noqa: E731
            ratio = learn[-1] / m["rmse_dob"] if learn and learn[-1] is not None and m.get("rmse_dob") else None
            rows.append([str(sc.get("id", "?")), name, mm(m.get("rmse_no_dob")), mm(m.get("rmse_dob"))]
                        + [mm(v) for v in learn] + ["-"] * (n - len(learn))
                        + [_fmt(ratio) if ratio is not None else "-", _fmt(m.get("rmse_dhat_dob"))]
                        + [_fmt(v) for v in dl] + ["-"] * (n - len(dl)))
    return _table(header, rows)


#: Learning iterations whose RMSE agree to this share coincide (:func:`_same_learning`).
_SAME_RMSE = 1e-3


def _same_learning(data: dict) -> str:
    """A sentence naming, per scenario, the systems whose learning iterations all leave the same tracking
    RMSE (within :data:`_SAME_RMSE`), as with exact models; empty when there are none."""
    found = []
    for sc in data["scenarios"]:
        names = []
        for name in sc.get("order") or list(sc["systems"]):
            learn = [v for v in sc["systems"][name].get("rmse_learning", []) if v is not None]
            if len(learn) >= 2 and max(learn) - min(learn) <= _SAME_RMSE * max(learn):
                names.append(name)
        if names:
            found.append((sc.get("id", "?"), names, len(sc["systems"])))
    if not found:
        return ""
    n = _fmt(data.get("iterations"))
    if len(found) == len(data["scenarios"]) and all(len(names) == total for _, names, total in found):
        where = "every system of every scenario"
    else:
        where = "; ".join(f"scenario {sid}: {', '.join(names)}" for sid, names, _ in found)
    return (f"<p>The learning iterations coincide for {html_text(where)}: all {html_text(n)} leave the same "
            f"tracking RMSE (within {100 * _SAME_RMSE:g} %). The figures draw iterations whose curves coincide "
            "as one line and say so.</p>")


def _plant_section(res: JsonInput) -> str:
    data = res.data
    folder = res.folder
    from ilcdob.design.law.laws import LAW_DESCRIPTIONS

    law = data.get("law")
    law_html = (f"learning law <strong>{html_text(str(law))}</strong>"
                + (f" ({html_text(LAW_DESCRIPTIONS[law])})" if law in LAW_DESCRIPTIONS else "")
                if law is not None else "learning law not recorded (files written before the law choice existed "
                                        "come from the paper's law)")
    parts = [f"<p>From {html_text(str(res.path))}: {law_html}; {len(data['scenarios'])} scenario(s), "
             f"{html_text(_fmt(data.get('iterations')))} learning iteration(s), sample time "
             f"{html_text(_fmt(data.get('sample_time')))} s. Tracking RMSE in mm (no DOB, only DOB, learning "
             "iterations) and RMSE of the total disturbance estimate (d_hat + d_f) against the true disturbance "
             "in m/s^2.</p>", _rmse_table(data), _same_learning(data),
             _file_figure(folder, "rmse_bars.png", "Tracking RMSE (m, log scale) per scenario and system: no DOB, "
                          "only DOB and every learning iteration")]
    for sc in data["scenarios"]:
        sid = sc.get("id", "?")
        parts.append(f"<h3>Scenario {html_text(str(sid))}: {html_text(str(sc.get('title', '')))}</h3>")
        parts.append(_file_figure(folder, f"error_s{sid}.png",
                                  f"Scenario {sid}: tracking error e (m) against time (s), one row per system; "
                                  "left no DOB, only DOB and every learning iteration, right the learning "
                                  "iterations alone (zoom)"))
        parts.append(_file_figure(folder, f"disturbance_s{sid}.png",
                                  f"Scenario {sid}: true disturbance (wind + noise) and its estimates (m/s^2) "
                                  "against time (s), one row per system: only DOB (d_hat) and every learning "
                                  "iteration (d_hat + d_f); right each estimate minus the true disturbance"))
    return "\n".join(parts)


def _theorem_data(fleet: Fleet, orders: list[list[str]]) -> tuple[dict[str, Any], list[Any] | None]:
    """The Theorem check of every learning order (``theorem.json``) and the checks of the first order
    (for :func:`_theorem_figure`; None: no check).

    The check reads each source's Delta set through its bound only (``source="bound"``), so the
    sets are the bounds (:func:`ilcdob.design.checks.theorem.bound_delta_sets`, one per system for every
    order) and no sampled plant is built: the results are those of the sets of
    :data:`THEOREM_SAMPLES` samples drawn with seed 0 that ``theorem.json`` names (and
    ``ilcdob check`` draws).
    """
    from ilcdob.design.pair import pair_band
    from ilcdob.design.checks.theorem import bound_delta_sets, format_theorem_table, learning_pairs, theorem_check

    missing = [s.name for s in fleet.systems if s.identification is None]
    if missing:
        return {"missing": f"the fleet {fleet.source} has no identified covariance for {missing}, so no Delta set "
                           "and no Theorem check"}, None
    data: dict[str, Any] = {"samples": THEOREM_SAMPLES, "seed": 0, "orders": []}
    sets = bound_delta_sets(fleet, [name for name in fleet.names if any(name in o for o in orders)])
    first = None
    for order in orders:
        deltas = {name: sets[name] for name in order}
        bands = {(a, b): pair_band(fleet, a, b, deltas=deltas) for a, b in learning_pairs(fleet.names, order)}
        checks = theorem_check(fleet, order, deltas, bands=bands)
        first = first or checks
        data["orders"].append({"order": order, "table": format_theorem_table(checks),
                               "pairs": [_theorem_pair(c) for c in checks]})
    return data, first


def _theorem_figure(first: list[Any]) -> Any:
    """``theorem.png``: the paper's condition per source of the first order's checks."""
    from matplotlib.figure import Figure

    from ilcdob.design.checks.figure import TITLE_Y, minor_log_grid

    fig = Figure(figsize=(4.0 * len(first), 3.2))
    for ax, c in zip(fig.subplots(1, len(first), squeeze=False)[0], first):
        ax.loglog(c.w, c.delta, label="|Delta_(j-1)| (3 sigma)")
        ax.loglog(c.w, c.rhs, label="|1 + P C|_(j-1) / 2")
        ax.set_title(f"source {c.source}", fontsize=9, y=TITLE_Y)
        ax.set_xlabel("frequency (rad/s)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    minor_log_grid(fig)
    fig.set_layout_engine("tight")
    return fig


_THEOREM_KEYS = ("source", "target", "min_margin", "worst_w", "holds_everywhere", "failing_band", "delta_source",
                 "verdict", "agrees", "statement")


def _theorem_pair(check: Any) -> dict[str, Any]:
    """One pair of ``theorem.json``: the paper's condition, the exact worst case and the verdict."""
    d = check.to_dict()
    exact = d.get("exact") or {}
    return {**{k: v for k, v in d.items() if k in _THEOREM_KEYS}, "band_rad_s": check.band.cutoff,
            "exact_worst_ratio": exact.get("worst_ratio"), "exact_worst_w_rad_s": exact.get("worst_w_rad_s")}


def _read_theorem(folder: Path) -> dict[str, Any] | None:
    """The checked ``theorem.json`` of ``folder`` (None: the folder has none)."""
    path = folder / "theorem.json"
    return _read_checked(path, _check_theorem) if path.is_file() else None


def _theorem_html(folder: Path, data: dict[str, Any] | None) -> str:
    """The Theorem section of one folder from its checked ``theorem.json`` ``data`` (None: absent)."""
    if data is None:
        return _missing(f"{folder} has no theorem.json (written by `ilcdob reproduce`).", "theorem.json")
    if "missing" in data:
        return _missing(str(data["missing"]) + ".", "a fleet identified with `ilcdob identify-fleet` "
                        "(or run `ilcdob check --bound B`)")
    parts = ["<p>The verdict follows the exact worst case of |e_j / e'_j| (the learning vehicle's error with "
             "learning over its error with the DOB alone) over every Delta_(j-1) with |Delta| at most the 3-sigma "
             f"bound of the identification ({html_text(data['samples'])} sampled plants per Delta set, seed "
             f"{html_text(data['seed'])}), "
             "for the law as flown (the Theorem's filters through the learning band F, "
             "<code>ilcdob.design.filters.band</code>); it holds where that stays within 1.01 at every frequency. "
             "Beside it, "
             "the paper's first-order condition |Delta_(j-1)| &lt; |1 + P_(j-1) C_(j-1)| / 2 (paper Sec. III; "
             "margin = rhs / |Delta|, &gt; 1: holds), which is neither sufficient nor necessary; "
             "docs/theory.md section 2 explains both.</p>"]
    for o in data["orders"]:
        rows = [[f"{c['source']} -> {c['target']}", "yes" if c["holds_everywhere"] else "NO", _fmt(c.get("min_margin")),
                 "-" if c.get("failing_band") is None
                 else f"{c['failing_band'][0]:.4g} .. {c['failing_band'][1]:.4g}",
                 "off" if c.get("band_rad_s") is None else f"{c['band_rad_s']:.4g}",
                 "-" if "exact_worst_ratio" not in c else
                 "unbounded" if c["exact_worst_ratio"] is None else _fmt(c["exact_worst_ratio"]),
                 "-" if c.get("exact_worst_w_rad_s") is None else f"{c['exact_worst_w_rad_s']:.4g}",
                 {"holds": "holds", "fails": "FAILS"}.get(c.get("verdict"), "-"),
                 "-" if c.get("agrees") is None else ("yes" if c["agrees"] else "NO")]
                for c in o["pairs"]]
        parts.append(f"<h3>Order {html_text(' -> '.join(o['order']))}</h3>")
        parts.append(_table(["pair", "paper's first-order condition", "min margin", "failing band (rad/s)",
                             "learning band (rad/s)", "exact worst ratio", "at w (rad/s)", "verdict",
                             "paper agrees"], rows))
        parts.extend(f"<p>{html_text(c['statement'])}</p>" for c in o["pairs"] if c.get("statement"))
        parts.append("<details><summary>as printed by <code>ilcdob check</code></summary>"
                     f'<pre class="plain">{html_text(o["table"])}</pre></details>')
    parts.append(_file_figure(folder, "theorem.png", "The Theorem's condition per source system of the first "
                              "order against frequency (rad/s): |Delta_(j-1)| (3-sigma uncertainty) and "
                              "|1 + P C|_(j-1) / 2; learning helps where the first stays below the second"))
    return "\n".join(parts)


def report_files(fleet: Fleet, orders: list[list[str]], figures: bool = True, pending: bool = False) -> dict[str, Any]:
    """The report's inputs besides ``results.json``: ``fleet.json``, ``theorem.json`` (+ ``theorem.png``).

    Parameters
    ----------
    fleet : Fleet
        The fleet the reproduction flew (its identified models, when it has them).
    orders : list of list of str
        The learning orders of the scenarios.
    figures : bool
        Include ``theorem.png`` (when the fleet has a Theorem check).
    pending : bool
        ``theorem.png`` unbuilt (:class:`ilcdob.validation.figures.PendingFigure`), for
        :func:`ilcdob.validation.figures.render_figures`.

    Returns
    -------
    dict of str to content
        A content map for :class:`ilcdob.app.output.OutputFolder`.
    """
    unique: list[list[str]] = []
    for o in orders:
        if list(o) not in unique:
            unique.append(list(o))
    theorem, first = _theorem_data(fleet, unique)
    files: dict[str, Any] = {"fleet.json": _fleet_table(fleet), "theorem.json": theorem}
    if figures and first is not None:
        if pending:
            from ilcdob.validation.figures import PendingFigure

            files["theorem.png"] = PendingFigure(lambda: _theorem_figure(first), axes=len(first))
        else:
            files["theorem.png"] = _theorem_figure(first)
    return files


def _json_section(j: JsonInput, what: str) -> str:
    data = j.data
    parts = [f"<h3>{html_text(str(j.path))}</h3>"]
    if isinstance(data, dict):
        meta = [[_label(k), _cell(k, v)] for k, v in data.items()
                if v is None or isinstance(v, (str, int, float, bool))]
        if meta:
            parts.append(_table(["setting", "value"], meta, "meta"))
    tables = json_tables(data)
    if not tables:
        text = json.dumps(data, indent=1)
        cut = text[:4000] + ("\n..." if len(text) > 4000 else "")
        parts.append(_missing(f"{j.path} holds no table of {what} (rows = methods with numeric fields); its content "
                              "is shown as is.", "an object of methods, e.g. {\"methods\": {name: {field: number}}}"))
        parts.append(f'<pre class="plain">{html_text(cut)}</pre>')
    paths = [t.path for t in tables]
    for t in tables:
        note = f" ({t.omitted} list values not tabulated)" if t.omitted else ""
        where = _where(t.path, paths)
        if where or note:
            parts.append(f'<p class="where">{html_text(where)}<span class="omitted">{html_text(note)}</span></p>')
        parts.append(_method_table(t))
    return "\n".join(parts)


def _where(path: str, paths: list[str]) -> str:
    """Heading of the method table at ``path`` among the document's tables ``paths``: the campaign's
    per-scenario tables by their scenario, its top-level table as "all scenarios"; other paths as they are."""
    if path == "methods":
        return "all scenarios" if any(p.startswith("scenarios.") for p in paths) else ""
    if path.startswith("scenarios.") and path.endswith(".methods"):
        return path[len("scenarios."):-len(".methods")]
    return path or "(top level)"


def _method_table(t: JsonTable) -> str:
    """A method table as HTML; a row without result (:attr:`JsonTable.failed`) shows its reason
    across the value columns instead of empty cells."""
    reasons = dict(t.failed)
    head = "<th>method</th>" + "".join(f'<th title="{html_text(h)}">{html_text(_label(h))}</th>' for h in t.columns)
    body = []
    for label, values in t.rows:
        if label in reasons:
            body.append(f'<tr class="failed"><td>{html_text(label)}</td><td colspan="{max(len(t.columns), 1)}">'
                        f"<strong>no result</strong>: {html_text(reasons[label])}</td></tr>")
        else:
            body.append("<tr>" + "".join(f"<td>{html_text(c)}</td>" for c in
                                         [label, *(_cell(k, values[k]) if k in values else "-" for k in t.columns)])
                        + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead>\n<tbody>\n" + "\n".join(body) + "\n</tbody></table>"


_COMPARE_CAPTION = ("Improvement ratio ||e_j|| / ||e'_j|| (log scale; below 1: learning helped) of every design "
                    "for the pair flown: diamond the nominal plants, dots each sampled plant of the Delta set; "
                    "dotted line the robust design's guaranteed factor rho when given. A design that failed has "
                    "no points")
_CAMPAIGN_CAPTION = ("Distribution of the improvement ratio ||e_j|| / ||e'_j|| (log scale; below 1: learning "
                     "improved) over the sampled plants, per method (with its share of improved runs) and per "
                     "scenario: box quartiles, whiskers the range, dots the single runs")


def _compare_html(j: JsonInput) -> str:
    return _json_section(j, "design methods") + "\n" + _file_figure(j.folder, "compare_ratios.png",
                                                                    _COMPARE_CAPTION, "compare.json")


def _campaign_html(j: JsonInput) -> str:
    return _json_section(j, "campaign statistics") + "\n" + _file_figure(j.folder, "campaign_ratios.png",
                                                                         _CAMPAIGN_CAPTION, "campaign.json")


_CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1200px; padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; } h2 { border-bottom: 1px solid #ccc; margin-top: 2em; } h3 { margin-top: 1.4em; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.5em; text-align: right; }
th { background: #f0f0f0; } td:first-child, th:first-child { text-align: left; }
table.wide td, table.wide th { text-align: left; }
figure { margin: 1em 0; } img { max-width: 100%; height: auto; }
figcaption { font-size: 0.85em; color: #555; }
tr.failed td { color: #8a2a00; background: #fff4e5; text-align: left; }
.missing { background: #fff4e5; border-left: 4px solid #e8a33d; padding: 0.4em 0.8em; }
.status-ok { color: #1a7f37; } .status-none { color: #b35900; font-weight: bold; }
.where { font-size: 0.9em; font-weight: bold; color: #444; margin-bottom: 0; }
.where .omitted { font-weight: normal; color: #666; } table.meta td { text-align: left; }
.not-included { font-size: 0.9em; color: #555; }
pre.plain { font-size: 0.8em; background: #f7f7f7; padding: 0.5em; overflow-x: auto; }
"""


def _left_out(section: _Section) -> str:
    """``Heading (`command`)`` of a section left out of the report: its heading without the parenthesis,
    and the command its input comes from (the first quoted command of its ``expected``)."""
    command = re.search(r"`([^`]+)`", section.expected)
    return (f"{html_text(section.heading.split(' (')[0])}"
            + (f" (<code>{html_text(command.group(1))}</code>)" if command else f" ({html_text(section.expected)})"))


def build_report(dirs: list[str | Path], options: ReportOptions | None = None,
                 progress: Callable[[int, int, str], None] | None = None) -> str:
    """The HTML text of the report of the folders ``dirs`` (see the module docstring).

    Parameters
    ----------
    dirs : list of str or Path
        Output folders of ``ilcdob reproduce``, ``ilcdob compare`` and ``ilcdob campaign``.
    options : ReportOptions, optional
    progress : callable, optional
        ``progress(done, total, what)`` before each section is rendered (figures are embedded as they come).

    Returns
    -------
    str
        A self-contained HTML document.

    Raises
    ------
    ReportError
        See :func:`discover_inputs`.
    """
    options = options if options is not None else ReportOptions()
    if not isinstance(options, ReportOptions):
        raise ReportError(f"`options`: got {type(options).__name__}, expected a ReportOptions")
    inputs = discover_inputs(list(dirs))
    # every input is read and checked before anything is rendered
    fleet_tables = [_read_checked(r.folder / "fleet.json", _check_fleet_table)
                    if (r.folder / "fleet.json").is_file() else None for r in inputs.results]
    theorems = [_read_theorem(r.folder) for r in inputs.results]
    reproduce_cmd = f"results.json from `{KNOWN_FILES['results.json']}`"
    makers = [("fleet and identified models", lambda: _fleet_section(inputs.results, fleet_tables, reproduce_cmd)),
              ("Bode figures", lambda: _bode_section(inputs.results, reproduce_cmd)),
              *((f"the {plant} plant", lambda plant=plant: _plant_section_of(inputs.results, plant))
                for plant in PLANTS),
              ("the Theorem check", lambda: _theorem_section(inputs.results, theorems, reproduce_cmd)),
              ("vehicles on their own controllers", lambda: _own_section(list(inputs.own))),
              ("design comparison", lambda: _compare_section(inputs.compare)),
              ("campaign statistics", lambda: _campaign_section(inputs.campaign))]
    sections = []
    for k, (what, make) in enumerate(makers):
        if progress is not None:
            progress(k, len(makers), f"report section: {what}")
        sections.append(make())
    return _document(sections, list(inputs.provenance), options.title)


def _results_heading(res: JsonInput) -> str:
    """``<h3>`` of one results.json's part of a section: its plant and folder."""
    plant = _PLANT_TITLE[res.data["plant"]].split(" (")[0].lower()
    return f"<h3>{html_text(plant.capitalize())}: {html_text(str(res.folder))}</h3>"


def _fleet_section(results: list[JsonInput], tables: list[Any], expected: str) -> _Section:
    """Fleet and identified models: each results folder's fleet.json table and identified-model figure."""
    body, srcs = [], []
    for res, table in zip(results, tables):
        body.append(_results_heading(res))
        if table is not None:
            body.append(_fleet_html(table))
            srcs.append(str(res.folder / "fleet.json"))
        else:
            body.append(_missing(f"{res.folder} has no fleet.json (written by `ilcdob reproduce`).", "fleet.json"))
        if (res.folder / "identified_models.png").is_file():
            body.append(_file_figure(res.folder, "identified_models.png",
                                     "Identified plant models: magnitude (dB) against frequency (rad/s) with "
                                     "their 3-sigma multiplicative uncertainty band, and that bound |Delta(jw)|"))
    return _Section("fleet", "Fleet and identified models", "\n".join(body), srcs, expected)


def _bode_section(results: list[JsonInput], expected: str) -> _Section:
    """The paper's Bode figures of each results folder."""
    body, srcs = [], []
    for res in results:
        body.append(_results_heading(res))
        for name, caption in _BODE_FIGURES.items():
            body.append(_file_figure(res.folder, name, caption))
        if any((res.folder / name).is_file() for name in _BODE_FIGURES):
            srcs.append(str(res.path))
    return _Section("bode", "Bode figures of the paper", "\n".join(body), srcs, expected)


def _plant_section_of(results: list[JsonInput], plant: str) -> _Section:
    """The section of one plant: every results.json flown on it."""
    mine = [r for r in results if r.data["plant"] == plant]
    return _Section(plant, _PLANT_TITLE[plant], "\n".join(_plant_section(r) for r in mine), [str(r.path) for r in mine],
                    f"results.json with \"plant\": \"{plant}\" from `ilcdob reproduce"
                    + ("" if plant == "linear" else f" --plant {plant}") + " --out DIR`")


def _theorem_section(results: list[JsonInput], theorems: list[Any], expected: str) -> _Section:
    """The Theorem check of each results folder (theorem.json)."""
    body, srcs = [], []
    for res, theorem in zip(results, theorems):
        body.append(_results_heading(res))
        body.append(_theorem_html(res.folder, theorem))
        if theorem is not None and "missing" not in theorem:
            srcs.append(str(res.folder / "theorem.json"))
    return _Section("theorem", "Theorem check", "\n".join(body), srcs,
                    f"{expected}, naming a fleet with identified models")


def _own_html(j: JsonInput) -> str:
    """One own-controller run: its settings, vehicles, identification, learning ratios, acceptance and figure."""
    d, s = j.data, j.data["settings"]
    parts = [f"<h3>{html_text(str(j.folder))}</h3>",
             _table(["setting", "value"], [["channels", ", ".join(map(str, s.get("channels", [])))],
                                           ["setpoint period (s)", _fmt(s["sample_time"])],
                                           ["position noise (mm)", _fmt(1e3 * s["sensor_noise_std"])],
                                           ["trial (s)", _fmt(s["trial_s"])],
                                           ["add-on DOB", "-" if s.get("dob") is None else _fmt(s["dob"])]], "meta"),
             _table(["vehicle", "mass (kg)", "arm (m)", "kp (1/s^2)", "kd (1/s)"],
                    [[v["name"], _cell("", v.get("mass_kg")), _cell("", v.get("arm_m")),
                      *(("rotorpy's", "rotorpy's") if v.get("position_gains") is None else
                        (", ".join(_fmt(g) for g in k) for k in v["position_gains"]))] for v in s["vehicles"]]),
             _table(["channel", "vehicle", "axis", "channel map held-out fit (%)", "airframe held-out fit (%)"],
                    [[ch, name, ax, _fmt(f["held_out_fit_percent"]), _cell("", f.get("airframe_fit_percent"))]
                     for ch, per in d["identification"].items() for name, axes in per.items()
                     for ax, f in axes.items()])]
    width = max((len(v) for r in d["runs"] for v in r["ratios"].values()), default=0)
    parts.append(_table(["scenario", "disturbance", "law", "channel", "vehicle", "no learning (mm)",
                         *(f"iteration {i + 1}" for i in range(width))],
                        [[str(r["scenario"]), r["disturbance"], r["law"], r["channel"], name,
                          _fmt(1e3 * r["rmse_no_learning"][name]), *(_fmt(v) for v in r["ratios"][name])]
                         for r in d["runs"] for name in r["order"]]))
    parts.append(_table(["acceptance figure", "measured", "limit", "met"],
                        [[row["what"], _fmt(row["value"]), _fmt(row["limit"]), "yes" if row["passed"] else "NO"]
                         for row in d["acceptance"]]))
    parts.append(_file_figure(j.folder, "learning.png", "Learning over iterations: RMSE over the same vehicle's "
                              "flight without learning (log scale), per disturbance and law"))
    return "\n".join(parts)


def _own_section(own: list[JsonInput]) -> _Section:
    """Vehicles flying their own controllers: every own-controller results.json."""
    return _Section(
        "own", "Vehicles on their own controllers (rotorpy)",
        "<p>rotorpy's multirotors fly rotorpy's SE3 controller; each channel map is identified from chirp flights "
        "and the learning signal enters a setpoint channel. Ratios are RMSE of the learning flight over the same "
        "vehicle's flight without learning (&lt; 1: learning helped).</p>\n" + "\n".join(_own_html(j) for j in own)
        if own else "", [str(j.path) for j in own],
        "results.json with \"controller\": \"own\" from `ilcdob reproduce --plant rotorpy --controller own --out DIR`")


def _compare_section(compare: list[JsonInput]) -> _Section:
    """The design comparison: every compare.json."""
    return _Section(
        "compare", "Design comparison",
        "<p>Each design of <code>ilcdob compare</code> flown for one pair, nominal and over the Delta set; "
        "ratio = ||e_j|| / ||e'_j|| (&lt; 1: learning helped). A design that could not be made is listed with "
        "its reason.</p>\n" + "\n".join(_compare_html(j) for j in compare) if compare else "",
        [str(j.path) for j in compare], f"compare.json from `{KNOWN_FILES['compare.json']}`")


def _campaign_section(campaign: list[JsonInput]) -> _Section:
    """The campaign statistics: every campaign.json."""
    return _Section(
        "campaign", "Campaign statistics",
        "<p>Statistics per method of the improvement ratio ||e_j|| / ||e'_j|| over the sampled plants "
        "(&lt; 1: learning improved on what system j would have had without it).</p>\n"
        + "\n".join(_campaign_html(j) for j in campaign)
        if campaign else "",
        [str(j.path) for j in campaign], f"campaign.json from `{KNOWN_FILES['campaign.json']}`")


def _document(sections: list[_Section], provenance: list[str], title: str) -> str:
    """The HTML document: the sections with an input, a table of them, and the ones left out named once."""
    shown = [s for s in sections if s.sources or s.body.strip()]
    left_out = [s for s in sections if s not in shown]
    status_rows = []
    for s in shown:
        if s.sources:
            status = f'<span class="status-ok">rendered</span> from {html_text(", ".join(s.sources))}'
        else:
            status = f'<span class="status-none">input missing</span>: expected {html_text(s.expected)}'
        status_rows.append(f'<tr><td><a href="#{html_text(s.sid)}">{html_text(s.heading)}</a></td>'
                           f"<td>{status}</td></tr>")
    not_included = ('<p class="not-included">Not included, as none of the folders holds their input: '
                    + "; ".join(_left_out(s) for s in left_out) + ".</p>") if left_out else ""
    out = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f"<title>{html_text(title)}</title><style>{_CSS}</style></head><body>",
           f"<h1>{html_text(title)}</h1>",
           "<p>Modi, Chen, Liang, Zheng (2024), <em>Improving Disturbance Estimation and Suppression via "
           "Learning among Systems with Mismatched Dynamics</em>: quadrotors with PID + disturbance observer "
           "learn a repetitive task in wind from each other through the learning filters L1, L2. Generated by "
           "<code>ilcdob report</code> from:</p><ul>"
           + "".join(f"<li>{html_text(p)}</li>" for p in provenance) + "</ul>",
           '<h2 id="contents">Sections and their inputs</h2>',
           '<table class="wide"><thead><tr><th>section</th><th>input</th></tr></thead><tbody>',
           *status_rows, "</tbody></table>", not_included]
    for s in shown:
        out.append(f'<h2 id="{html_text(s.sid)}">{html_text(s.heading)}</h2>')
        out.append(s.body)
    out.append("</body></html>")
    return "\n".join(out) + "\n"
