"""Bode figures of the learning design: ``bode.png`` of ``ilcdob design`` and the drawing rules
every Bode figure of ilcdob follows.

:func:`pair_bode_figure` draws, for one pair j-1 -> j, the paper's frequency responses
(Sec. III; docs/theory.md sections 1-2): the Theorem's learning filters ``L1`` (on
``e_{j-1}``) and ``L2`` (on ``d_f,{j-1}``), the error propagation with learning ``Te1`` and
``Te2`` (``e_j = Te1{e_{j-1}} + Te2{d_f,{j-1}}``, under a model error) and ``Omega``
(disturbance -> DOB estimate) of both vehicles, against frequency in rad/s up to Nyquist,
with the learning band marked.

Drawing rules (:func:`draw_bode`, also used by :mod:`ilcdob.validation.figures`):

* magnitude in dB, phase in degrees wrapped to (-180, 180] (the line is broken where it wraps);
* curves that coincide on the plot (every point within :data:`COINCIDE_RTOL` relative: 0.09 dB
  and 0.6 degrees) are drawn once, and their one legend entry names all of them ("coincide:
  ..."), instead of a legend listing curves hidden under each other.

Nothing here writes a file; the figure is laid out for PNG at 110 dpi.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, replace
from typing import Any, Sequence

import numpy as np
from matplotlib.figure import Figure

from ilcdob.channel_loop import CHANNEL_UNITS, ChannelLoop
from ilcdob.errors import NumericalError, SpecError, UnstableLoopError
from ilcdob.fleet import Fleet
from ilcdob.loop import LoopSystem, build_loop, freqresp
from ilcdob.specs import PlantSpec

from ..filters.band import LearningBand
from ..maps.channel_filters import channel_filters, channel_view, learning_channel
from ..maps.closed_form import LearningFilters, closed_form_filters
from ..methods import ClosedForm

__all__ = ["channel_pair_bode_figure", "BodeCurve", "COINCIDE_RTOL", "TE_GAIN_ERROR", "frequency_grid", "magnitude_db", "wrapped_phase",
           "coinciding", "group_label", "draw_bode", "finish_bode_axes", "mark_band", "with_gain_error",
           "loop_maps", "te_loops", "pair_bode_figure", "minor_log_grid", "decade_label", "TITLE_Y"]

#: Relative tolerance, at every frequency, under which two frequency responses coincide on a Bode
#: plot (drawn once): 1 %, i.e. 0.09 dB and 0.6 degrees, below a pixel of the figures. (Omega of
#: the built-in vehicles differ by at most 0.02 dB and 0.5 degrees, near Nyquist.)
COINCIDE_RTOL = 1e-2
#: Model error assumed for Te when the fleet states no true plant besides the model: every
#: true plant 10 % stronger than its model (with exact models Te1 = Te2 = 0, Case I).
TE_GAIN_ERROR = 0.10
_COLORS = ["#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860"]
_BAND_COLOR = "0.9"


@dataclass(frozen=True)
class BodeCurve:
    """One frequency response to draw.

    Attributes
    ----------
    label : str
        Legend text (e.g. ``"UAV1 -> UAV2"``).
    response : numpy.ndarray
        Complex response at the figure's frequencies.
    color : str
        Matplotlib colour.
    ls : str or tuple
        Matplotlib line style.
    """

    label: str
    response: np.ndarray
    color: str = _COLORS[0]
    ls: Any = "-"


def frequency_grid(ts: float, n: int = 400) -> np.ndarray:
    """Log-spaced frequencies from 0.01 rad/s to just below Nyquist (pi/ts).

    Parameters
    ----------
    ts : float
        Sample time, s.
    n : int
        Number of frequencies.

    Returns
    -------
    numpy.ndarray
        Frequencies, rad/s.
    """
    return np.logspace(-2, np.log10(0.999 * np.pi / ts), n)


def magnitude_db(x: np.ndarray) -> np.ndarray:
    """``20 log10 |x|`` (an exact zero becomes -6000 dB instead of -inf).

    Parameters
    ----------
    x : array_like
        Complex response.

    Returns
    -------
    numpy.ndarray
        Magnitude, dB.
    """
    return 20 * np.log10(np.maximum(np.abs(x), 1e-300))


def wrapped_phase(x: np.ndarray) -> np.ndarray:
    """Phase of ``x`` in degrees, wrapped to (-180, 180].

    Parameters
    ----------
    x : array_like
        Complex response.

    Returns
    -------
    numpy.ndarray
        Phase, degrees, each in (-180, 180].
    """
    deg = np.degrees(np.angle(np.asarray(x, dtype=complex)))
    return np.where(deg <= -180.0, deg + 360.0, deg)


def _broken_at_wraps(w: np.ndarray, deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(w, deg)`` with a NaN inserted wherever the wrapped phase jumps by more than 180 degrees, so that
    the line is broken there instead of crossing the axes."""
    jumps = np.flatnonzero(np.abs(np.diff(deg)) > 180.0) + 1
    return np.insert(np.asarray(w, float), jumps, np.nan), np.insert(deg, jumps, np.nan)


