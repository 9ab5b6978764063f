"""The learning law as a chain of stages, and the protocol every stage follows.

A design's learning law (docs/theory.md section 6, "One chain, four faces") is a composition: the reference term, the
learning gain, the band's trial extension and filter, the method's filter (``L1{.} + L2{.}`` or
the robust-set reconstruction), the airframe correction, the band's second pass and fold, the
acceleration limit. Each piece is one :class:`Stage` with four faces that agree:

* :meth:`Stage.apply` on the signals of a trial;
* :meth:`Stage.to_dict` / :meth:`Stage.from_dict`: its entries in ``filters.json``;
* :meth:`Stage.linear_map`: the same computation as a linear map over a finite trial
  (:class:`~ilcdob.design.maps.finite_horizon.LinearMap`), for the whole-trial check;
* :meth:`Stage.c_parts`: its C (tables, helper functions and the statements of ``learn``).

A stage sees a tuple of equally long signals: the error and learning signal of each source
before the method's filter (``place`` below :data:`CORE_PLACE`), the learning signal after it.
:class:`LearningLaw` runs the stages in the order of their ``place``; it is built from
``filters.json`` (:meth:`LearningLaw.from_dict`), optionally with the method's filter as
designed in memory, and the same chain gives ``ilcdob learn``, :meth:`PairDesign.learning
<ilcdob.design.pair.PairDesign.learning>`, the compiled ``learn`` and the finite-trial map.

A new stage is one class registered with :func:`register` in its own module of this package.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Sequence

import numpy as np

from ilcdob.errors import SpecError
from ilcdob.signals import as_signal

from ..maps.finite_horizon import LinearMap

__all__ = ["apply_learning", "Stage", "CParts", "LawContext", "LearningLaw", "STAGE_KINDS", "CORE_PLACE", "OUTPUT_PLACE", "register", "hstack_maps",
           "diag_maps", "Signals"]

#: The signals a stage sees: ``(e_1, d_f1, ..., e_k, d_fk)`` before the method's filter, ``(d_f,)`` after.
Signals = tuple[np.ndarray, ...]

#: The place of the method's filter in the chain: stages placed before it see error/learning pairs.
CORE_PLACE = 40
#: In C, stages placed after this run on ``df_next`` (the learning signal written), those before on ``a``.
OUTPUT_PLACE = 65

#: The stage classes by kind, in registration order (:func:`register`).
STAGE_KINDS: dict[str, type["Stage"]] = {}


@dataclass(frozen=True)
class CParts:
    """A stage's share of the C ``learn`` function.

    Attributes
    ----------
    tables : str
        Coefficient tables, before ``learn``.
    helpers : str
        Static helper functions, after every stage's tables.
    step : str
        Statements of ``learn``'s body: they run on ``a`` (and ``b`` before the method's filter),
        ``len`` samples each (``n`` the trial's), with ``work`` beyond them.
    sections : bool
        The stage calls the shared second-order-section runner ``<prefix>sections``.
    loads, stores : bool
        The step reads ``e``/``df_prev`` into ``a``/``b`` (the first stage), or writes ``df_next``
        from ``a`` (the last); without such a stage ``learn`` copies.
    macros : str
        ``#define`` lines of the header.
    note : str
        Comment lines of the header on what ``learn`` does (each starting `` * ``).
    readme : str
        A sentence for the design folder's README.
    """

    tables: str = ""
    helpers: str = ""
    step: str = ""
    sections: bool = False
    loads: bool = False
    stores: bool = False
    macros: str = ""
    note: str = ""
    readme: str = ""


@dataclass(frozen=True)
class LawContext:
    """What a law is built with beside ``filters.json`` (:meth:`LearningLaw.from_dict`).

    Attributes
    ----------
    core : Stage or None
        The method's filter as designed, in memory, in place of the file's coefficients.
    band : object or None
        A :class:`~ilcdob.design.filters.band.LearningBand` in place of the file's ``band`` entry.
    reference : object or None
        The :class:`~ilcdob.design.law.laws.ReferenceTerms` of an ``exact-reference`` law (their
        signals are not in ``filters.json``); None: the law runs without them.
    gain : float
        Learning gain in (0, 1] on the error (not recorded in ``filters.json``).
    limits : object or None
        A :class:`~ilcdob.specs.LimitSpec` in place of the file's ``limit`` entry.
    on_limit : str or None
        ``"clip"`` or ``"refuse"`` in place of the file's ``limit.on_limit``; ``"off"``: the law
        without its limit stage.
    what : str
        What the learning signal is, for messages.
    """

    core: "Stage | None" = None
    band: Any = None
    reference: Any = None
    gain: float = 1.0
    limits: Any = None
    on_limit: str | None = None
    what: str = "learning signal"


class Stage:
    """One piece of the learning law with its four faces (module docstring).

    Subclasses set ``kind`` (a unique name), ``place`` (position in the chain) and ``keys`` (the
    ``filters.json`` entries they own), and implement the faces. A face a stage cannot have
    raises :class:`~ilcdob.errors.SpecError` saying why (``linear = False``: no linear map;
    ``emits_c = False``: no C).
    """

    kind: ClassVar[str] = ""
    place: ClassVar[int] = 0
    keys: ClassVar[tuple[str, ...]] = ()
    linear: ClassVar[bool] = True
    emits_c: ClassVar[bool] = True

    def apply(self, x: Signals, n: int, notes: dict[str, Any]) -> Signals:
        """The stage on the signals of a trial.

        Parameters
        ----------
        x : tuple of numpy.ndarray
            Equally long signals (module docstring), m and m/s^2.
        n : int
            Samples of the trial (the signals may be longer: the band's extended horizon).
        notes : dict
            Where a stage records what it found (e.g. the limit's report).

        Returns
        -------
        tuple of numpy.ndarray
        """
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        """The stage's entries of ``filters.json`` (empty: not recorded)."""
        return {}

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext) -> "Stage | None":
        """The stage of ``filters.json`` (and ``ctx``), or None when the design has none.

        Parameters
        ----------
        filters : dict
            ``filters.json`` content.
        ctx : LawContext
            What the law is built with beside the file.

        Returns
        -------
        Stage or None

        Raises
        ------
        SpecError
            An entry of the wrong type, shape or value, naming its key.
        """
        return None

    def linear_map(self, m: int, k: int, n: int) -> LinearMap:
        """The stage over ``k`` stacked signals of ``m`` samples (trial of ``n``) as a linear map.

        Parameters
        ----------
        m : int
            Samples of each signal the stage receives.
        k : int
            Signals it receives (2 per source before the method's filter, 1 after).
        n : int
            Samples of the trial.

        Returns
        -------
        LinearMap
            ``R^(k m) -> R^(k' m')`` (:meth:`shape`).

        Raises
        ------
        SpecError
            The stage is not linear (``linear = False``).
        """
        raise SpecError(f"stage {self.kind!r}: no linear map ({self.why_not_linear()})")

    def why_not_linear(self) -> str:
        """Why the stage has no linear map (shown when one is asked for)."""
        return "not linear in the trial"

    def shape(self, m: int, k: int, n: int) -> tuple[int, int]:
        """``(m', k')``: samples and signals after the stage, given them before (default: unchanged).

        Parameters
        ----------
        m : int
            Samples of each signal the stage receives.
        k : int
            Signals it receives (2 per source before the method's filter, 1 after).
        n : int
            Samples of the trial.
        """
        return m, k

    def c_parts(self, prefix: str) -> CParts:
        """The stage's C (:class:`CParts`).

        Parameters
        ----------
        prefix : str
            Start of every C symbol (:func:`~..export.c_export.check_c_prefix`).

        Returns
        -------
        CParts

        Raises
        ------
        SpecError
            The stage has no C (``emits_c = False``).
        """
        raise SpecError(f"stage {self.kind!r}: no C code")

    def __repr__(self) -> str:
        return f"<stage {self.kind}>"


def register(cls: type[Stage]) -> type[Stage]:
    """Class decorator: add a stage class to :data:`STAGE_KINDS`.

    Parameters
    ----------
    cls : type
        A :class:`Stage` subclass with a ``kind`` no other registered class has.

    Raises
    ------
    SpecError
        No ``kind``, or one already registered.
    """
    if not cls.kind or cls.kind in STAGE_KINDS:
        raise SpecError(f"stage class {cls.__name__}: kind {cls.kind!r} missing or registered twice")
    STAGE_KINDS[cls.kind] = cls
    return cls


def hstack_maps(maps: Sequence[LinearMap], name: str = "") -> LinearMap:
    """``[M_1 ... M_k]``: the sum of the maps of ``k`` stacked inputs.

    Parameters
    ----------
    maps : sequence of LinearMap
        The maps, all with the same ``n_out``.
    name : str
        Name of the result (default: the maps' names).
    """
    sizes = [mp.n_in for mp in maps]
    cuts = np.cumsum([0, *sizes])

    def fwd(x: np.ndarray) -> np.ndarray:
        return sum(mp(x[a:b]) for mp, a, b in zip(maps, cuts[:-1], cuts[1:]))

    def adj(y: np.ndarray) -> np.ndarray:
        return np.concatenate([mp.T(y) for mp in maps])

    return LinearMap(int(cuts[-1]), maps[0].n_out, fwd, adj, name or "[" + " ".join(mp.name for mp in maps) + "]")


def diag_maps(mp: LinearMap, k: int) -> LinearMap:
    """``diag(M, ..., M)``: ``M`` on each of ``k`` stacked signals.

    Parameters
    ----------
    mp : LinearMap
        The map of one signal.
    k : int
        Number of signals.
    """
    def fwd(x: np.ndarray) -> np.ndarray:
        return np.concatenate([mp(part) for part in np.split(x, k)])

    def adj(y: np.ndarray) -> np.ndarray:
        return np.concatenate([mp.T(part) for part in np.split(y, k)])

    return LinearMap(k * mp.n_in, k * mp.n_out, fwd, adj, f"{mp.name} x{k}")


@dataclass(frozen=True)
class LearningLaw:
    """The learning law of a design: its stages in chain order (module docstring).

    Attributes
    ----------
    stages : tuple of Stage
        In the order of their ``place``; exactly one is the method's filter (``place`` =
        :data:`CORE_PLACE`).
    """

    stages: tuple[Stage, ...] = field(default=())

    def __post_init__(self) -> None:
        order = sorted(self.stages, key=lambda s: s.place)
        if [s.place for s in order] != [s.place for s in self.stages]:
            raise SpecError(f"learning law: stages out of order {[s.kind for s in self.stages]}")
        if sum(s.place == CORE_PLACE for s in self.stages) != 1:
            raise SpecError(f"learning law: expected one method filter among {[s.kind for s in self.stages]}")

    @classmethod
    def from_dict(cls, filters: dict[str, Any], ctx: LawContext | None = None) -> "LearningLaw":
        """The law of ``filters.json`` (with ``ctx``: the method's filter, band or limit in memory).

        Parameters
        ----------
        filters : dict
            ``filters.json`` content.
        ctx : LawContext, optional

        Returns
        -------
        LearningLaw

        Raises
        ------
        SpecError
            No method filter (neither ``L1``/``L2`` nor a robust-set ``law_maps``), or an entry
            of the wrong type, shape or value (the message names the key).
        """
        ctx = ctx or LawContext()
        stages = []
        for kind, kls in sorted(STAGE_KINDS.items(), key=lambda kv: kv[1].place):
            if kls.place == CORE_PLACE and ctx.core is not None:
                continue
            found = kls.from_dict(filters, ctx)
            if found is not None:
                stages.append(found)
        if ctx.core is not None:
            stages.append(ctx.core)
        elif not any(s.place == CORE_PLACE for s in stages):
            raise SpecError(f"filters: missing key(s) {[k for k in ('L1', 'L2') if k not in filters]}; method "
                            f"{filters.get('method')!r} has no L1/L2 filters (and no robust-set `law_maps`)")
        return cls(tuple(sorted(stages, key=lambda s: s.place)))

    def to_dict(self) -> dict[str, Any]:
        """The stages' ``filters.json`` entries, merged (what :meth:`from_dict` reads back)."""
        out: dict[str, Any] = {}
        for s in self.stages:
            out.update(s.to_dict())
        return out

    def stage(self, kind: str) -> Stage | None:
        """The stage of ``kind``, None when the law has none.

        Parameters
        ----------
        kind : str
            A key of :data:`STAGE_KINDS`.
        """
        return next((s for s in self.stages if s.kind == kind), None)

    @property
    def core(self) -> Stage:
        """The method's filter."""
        return next(s for s in self.stages if s.place == CORE_PLACE)

    def run(self, signals: Sequence[object], notes: dict[str, Any] | None = None) -> np.ndarray:
        """The learning signal of a trial from its signals.

        Parameters
        ----------
        signals : sequence of array
            ``(e, d_f)`` of the source (m, m/s^2), all ``N`` samples (more pairs for a
            multi-source filter).
        notes : dict, optional
            Filled with what the stages report (``"limit"``: the limit's report).

        Returns
        -------
        numpy.ndarray
            The learning signal, m/s^2, ``N`` samples.
        """
        first = as_signal(signals[0], "e_prev")
        x = (first, *(as_signal(s, "df_prev" if i == 0 else f"signal {i + 1}", first.size)
                      for i, s in enumerate(signals[1:])))
        notes = {} if notes is None else notes
        for s in self.stages:
            x = s.apply(x, first.size, notes)
        return x[0]

    def apply(self, e_prev: object, df_prev: object) -> np.ndarray:
        """The learning signal of one trial of one source: ``run((e_prev, df_prev))``.

        Parameters
        ----------
        e_prev : array, m
            The source's tracking error.
        df_prev : array, m/s^2
            The learning signal it flew (zeros if none).

        Returns
        -------
        numpy.ndarray
            The learning signal, m/s^2.
        """
        return self.run((e_prev, df_prev))

    def linear_map(self, n: int, k: int = 2) -> LinearMap:
        """The law over a trial of ``n`` samples as a linear map of its ``k`` stacked signals (``k n -> n``).

        Parameters
        ----------
        n : int
            Samples of the trial.
        k : int
            Signals of the trial (2 per source: error, learning signal).

        Returns
        -------
        LinearMap

        Raises
        ------
        SpecError
            ``n < 2``, or a stage without a linear map (its message says why).
        """
        n = int(n)
        if n < 2:
            raise SpecError(f"`n`: got {n}, expected a trial of at least 2 samples")
        m, out = n, None
        for s in self.stages:
            mp = s.linear_map(m, k, n)
            out = mp if out is None else mp @ out
            m, k = s.shape(m, k, n)
        return out

    def error_map(self, n: int) -> LinearMap:
        """The law's map ``e'_{j-1} -> d_f,j`` of one trial flown without learning (``d_f = 0``).

        Parameters
        ----------
        n : int
            Samples of the trial.

        Returns
        -------
        LinearMap
        """
        full = self.linear_map(n)
        return LinearMap(n, n, lambda x: full(np.concatenate([x, np.zeros(n)])), lambda y: full.T(y)[:n],
                         "learning law")


def apply_learning(filters: dict[str, Any], e_prev: object, df_prev: object) -> np.ndarray:
    """The learning law of a ``filters.json`` computed from its entries alone (what ``ilcdob learn``
    and the C function ``<prefix>learn`` run): :meth:`LearningLaw.from_dict` then :meth:`LearningLaw.apply`.

    Parameters
    ----------
    filters : dict
        ``filters.json`` content with ``L1`` and ``L2`` (closed-form and FIR designs) or with
        ``law_maps``, ``F`` and ``trial_ends`` (robust-set designs).
    e_prev : array, m
        The previous vehicle's tracking error (for ``exact-reference``: with its reference
        error removed).
    df_prev : array, m/s^2
        The learning signal it flew (zeros if none).

    Returns
    -------
    numpy.ndarray
        The learning signal, m/s^2 (for ``exact-reference``: before the reference correction;
        without the acceleration limit).

    Raises
    ------
    SpecError
        No learning law in ``filters`` or an entry of the wrong type, shape or value.
    """
    return LearningLaw.from_dict(filters, LawContext(on_limit="off")).apply(e_prev, df_prev)
