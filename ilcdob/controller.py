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

Units: positions in m, accelerations (commands, ``d_hat``, ``d_f``, ``a_ff``) in m/s^2; the
object runs at the loop's sample time ``loop.ts``.
"""

from __future__ import annotations

import numpy as np

from .errors import SpecError
from .loop import LoopSystem

__all__ = ["OuterLoopController"]


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
        self.ts = loop.ts
        self.reset()

    def reset(self) -> None:
        """Back to rest: every block's state zero, no command pending."""
        self._c, self._q, self._m = _Block(self.loop.C), _Block(self.loop.Q), _Block(self.loop.M)
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
            self.d_hat = self._m.output(measurement) - self._q.output()
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
            self._q.update(u2 if applied is None else applied)
            self._m.update(measurement)
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