def coinciding(values: Sequence[np.ndarray], rtol: float = COINCIDE_RTOL, pointwise: bool = True) -> list[list[int]]:
    """Groups of the curves that coincide, in order of first appearance.

    Curve ``i`` joins the first group whose first curve ``r`` it matches: ``|v_i - v_r| <=
    rtol |v_r|`` at every point (``pointwise``; for frequency responses, which span many
    decades) or ``max |v_i - v_r| <= rtol max |v_r|`` (for time series).

    Parameters
    ----------
    values : sequence of array
        The curves, all of one length.
    rtol : float
        Relative tolerance.
    pointwise : bool
        Compare point by point (True) or against the first curve's peak.

    Returns
    -------
    list of list of int
        Indices into ``values``; every index in exactly one group.
    """
    groups: list[list[int]] = []
    arrays = [np.asarray(v) for v in values]
    for i, v in enumerate(arrays):
        for g in groups:
            ref = arrays[g[0]]
            if ref.shape != v.shape:
                continue
            diff = np.abs(v - ref)
            same = (np.all(diff <= rtol * np.abs(ref)) if pointwise
                    else float(np.max(diff, initial=0.0)) <= rtol * float(np.max(np.abs(ref), initial=0.0)))
            if same:
                g.append(i)
                break
        else:
            groups.append([i])
    return groups


def _names(labels: Sequence[str]) -> str:
    labels = list(labels)
    return labels[0] if len(labels) == 1 else ", ".join(labels[:-1]) + " and " + labels[-1]


def group_label(labels: Sequence[str], width: int = 36) -> str:
    """Legend text of a group of coinciding curves: ``"coincide: A, B and C"`` (wrapped).

    Parameters
    ----------
    labels : sequence of str
        Labels of the curves (one label is returned as it is).
    width : int
        Characters per legend line.

    Returns
    -------
    str
    """
    if len(labels) == 1:
        return labels[0]
    return "\n".join(textwrap.wrap(f"coincide: {_names(labels)}", width))


def draw_bode(mag_ax: Any, phase_ax: Any, w: np.ndarray, curves: Sequence[BodeCurve],
              rtol: float = COINCIDE_RTOL) -> list[list[int]]:
    """Draw ``curves`` on a magnitude (dB) and a phase (degrees, wrapped) axes, each group of
    coinciding curves once (:func:`coinciding`), labelled with every member (:func:`group_label`).

    Parameters
    ----------
    mag_ax, phase_ax : matplotlib.axes.Axes
        Magnitude and phase axes.
    w : numpy.ndarray
        Frequencies, rad/s.
    curves : sequence of BodeCurve
        The responses at ``w``.
    rtol : float
        Tolerance of :func:`coinciding` (pointwise).

    Returns
    -------
    list of list of int
        The groups drawn (indices into ``curves``).
    """
    groups = coinciding([c.response for c in curves], rtol)
    for g in groups:
        c = curves[g[0]]
        label = group_label([curves[i].label for i in g])
        mag_ax.semilogx(w, magnitude_db(c.response), color=c.color, ls=c.ls, label=label)
        phase_ax.semilogx(*_broken_at_wraps(w, wrapped_phase(c.response)), color=c.color, ls=c.ls, label=label)
    return groups


