"""The loop of one system: plant, PID, DOB, and its closed-loop maps (docs/theory.md section 1).

Block diagram (discrete time, sample time ``Ts``)::

    y     = P{u2 + d}
    u2    = C{r - y} - d_hat - d_f
    d_hat = M{y} - Q{u2},      M = Q/P_hat

With ``D = 1 - Q + P (M + C)`` the closed-loop maps (paper, Section II) are::

    G_r = P C / D      (r   -> y)
    G_d = P (1-Q) / D  (d   -> y)
    G_f = -P / D       (d_f -> y)
    Omega = (M + Q C) P / D    (d -> d_hat)

They are built here as state-space interconnections (never as quotients of transfer-function
polynomials, which leave near-cancelled unstable pole/zero pairs at z = 1), and the
interconnection's eigenvalues are checked when the system is built.

Stability is decided on ``A - I``, assembled from the blocks' delta forms
(:class:`~ilcdob.discretize.DiscreteBlock`: ``A - I`` without the cancellation of ``1 - small``)
and the couplings of the interconnection: a pole ``z = 1 + lambda`` is outside the circle when
``2 Re(lambda) + |lambda|^2 >= STABILITY_MARGIN^2 - 1``. With the blocks realised from their
poles and zeros (never from high-degree polynomials) the eigenvalue problem is well
conditioned: the 2 ``q_order`` poles that ``Q`` and ``M`` put about ``Ts/tau`` inside the
circle (near ``1 - Ts/tau``) are a cluster whose members are individually sensitive, but they
come out within 5 % of ``Ts/tau`` of their exact values (2.9e-4 at ``Ts`` = 1 ms, ``q_order``
8, against 120-digit roots of the characteristic polynomial), where companion forms misplaced
them by up to 0.03 and reported stable loops as unstable (|z| up to 1.02). A real instability
(an eigenvalue outside by more than that error) is reported as before. When the plant and the Q branch carry delay lines of the same length their
difference contributes exact poles at z = 0, which are deflated (:func:`loop_eigenvalues`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import control as ct
import numpy as np

from .discretize import DiscreteBlock, m_block, pid_block, plant_block, q_block
from .errors import IlcdobError, SpecError, UnstableLoopError
from .response import response
from .specs import SystemSpec

__all__ = ["LoopSystem", "build_loop", "freqresp", "delta_poles", "loop_eigenvalues", "STABILITY_MARGIN"]

#: A discrete closed loop counts as stable when every eigenvalue has modulus below this.
STABILITY_MARGIN = 1.0 - 1e-9

#: Units of the closed loops' signals (:class:`LoopSystem`), for its repr.
_SIGNAL_UNITS = {"r": "m", "y": "m", "e": "m", "d": "m/s^2", "d_f": "m/s^2", "d_hat": "m/s^2", "u2": "m/s^2"}


def freqresp(sys: ct.LTI, w: np.ndarray) -> np.ndarray:
    """Complex frequency response of a discrete SISO system, ``sys(e^{j w Ts})``.

    Computed by :func:`ilcdob.response.response`.

    Parameters
    ----------
    sys : control.LTI
        Discrete-time SISO system (``sys.dt`` is the sample time ``Ts``).
    w : array_like
        Frequencies, rad/s (up to Nyquist ``pi/Ts``).

    Returns
    -------
    numpy.ndarray
        Complex response, the shape of ``w``.
    """
    return response((sys,), w, sys.dt)


def _named(sys: ct.StateSpace, inp: str, out: str, name: str) -> ct.StateSpace:
    return ct.ss(sys.A, sys.B, sys.C, sys.D, sys.dt, inputs=[inp], outputs=[out], name=name)


def _finite_or_raise(mats: list[np.ndarray], what: str, system: str) -> None:
    if not all(np.all(np.isfinite(m)) for m in mats):
        raise SpecError(f"system {system!r}: the {what} has non-finite state matrices (overflow); the plant, "
                        "controller or DOB coefficients are out of double-precision range: give values within about "
                        "1e-6 to 1e6 in their units")


def delta_poles(a_minus_i: np.ndarray) -> np.ndarray:
    """Eigenvalues ``z`` of ``A`` computed as ``1 + eig(A - I)`` (module docstring: the delta form).

    Parameters
    ----------
    a_minus_i : numpy.ndarray
        ``A - I`` of a discrete system, computed without cancellation.

    Returns
    -------
    numpy.ndarray
        The eigenvalues of ``A`` (complex).
    """
    if a_minus_i.size == 0:
        return np.zeros(0, dtype=complex)
    return 1.0 + np.linalg.eigvals(a_minus_i).astype(complex)


def loop_eigenvalues(a_minus_i: np.ndarray, blocks: dict | None) -> np.ndarray:
    """Eigenvalues ``lambda`` of ``A - I`` of the DOB loop (states ``[P, C, Q, M]``, :func:`_dob_loop`).

    When the plant and the Q branch carry input-delay lines of the same length (the Q branch
    takes the model's delay; the nominal loop always), the difference of the two lines is a
    shift register driven by ``d`` alone: ``A`` is block triangular in coordinates
    ``(line_P - line_Q, rest)`` and has exactly that many eigenvalues at z = 0
    (``lambda = -1``). They are returned exactly, and the rest are the eigenvalues of the
    loop with the plant fed from the Q branch's line (the quotient), instead of letting a
    nilpotent block of that size spread its eigenvalues to radius ~eps^(1/n).

    Parameters
    ----------
    a_minus_i : numpy.ndarray
        ``A - I`` of the DOB loop.
    blocks : dict or None
        The loop's :class:`~ilcdob.discretize.DiscreteBlock` s (None: no deflation).

    Returns
    -------
    numpy.ndarray
        ``lambda`` (complex); the poles are ``z = 1 + lambda``.
    """
    if a_minus_i.size == 0:
        return np.zeros(0, dtype=complex)
    k = blocks["P"].delay_states if blocks else 0
    if not k or blocks["Q"].delay_states != k:
        return np.linalg.eigvals(a_minus_i).astype(complex)
    sizes = [blocks[key].a_minus_i.shape[0] for key in ("P", "C", "Q", "M")]
    o = np.cumsum([0] + sizes)
    line_p = np.arange(o[1] - k, o[1])
    line_q = np.arange(o[3] - k, o[3])
    keep = np.setdiff1d(np.arange(o[-1]), line_p)
    reduced = a_minus_i[np.ix_(keep, keep)].copy()
    cols_q = np.searchsorted(keep, line_q)
    reduced[:, cols_q] += a_minus_i[np.ix_(keep, line_p)]
    return np.concatenate([np.linalg.eigvals(reduced).astype(complex), np.full(k, -1.0 + 0j)])


def _check_stable(a_minus_i: np.ndarray, what: str, system: str, ts: float, blocks: dict | None = None) -> None:
    """UnstableLoopError when an eigenvalue ``z = 1 + lambda`` of the loop, ``lambda`` an eigenvalue of
    ``A - I`` (:func:`loop_eigenvalues`), has ``|z| >= STABILITY_MARGIN``; ``|z|^2 - 1 =
    2 Re(lambda) + |lambda|^2`` is compared without forming ``1 + lambda``."""
    if a_minus_i.size == 0:
        return
    lam = loop_eigenvalues(a_minus_i, blocks)
    excess = 2.0 * lam.real + np.abs(lam) ** 2  # |z|^2 - 1
    bad = excess >= STABILITY_MARGIN**2 - 1.0
    if np.any(bad):
        listed = ", ".join(f"{1.0 + p:.4g} (|z|={math.sqrt(1.0 + x):.4f})" for p, x in zip(lam[bad], excess[bad]))
        raise UnstableLoopError(
            f"system {system!r}: the {what} is unstable at the sample time {ts:g} s; closed-loop poles outside the "
            f"unit circle: {listed}. Lower the controller gains, raise controller.derivative_filter or slow the DOB "
            f"(larger dob.q_time_constant), or check the sample time: gains tuned at one rate can be unstable at a "
            f"slower one (a fleet file made from a model takes the model's rate)."
        )


@dataclass(frozen=True)
class LoopSystem:
    """One system's discrete blocks and closed-loop maps.

    Build with :func:`build_loop`. All maps are discrete ``control.StateSpace`` with
    ``dt = ts``; signals: ``r``, ``y`` in m, ``d``, ``d_f``, ``d_hat``, ``u2`` in m/s^2.

    Attributes
    ----------
    spec : SystemSpec
        The system the loop was built from.
    ts : float
        Sample time, s.
    P, C, Q, M : control.StateSpace
        Discrete plant (true), PID, Q branch (with the model's delay), ``M = Q/P_hat``.
    closed_loop : control.StateSpace
        Inputs ``(r, d, d_f)``, outputs ``(y, e, d_hat, u2)`` of the DOB loop.
    open_loop_pid : control.StateSpace
        Inputs ``(r, d, d_f)``, outputs ``(y, e)`` of the plain PID loop ("no DOB").
    blocks : dict
        ``"P"``, ``"C"``, ``"Q"``, ``"M"`` -> :class:`~ilcdob.discretize.DiscreteBlock`: the same
        blocks with their delta form and analytic poles (accurate numerics, module docstring).
    closed_loop_a_minus_i : numpy.ndarray
        ``closed_loop.A - I`` computed without cancellation (from the blocks' delta forms).
    """

    spec: SystemSpec
    ts: float
    P: ct.StateSpace
    C: ct.StateSpace
    Q: ct.StateSpace
    M: ct.StateSpace
    closed_loop: ct.StateSpace
    open_loop_pid: ct.StateSpace
    _cache: dict = field(default_factory=dict, repr=False, compare=False)
    blocks: dict = field(default_factory=dict, repr=False, compare=False)
    closed_loop_a_minus_i: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __repr__(self) -> str:
        sizes = ", ".join(f"{k} {getattr(self, k).nstates}" for k in ("P", "C", "Q", "M"))
        model = "exact model" if self.spec.model is None else "model differs from the plant"

        def named(labels: list[str]) -> str:
            return ", ".join(f"{n} [{_SIGNAL_UNITS.get(n, '?')}]" for n in labels)

        return (f"<LoopSystem {self.name[:60]!r}: Ts {self.ts:g} s, DOB loop {self.closed_loop.nstates} states "
                f"({sizes}), {model}; {named(self.closed_loop.input_labels)} -> "
                f"{named(self.closed_loop.output_labels)}>")

    @property
    def name(self) -> str:
        """The system's name (``spec.name``)."""
        return self.spec.name

    def _map(self, sys: ct.StateSpace, inp: str, out: str) -> ct.StateSpace:
        key = (id(sys), inp, out)
        if key not in self._cache:
            i = sys.input_labels.index(inp)
            o = sys.output_labels.index(out)
            self._cache[key] = ct.ss(sys.A, sys.B[:, [i]], sys.C[[o], :], sys.D[[o]][:, [i]], sys.dt)
        return self._cache[key]

    @property
    def G_r(self) -> ct.StateSpace:
        """``G_r = P C / D``: reference -> position (paper Sec. II)."""
        return self._map(self.closed_loop, "r", "y")

    @property
    def G_d(self) -> ct.StateSpace:
        """``G_d = P (1 - Q) / D``: disturbance -> position (paper Sec. II)."""
        return self._map(self.closed_loop, "d", "y")

    @property
    def G_f(self) -> ct.StateSpace:
        """``G_f = -P / D``: learning signal -> position (paper Sec. II)."""
        return self._map(self.closed_loop, "d_f", "y")

    @property
    def Omega(self) -> ct.StateSpace:
        """``Omega = (M + Q C) P / D``: disturbance -> DOB estimate (paper Sec. II)."""
        return self._map(self.closed_loop, "d", "d_hat")

    @property
    def G_r_no_dob(self) -> ct.StateSpace:
        """``P C / (1 + P C)``: reference -> position without DOB."""
        return self._map(self.open_loop_pid, "r", "y")

    @property
    def G_d_no_dob(self) -> ct.StateSpace:
        """``P / (1 + P C)``: disturbance -> position without DOB."""
        return self._map(self.open_loop_pid, "d", "y")

    @cached_property
    def nominal(self) -> "LoopSystem":
        """The same loop with the plant replaced by its model ``P_hat`` (what learning assumes)."""
        if self.spec.model is None:
            return self
        return build_loop(self.spec.exact(), self.ts)

    def poles(self) -> np.ndarray:
        """Eigenvalues of the DOB closed loop (z-plane), ``1 + eig(A - I)`` (:func:`loop_eigenvalues`)."""
        if self.closed_loop_a_minus_i is None:
            return np.linalg.eigvals(self.closed_loop.A)
        return 1.0 + loop_eigenvalues(self.closed_loop_a_minus_i, self.blocks)


def build_loop(spec: SystemSpec, ts: float) -> LoopSystem:
    """Discretise the blocks of ``spec`` and interconnect them (see module docstring).

    The plant is sampled with a zero-order hold, the PID and ``M`` with Tustin, the Q branch
    with a zero-order hold (:mod:`ilcdob.discretize`); the DOB loop and the plain PID loop are
    state-space interconnections (paper Sec. II, docs/theory.md section 1).

    Parameters
    ----------
    spec : SystemSpec
        Plant, model, PID and DOB of the system.
    ts : float
        Sample time, s.

    Returns
    -------
    LoopSystem
        The blocks and both closed loops, checked for stability.

    Raises
    ------
    UnstableLoopError
        If the DOB loop or the plain PID loop has a pole on or outside the unit circle;
        the message names the system and the offending poles.
    SpecError
        A block that cannot be discretised (:mod:`ilcdob.discretize`) or a loop whose matrices
        overflow; the message names the system first, whichever step failed.
    """
    try:
        return _build_loop(spec, ts)
    except IlcdobError as exc:
        named = f"system {spec.name!r}: "
        if str(exc).startswith(named):
            raise
        raise type(exc)(named + str(exc)) from exc


def _build_loop(spec: SystemSpec, ts: float) -> LoopSystem:
    """:func:`build_loop` without its naming of the system in errors that do not name it."""
    model = spec.nominal_plant
    blocks = {"P": plant_block(spec.plant, ts), "C": pid_block(spec.controller, ts),
              "Q": q_block(spec.dob, model, ts), "M": m_block(spec.dob, model, ts)}
    p, c, q, m = (_named(blocks[k].sys, i, o, k) for k, i, o in
                  (("P", "up", "y"), ("C", "e", "u1"), ("Q", "u2", "qo"), ("M", "y", "mo")))
    with np.errstate(over="ignore", invalid="ignore"):
        a_plain, a_plain_m1, b_plain, c_plain, d_plain = _pid_loop(blocks)
        a_cl, a_cl_m1, b_cl, c_cl, d_cl = _dob_loop(blocks)
    _finite_or_raise([a_plain, a_plain_m1, b_plain, c_plain, d_plain], "PID loop without DOB", spec.name)
    _check_stable(a_plain_m1, "PID loop without DOB", spec.name, ts)
    _finite_or_raise([a_cl, a_cl_m1, b_cl, c_cl, d_cl], "DOB loop", spec.name)
    _check_stable(a_cl_m1, "DOB loop", spec.name, ts, blocks)
    closed = ct.ss(a_cl, b_cl, c_cl, d_cl, ts, inputs=["r", "d", "d_f"], outputs=["y", "e", "d_hat", "u2"])
    plain = ct.ss(a_plain, b_plain, c_plain, d_plain, ts, inputs=["r", "d", "d_f"], outputs=["y", "e"])
    return LoopSystem(spec=spec, ts=ts, P=p, C=c, Q=q, M=m, closed_loop=closed, open_loop_pid=plain,
                      blocks=blocks, closed_loop_a_minus_i=a_cl_m1)


def _mats(block: DiscreteBlock) -> tuple[np.ndarray, ...]:
    s = block.sys
    return (np.asarray(s.A, dtype=float), np.asarray(s.B, dtype=float), np.asarray(s.C, dtype=float),
            np.asarray(s.D, dtype=float))


def _dob_loop(blocks: dict) -> tuple[np.ndarray, ...]:
    """The DOB loop's ``(A, A - I, B, C, D)``, states ``[P, C, Q, M]``, inputs ``(r, d, d_f)``,
    outputs ``(y, e, d_hat, u2)`` (module docstring); ``A - I`` from the blocks' delta forms.

    ``u2 = C{r - y} - (M{y} - Q{u2}) - d_f`` with ``P`` and ``Q`` strictly proper::

        u2 = -(Dc + Dm) Cp xp + Cc xc + Cq xq - Cm xm + Dc r - d_f
    """
    (ap, bp, cp, dp), (ac, bc, cc, dc), (aq, bq, cq, dq), (am, bm, cm, dm) = (
        _mats(blocks[k]) for k in ("P", "C", "Q", "M"))
    if np.any(dp != 0) or np.any(dq != 0):
        raise SpecError("P and Q must be strictly proper in discrete time (algebraic loop)")
    n = [ap.shape[0], ac.shape[0], aq.shape[0], am.shape[0]]
    o = np.cumsum([0] + n)
    sl = [slice(o[i], o[i + 1]) for i in range(4)]
    nt = int(o[-1])
    k_x = np.zeros((1, nt))
    k_x[:, sl[0]] = -(dc + dm) * cp
    k_x[:, sl[1]] = cc
    k_x[:, sl[2]] = cq
    k_x[:, sl[3]] = -cm
    k_u = np.array([[dc[0, 0], 0.0, -1.0]])
    b_u2 = np.zeros((nt, 1))  # where u2 enters: the plant (with d) and Q
    b_u2[sl[0]] = bp
    b_u2[sl[2]] = bq
    coupling = b_u2 @ k_x
    coupling[sl[1], sl[0]] += -bc @ cp
    coupling[sl[3], sl[0]] += bm @ cp
    a_m1 = coupling.copy()
    a = coupling.copy()
    for i, key in enumerate(("P", "C", "Q", "M")):
        a_m1[sl[i], sl[i]] += blocks[key].a_minus_i
        a[sl[i], sl[i]] += np.asarray(blocks[key].sys.A, dtype=float)
    b = b_u2 @ k_u
    b[sl[0], 1:2] += bp
    b[sl[1], 0:1] += bc
    c = np.zeros((4, nt))
    d = np.zeros((4, 3))
    c[0, sl[0]] = cp
    c[1, sl[0]] = -cp
    d[1, 0] = 1.0
    c[2, sl[0]] = dm * cp
    c[2, sl[2]] = -cq
    c[2, sl[3]] = cm
    c[3] = k_x
    d[3] = k_u
    return a, a_m1, b, c, d


def _pid_loop(blocks: dict) -> tuple[np.ndarray, ...]:
    """The plain PID loop's ``(A, A - I, B, C, D)``, states ``[P, C]``, inputs ``(r, d, d_f)``,
    outputs ``(y, e)``: ``u_p = C{r - y} + d - d_f``."""
    (ap, bp, cp, _), (ac, bc, cc, dc) = _mats(blocks["P"]), _mats(blocks["C"])
    n1, n2 = ap.shape[0], ac.shape[0]
    coupling = np.zeros((n1 + n2, n1 + n2))
    coupling[:n1, :n1] = -dc[0, 0] * bp @ cp
    coupling[:n1, n1:] = bp @ cc
    coupling[n1:, :n1] = -bc @ cp
    a = coupling.copy()
    a_m1 = coupling.copy()
    a[:n1, :n1] += ap
    a[n1:, n1:] += ac
    a_m1[:n1, :n1] += blocks["P"].a_minus_i
    a_m1[n1:, n1:] += blocks["C"].a_minus_i
    b = np.zeros((n1 + n2, 3))
    b[:n1, 0:1] = dc[0, 0] * bp
    b[:n1, 1:2] = bp
    b[:n1, 2:3] = -bp
    b[n1:, 0:1] = bc
    c = np.zeros((2, n1 + n2))
    c[0, :n1] = cp
    c[1, :n1] = -cp
    d = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    return a, a_m1, b, c, d
