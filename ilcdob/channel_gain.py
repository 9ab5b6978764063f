"""``K``: the acceleration a vehicle's controller commands per unit of its learning channel (docs/closed_loop.md).

A learning signal added to a setpoint row reaches the airframe only through the controller's map from that row
to its acceleration command, so ``Gf = K Gd`` (:mod:`ilcdob.channel_loop`). On a single position/velocity loop
(rotorpy's SE3, a Crazyflie's Mellinger controller without its integral) ``K`` is a constant: ``kp`` on the
position channel, ``kd`` on the velocity channel, 1 on the acceleration feed-forward. On a cascade (PX4's and
ArduPilot's position P over a velocity PI, the velocity's derivative term acting on the measurement) it is a
transfer function with the velocity integral in it::

    position channel:   K(s) = kpp (kpv + kiv / s)
    velocity channel:   K(s) = kpv + kiv / s

(:meth:`ChannelGain.cascade`; on PX4 ``kpp``, ``kpv``, ``kiv`` are ``MPC_XY_P``, ``MPC_XY_VEL_P_ACC`` and
``MPC_XY_VEL_I_ACC`` horizontally, ``MPC_Z_P``, ``MPC_Z_VEL_P_ACC`` and ``MPC_Z_VEL_I_ACC`` vertically).
A ``K(s)`` is a controller the user states from its gains, not a fit: it must be minimum phase (``Gd = G_ch / K``
must stay stable) with its poles in the closed left half-plane, on the imaginary axis only at ``s = 0`` (an
integrator, which gives ``Gd`` its zero at the origin), and positive at low frequency.

Units: s; ``K`` in m/s^2 per channel unit (:data:`ilcdob.channel_loop.CHANNEL_UNITS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import SpecError
from .specs import as_polynomial

__all__ = ["ChannelGain", "as_channel_gain"]

#: Roots of ``K``'s denominator within this distance of ``s = 0`` (relative to its largest root, at least 1) are
#: an integrator, placed at the origin exactly.
_ORIGIN_RTOL = 1e-9


@dataclass(frozen=True)
class ChannelGain:
    """``K(s) = num(s) / den(s)`` (module docstring).

    Attributes
    ----------
    num, den : tuple of float
        Polynomial coefficients in s, highest power first; ``den`` defaults to ``(1.0,)`` (a constant).

    Raises
    ------
    SpecError
        Bad polynomials, a zero outside the open left half-plane, a pole in the right half-plane or on the
        imaginary axis away from ``s = 0``, or a gain not positive at low frequency.
    """

    num: tuple[float, ...]
    den: tuple[float, ...] = (1.0,)

    def __post_init__(self) -> None:
        num = np.asarray(as_polynomial(self.num, "channel_gain.num"))
        den = np.asarray(as_polynomial(self.den, "channel_gain.den"))
        num, den = num / den[0], den / den[0]
        object.__setattr__(self, "num", tuple(float(c) for c in num))
        object.__setattr__(self, "den", tuple(float(c) for c in den))
        zeros, poles = np.roots(num), np.roots(den)
        if np.any(zeros.real >= 0):
            raise SpecError(f"`channel_gain`: num = {list(self.num)} has zeros {np.round(zeros, 6).tolist()} outside "
                            "the open left half-plane; the controller's map from the channel to its acceleration "
                            "must be minimum phase (Gd = G_ch / K is then stable)")
        scale = max(1.0, float(np.max(np.abs(poles)))) if poles.size else 1.0
        origin = np.abs(poles) <= _ORIGIN_RTOL * scale
        if np.any(poles[~origin].real >= 0):
            raise SpecError(f"`channel_gain`: den = {list(self.den)} has poles {np.round(poles, 6).tolist()}; "
                            "expected them in the left half-plane or at s = 0 (an integrator)")
        k0 = num[np.flatnonzero(num)[-1]] / den[np.flatnonzero(den)[-1]]
        if not k0 > 0:
            raise SpecError(f"`channel_gain`: num = {list(self.num)}, den = {list(self.den)} is negative at low "
                            "frequency; expected the acceleration the controller commands per unit of channel "
                            "signal, > 0")

    @classmethod
    def cascade(cls, channel: str, position_p: float, velocity_p: float, velocity_i: float = 0.0) -> "ChannelGain":
        """``K`` of a position P over a velocity PI (module docstring).

        Parameters
        ----------
        channel : {"position", "velocity"}
            The setpoint row the learning signal is added to.
        position_p : float
            ``kpp``, 1/s (unused on the velocity channel, but checked).
        velocity_p : float
            ``kpv``, 1/s (m/s^2 per m/s).
        velocity_i : float
            ``kiv``, 1/s^2 (>= 0; 0 gives a constant ``K``).

        Returns
        -------
        ChannelGain
            ``kpp (kpv s + kiv) / s`` on the position channel, ``(kpv s + kiv) / s`` on the velocity channel (a
            constant where ``kiv = 0``).

        Raises
        ------
        SpecError
            Another channel, or gains not finite and positive (``velocity_i`` >= 0).
        """
        for name, value, low in (("position_p", position_p, 0.0), ("velocity_p", velocity_p, 0.0),
                                 ("velocity_i", velocity_i, None)):
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            if not ok or (value <= 0 if low is not None else value < 0):
                raise SpecError(f"`{name}`: got {value!r}, expected a finite gain "
                                + ("> 0" if low is not None else ">= 0"))
        if channel not in ("position", "velocity"):
            raise SpecError(f"`channel`: got {channel!r}; a cascade's K is defined on the 'position' and "
                            "'velocity' channels (1 on the acceleration channel)")
        k = float(position_p) if channel == "position" else 1.0
        if velocity_i == 0:
            return cls((k * velocity_p,))
        return cls((k * velocity_p, k * velocity_i), (1.0, 0.0))

    @property
    def constant(self) -> float | None:
        """``K`` where it does not depend on frequency, else None."""
        return self.num[0] / self.den[0] if len(self.num) == len(self.den) == 1 else None

    @property
    def integrators(self) -> int:
        """Poles of ``K`` at ``s = 0``."""
        den = np.asarray(self.den)
        return int(den.size - 1 - np.flatnonzero(den)[-1])

    def response(self, s: np.ndarray) -> np.ndarray:
        """``K(s)`` at complex frequencies ``s`` (rad/s).

        Parameters
        ----------
        s : array_like
            Complex frequencies, e.g. ``1j * w``.

        Returns
        -------
        numpy.ndarray
            Complex, the shape of ``s``.
        """
        s = np.asarray(s, complex)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.polyval(self.num, s) / np.polyval(self.den, s)

    def describe(self) -> str:
        """``K`` as a user reads it: ``"K = 0.95"`` or ``"K(s) = (1.71 s + 0.38) / s"``."""
        if self.constant is not None:
            return f"K = {self.constant:g}"
        num, den = _poly_text(self.num), _poly_text(self.den)
        return f"K(s) = ({num}) / " + (den if " " not in den else f"({den})")

    def to_value(self) -> float | dict[str, list[float]]:
        """``K`` as a fleet file's ``channel_gain`` holds it: a number, or ``{"num": [...], "den": [...]}``."""
        if self.constant is not None:
            return self.constant
        return {"num": list(self.num), "den": list(self.den)}