#: Height of axes titles, in axes coordinates (1: the top edge; matplotlib's title pad above it). Given
#: to every ``set_title``, it switches off matplotlib's automatic title placement, which looks for
#: tick labels and an x label above the axes and for a y offset text in the title's way, for every
#: title at every layout pass and draw: a tenth of the time of a reproduction's figures. Our axes
#: draw nothing above them but a y offset text at the left corner, clear of a centred title, so the
#: titles land where the automatic placement puts them, pixel for pixel (docs/performance.md,
#: "Reproduce and figures").
TITLE_Y = 1.0


def _min_span(ax: Any, span: float) -> None:
    """Keep matplotlib from zooming into rounding noise (L2 = 1 to 1e-8 with exact models)."""
    lo, hi = ax.get_ylim()
    if hi - lo < span:
        mid = 0.5 * (lo + hi)
        ax.set_ylim(mid - span / 2, mid + span / 2)


def finish_bode_axes(mag_ax: Any, phase_ax: Any, title: str, ts: float, legend: bool = True) -> None:
    """Title, units, grid, the Nyquist line and a phase axis of -180 .. 180 degrees.

    Parameters
    ----------
    mag_ax, phase_ax : matplotlib.axes.Axes
        Magnitude and phase axes of one response.
    title : str
        Title of the magnitude axes.
    ts : float
        Sample time, s (Nyquist at pi/ts).
    legend : bool
        Add the magnitude axes' legend.
    """
    _min_span(mag_ax, 10.0)
    mag_ax.set_title(title, fontsize=10, y=TITLE_Y)
    mag_ax.set_ylabel("magnitude (dB)")
    phase_ax.set_ylabel("phase (deg)")
    phase_ax.set_xlabel("frequency (rad/s)")
    phase_ax.set_ylim(-195, 195)
    phase_ax.set_yticks([-180, -90, 0, 90, 180])
    for ax in (mag_ax, phase_ax):
        ax.grid(True, alpha=0.3)  # the minor grid: minor_log_grid, once the figure is complete
        ax.axvline(np.pi / ts, color="0.6", lw=0.8, label="_nyquist")
    if legend:
        mag_ax.legend(fontsize=7)


#: Unicode superscripts of an exponent's characters, for :func:`decade_label`.
_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def decade_label(x: float, pos: int | None = None) -> str:
    """Tick label of a power of ten as plain text, ``10`` and its exponent in superscripts (``10⁻²``).

    The label matplotlib's log axes draw as mathtext (``$\\mathdefault{10^{-2}}$``), without mathtext:
    see :func:`minor_log_grid`. Other values get no label (matplotlib labels only decades on long views).

    Parameters
    ----------
    x : float
        Tick position.
    pos : int, optional
        Tick index (unused; the signature of :class:`matplotlib.ticker.FuncFormatter`).

    Returns
    -------
    str
    """
    if not x > 0 or not np.isfinite(x):
        return ""
    e = round(float(np.log10(x)))
    return "10" + str(e).translate(_SUPERSCRIPT) if np.isclose(x, 10.0 ** e, rtol=1e-9, atol=0) else ""


