"""Design methods as registered objects: what each needs, owns and emits, and how it designs.

A method turns a pair of loops (systems j-1 -> j) into the learning filter of the paper's law
(docs/theory.md, sections 2 and 3): the closed form of the Theorem, a robust FIR, the
norm-optimal law, the per-trial robust SOCP or the closed form with a robustness filter
guaranteed over the Delta set. Each is one class here with the same faces:

* ``name``, as ``--method`` and ``filters.json`` spell it;
* ``guaranteed``: robust to the Delta set by its own construction, so the learning band leaves
  the model edge to it (:func:`~..pair.design_pair`);
* ``needs_delta_sets``: it designs over the fleet's Delta sets (:mod:`..sets.delta`);
* ``compared_by_default``: comparisons and campaigns run it unless told otherwise;
* ``per_trial``: its learning signal is solved anew for every trial (its cost grows with the
  Delta-set models it carries);
* ``cli_options``: the ``ilcdob design`` options only some methods use, of which it uses these;
* its options as fields (``FIR(options=FIROptions(...), deltas=...)``); :meth:`Method.configured`
  takes them from the :class:`MethodSettings` a caller running methods by name states once;
* :meth:`Method.check_options`: the command-line options it takes, checked before anything is built;
* :meth:`Method.design`: the filters and the ``filters.json`` content, before the band;
* :meth:`Method.order`: the implementation size a report shows.

:data:`METHODS` is built from the classes (each with its default options); nothing else asks which
method a name is.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from ilcdob.channel_loop import ChannelLoop
from ilcdob.errors import SpecError
from ilcdob.fleet import Fleet
from ilcdob.loop import LoopSystem

from ..filters.coefficients import zpk_to_coefficients
from ..maps.closed_form import LearningFilters, inverse_gd_filter
from ..maps.finite_horizon import LinearMap, causal_map, identity_map, zpk_map
from ..sets.delta import DeltaSet
from ..law import Stage
from ..law.designed import Designed
from ..law.filters import FilterPair
from ..law.robust_set import robust_set_maps
from ..law.stage import hstack_maps
from .fir import FIROptions, design_fir
from .norm_optimal import NormOptimalDesigner, NormOptimalOptions, check_norm_optimal_size, norm_optimal_learning
from .robust import RobustOptions, RobustPairDesigner
from .channel_robust_set import design_channel_robust_set
from .robust_set import RobustSetOptions, design_robust_set, structured_set

__all__ = ["DesignInputs", "MethodSettings", "MethodDesign", "Method", "ClosedForm", "FIR", "NormOptimal", "Robust",
           "RobustSet", "METHODS", "DEFAULT_METHOD", "DEFAULT_METHODS", "GUARANTEED", "method_named"]


@dataclass(frozen=True)
class DesignInputs:
    """What a method may use to design one pair (:func:`~..pair.design_pair` gathers it).

    Attributes
    ----------
    fleet : Fleet
    src, tgt : LoopSystem
        Loops of systems j-1 and j.
    head : dict
        The ``filters.json`` entries every method writes first (method, law, from, to, sample_time).
    closed_form : callable () -> LearningFilters
        The Theorem's filters of the pair, built once when first asked for.
    deltas : dict of str to DeltaSet, or None
        The Delta sets by system name (methods with ``needs_delta_sets``: the method's own, else the
        fleet's, :func:`~..pair.fleet_delta_sets`).
    """

    fleet: Fleet
    src: LoopSystem
    tgt: LoopSystem
    head: dict[str, Any]
    closed_form: Callable[[], LearningFilters]
    deltas: dict[str, DeltaSet] | None = None


@dataclass(frozen=True)
class MethodSettings:
    """The settings a caller that runs methods by name (the CLI, comparisons, campaigns) states once:
    :meth:`Method.configured` takes from them what its method uses and leaves the rest.

    Attributes
    ----------
    n : int or None
        Norm-optimal: trial length, samples (None: 500).
    lifted : bool
        Norm-optimal: also the N x N lifted matrices.
    rho : float or None
        Robust and robust-set: the improvement factor asked for (None: the options' own).
    relax : bool
        Robust: relax the SOCP where the exact one is infeasible.
    deltas : dict of str to DeltaSet, or None
        The Delta sets the design is made for (:attr:`Method.deltas`; None: the fleet's).
    fir, norm_optimal, robust, robust_set : options or None
        Each method's options (None: its defaults; ``rho`` overrides theirs).
    """

    n: int | None = None
    lifted: bool = False
    rho: float | None = None
    relax: bool = False
    deltas: dict[str, DeltaSet] | None = None
    fir: FIROptions | None = None
    norm_optimal: NormOptimalOptions | None = None
    robust: RobustOptions | None = None
    robust_set: RobustSetOptions | None = None


def _with_rho(options: Any, rho: float | None) -> Any:
    """``options`` with ``rho`` set where one is given."""
    return options if rho is None else replace(options, rho=rho)


@dataclass(frozen=True)
class MethodDesign:
    """A method's result, before the band (:class:`~..pair.PairDesign` carries it on).

    Attributes
    ----------
    filters : dict
        The method's ``filters.json`` content.
    core : Stage
        Its learning filter as the law's stage (:class:`~..law.designed.Designed`: on a trial, its
        file entries and, where it has one, its linear map).
    lifted : dict of str to numpy.ndarray, or None
        Norm-optimal: the law's gains (and lifted matrices when asked for).
    robust : RobustPairDesigner or None
        Robust: the per-trial SOCP.
    """

    filters: dict[str, Any]
    core: Stage
    lifted: dict[str, np.ndarray] | None = None
    robust: RobustPairDesigner | None = field(default=None, repr=False)


def _l1_l2_size(filters: dict[str, Any]) -> str:
    """``"L1: 23 taps + 6 SOS, advance 24, L2: 79/0"`` of the ``L1``/``L2`` coefficient entries."""
    def size(coeffs: dict[str, Any]) -> str:
        if coeffs.get("sos"):
            taps = f"{len(coeffs['lookahead'])} taps + " if coeffs.get("lookahead") else ""
            return f"{taps}{len(coeffs['sos'])} SOS, advance {coeffs['advance']}"
        return f"{len(coeffs['num']) - 1}/{len(coeffs['den']) - 1}"

    return ", ".join(f"{k}: {size(filters[k])}" for k in ("L1", "L2"))


class Method:
    """The protocol of a design method (module docstring); subclasses set the attributes."""

    name: str = ""
    guaranteed: bool = False
    needs_delta_sets: bool = False
    per_trial: bool = False
    cli_options: tuple[str, ...] = ()
    compared_by_default: bool = True
    #: The Delta sets the design is made for, by system name: the source's sets the learning band's
    #: model edge, and methods with ``needs_delta_sets`` design over them (None: the fleet's).
    deltas: dict[str, DeltaSet] | None = None

    def configured(self, settings: MethodSettings) -> "Method":
        """This method with what it uses of ``settings`` (the base: nothing to take).

        Parameters
        ----------
        settings : MethodSettings

        Returns
        -------
        Method
            A method of the same kind carrying its options.
        """
        return self

    def check_options(self, given: dict[str, Any]) -> None:
        """Refuse command-line values this method cannot design with (the base: none).

        Parameters
        ----------
        given : dict of str to object
            Option (``"--rho"``, ``"--trial"``, ...) -> its value, None where not given.

        Raises
        ------
        SpecError
            A value the method refuses, naming the option.
        """

    def design(self, inputs: DesignInputs) -> MethodDesign:
        """The method's filters and ``filters.json`` content for the pair of ``inputs`` (before the band).

        Parameters
        ----------
        inputs : DesignInputs

        Returns
        -------
        MethodDesign
        """
        raise NotImplementedError

    def order(self, filters: dict[str, Any], lifted: dict[str, np.ndarray] | None) -> str:
        """Implementation size: filter orders, FIR taps, Riccati gains or SOCP models.

        Parameters
        ----------
        filters : dict
            The design's ``filters.json`` content.
        lifted : dict or None
            Its lifted arrays (norm-optimal).
        """
        return _l1_l2_size(filters)

    def __repr__(self) -> str:
        return f"<method {self.name}>"


@dataclass(frozen=True, repr=False)
class ClosedForm(Method):
    """The Theorem's filters (paper Sec. III): ``L1 = -(1 - Q_j) Gd_hat_{j-1}^{-1}``, ``L2 = L1 Gf_hat_{j-1}``.

    Parameters
    ----------
    deltas : dict of str to DeltaSet, optional
        The Delta sets the design is made for (the learning band's model edge; default: the fleet's).
    """

    name = "closed-form"
    cli_options = ("--c-prefix", "--c-float")
    deltas: dict[str, DeltaSet] | None = None

    def configured(self, settings: MethodSettings) -> "ClosedForm":  # noqa: D102 - Method.configured
        return ClosedForm(settings.deltas or self.deltas)

    def design(self, inputs: DesignInputs) -> MethodDesign:  # noqa: D102 - Method.design
        lf = inputs.closed_form()
        entries = {"L1": zpk_to_coefficients(lf.L1), "L2": zpk_to_coefficients(lf.L2)}
        filters = {**inputs.head, **entries, "units": {"L1": "(m/s^2)/m", "L2": "1"}}
        return MethodDesign(filters, Designed(self.name, lf.apply, entries, lambda m: hstack_maps(
            [zpk_map(lf.L1, m), zpk_map(lf.L2, m)], "L1/L2")))


@dataclass(frozen=True, repr=False)
class FIR(Method):
    """FIR learning filters robust over the Delta sets (:mod:`.fir`).

    Parameters
    ----------
    options : FIROptions, optional
        The FIR's size, grid and robustness (default: :class:`~.fir.FIROptions`).
    deltas : dict of str to DeltaSet, optional
        The Delta sets of source and target (default: the fleet's).
    """

    name = "fir"
    needs_delta_sets = True
    cli_options = ("--samples", "--bound", "--c-prefix", "--c-float", "--fir-unattainable")
    options: FIROptions | None = None
    deltas: dict[str, DeltaSet] | None = None

    def configured(self, settings: MethodSettings) -> "FIR":  # noqa: D102 - Method.configured
        return FIR(settings.fir or self.options, settings.deltas or self.deltas)

    def design(self, inputs: DesignInputs) -> MethodDesign:  # noqa: D102 - Method.design
        fd = design_fir(inputs.src, inputs.tgt, inputs.deltas[inputs.src.name], inputs.deltas[inputs.tgt.name],
                        self.options)
        info = fd.to_dict()
        entries = {"L1": info.pop("L1"), "L2": info.pop("L2")}
        filters = {**inputs.head, **entries, "units": {"L1": "(m/s^2)/m", "L2": "1"},
                   "robustness": {k: v for k, v in info.items() if k not in ("source", "target")}}
        pair = FilterPair(entries["L1"], entries["L2"])
        return MethodDesign(filters, Designed(self.name, fd.apply, entries, lambda m: pair.linear_map(m, 2, m)))


@dataclass(frozen=True, repr=False)
class NormOptimal(Method):
    """The lifted norm-optimal law over a trial of ``n`` samples (:mod:`.norm_optimal`).

    Parameters
    ----------
    options : NormOptimalOptions, optional
        Weights of the cost (default: :class:`~.norm_optimal.NormOptimalOptions`).
    n : int
        Trial length, samples (>= 2).
    lifted : bool
        Also build the N x N matrices L1, L2 (about 8 N^2 numbers of memory while they are built,
        O(N^3) time; not needed to learn). Without, the design holds its law in compact form
        (:class:`~.norm_optimal.NormOptimalLaw`, O(N)).
    deltas : dict of str to DeltaSet, optional
        The Delta sets the design is made for (the learning band's model edge; default: the fleet's).
    """

    name = "norm-optimal"
    cli_options = ("--n", "--lifted")
    options: NormOptimalOptions | None = None
    n: int = 500
    lifted: bool = False
    deltas: dict[str, DeltaSet] | None = None

    def configured(self, settings: MethodSettings) -> "NormOptimal":  # noqa: D102 - Method.configured
        return NormOptimal(settings.norm_optimal or self.options, self.n if settings.n is None else settings.n,
                           settings.lifted or self.lifted, settings.deltas or self.deltas)

    def design(self, inputs: DesignInputs) -> MethodDesign:  # noqa: D102 - Method.design
        src, tgt = inputs.src, inputs.tgt
        opts = self.options or NormOptimalOptions()
        n = int(self.n)
        if n < 2:
            raise SpecError(f"`n`: got {n}, expected a trial length >= 2 samples")
        order = max(tgt.nominal.G_f.nstates, src.nominal.G_d.nstates)
        check_norm_optimal_size(n, order, self.lifted, "n", "lifted=True")
        designer = NormOptimalDesigner(tgt, n, opts)
        arrays = designer.law(src).to_arrays()
        what = ("lifted.npz: the law d_f,j = L1 e_{j-1} + L2 d_f,{j-1} as Riccati gains "
                "(ilcdob.design.methods.norm_optimal.NormOptimalLaw.from_arrays(...).apply(e, d_f))")
        if self.lifted:
            arrays["L1"], arrays["L2"] = designer.lifted_matrices(src)
            what += " and as the N x N matrices L1, L2"
        filters = {**inputs.head, "options": {"lam": opts.lam, "mu": opts.mu, "weight": opts.weight}, "n": n,
                   "lifted": what}
        def lifted(m: int) -> LinearMap:
            """What :func:`norm_optimal_learning` computes on m samples: the cost's solve (its dense matrix,
            m solves) of ``e0 = Gd_hat_j Gd_hat_{j-1}^{-1}{e + Gf_hat_{j-1}{d_f}}``; for checks on short trials."""
            sol = np.column_stack([NormOptimalDesigner(tgt, m, opts).solve(c) for c in np.eye(m)])
            eye = identity_map(m)
            e0 = (causal_map(tgt.nominal.G_d, m, "Gd_hat_j") @ zpk_map(inverse_gd_filter(src, True), m)
                  @ hstack_maps([eye, causal_map(src.nominal.G_f, m, "Gf_hat_{j-1}")], "e + Gf d_f"))
            return LinearMap(m, m, sol.__matmul__, sol.T.__matmul__, "solve") @ e0

        return MethodDesign(filters, Designed(self.name, lambda e, df: norm_optimal_learning(src, tgt, e, df, opts),
                                              maps=lifted), arrays)

    def order(self, filters: dict[str, Any], lifted: dict[str, np.ndarray] | None) -> str:  # noqa: D102
        matrices = f", lifted {filters['n']}x{filters['n']}" if lifted is not None and "L1" in lifted else ""
        return f"Riccati gains over {filters['n']} samples{matrices}"


@dataclass(frozen=True, repr=False)
class Robust(Method):
    """The per-trial SOCP over the models of both Delta sets (:mod:`.robust`).

    Parameters
    ----------
    options : RobustOptions, optional
        The SOCP's rho and weights (default: :class:`~.robust.RobustOptions`); its models are the
        nominal pair plus the paired Delta-set samples.
    deltas : dict of str to DeltaSet, optional
        The Delta sets of source and target (default: the fleet's).
    relax : bool
        Design at the smallest feasible rho (with a warning) when ``rho`` is infeasible for a
        trial, instead of raising.
    """

    name = "robust"
    guaranteed = True
    needs_delta_sets = True
    per_trial = True
    cli_options = ("--rho", "--samples", "--bound")
    options: RobustOptions | None = None
    deltas: dict[str, DeltaSet] | None = None
    relax: bool = False

    def configured(self, settings: MethodSettings) -> "Robust":  # noqa: D102 - Method.configured
        options = settings.robust or self.options
        if settings.rho is not None:
            options = _with_rho(options or RobustOptions(), settings.rho)
        return Robust(options, settings.deltas or self.deltas, settings.relax or self.relax)

    def design(self, inputs: DesignInputs) -> MethodDesign:  # noqa: D102 - Method.design
        source, target = inputs.src.name, inputs.tgt.name
        opts = self.options or RobustOptions()
        designer = RobustPairDesigner([inputs.src, *inputs.deltas[source].loops],
                                      [inputs.tgt, *inputs.deltas[target].loops], opts, self.relax)
        filters = {**inputs.head, "models": len(designer.sources),
                   "delta_set": {source: inputs.deltas[source].source, target: inputs.deltas[target].source},
                   "options": {"rho": opts.rho, "lam": opts.lam, "mu": opts.mu, "reduction_tol": opts.reduction_tol},
                   "learning": "per trial (SOCP over the models): learning_signal.csv and lifted.npz"}
        return MethodDesign(filters, Designed(self.name, designer.learn, why_not="the robust SOCP designs its filter "
                                              "from each trial: not linear in the trial"), robust=designer)

    def check_options(self, given: dict[str, Any]) -> None:  # noqa: D102 - Method.check_options
        if given.get("--trial") is None:
            raise SpecError("`--method robust`: the robust learning signal is an SOCP solved per trial; give the "
                            "previous system's trial with --trial CSV (columns time, error, learning)")

    def order(self, filters: dict[str, Any], lifted: dict[str, np.ndarray] | None) -> str:  # noqa: D102
        return f"per-trial SOCP, {filters['models']} models"


@dataclass(frozen=True, repr=False)
class RobustSet(Method):
    """The closed form with a robustness FIR guaranteed over the source's whole Delta set (:mod:`.robust_set`).

    Parameters
    ----------
    options : RobustSetOptions, optional
        The FIR's rho, size and grids (default: :class:`~.robust_set.RobustSetOptions`); its bound
        is the source's Delta set's.
    deltas : dict of str to DeltaSet, optional
        The Delta sets (default: the fleet's); the source's bound and model set the guarantee.
    """

    name = "robust-set"
    guaranteed = True
    needs_delta_sets = True
    compared_by_default = False  # a minute or more per source vehicle: on request
    cli_options = ("--rho", "--bound", "--c-prefix")
    options: RobustSetOptions | None = None
    deltas: dict[str, DeltaSet] | None = None

    def configured(self, settings: MethodSettings) -> "RobustSet":  # noqa: D102 - Method.configured
        options = settings.robust_set or self.options
        if settings.rho is not None:
            options = _with_rho(options or RobustSetOptions(), settings.rho)
        return RobustSet(options, settings.deltas or self.deltas)

    def design(self, inputs: DesignInputs) -> MethodDesign:  # noqa: D102 - Method.design
        if isinstance(inputs.src, ChannelLoop) or isinstance(inputs.tgt, ChannelLoop):
            return self._channel_design(inputs)
        source = inputs.src.name
        opts = self.options or RobustSetOptions()
        spec = next(s for s in inputs.fleet.systems if s.name == source)
        ds = inputs.deltas[source]
        rs = design_robust_set(inputs.src, inputs.tgt, ds.w, ds.bound, opts,
                               structured_set(spec, ds.source, ds.bound, opts.delta_set))
        filters = {**inputs.head, "closed_form": {"L1": zpk_to_coefficients(rs.filters.L1),
                                                  "L2": zpk_to_coefficients(rs.filters.L2)},
                   "units": {"L1": "(m/s^2)/m", "L2": "1", "F": "1"},
                   "learning": "d_f,j = F{L1{e_{j-1}} + L2{d_f,{j-1}}}, computed on a trial as (1 - Q_j){F{d_hat}} "
                               "with d_hat the disturbance reconstructed by the model (F: FIR, output(k) = "
                               "sum_i num[i] input(k + advance - i)); the trial's ends as `trial_ends` says"
                               + ("; the maps it runs under `law_maps` (C code: filters.c)" if rs.trial == "extended"
                                  else "; no C code (the projected law solves a least-squares problem per trial)"),
                   "delta_set": {source: ds.source}, **rs.to_dict()}
        if rs.trial == "extended":
            filters["law_maps"] = robust_set_maps(rs.filters)
        gf = rs.filters.source.nominal.G_f

        def maps(m: int) -> LinearMap:  # the law on (e, d_f): its map of e' = e + Gf_hat_{j-1}{d_f}
            eye = identity_map(m)
            return rs.trial_map(m) @ hstack_maps([eye, causal_map(gf, m, "Gf_hat_{j-1}")], "e + Gf d_f")

        entries = {k: filters[k] for k in ("law_maps", "F", "trial_ends") if k in filters}
        return MethodDesign(filters, Designed(self.name, rs.apply, entries if "law_maps" in entries else None, maps))

    def _channel_design(self, inputs: DesignInputs) -> MethodDesign:
        """:meth:`design` between vehicles on their own controller (:mod:`.channel_robust_set`; no C code)."""
        source = inputs.src.name
        ds = inputs.deltas[source]
        rs = design_channel_robust_set(inputs.src, inputs.tgt, ds.w, ds.bound, self.options or RobustSetOptions())
        filters = {**inputs.head, "closed_form": {"L1": zpk_to_coefficients(rs.filters.L1),
                                                  "L2": zpk_to_coefficients(rs.filters.L2)},
                   "learning": "u_j = -F{d_hat}/K_j with d_hat = -Gd_hat_{j-1}^{-1}{e_{j-1} + Gf_hat_{j-1}{u_{j-1}}} "
                               "the disturbance reconstructed by the source's model, on the target's channel (F: FIR, "
                               "output(k) = sum_i num[i] input(k + advance - i)); the trial's ends as `trial_ends` "
                               "says; no C code",
                   "delta_set": {source: ds.source}, **rs.to_dict()}
        gf = inputs.src.G_f

        def maps(m: int) -> LinearMap:  # the law on (e, u): its map of e' = e + Gf_hat_{j-1}{u}
            return rs.trial_map(m) @ hstack_maps([identity_map(m), causal_map(gf, m, "Gf_hat_{j-1}")], "e + Gf u")

        return MethodDesign(filters, Designed(self.name, rs.apply, None, maps))

    def check_options(self, given: dict[str, Any]) -> None:  # noqa: D102 - Method.check_options
        rho = given.get("--rho")
        if rho is not None and not (np.isfinite(rho) and 0 < rho <= 1):
            raise SpecError(f"`--rho`: got {rho!r}, expected a guaranteed improvement factor in (0, 1] for --method "
                            "robust-set (|e_j| <= rho |e'_j| on every plant of the Delta set; 1: never worse than "
                            "without learning)")

    def order(self, filters: dict[str, Any], lifted: dict[str, np.ndarray] | None) -> str:  # noqa: D102
        return f"closed form + {len(filters['F']['num'])}-tap FIR"


#: The design methods by name, in the order the tool lists them.
METHODS: dict[str, Method] = {m.name: m for m in (ClosedForm(), FIR(), NormOptimal(), Robust(), RobustSet())}

#: The designs whose improvement is guaranteed over the Delta set by their own construction (the
#: robust SOCP over its models, robust-set over the whole set): their learning band takes the
#: noise edges only, the model edge is theirs (:func:`~..pair.design_pair`).
GUARANTEED = tuple(name for name, m in METHODS.items() if m.guaranteed)

#: The designs that comparisons and campaigns run unless told otherwise.
DEFAULT_METHODS = tuple(name for name, m in METHODS.items() if m.compared_by_default)

#: The method a command designs with when none is named: the Theorem's closed form.
DEFAULT_METHOD = ClosedForm.name


def method_named(name: object, option: str = "method") -> Method:
    """The method called ``name`` (with its default options), or ``name`` itself if it is a method.

    Parameters
    ----------
    name : str or Method
        One of :data:`METHODS`, or a method object carrying its options.
    option : str
        The option or argument it came from, for the message.

    Raises
    ------
    SpecError
        No method has that name.
    """
    if isinstance(name, Method):
        return name
    if not isinstance(name, str) or name not in METHODS:
        raise SpecError(f"`{option}`: got {name!r}, valid methods are {list(METHODS)}")
    return METHODS[name]