def _poly_text(coeffs: tuple[float, ...]) -> str:
    n = len(coeffs) - 1
    terms = []
    for i, c in enumerate(coeffs):
        power = "" if n - i == 0 else "s" if n - i == 1 else f"s^{n - i}"
        if c != 0:
            terms.append(power if c == 1 and power else f"{c:.6g} {power}".strip())
    return " + ".join(terms).replace("+ -", "- ")


def as_channel_gain(value: object, what: str = "channel_gain") -> ChannelGain:
    """``value`` as a :class:`ChannelGain`: a number > 0 (constant ``K``), a mapping with ``num`` and ``den``, or a
    :class:`ChannelGain`.

    Parameters
    ----------
    value : float, dict or ChannelGain
    what : str
        Name of the input, for the message.

    Returns
    -------
    ChannelGain

    Raises
    ------
    SpecError
        Anything else, or a bad gain.
    """
    if isinstance(value, ChannelGain):
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if not (math.isfinite(value) and value > 0):
            raise SpecError(f"`{what}`: got {value!r}, expected the controller's acceleration per unit of channel "
                            "signal, > 0")
        return ChannelGain((float(value),))
    if isinstance(value, dict) and set(value) == {"num", "den"}:
        try:
            return ChannelGain(tuple(value["num"]), tuple(value["den"]))
        except TypeError as exc:
            raise SpecError(f"`{what}`: got {value!r}, expected lists of numbers for `num` and `den`") from exc
    raise SpecError(f"`{what}`: got {value!r}, expected a number > 0 or a transfer function in s "
                    "{num = [...], den = [...]} (docs/closed_loop.md)")