def minor_log_grid(fig: Figure, alpha: float = 0.3, min_decades: float = 2.0) -> Figure:
    """Draw the minor grid of a figure's log axes as one line collection per axis, without minor ticks,
    and label their decades in plain text.

    matplotlib draws each minor grid line as part of a tick object (two marks, a grid line, two
    labels), built and laid out for every minor position of every axes: a six-panel Bode figure
    holds hundreds, a third of its build and render time (docs/performance.md, "Reproduce and
    figures"). Here the positions matplotlib's own minor locator gives for the axis's view are drawn
    as a single :class:`~matplotlib.collections.LineCollection` in the minor grid's style, and the minor
    locator is cleared: the grid looks the same, the small minor tick marks are gone. Only views
    of at least ``min_decades`` decades are changed (matplotlib labels no minor tick there); call it
    once the figure's data and limits are final (its limits are read, not changed).

    On the same axes, matplotlib's default decade labels (mathtext, ``10^{-2}``) are replaced by
    :func:`decade_label` (``10⁻²``, the same text in superscript characters): mathtext costs every
    process that draws a figure its parser and fonts, and every label a parse.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure, complete.
    alpha : float
        Opacity of the minor grid lines (that of the major grid, as ``ax.grid(alpha=...)`` sets it).
    min_decades : float
        Views spanning fewer decades keep matplotlib's minor ticks.

    Returns
    -------
    matplotlib.figure.Figure
        ``fig``.
    """
    import matplotlib as mpl
    from matplotlib.collections import LineCollection
    from matplotlib.ticker import FuncFormatter, LogFormatterSciNotation, NullLocator

    todo = []
    for ax in fig.axes:  # every position first: axes sharing an axis share its locator
        for axis, limits, vertical in ((ax.xaxis, ax.get_xlim, True), (ax.yaxis, ax.get_ylim, False)):
            lo, hi = sorted(limits())
            if axis.get_scale() != "log" or lo <= 0 or np.log10(hi / lo) < min_decades:
                continue
            major = np.asarray(axis.get_majorticklocs(), float)
            pos = [p for p in axis.get_minor_locator().tick_values(lo, hi)
                   if lo <= p <= hi and not np.any(np.isclose(major, p, rtol=1e-9, atol=0))]
            todo.append((ax, axis, pos, vertical))
    for ax, axis, pos, vertical in todo:
        axis.set_minor_locator(NullLocator())
        if type(axis.get_major_formatter()) is LogFormatterSciNotation:  # matplotlib's default, not one set
            axis.set_major_formatter(FuncFormatter(decade_label))
        segments = [[(p, 0), (p, 1)] if vertical else [(0, p), (1, p)] for p in pos]
        transform = ax.get_xaxis_transform(which="grid") if vertical else ax.get_yaxis_transform(which="grid")
        style = {key: mpl.rcParams[f"grid.minor.{key}"] or mpl.rcParams[f"grid.{key}"]  # unset: the grid's
                 for key in ("color", "linestyle", "linewidth")}
        ax.add_collection(LineCollection(segments, transform=transform, colors=style["color"],
                                         linestyles=style["linestyle"], linewidths=style["linewidth"], alpha=alpha,
                                         zorder=axis.get_zorder()), autolim=False)
    return fig


def mark_band(axes: Sequence[Any], band: LearningBand | None, ts: float) -> None:
    """Mark the learning band: a dashed line at its corner and the frequencies above it shaded
    (where the band's filter F removes the learning). Nothing without a band.

    Parameters
    ----------
    axes : sequence of matplotlib.axes.Axes
        Axes against frequency, rad/s.
    band : LearningBand or None
        The design's learning band.
    ts : float
        Sample time, s.
    """
    if band is None or band.cutoff is None:
        return
    for ax in axes:
        ax.axvspan(band.cutoff, np.pi / ts, color=_BAND_COLOR, zorder=0, lw=0, label="_band")
        ax.axvline(band.cutoff, color="0.35", ls="--", lw=1.0, label="_band")


def with_gain_error(loop: LoopSystem, gain: float) -> LoopSystem:
    """The loop of ``loop``'s system whose true plant is its model times ``gain`` (same C, Q, M).

    Parameters
    ----------
    loop : LoopSystem
        A system's loop.
    gain : float
        True plant over model, > 0.

    Returns
    -------
    LoopSystem
    """
    if not (np.isfinite(gain) and gain > 0):
        raise SpecError(f"`gain`: got {gain!r}, expected a plant gain ratio > 0")
    model = loop.spec.nominal_plant
    true = PlantSpec(tuple(np.asarray(model.num) * gain), model.den, model.delay)
    return build_loop(replace(loop.spec, plant=true, model=model), loop.ts)


def _responses(loop: LoopSystem, w: np.ndarray) -> dict[str, np.ndarray]:
    """Responses of the blocks P, C, Q, M of ``loop`` from their delta forms (accurate near z = 1)."""
    out = {}
    for key in ("P", "C", "Q", "M"):
        blk = loop.blocks.get(key) if loop.blocks else None
        out[key] = blk.response(w) if blk is not None else freqresp(getattr(loop, key), w)
    return out


