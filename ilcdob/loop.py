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
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import control as ct
import numpy as np

from .discretize import discretize_m, discretize_pid, discretize_plant, discretize_q
from .errors import SpecError, UnstableLoopError
from .specs import SystemSpec

__all__ = ["LoopSystem", "build_loop", "freqresp", "STABILITY_MARGIN"]

#: A discrete closed loop counts as stable when every eigenvalue has modulus below this.
STABILITY_MARGIN = 1.0 - 1e-9


def freqresp(sys: ct.LTI, w: np.ndarray) -> np.ndarray:
    """Complex frequency response of a discrete SISO system, ``sys(e^{j w Ts})``.

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
    w = np.asarray(w, dtype=float)
    return np.asarray(sys(np.exp(1j * w * sys.dt)), dtype=complex).reshape(w.shape)


def _named(sys: ct.StateSpace, inp: str, out: str, name: str) -> ct.StateSpace:
    return ct.ss(sys.A, sys.B, sys.C, sys.D, sys.dt, inputs=[inp], outputs=[out], name=name)


def _check_stable(sys: ct.StateSpace, what: str, system: str) -> None:
    if not np.all(np.isfinite(np.asarray(sys.A, dtype=float))):
        raise SpecError(f"system {system!r}: the {what} has non-finite state matrices (overflow); the plant, "
                        "controller or DOB coefficients are out of double-precision range: give values within about "
                        "1e-6 to 1e6 in their units")
    poles = np.linalg.eigvals(sys.A) if sys.nstates else np.zeros(0)
    bad = poles[np.abs(poles) >= STABILITY_MARGIN]
    if bad.size:
        listed = ", ".join(f"{p:.4g} (|z|={abs(p):.4f})" for p in bad)
        raise UnstableLoopError(
            f"system {system!r}: the {what} is unstable; closed-loop poles outside the unit circle: "
            f"{listed}. Lower the controller gains, raise controller.derivative_filter or slow the DOB "
            f"(larger dob.q_time_constant)."
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
        """Eigenvalues of the DOB closed loop (z-plane)."""
        return np.linalg.eigvals(self.closed_loop.A)


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
    """
    model = spec.nominal_plant
    p = _named(discretize_plant(spec.plant, ts), "up", "y", "P")
    c = _named(discretize_pid(spec.controller, ts), "e", "u1", "C")
    q = _named(discretize_q(spec.dob, model, ts), "u2", "qo", "Q")
    m = _named(discretize_m(spec.dob, model, ts), "y", "mo", "M")
    sums = [
        ct.summing_junction(["r", "-y"], "e", name="sum_e"),
        ct.summing_junction(["u2", "d"], "up", name="sum_up"),
        ct.summing_junction(["u1", "-d_hat", "-d_f"], "u2", name="sum_u2"),
        ct.summing_junction(["mo", "-qo"], "d_hat", name="sum_dhat"),
    ]
    sums = [ct.ss(s.A, s.B, s.C, s.D, ts, inputs=s.input_labels, outputs=s.output_labels, name=s.name)
            for s in sums]
    closed = ct.interconnect([p, c, q, m, *sums], inplist=["r", "d", "d_f"],
                             outlist=["y", "e", "d_hat", "u2"], dt=ts,
                             inputs=["r", "d", "d_f"], outputs=["y", "e", "d_hat", "u2"])
    p2 = _named(discretize_plant(spec.plant, ts), "up", "y", "P")
    plain_sums = [
        ct.summing_junction(["r", "-y"], "e", name="sum_e"),
        ct.summing_junction(["u1", "d", "-d_f"], "up", name="sum_up"),
    ]
    plain_sums = [ct.ss(s.A, s.B, s.C, s.D, ts, inputs=s.input_labels, outputs=s.output_labels,
                        name=s.name) for s in plain_sums]
    plain = ct.interconnect([p2, c, *plain_sums], inplist=["r", "d", "d_f"], outlist=["y", "e"], dt=ts,
                           inputs=["r", "d", "d_f"], outputs=["y", "e"])
    _check_stable(plain, "PID loop without DOB", spec.name)
    _check_stable(closed, "DOB loop", spec.name)
    return LoopSystem(spec=spec, ts=ts, P=p, C=c, Q=q, M=m, closed_loop=closed, open_loop_pid=plain)
