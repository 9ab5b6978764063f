"""ilcdob's control law of one axis as a per-sample object: outer PID, DOB and learning signal
(paper Sec. II; docs/theory.md section 1).

Any loop that flies a vehicle sample by sample (ilcdob's linear and nonlinear simulations, a
third-party simulator, a companion computer) calls the same object. Per sample ``k``, with the
measured position ``y_m``::

    e[k]     = r[k] - y_m[k]
    u1[k]    = C{e}[k] + a_ff[k]              (a_ff: reference acceleration fed forward, if any)
    d_hat[k] = M{y_m}[k] - Q{u2}[k]           (DOB, M = Q/P_hat; Q strictly proper: no algebraic loop)
    u2[k]    = u1[k] - d_hat[k] - d_f[k]      (d_f: the learning signal)

``u2`` is the acceleration command. The DOB's ``Q`` must see the command the vehicle actually
received: when the vehicle limits it (tilt, thrust), pass the applied value to
:meth:`OuterLoopController.update`. Without the DOB (``dob=False``) ``u2 = u1``.

While the vehicle applies the commands as computed, the law is a discrete LTI system of its
inputs ``(r, y_m, a_ff, d_f)``; :meth:`OuterLoopController.state_space` gives it (the same
equations, in matrices: :class:`LawStateSpace`), for simulations that run a linear plant over
a whole trial at once.

Units: positions in m, accelerations (commands, ``d_hat``, ``d_f``, ``a_ff``) in m/s^2; the
object runs at the loop's sample time ``loop.ts``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import SpecError
from .loop import LoopSystem

__all__ = ["OuterLoopController", "DisturbanceObserver", "LawStateSpace"]


class _Block:
    """A discrete SISO state-space block stepped by hand, ``y = C x + D u``, ``x+ = A x + B u`` (pure-Python
    products: faster than NumPy's for the few states of a PID, Q or M)."""

    def __init__(self, sys_) -> None:
        self.a = np.asarray(sys_.A, float).tolist()
        self.b = np.asarray(sys_.B, float)[:, 0].tolist()
        self.c = np.asarray(sys_.C, float)[0].tolist()
        self.d = float(np.asarray(sys_.D).ravel()[0])
        self.x = [0.0] * len(self.b)

    def output(self, u: float = 0.0) -> float:
        return sum(ci * xi for ci, xi in zip(self.c, self.x)) + self.d * u

    def update(self, u: float) -> None:
        x = self.x
        self.x = [sum(aij * xj for aij, xj in zip(row, x)) + bi * u for row, bi in zip(self.a, self.b)]


class DisturbanceObserver:
    """The DOB of one axis stepped per sample: ``d_hat[k] = M{y_m}[k] - Q{u2}[k]`` (module docstring).

    Used by :class:`OuterLoopController` and, on a vehicle flying its own controller, by the add-on DOB of
    :mod:`ilcdob.vehicles.dob_loop`, whose ``u2`` is the acceleration that controller commanded.

    Parameters
    ----------
    q, m : control.StateSpace
        Discrete ``Q`` (strictly proper) and ``M = Q/P_hat`` (:func:`ilcdob.discretize.q_block`,
        :func:`~ilcdob.discretize.m_block`).

    Raises
    ------
    SpecError
        ``Q`` is not strictly proper (an algebraic loop through the DOB).
    """

    def __init__(self, q, m) -> None:
        if float(np.asarray(q.D).ravel()[0]) != 0.0:
            raise SpecError("`q`: the DOB's Q must be strictly proper in discrete time (algebraic loop through the "
                            "DOB)")
        self._sys = (q, m)
        self.reset()

    def reset(self) -> None:
        """Both blocks at rest, the estimate 0."""
        self._q, self._m = _Block(self._sys[0]), _Block(self._sys[1])
        self.d_hat = 0.0

    def estimate(self, measurement: float) -> float:
        """The estimate of this sample.

        Parameters
        ----------
        measurement : float
            The measured position ``y_m[k]``, m.

        Returns
        -------
        float
            ``d_hat[k]``, m/s^2 (also :attr:`d_hat`).
        """
        self.d_hat = self._m.output(measurement) - self._q.output()
        return self.d_hat

    def update(self, command: float, measurement: float) -> None:
        """Advance both blocks by one sample.

        Parameters
        ----------
        command : float
            ``u2[k]``, m/s^2, as the vehicle received it.
        measurement : float
            ``y_m[k]``, m.
        """
        self._q.update(command)
        self._m.update(measurement)


@dataclass(frozen=True)
class LawStateSpace:
    """The control law of :class:`OuterLoopController` from rest as a discrete state-space system
    ``x[k+1] = a x[k] + b v[k]``, ``(u2, d_hat)[k] = c x[k] + d v[k]`` (:meth:`OuterLoopController.state_space`).

    Attributes
    ----------
    a, b, c, d : numpy.ndarray
        The matrices; states: the PID's, then (with the DOB) Q's and M's.
    dob : bool
        With the DOB (else ``d_hat = 0`` and the learning input is unused).
    blocks : tuple
        ``(A, B, C, D)`` of the PID, Q and M as the controller steps them (``B``, ``C`` vectors,
        ``D`` a float), for :meth:`evaluate`.
    inputs : tuple of str
        ``("r", "y_m", "a_ff", "d_f")``: reference and measured position (m), feedforward and
        learning signal (m/s^2).
    outputs : tuple of str
        ``("u2", "d_hat")``, m/s^2.
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    dob: bool
    blocks: tuple = field(repr=False, default=())
    inputs: tuple[str, ...] = ("r", "y_m", "a_ff", "d_f")
    outputs: tuple[str, ...] = ("u2", "d_hat")

    def evaluate(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The law's step for a run of samples, computed block by block as :meth:`OuterLoopController.step`
        does (the matrices hold products of the blocks' entries, rounded; this does not use them).

        Parameters
        ----------
        x : numpy.ndarray
            States, one column per sample (the order of :attr:`a`).
        v : numpy.ndarray or sequence of arrays
            Inputs ``(r, y_m, a_ff, d_f)`` (rows), one column per sample.

        Returns
        -------
        tuple of numpy.ndarray
            The next states (columns) and the outputs ``(u2, d_hat)`` (rows).
        """
        (ac, bc, cc, dc), (aq, bq, cq, _), (am, bm, cm, dm) = self.blocks
        nc, nq = len(bc), len(bq)
        xc, xq, xm = x[:nc], x[nc:nc + nq], x[nc + nq:]
        r, ym, aff, df = v
        e = r - ym
        u1 = (cc @ xc + dc * e) + aff
        nxt = np.empty_like(x)
        np.matmul(ac, xc, out=nxt[:nc])
        nxt[:nc] += bc[:, None] * e
        if not self.dob:
            return nxt, np.vstack([u1, np.zeros_like(u1)])
        d_hat = (cm @ xm + dm * ym) - cq @ xq
        u2 = u1 - d_hat - df
        np.matmul(aq, xq, out=nxt[nc:nc + nq])
        nxt[nc:nc + nq] += bq[:, None] * u2
        np.matmul(am, xm, out=nxt[nc + nq:])
        nxt[nc + nq:] += bm[:, None] * ym
        return nxt, np.vstack([u2, d_hat])


def _matrices(sys_) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    return (np.asarray(sys_.A, float), np.asarray(sys_.B, float)[:, 0], np.asarray(sys_.C, float)[0],
            float(np.asarray(sys_.D).ravel()[0]))


class OuterLoopController:
    """The outer loop of one axis of one vehicle (module docstring), from rest.

    Parameters
    ----------
    loop : LoopSystem
        Supplies the discrete PID ``C``, ``Q`` and ``M = Q/P_hat`` (built from the model).
    dob : bool
        Run the DOB (and accept a learning signal); False: the PID alone.

    Raises
    ------
    SpecError
        ``loop`` is not a :class:`~ilcdob.loop.LoopSystem`, or its ``Q`` is not strictly proper.

    Examples
    --------
    >>> import ilcdob
    >>> from ilcdob.controller import OuterLoopController
    >>> ctl = OuterLoopController(ilcdob.default_fleet().loop("UAV1"))
    >>> u = ctl.step(1.0, 0.0)   # reference 1 m, measured 0 m: the first command (derivative kick), m/s^2
    >>> round(u, 2)
    43.34
    """

    def __init__(self, loop: LoopSystem, dob: bool = True):
        if not isinstance(loop, LoopSystem):
            raise SpecError(f"`loop`: got {type(loop).__name__}, expected a LoopSystem")
        if float(loop.Q.D[0, 0]) != 0.0:
            raise SpecError("`loop`: its Q must be strictly proper in discrete time (algebraic loop through the DOB)")
        self.loop, self.dob = loop, bool(dob)
        self._observer = DisturbanceObserver(loop.Q, loop.M)
        self.ts = loop.ts
        self.reset()

    def reset(self) -> None:
        """Back to rest: every block's state zero, no command pending."""
        self._c = _Block(self.loop.C)
        self._observer.reset()
        self.d_hat = 0.0
        self._pending: tuple[float, float] | None = None

    def command(self, reference: float, measurement: float, *, feedforward: float = 0.0,
                learning: float = 0.0) -> float:
        """The acceleration command of this sample; :meth:`update` must follow before the next one.

        Parameters
        ----------
        reference : float
            ``r[k]``, m.
        measurement : float
            The measured position ``y_m[k]``, m.
        feedforward : float
            ``a_ff[k]``, m/s^2.
        learning : float
            ``d_f[k]``, m/s^2 (0 without the DOB).

        Returns
        -------
        float
            ``u2[k]``, m/s^2. The DOB's estimate of the sample is :attr:`d_hat`.

        Raises
        ------
        SpecError
            :meth:`update` was not called after the previous command, or a learning signal
            without the DOB.
        """
        if self._pending is not None:
            raise SpecError("OuterLoopController.command: the previous command was not followed by update()")
        e = reference - measurement
        u1 = self._c.output(e) + feedforward
        self._c.update(e)
        if self.dob:
            self.d_hat = self._observer.estimate(measurement)
            u2 = u1 - self.d_hat - learning
        else:
            if learning:
                raise SpecError(f"`learning`: got {learning!r}; a learning signal needs the DOB (dob=True)")
            u2 = u1
        self._pending = (u2, measurement)
        return u2

    def update(self, applied: float | None = None) -> None:
        """Advance the DOB with the command the vehicle received this sample.

        Parameters
        ----------
        applied : float, optional
            The command after the vehicle's limits, m/s^2 (default: as computed).
        """
        if self._pending is None:
            raise SpecError("OuterLoopController.update: no command to update with; call command() first")
        u2, measurement = self._pending
        if self.dob:
            self._observer.update(u2 if applied is None else applied, measurement)
        self._pending = None

    def step(self, reference: float, measurement: float, *, feedforward: float = 0.0,
             learning: float = 0.0) -> float:
        """:meth:`command` then :meth:`update` with the command as computed (a vehicle without limits).

        Parameters
        ----------
        reference, measurement : float
            m.
        feedforward, learning : float
            m/s^2.

        Returns
        -------
        float
            ``u2[k]``, m/s^2.
        """
        u2 = self.command(reference, measurement, feedforward=feedforward, learning=learning)
        self.update()
        return u2

    def state_space(self) -> LawStateSpace:
        """The law (module docstring) as a discrete LTI system from rest, for a vehicle that applies
        every command as computed (:meth:`step`); the controller's own state is not used.

        Per sample, with ``e = r - y_m`` and the blocks' ``(A, B, C, D)``::

            u2    = Cc xc + Dc e + a_ff - d_hat - d_f
            d_hat = Cm xm + Dm y_m - Cq xq              (with the DOB; 0 without)
            xc+   = Ac xc + Bc e,  xq+ = Aq xq + Bq u2,  xm+ = Am xm + Bm y_m

        Returns
        -------
        LawStateSpace
            Inputs ``(r, y_m, a_ff, d_f)``, outputs ``(u2, d_hat)``; without the DOB the ``d_f``
            column and the ``d_hat`` row are zero (a learning signal is refused there).
        """
        blocks = tuple(_matrices(s) for s in (self.loop.C, self.loop.Q, self.loop.M))
        (ac, bc, cc, dc), (aq, bq, cq, _), (am, bm, cm, dm) = blocks
        if not self.dob:
            c = np.vstack([cc, np.zeros_like(cc)])
            d = np.array([[dc, -dc, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
            return LawStateSpace(a=ac.copy(), b=np.outer(bc, [1.0, -1.0, 0.0, 0.0]), c=c, d=d, dob=False,
                                 blocks=blocks)
        nc, nq, nm = len(bc), len(bq), len(bm)
        z = np.zeros
        c = np.vstack([np.concatenate([cc, cq, -cm]), np.concatenate([z(nc), -cq, cm])])
        d = np.array([[dc, -(dc + dm), 1.0, -1.0], [0.0, dm, 0.0, 0.0]])
        a = np.zeros((nc + nq + nm,) * 2)
        a[:nc, :nc] = ac
        a[nc:nc + nq, nc:nc + nq] = aq
        a[nc + nq:, nc + nq:] = am
        a[nc:nc + nq] += np.outer(bq, c[0])  # Q is driven by u2
        b = np.vstack([np.outer(bc, [1.0, -1.0, 0.0, 0.0]), np.outer(bq, d[0]), np.outer(bm, [0.0, 1.0, 0.0, 0.0])])
        return LawStateSpace(a=a, b=b, c=c, d=d, dob=True, blocks=blocks)