def loop_maps(loop: LoopSystem, w: np.ndarray) -> dict[str, np.ndarray]:
    """``G_d``, ``G_f`` and ``Omega`` of a loop from its blocks' responses (paper Sec. II).

    ``D = 1 - Q + P (M + C)``, ``G_d = P (1 - Q) / D``, ``G_f = -P / D``, ``Omega = (M + Q C) P / D``,
    each block evaluated from its delta form (:meth:`ilcdob.discretize.DiscreteBlock.response`):
    the closed loop's state-space response loses digits at low frequency, where ``z - A`` is
    nearly singular.

    Parameters
    ----------
    loop : LoopSystem
    w : numpy.ndarray
        Frequencies, rad/s.

    Returns
    -------
    dict of str to numpy.ndarray
        ``"G_d"``, ``"G_f"``, ``"Omega"`` and the blocks ``"P"``, ``"C"``, ``"Q"``, ``"M"``.
    """
    b = _responses(loop, w)
    d = 1 - b["Q"] + b["P"] * (b["M"] + b["C"])
    return {**b, "G_d": b["P"] * (1 - b["Q"]) / d, "G_f": -b["P"] / d, "Omega": (b["M"] + b["Q"] * b["C"]) * b["P"] / d}


def te_loops(fleet: Fleet, source: str, target: str) -> tuple[LoopSystem | None, LoopSystem | None, str]:
    """The true loops ``Te1`` and ``Te2`` are drawn for, and how they were chosen.

    The fleet's true plants when it states one besides the model for either vehicle (Te is
    then what learning leaves on these vehicles); otherwise, since with exact models Te1 =
    Te2 = 0 (Case I), every true plant :data:`TE_GAIN_ERROR` stronger than its model. When
    that stronger plant makes a loop unstable there is no Te to draw: the loops are None and
    the text says why.

    Parameters
    ----------
    fleet : Fleet
    source, target : str
        Systems j-1 and j.

    Returns
    -------
    tuple of (LoopSystem or None, LoopSystem or None, str)
        True loops of ``source`` and ``target``, and a short description of them for titles (or, without
        loops, the reason).
    """
    src, tgt = fleet.loop(source), fleet.loop(target)
    if src.spec.model is not None or tgt.spec.model is not None:
        return src, tgt, "the fleet's true plants"
    gain = 1 + TE_GAIN_ERROR
    pct = f"{100 * TE_GAIN_ERROR:.0f} %"
    loops = []
    for loop in (src, tgt):
        try:
            loops.append(with_gain_error(loop, gain))
        except UnstableLoopError:
            return None, None, f"a plant {pct} stronger than its model makes the loop of {loop.name} unstable"
    return loops[0], loops[1], f"true plants {pct} stronger than models"


def _describe(source: str, target: str, method: str, te_basis: str | None, band: LearningBand | None,
              ts: float) -> str:
    lines = [f"{source} -> {target}: {target} learns from {source}",
             "the Theorem's closed-form filters (paper Sec. III):",
             "  d_f,j = L1{e_j-1} + L2{d_f,j-1}",
             "  L1 = -(1 - Q_j) Gd_j-1^-1,  L2 = L1 Gf_j-1",
             "  Te1 = Gd_j Gd_j-1^-1 - Gf_j L1,  Te2 = Te1 Gf_j-1",
             f"Te1, Te2 with {te_basis}" if te_basis else "Te1, Te2 not drawn (see their panels)",
             "Omega = (M + Q C) P / D: disturbance -> DOB estimate"]
    if method != ClosedForm.name:
        lines.append(f"design method {method}: its own learning is in filters.json")
    if band is None or band.cutoff is None:
        lines.append("learning band: off (the filters act at every frequency)")
    else:
        lines.append(f"learning band: corner {band.cutoff:.4g} rad/s ({band.source});")
        lines.append("  shaded above it, where F removes the learning")
    lines.append(f"sample time {ts:g} s, Nyquist {np.pi / ts:.4g} rad/s")
    return "\n".join(lines)


