"""One learning design for a pair of systems (j-1 -> j), by method, and its outputs.

This is the API behind ``ilcdob design``: it builds the design, the ``filters.json``
content (discrete filters applied to the previous system's error and learning signal:
second-order sections or FIR taps with a non-causal ``advance``, see :mod:`.filters.coefficients`; the C
code of :mod:`.export.c_export` runs them), the norm-optimal law's gains (and, when asked, its
lifted matrices), and the learning signal for a given trial of the previous system.

Every design learns through the chain of stages of :mod:`.law` (docs/theory.md section 6),
built from its ``filters.json`` with the method's filter as designed in memory
(:meth:`PairDesign.learning_law`); ``ilcdob learn`` and the C code run the same chain from the
file alone, the whole-trial check its linear map.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cache, partial
from typing import Any, Callable

import numpy as np
from scipy import signal as sps

from ilcdob.channel_loop import CHANNEL_UNITS, ChannelLoop
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet
from ilcdob.display import html_table
from ilcdob.loop import LoopSystem
from ilcdob.signals import as_signal
from ilcdob.specs import LimitSpec

from .filters.band import LearningBand, check_bandwidth, choose_band
from .maps.channel_filters import channel_filters, channel_gf, channel_view, learning_channel
from .maps.closed_form import LearningFilters, closed_form_filters, simulate_map
from .maps.finite_horizon import finite_horizon_ratio
from .law import LawContext, LearningLaw, Stage
from .law.designed import Designed
from .law.limit import Limit
from .sets.delta import DeltaSet, channel_delta_set, delta_bound, delta_set
from .maps.flown import check_disturbance, disturbance_path
from .law.laws import DEFAULT_LAW, LAW_DESCRIPTIONS, ExactReference, ReferenceTerms, check_law, reference_terms
from .law.limit import LIMIT_POLICIES, LimitReport
from .methods import METHODS, DesignInputs, Method, method_named
from .methods.robust import RobustPairDesigner
from .checks.channel import channel_worst
from .checks.theorem import exact_worst_on_set, theorem_rhs

__all__ = ["PairDesign", "LearningSignal", "design_pair", "design_channel_pair", "pair_band", "with_law",
           "fleet_delta_sets", "design_with_band"]


Learn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class LearningSignal:
    """The learning signal of one trial and how it was made.

    Attributes
    ----------
    d_f : numpy.ndarray, m/s^2
        The learning signal to feed forward on the learning vehicle's next flight.
    band : LearningBand
        The learning band it was computed with.
    limit : LimitReport or None
        Its check against the learning vehicle's acceleration limit (None: no limit stated).
    """

    d_f: np.ndarray
    band: LearningBand
    limit: LimitReport | None = None

    def __repr__(self) -> str:
        peak = float(np.max(np.abs(self.d_f))) if self.d_f.size else 0.0
        clipped = "" if self.limit is None or not self.limit.beyond else (
            f"; {self.limit.beyond} samples beyond the limit {self.limit.limit:g} m/s^2"
            + (" (clipped)" if self.limit.clipped else ""))
        return (f"<LearningSignal {self.d_f.size} samples, peak {peak:.4g} m/s^2; band {self.band.describe()[:60]}"
                f"{clipped}>")


@dataclass(frozen=True)
class PairDesign:
    """A learning design for system ``target`` learning from ``source``.

    Attributes
    ----------
    method : str
        Design method (one of :data:`METHODS`).
    filters : dict
        ``filters.json`` content.
    core : Stage or callable
        The method's learning filter as designed (:class:`~.law.designed.Designed`), the stage
        of the law that the file holds as coefficients; a function ``learn(e, d_f)`` is wrapped
        into one.
    lifted : dict of str -> array, or None
        Norm-optimal: its learning law in compact form (the gains of
        :meth:`~ilcdob.design.methods.norm_optimal.NormOptimalLaw.to_arrays`, O(N)), and the N x N
        matrices ``L1``, ``L2`` when asked for (``lifted=True``).
    robust : RobustPairDesigner or None
        For the robust method: the per-trial SOCP (its ``design`` gives ratios per model).
    law : str
        Learning law (:mod:`ilcdob.design.law.laws`): ``"paper"`` or ``"exact-reference"``.
    reference : ReferenceTerms or None
        ``exact-reference``: the pair's reference terms, applied by :meth:`learning`.
    band : LearningBand or None
        The learning band fixed at design time (what ``filters.json`` and the C code carry):
        stated, chosen from the fleet by :func:`design_pair`, or from one trial by
        :func:`design_with_band`.
    choose : callable or None
        With ``bandwidth="auto"``: ``choose(error=e)`` chooses the band of each trial from its
        error (:func:`~ilcdob.design.filters.band.choose_band` with the fleet's inputs bound).
    path : numpy.ndarray or None
        Sections of the airframe correction W (disturbance on the airframe; the band's choice).
    limits : LimitSpec or None
        The learning vehicle's acceleration limit.
    on_limit : str
        ``"clip"`` or ``"refuse"`` a learning signal beyond the limit.
    source_gf : control.StateSpace or None
        ``Gf_hat_{j-1}`` of the source's model (the band's choice, :meth:`band_for`).
    loops : tuple of LoopSystem or None
        The models' loops of source and target (the whole-trial check's default plants).
    """

    method: str
    filters: dict[str, Any]
    core: Stage
    lifted: dict[str, np.ndarray] | None = field(default=None)
    robust: RobustPairDesigner | None = field(default=None, repr=False)
    law: str = DEFAULT_LAW
    reference: ReferenceTerms | None = field(default=None, repr=False)
    band: LearningBand | None = None
    choose: Callable[..., LearningBand] | None = field(default=None, repr=False)
    path: np.ndarray | None = field(default=None, repr=False)
    limits: LimitSpec | None = None
    on_limit: str = "clip"
    source_gf: Any = field(default=None, repr=False)
    loops: tuple[LoopSystem, LoopSystem] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.core, Stage):
            if not callable(self.core):
                raise SpecError(f"`core`: got {type(self.core).__name__}, expected a law stage or a learning "
                                "function learn(e, d_f)")
            object.__setattr__(self, "core", Designed(self.method, self.core))

    def __repr__(self) -> str:
        pair = f"{self.filters.get('from', '?')} -> {self.filters.get('to', '?')}"
        band = self.band.describe() if self.band is not None else "chosen per trial"
        return f"<PairDesign {self.method} {pair}, law {self.law}, band {band}: {self.order}>"

    def _repr_html_(self) -> str:
        rows = [[k, v] for k, v in self.filters.items() if isinstance(v, (str, int, float, bool))]
        return html_table(f"{self.method} design {self.filters.get('from', '?')} -> {self.filters.get('to', '?')}",
                          ["", "value"], [*rows, ["order", self.order]])

    @property
    def order(self) -> str:
        """Implementation size: filter orders (zpk/FIR), Riccati gains (and lifted matrix size), or SOCP models."""
        return METHODS[self.method].order(self.filters, self.lifted)

    def band_for(self, e_prev: object, df_prev: object | None = None) -> LearningBand:
        """The learning band for a trial of the source (its law-adjusted error ``e_prev``, m, and
        the learning signal it flew, ``df_prev``, m/s^2).

        ``bandwidth="auto"``: chosen from the error the source would have had without learning,
        ``e' = e + Gf_hat_{j-1}{d_f,{j-1}}`` (its spectrum carries the whole disturbance, even
        when learning has already removed most of it from ``e``), and the fleet
        (:mod:`.filters.band`); otherwise the band fixed at design time.

        Parameters
        ----------
        e_prev : array, m
            The source's (law-adjusted) measured tracking error.
        df_prev : array, m/s^2, optional
            The learning signal it flew.

        Returns
        -------
        LearningBand
        """
        if self.choose is None:
            if self.band is None:  # a design built without one: the method's filter as it is
                return LearningBand(float(self.filters.get("sample_time", 1.0)), None, source="off",
                                    reason="no band given")
            return self.band
        e = as_signal(e_prev, "e_prev")
        if df_prev is not None and self.source_gf is not None and np.any(df_prev):
            e = e + simulate_map(self.source_gf, as_signal(df_prev, "df_prev", e.size))
        return self.choose(error=e)

    def learning_law(self, band: LearningBand | None = None, gain: float = 1.0, learn: Learn | None = None
                     ) -> LearningLaw:
        """The design's learning law: the stages of ``filters.json`` with the method's filter in memory.

        Parameters
        ----------
        band : LearningBand, optional
            The band to learn with (default: the band fixed at design time).
        gain : float
            Learning gain ``gamma`` in (0, 1] on the new error (1: the Theorem's law).
        learn : callable, optional
            ``learn(e, d_f)`` in place of the method's filter (e.g. one that records the robust
            SOCP's result for the caller).

        Returns
        -------
        LearningLaw
        """
        core = self.core if learn is None else Designed(self.method, learn)
        what = f"learning signal of {self.filters.get('to', '?')} from {self.filters.get('from', '?')}"
        return LearningLaw.from_dict(self.filters, LawContext(
            core=core, band=band if band is not None else self.band, reference=self.reference, gain=gain,
            limits=self.limits, on_limit=self.on_limit if self.limits is not None else "off", what=what))

    def learning(self, e_prev: object, df_prev: object, gain: float = 1.0, learn: Learn | None = None
                 ) -> LearningSignal:
        """The learning signal of the target from one trial of the source (:meth:`learning_law` on the
        trial's band).

        Parameters
        ----------
        e_prev : array, m
            The source's measured tracking error over the trial.
        df_prev : array, m/s^2
            The learning signal the source flew (zeros if none).
        gain : float
            Learning gain ``gamma`` in (0, 1] on the new error (1: the Theorem's law).
        learn : callable, optional
            ``learn(e, d_f)`` in place of the method's filter.

        Returns
        -------
        LearningSignal

        Raises
        ------
        LearningLimitError
            ``on_limit="refuse"`` and the signal exceeds the limit.
        """
        e = as_signal(e_prev, "e_prev")
        df = as_signal(df_prev, "df_prev", e.size)
        band = self.band_for(e if self.reference is None else self.reference.error_in(e), df)
        notes: dict[str, Any] = {}
        d_f = self.learning_law(band, gain, learn).run((e, df), notes)
        return LearningSignal(d_f, band, notes.get("limit"))

    def finite_trial(self, n: int, source: LoopSystem | None = None, target: LoopSystem | None = None) -> Any:
        """The whole-trial figure ``rho_N = max_d ||e_j|| / ||e'_j||`` of this law over ``n`` samples.

        The linear map of :meth:`learning_law` over ``n`` samples (:mod:`.maps.finite_horizon`): the
        fixed band (:attr:`band`), no limit, one trial of the source flown without learning.

        Parameters
        ----------
        n : int
            Samples of the trial.
        source, target : LoopSystem, optional
            True loops of the two vehicles (default: their models, exact models).

        Returns
        -------
        FiniteHorizonRatio

        Raises
        ------
        SpecError
            The law is not the paper's, or the method's filter has no linear map (the robust SOCP).
        """
        if self.law != DEFAULT_LAW:
            raise SpecError(f"`finite_trial`: law {self.law!r}; only the paper's law is linear in the error alone")
        src, tgt = self.loops if self.loops is not None else (None, None)
        if (source or src) is None or (target or tgt) is None:
            raise SpecError("`finite_trial`: give the source and target loops (a design made without them)")
        return finite_horizon_ratio(self.learning_law().error_map(n), source or src, target or tgt)

    def learn(self, e_prev: object, df_prev: object) -> np.ndarray:
        """The learning signal only (``learning(e_prev, df_prev).d_f``), m/s^2.

        Parameters
        ----------
        e_prev : array, m
            The source's measured tracking error.
        df_prev : array, m/s^2
            The learning signal the source flew (zeros if none).
        """
        return self.learning(e_prev, df_prev).d_f


def fleet_delta_sets(fleet: Fleet, names: list[str], k: int = 8, bound: float | None = None,
                     scale: float = 1.0, seed: int = 0) -> dict[str, DeltaSet]:
    """Delta sets of the named systems: from each identification (scaled), or a common ``bound``.

    Parameters
    ----------
    fleet : Fleet
        The fleet.
    names : list of str
        Systems to draw Delta sets for, in this order (one generator serves them all).
    k : int
        Sampled true plants per system.
    bound : float, optional
        A common multiplicative bound for every system (default: each system's own stated
        bound or identification, see :func:`~ilcdob.design.sets.delta.delta_set`).
    scale : float
        Multiplier of the identified standard deviations.
    seed : int
        Seed of the random generator.

    Returns
    -------
    dict of str to DeltaSet
        Name -> Delta set.

    Notes
    -----
    A system on its own controller gets its sampled channel maps
    (:func:`~ilcdob.design.sets.delta.channel_delta_set`).
    """
    rng = np.random.default_rng(seed)
    own = set(fleet.own_controller)
    return {name: channel_delta_set(fleet.loop(name), k, rng, scale=scale, bound=bound) if name in own else
            delta_set(next(s for s in fleet.systems if s.name == name), fleet.sample_time, k, rng, scale=scale,
                      bound=bound) for name in names}


def _sos_gain(sos: np.ndarray | None, w: np.ndarray, ts: float) -> np.ndarray:
    if sos is None:
        return np.ones_like(w)
    return np.abs(sps.sosfreqz(sos, worN=w * ts)[1])


def _band_inputs(fleet: Fleet, src: LoopSystem, tgt: LoopSystem, path: np.ndarray | None,
                 deltas: dict[str, DeltaSet] | None, closed_form: Callable[[], LearningFilters],
                 model_edge: bool = True) -> dict[str, Any]:
    """What the band's choice knows from the fleet (:func:`~ilcdob.design.filters.band.choose_band` keywords);
    without ``model_edge`` the Delta set is left out (designs that are robust to it themselves)."""
    specs = {s.name: s for s in fleet.systems}
    s_spec, t_spec = specs[src.name], specs[tgt.name]
    if not model_edge:
        found = None
    elif deltas is not None and src.name in deltas:
        found = (deltas[src.name].w, deltas[src.name].bound)
    else:
        b = delta_bound(s_spec, fleet.sample_time)
        found = None if b is None else b[:2]
    trust = exact = None
    if found is not None:
        w = np.asarray(found[0], float)
        trust = (w, np.asarray(found[1], float) / theorem_rhs(src, w))
        exact = exact_worst_on_set(src, w, found[1])
    return {"noise_std": s_spec.sensor.noise_std if s_spec.sensor is not None else None,
            "a_max": t_spec.limits.max_acceleration if t_spec.limits is not None else None,
            "l1_gain": lambda w: np.abs(closed_form().l1_response(w)) * _sos_gain(path, w, fleet.sample_time),
            "trust": trust, "exact": exact}


def _band_chooser(fleet: Fleet, src: LoopSystem, tgt: LoopSystem, request: object, path: np.ndarray | None,
                  deltas: dict[str, DeltaSet] | None, closed_form: Callable[[], LearningFilters],
                  model_edge: bool = True) -> Callable[..., LearningBand]:
    """``choose(error=...)``: :func:`~ilcdob.design.filters.band.choose_band` with the fleet's inputs bound."""
    return partial(choose_band, fleet.sample_time, request,
                   **_band_inputs(fleet, src, tgt, path, deltas, closed_form, model_edge))


def pair_band(fleet: Fleet, source: str, target: str, bandwidth: object = "auto", *, error: object | None = None,
              deltas: dict[str, DeltaSet] | None = None, disturbance: str = "command") -> LearningBand:
    """The learning band of a pair without designing it (what :func:`design_pair` would fix).

    Parameters
    ----------
    fleet : Fleet
    source, target : str
        Systems j-1 and j.
    bandwidth : "auto", float or None
        As in :func:`design_pair`.
    error : array, m, optional
        The error of the trial learned from (``"auto"``: chooses from it).
    deltas : dict name -> DeltaSet, optional
        Delta set of the source (default: its identification or stated bound).
    disturbance : {"command", "airframe", "wind"}
        Where the disturbance acts (the airframe correction enters the noise budget).

    Returns
    -------
    LearningBand
    """
    check_disturbance(disturbance)
    src, tgt = fleet.loop(source), fleet.loop(target)
    path, _ = disturbance_path(src, tgt, disturbance)
    request = check_bandwidth(bandwidth, fleet.sample_time)
    return _band_chooser(fleet, src, tgt, request, path, deltas, cache(partial(closed_form_filters, src, tgt)))(
        error=error)


def design_pair(fleet: Fleet, source: str, target: str, method: str | Method = "closed-form", *,
                law: str | ExactReference = DEFAULT_LAW, band: object = "auto", disturbance: str = "command",
                on_limit: str = "clip") -> PairDesign:
    """Design the learning filters of ``target`` from ``source`` with ``method``.

    Parameters
    ----------
    fleet : Fleet
    source, target : str
        System names (j-1 and j).
    method : str or Method
        A name of :data:`~.methods.METHODS` (``"closed-form"``, ``"fir"``, ``"norm-optimal"``,
        ``"robust"``, ``"robust-set"``) with its default options, or a method object carrying its
        own (``FIR(options=FIROptions(...), deltas=...)``, ``NormOptimal(n=3000)``,
        ``RobustSet(RobustSetOptions(rho=0.8))``, :mod:`.methods`). Its ``deltas`` are the Delta
        sets the design is made for: the source's bound sets the band's ``model`` edge, and methods
        that design over Delta sets use them (without: :func:`fleet_delta_sets`, K = 8, from the
        identifications).
    law : {"paper", "exact-reference"} or ExactReference
        Learning law (:mod:`ilcdob.design.law.laws`). The exact-reference law needs the trial's
        reference: give :class:`~.law.laws.ExactReference` (``law_for(name, reference,
        acceleration)``); it adds the reference terms around the method's learning.
        ``multi-source`` learns from several trials and is refused here.
    band : "auto", float or None
        The learning band's corner (:mod:`.filters.band`): ``"auto"`` (default) chooses it per trial
        from the trial's error and the fleet (sensor noise, the target's acceleration limit, the
        source's Delta set); a number states it (rad/s); ``None`` or ``"off"``: the method's
        filter as it is. For the designs of :data:`~.methods.GUARANTEED` the automatic band leaves out
        the model edge: they are robust to the Delta set by construction, and a band closed on
        it only takes learning away (and, on whole trials, some of their guarantee).
    disturbance : {"command", "airframe", "wind"}
        Where the disturbance acts (:mod:`.maps.flown`): at the command, as in the paper's loop, on
        the airframe (adds the correction W; models with a rigid body to split off), or as a
        wind velocity through each airframe's drag (W times the ratio of the drag poles; models
        with one integrator and a drag pole).
    on_limit : {"clip", "refuse"}
        A learning signal beyond the target's acceleration limit (fleet ``limits``) is clipped
        with a warning, or refused.

    Raises
    ------
    SpecError
        Unknown method, law, disturbance path or limit policy; ``multi-source``;
        ``exact-reference`` without its reference; a bad band.
    """
    if isinstance(law, ExactReference) or check_law(law) != DEFAULT_LAW:
        name, reference, acceleration = ((law.name, law.reference, law.acceleration) if isinstance(law, ExactReference)
                                         else (law, None, None))
        _check_law_request(fleet, source, target, name, reference)  # before the design, which may take long
        design = design_pair(fleet, source, target, method, band=band, disturbance=disturbance, on_limit=on_limit)
        return with_law(design, fleet, source, target, name, reference, acceleration)
    if any(isinstance(fleet.loop(n), ChannelLoop) for n in (source, target)):
        return _fleet_channel_pair(fleet, source, target, method, band=band, disturbance=disturbance,
                                   on_limit=on_limit)
    chosen = method_named(method)
    check_disturbance(disturbance)
    if on_limit not in LIMIT_POLICIES:
        raise SpecError(f"`on_limit`: got {on_limit!r}, expected one of {list(LIMIT_POLICIES)}")
    request = check_bandwidth(band, fleet.sample_time)
    src, tgt = fleet.loop(source), fleet.loop(target)
    path, path_entry = disturbance_path(src, tgt, disturbance)
    closed_form = cache(partial(closed_form_filters, src, tgt))  # built once, when first needed
    head = {"method": chosen.name, "law": DEFAULT_LAW, "from": source, "to": target,
            "sample_time": fleet.sample_time}
    deltas = chosen.deltas
    if chosen.needs_delta_sets and deltas is None:
        deltas = fleet_delta_sets(fleet, [source, target])
    made = chosen.design(DesignInputs(fleet, src, tgt, head, closed_form, deltas=deltas))
    design = PairDesign(chosen.name, made.filters, made.core, made.lifted, robust=made.robust, loops=(src, tgt))
    chooser = _band_chooser(fleet, src, tgt, request, path, deltas, closed_form, model_edge=not chosen.guaranteed)
    limits = {s.name: s for s in fleet.systems}[target].limits
    filters = {**design.filters, "disturbance": path_entry}
    if limits is not None:
        filters["limit"] = Limit.entry(limits, on_limit)
    design = replace(design, filters=filters, choose=chooser if request == "auto" else None, path=path,
                     limits=limits, on_limit=on_limit, source_gf=src.nominal.G_f)
    return design_with_band(design, chooser(error=None))


def _fleet_channel_pair(fleet: Fleet, source: str, target: str, method: str | Method, *,
                        band: object, disturbance: str, on_limit: str) -> PairDesign:
    """:func:`design_pair` with the paper's law for a pair with a vehicle on its own controller:
    :func:`design_channel_pair` with the target's limit (its Limit stage on the acceleration channel; in the
    band's noise budget on every channel).

    Raises
    ------
    SpecError
        A method not of :data:`CHANNEL_METHODS` (:func:`design_channel_pair`), a bad limit policy.
    """
    chosen = _channel_method(method)
    if on_limit not in LIMIT_POLICIES:
        raise SpecError(f"`on_limit`: got {on_limit!r}, expected one of {list(LIMIT_POLICIES)}")
    limits = {s.name: s for s in fleet.systems}[target].limits
    tgt = fleet.loop(target)
    deltas = chosen.deltas
    if chosen.needs_delta_sets and deltas is None:
        deltas = fleet_delta_sets(fleet, [source, target])
    design = design_channel_pair(fleet.loop(source), tgt, method=chosen, deltas=deltas, band=band,
                                 disturbance=disturbance,
                                 acceleration_limit=None if limits is None else limits.max_acceleration)
    if limits is None or learning_channel(tgt) != "acceleration":
        return design
    design = replace(design, filters={**design.filters, "limit": Limit.entry(limits, on_limit)}, limits=limits,
                     on_limit=on_limit)
    return design_with_band(design, design.band)


#: The methods that design a pair with a vehicle on its own controller (:func:`design_channel_pair`).
CHANNEL_METHODS = ("closed-form", "robust", "robust-set")


def _channel_method(method: str | Method) -> Method:
    """``method`` if it designs for vehicles on their own controller (:data:`CHANNEL_METHODS`), else SpecError."""
    chosen = method_named(method)
    if chosen.name not in CHANNEL_METHODS:
        raise SpecError(f"`method`: got {chosen.name!r}, which designs for ilcdob's PID + DOB loop only; design a "
                        f"pair with a vehicle on its own controller with {' or '.join(map(repr, CHANNEL_METHODS))} "
                        "(on the identified channel maps and their uncertainty; docs/closed_loop.md)")
    return chosen


def design_channel_pair(source: ChannelLoop | LoopSystem, target: ChannelLoop | LoopSystem, *,
                        method: str | Method = "closed-form", deltas: dict[str, DeltaSet] | None = None,
                        band: object = "auto", acceleration_limit: float | None = None,
                        disturbance: str = "command") -> PairDesign:
    """The design between two vehicles learning through a setpoint channel (:mod:`.maps.channel_filters`).

    Either may be a vehicle on its own controller, with or without the add-on DOB, or ilcdob's PID + DOB
    loop learning on its acceleration feed-forward (a mixed fleet).

    The learning signal enters the target's channel (:attr:`ilcdob.channel_loop.ChannelLoop.channel`) in that
    channel's unit; the law is the paper's (the reference's share of the error is learned with the
    disturbance), through the learning band as every design (:mod:`.filters.band`).

    Parameters
    ----------
    source, target : ChannelLoop or LoopSystem
        Vehicles j-1 and j (a LoopSystem: its model's maps).
    method : {"closed-form", "robust", "robust-set"} or Method
        The Theorem's filters, the per-trial SOCP over both vehicles' sampled channel maps
        (:mod:`.methods.robust`) or the closed form with a robustness FIR over the source's disc
        (:mod:`.methods.channel_robust_set`); the last two between vehicles on their own controller.
    deltas : dict of str to DeltaSet, optional
        The robust methods' sets by vehicle (default: the method's own, else 8 maps per vehicle drawn from
        each fit, :func:`~.sets.delta.channel_delta_set`).
    band : "auto", float or None
        As :func:`design_pair`; ``"auto"`` chooses the corner per trial from the source's error and, with
        ``acceleration_limit``, the noise the filter passes (in the acceleration it makes the target command).
    acceleration_limit : float, optional
        What the target may be asked to command on top of its flight, m/s^2 (> 0).
    disturbance : {"command", "airframe", "wind"}
        Where the disturbance acts (:mod:`.maps.flown`): added to the command as the learning signal is (the
        paper's), an acceleration on the rigid body, or a wind velocity through each airframe's drag (the
        wind law); the last two through the airframe correction ``W`` of the vehicles' identified airframes
        (:attr:`~ilcdob.channel_loop.ChannelLoop.airframe`).

    Returns
    -------
    PairDesign

    Raises
    ------
    SpecError
        Not vehicles, other sample times, a target without a DOB after a source with one, a bad band, limit,
        method or disturbance; off the command, an airframe missing or without a rigid body to split off, or a
        drag too small to learn the wind from; a robust method with ilcdob's loop in the pair or a vehicle
        without an identification.
    """
    check_disturbance(disturbance)
    chosen = _channel_method(method)
    lf = channel_filters(source, target)
    request = check_bandwidth(band, source.ts)
    if acceleration_limit is not None and not (isinstance(acceleration_limit, (int, float))
                                               and np.isfinite(acceleration_limit) and acceleration_limit > 0):
        raise SpecError(f"`acceleration_limit`: got {acceleration_limit!r}, expected a limit > 0 m/s^2")
    ch_src, ch_tgt = learning_channel(source), learning_channel(target)
    head = {"method": chosen.name, "law": DEFAULT_LAW, "from": source.name, "to": target.name,
            "sample_time": source.ts, "channel": ch_tgt, "source_channel": ch_src}
    if chosen.needs_delta_sets:
        mixed = [lp.name for lp in (source, target) if not isinstance(lp, ChannelLoop)]
        if mixed:
            raise SpecError(f"`method`: {chosen.name!r} between a vehicle on its own controller and ilcdob's PID + "
                            f"DOB loop ({mixed}) is not built; design this pair with 'closed-form'")
        deltas = deltas or chosen.deltas
        if deltas is None:
            rng = np.random.default_rng(0)
            deltas = {lp.name: channel_delta_set(lp, 8, rng) for lp in (source, target)}
        missing = [lp.name for lp in (source, target) if lp.name not in deltas]
        if missing:
            raise SpecError(f"`deltas`: no sampled maps of {missing} for the {chosen.name} method (draw them with "
                            "ilcdob.design.sets.delta.channel_delta_set)")
    made = chosen.design(DesignInputs(None, source, target, head, lambda: lf, deltas=deltas))
    path, path_entry = disturbance_path(source, target, disturbance)
    per = {"m/s": "(m/s)", "m/s^2": "(m/s^2)"}
    unit = CHANNEL_UNITS[ch_tgt]
    units = ({"L1": f"{unit}/m", "L2": f"{unit}/{per.get(CHANNEL_UNITS[ch_src], 'm')}"} if "L1" in made.filters
             else {"learning": unit})
    filters = {**made.filters, "units": units, "disturbance": path_entry}
    k_j = channel_view(target).gain
    chooser = partial(choose_band, source.ts, request, a_max=acceleration_limit,
                      l1_gain=lambda w: np.abs(k_j(w) * lf.l1_response(w)) * _sos_gain(path, w, source.ts),
                      exact=_channel_exact(source, target, lf) if not chosen.needs_delta_sets else None)
    design = PairDesign(chosen.name, filters, made.core, robust=made.robust, source_gf=channel_gf(source), path=path,
                        choose=chooser if request == "auto" else None)
    return design_with_band(design, chooser(error=None))


def _channel_exact(source: ChannelLoop | LoopSystem, target: ChannelLoop | LoopSystem,
                   lf: LearningFilters) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]] | None:
    """The channel pair's exact worst case for the band's ``model`` edge (what ``check`` reports,
    :func:`~.checks.channel.channel_worst`); None where the source has no Delta set (no identification)."""
    try:
        w, _, _, _, worst = channel_worst(source, target, filters=lf)
    except SpecError:
        return None
    return w, worst


def design_with_band(design: PairDesign, band: LearningBand) -> PairDesign:
    """``design`` with its fixed band (and the ``band`` entry of ``filters.json``) set to ``band``.

    With ``bandwidth="auto"``, :func:`design_pair` fixes the band the fleet alone gives;
    ``design_with_band(design, design.band_for(e, d_f))`` fixes it to the band of one trial
    (what ``ilcdob design --trial`` writes into ``filters.json`` and the C code). Learning
    (:meth:`PairDesign.learning`) still chooses per trial.

    Parameters
    ----------
    design : PairDesign
    band : LearningBand

    Returns
    -------
    PairDesign
    """
    request = "auto" if design.choose is not None else band.cutoff
    return replace(design, band=band, filters={**design.filters, "band": {"request": request, **band.to_dict()}})


def _check_law_request(fleet: Fleet, source: str, target: str, law: str, reference: object) -> None:
    """Refuse a law a pair design cannot learn with: ``multi-source``, or ``exact-reference`` without its reference
    or, for a vehicle on its own controller, without its reference map (:attr:`ChannelLoop.G_r`)."""
    if law == "multi-source":
        raise SpecError("`law`: 'multi-source' learns from the trials of every earlier system at once, and a pair "
                        f"design ({source} -> {target}) learns from one trial of {source}; use "
                        "ilcdob.design.law.multi_source.multi_source_learning with every trial, or "
                        "reproduce(..., law='multi-source') for a learning chain")
    if reference is None:
        raise SpecError(f"`reference`: the exact-reference law needs the reference trajectory of the trial "
                        f"(m, sampled every {fleet.sample_time} s); got none")
    for lp in (fleet.loop(source), fleet.loop(target)):
        if isinstance(lp, ChannelLoop):
            lp.G_r  # noqa: B018 - raises where the reference map is not known


def with_law(design: PairDesign, fleet: Fleet, source: str, target: str, law: str,
             reference: np.ndarray | None = None, acceleration: np.ndarray | None = None) -> PairDesign:
    """``design`` (made for the paper's law) learning with ``law`` instead (see :func:`design_pair`).

    Parameters
    ----------
    design : PairDesign
        A design of ``source`` -> ``target`` with the paper's law.
    fleet : Fleet
    source, target : str
        Systems j-1 and j.
    law : {"exact-reference"}
        ``multi-source`` is refused (it needs every earlier trial); ``paper`` returns ``design``.
    reference, acceleration : array, optional
        Reference position (m) and acceleration (m/s^2) of the trial.

    Raises
    ------
    SpecError
        Unknown law, ``multi-source``, a design that already has a law other than the paper's,
        no ``reference``, or no ``acceleration`` for a pair with acceleration feed-forward.
    """
    if check_law(law) == DEFAULT_LAW:
        return design
    if design.law != DEFAULT_LAW:
        raise SpecError(f"`design`: already learns with law {design.law!r}; give a design made with the paper's law")
    _check_law_request(fleet, source, target, law, reference)
    src, tgt = fleet.loop(source), fleet.loop(target)
    terms = reference_terms(src, tgt, reference, acceleration)
    maps = {lp.name: lp.reference_source for lp in (src, tgt) if isinstance(lp, ChannelLoop)}
    filters = {**design.filters, "law": law,
               "reference_terms": {**terms.to_dict(),
                                   "rule": "d_f,j = learning{e_{j-1} - e_ref,{j-1}, d_f,{j-1}} + correction "
                                           f"(reference_terms.csv: e_ref_source in m, correction in {terms.unit})",
                                   **({"reference_maps": maps} if maps else {}),
                                   "law": LAW_DESCRIPTIONS[law]}}
    return replace(design, filters=filters, law=law, reference=terms)
