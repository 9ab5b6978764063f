"""Continuous-time transfer-function model structure used by the fits.

``G(s) = B(s) / (s^K A(s)) * exp(-s * delay)`` with ``A(s) = s^n + a_{n-1} s^{n-1} + ... + a_0``
(monic, ``n = n_poles - K`` free poles), ``B(s) = b_m s^m + ... + b_0`` (``m = n_zeros``)
and ``K = n_integrators`` fixed poles at s = 0. Parameters ``theta = (a_{n-1}..a_0,
b_m..b_0)``; the input is sampled with a zero-order hold at ``ts``, so simulation uses the
exact ZOH equivalent (with a fractional delay: the modified z-transform). The state-space
realisation is the controllable companion form, adequate for the low orders (<= 6) that
flight-vehicle models need.
"""

from __future__ import annotations

from dataclasses import dataclass

import control as ct
import numpy as np

from ilcdob.errors import SpecError

__all__ = ["ModelStructure", "simulate_zoh", "companion"]


#: Largest model order a fit accepts: the companion-form coefficients of higher orders span
#: too many decades to be estimated in double precision.
MAX_POLES = 12


@dataclass(frozen=True)
class ModelStructure:
    """Orders of a continuous-time transfer-function model.

    Attributes
    ----------
    n_poles : int
        Total number of poles, including the fixed integrators (>= 1).
    n_zeros : int
        Number of zeros (< n_poles: the model is strictly proper).
    n_integrators : int
        Poles fixed at s = 0 (0 <= K <= n_poles).
    """

    n_poles: int
    n_zeros: int = 0
    n_integrators: int = 0

    def __post_init__(self) -> None:
        for name in ("n_poles", "n_zeros", "n_integrators"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise SpecError(f"`{name}`: got {v!r}, expected an integer >= 0")
        if not 1 <= self.n_poles <= MAX_POLES:
            raise SpecError(f"`n_poles`: got {self.n_poles}, expected 1 to {MAX_POLES} (a flight vehicle's "
                            "input-output model rarely needs more than 6; polynomial coefficients of higher "
                            "orders are numerically meaningless)")
        if self.n_zeros >= self.n_poles:
            raise SpecError(f"`n_zeros`: got {self.n_zeros} with {self.n_poles} poles; the model must be "
                            f"strictly proper (n_zeros <= {self.n_poles - 1})")
        if self.n_integrators > self.n_poles:
            raise SpecError(f"`n_integrators`: got {self.n_integrators}, more than the {self.n_poles} poles")

    @property
    def n_free_poles(self) -> int:
        return self.n_poles - self.n_integrators

    @property
    def n_params(self) -> int:
        """Number of transfer-function parameters (free denominator + numerator)."""
        return self.n_free_poles + self.n_zeros + 1

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``theta`` -> (full denominator incl. integrators, numerator), s-polynomials highest first."""
        theta = np.asarray(theta, dtype=float)
        a = np.concatenate([[1.0], theta[: self.n_free_poles]])
        den = np.concatenate([a, np.zeros(self.n_integrators)])
        num = theta[self.n_free_poles:]
        return den, num

    def join(self, num: np.ndarray, den: np.ndarray) -> np.ndarray:
        """(numerator, denominator) -> ``theta`` (denominator normalised to monic)."""
        den = np.trim_zeros(np.asarray(den, dtype=float), "f")
        num = np.trim_zeros(np.asarray(num, dtype=float), "f")
        lead = den[0]
        den, num = den / lead, num / lead
        if len(den) != self.n_poles + 1:
            raise SpecError(f"`den`: degree {len(den) - 1}, the structure has {self.n_poles} poles")
        if self.n_integrators and np.any(den[len(den) - self.n_integrators:] != 0):
            raise SpecError(f"`den`: must end with {self.n_integrators} zero coefficient(s) (integrators)")
        num = np.concatenate([np.zeros(self.n_zeros + 1 - len(num)), num]) if len(num) <= self.n_zeros + 1 \
            else num
        if len(num) != self.n_zeros + 1:
            raise SpecError(f"`num`: degree {len(num) - 1}, the structure has {self.n_zeros} zeros")
        return np.concatenate([den[1:1 + self.n_free_poles], num])

    def tf(self, theta: np.ndarray) -> ct.TransferFunction:
        """python-control continuous-time transfer function (without the delay)."""
        den, num = self.split(theta)
        return ct.tf(num, den)


def companion(den: np.ndarray, num: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Controllable companion form (A, B, C) of ``num/den`` (den monic, strictly proper)."""
    n = len(den) - 1
    a = np.zeros((n, n))
    a[:-1, 1:] = np.eye(n - 1)
    a[-1, :] = -den[1:][::-1]
    b = np.zeros((n, 1))
    b[-1, 0] = 1.0
    c = np.zeros((1, n))
    c[0, : len(num)] = num[::-1]
    return a, b, c


def simulate_zoh(structure: ModelStructure, theta: np.ndarray, u: np.ndarray, ts: float,
                 delay: float = 0.0, x0: np.ndarray | None = None) -> np.ndarray:
    """Output of the model for a ZOH input ``u`` sampled at ``ts`` (from rest unless ``x0``,
    the companion-form state at the first sample); computed by filtering (:mod:`.oe`)."""
    from .oe import discretise, response, zoh_inputs

    d = discretise(structure, theta, ts, delay, derivatives=False)
    u = np.asarray(u, dtype=float)
    x0 = None if x0 is None else np.asarray(x0, dtype=float).reshape(-1)
    return response(d.phi, d.c[0], d.sos, d.den, u.size, zoh_inputs(d, u), x0)