def pair_bode_figure(fleet: Fleet, source: str, target: str, band: LearningBand | None = None,
                     method: str = "closed-form", filters: LearningFilters | None = None) -> Figure:
    """Bode figure of a pair (``bode.png`` of ``ilcdob design``): L1, L2, Te1, Te2 and Omega.

    Top row: magnitude (dB) and phase (degrees, wrapped to (-180, 180]) of ``L1`` and ``L2``
    and a panel stating what is drawn; bottom row: ``Te1`` and ``Te2`` with the true loops of
    :func:`te_loops`, and ``Omega`` of both vehicles (one line, naming both, when they coincide).
    Frequencies from 0.01 rad/s to Nyquist; the learning band is marked (:func:`mark_band`).
    Each axes carries a label (``"L1 magnitude"``, ``"L1 phase"``, ...).

    Parameters
    ----------
    fleet : Fleet
    source, target : str
        Systems j-1 (learned from) and j (learning).
    band : LearningBand, optional
        The design's learning band (None: not marked).
    method : str
        The design method, stated in the figure (the filters drawn are the Theorem's).
    filters : LearningFilters, optional
        The closed-form filters of the pair (default: :func:`~ilcdob.design.maps.closed_form.closed_form_filters`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    if {source, target} & set(fleet.own_controller):
        return channel_pair_bode_figure(fleet, source, target, band)
    ts = fleet.sample_time
    w = frequency_grid(ts)
    pair = f"{source} -> {target}"
    lf, missing = filters, None
    if lf is None:
        try:
            lf = closed_form_filters(fleet.loop(source), fleet.loop(target))
        except (NumericalError, SpecError) as exc:  # another method's design may not need them: said in the figure
            missing = f"the closed-form filters cannot be made: {exc}"
    src_true, tgt_true, basis = te_loops(fleet, source, target)
    l1 = [] if lf is None else [BodeCurve(pair, lf.l1_response(w), _COLORS[0])]
    l2 = [] if lf is None else [BodeCurve(pair, lf.l2_response(w), _COLORS[0])]
    te1 = te2 = []
    if lf is not None and src_true is not None:
        r1, r2 = lf.te_responses(w, src_true, tgt_true)
        te1, te2 = [BodeCurve(pair, r1, _COLORS[2])], [BodeCurve(pair, r2, _COLORS[2])]
    te_missing = missing or (None if src_true is not None else basis)
    on = f" ({basis})" if src_true is not None else ""
    panels = [("L1", f"L1 {pair} (on e_j-1, (m/s^2)/m)", l1, missing),
              ("L2", f"L2 {pair} (on d_f,j-1)", l2, missing),
              ("Te1", f"Te1 {pair}{on}", te1, te_missing),
              ("Te2", f"Te2 {pair}{on}", te2, te_missing),
              ("Omega", "Omega: disturbance -> DOB estimate",
               [BodeCurve(name, loop_maps(fleet.loop(name), w)["Omega"], _COLORS[k + 3])
                for k, name in enumerate(dict.fromkeys([source, target]))], None)]
    fig = Figure(figsize=(15, 10.5), layout="constrained")
    grid = fig.add_gridspec(4, 3)
    slots = {"L1": (0, 0), "L2": (0, 1), "Te1": (2, 0), "Te2": (2, 1), "Omega": (2, 2)}
    _draw_panels(fig, grid, slots, panels, w, band, ts, legend="Omega")
    _describe_in(fig, grid[0:2, 2], _describe(source, target, method, basis if src_true is not None else None,
                                               band, ts))
    fig.suptitle(f"Learning design {pair}: Bode plots of L1, L2, Te1, Te2 and Omega")
    return minor_log_grid(fig)


def _draw_panels(fig: Figure, grid: Any, slots: dict[str, tuple[int, int]], panels: Sequence[tuple], w: np.ndarray,
                 band: LearningBand | None, ts: float, legend: str) -> None:
    """One magnitude/phase pair of axes per panel ``(key, title, curves, why not drawn)`` at ``slots[key]``."""
    first = None
    for key, title, curves, why in panels:
        row, col = slots[key]
        mag = fig.add_subplot(grid[row, col], sharex=first)
        first = first or mag
        phase = fig.add_subplot(grid[row + 1, col], sharex=first)
        mag.set_label(f"{key} magnitude")
        phase.set_label(f"{key} phase")
        draw_bode(mag, phase, w, curves)
        if why is not None:
            mag.text(0.5, 0.5, textwrap.fill(f"not drawn: {why}", 50), ha="center", va="center", fontsize=8,
                     transform=mag.transAxes)
            mag.set_xscale("log")
            mag.set_xlim(w[0], w[-1])
        mark_band([mag, phase], band, ts)
        finish_bode_axes(mag, phase, title, ts, legend=key == legend)
        mag.tick_params(labelbottom=False)


def _describe_in(fig: Figure, slot: Any, text: str) -> None:
    """The figure's description panel: ``text`` in monospace, top left of ``slot``."""
    ax = fig.add_subplot(slot)
    ax.set_label("description")
    ax.axis("off")
    ax.text(0.0, 1.0, text, va="top", ha="left", fontsize=9, family="monospace", transform=ax.transAxes)


def channel_pair_bode_figure(fleet: Fleet, source: str, target: str, band: LearningBand | None = None) -> Figure:
    """Bode figure of a pair with a vehicle on its own controller (``bode.png`` of ``ilcdob design``): L1, L2 and
    both vehicles' ``Gd`` (:mod:`ilcdob.design.maps.channel_filters`).

    Parameters
    ----------
    fleet : Fleet
    source, target : str
        Systems j-1 (learned from) and j (learning); at least one a ``channel`` system.
    band : LearningBand, optional
        The design's learning band (None: not marked).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    SpecError
        A pair the channel design refuses (:func:`~ilcdob.design.maps.channel_filters.channel_filters`).
    """
    ts = fleet.sample_time
    w = frequency_grid(ts)
    pair = f"{source} -> {target}"
    src, tgt = fleet.loop(source), fleet.loop(target)
    lf = channel_filters(src, tgt)
    units = {name: CHANNEL_UNITS[learning_channel(fleet.loop(name))] for name in (source, target)}
    gd = [BodeCurve(name, 1.0 / channel_view(fleet.loop(name)).inverse(w), _COLORS[k + 3])
          for k, name in enumerate(dict.fromkeys([source, target]))]
    panels = [("L1", f"L1 {pair} (on e_j-1, {units[target]}/m)", [BodeCurve(pair, lf.l1_response(w), _COLORS[0])],
               None),
              ("L2", f"L2 {pair} (on u_j-1, {units[target]}/{units[source]})",
               [BodeCurve(pair, lf.l2_response(w), _COLORS[0])], None),
              ("Gd", "Gd: disturbance (m/s^2) -> position (m)", gd, None)]
    fig = Figure(figsize=(12, 9), layout="constrained")
    grid = fig.add_gridspec(4, 2)
    _draw_panels(fig, grid, {"L1": (0, 0), "L2": (0, 1), "Gd": (2, 0)}, panels, w, band, ts, legend="Gd")
    kinds = {name: (f"own controller, {learning_channel(fleet.loop(name))} channel"
                    if isinstance(fleet.loop(name), ChannelLoop) else "ilcdob's PID + DOB")
             for name in (source, target)}
    lines = [f"{source} -> {target}: {target} learns from {source}",
             *(f"  {name}: {kind}" for name, kind in kinds.items()),
             "the paper's filters on the identified maps:",
             "  u_j = L1{e_j-1} + L2{u_j-1}",
             "  L1 = R_j Gd_j-1^-1,  L2 = R_j / R_j-1",
             "  R = Gd/Gf = (1 - Q)/K  (1/K without a DOB)",
             "learning band: off" if band is None or band.cutoff is None else
             f"learning band: corner {band.cutoff:.4g} rad/s ({band.source})",
             f"sample time {ts:g} s, Nyquist {np.pi / ts:.4g} rad/s"]
    _describe_in(fig, grid[2:4, 1], "\n".join(lines))
    fig.suptitle(f"Learning design {pair}: Bode plots of L1, L2 and Gd")
    return minor_log_grid(fig)
