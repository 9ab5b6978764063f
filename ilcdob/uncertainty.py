"""Parametric model uncertainty: the transfer-function structure of an identified model, its
frequency response and the multiplicative error bound its covariance implies.

The structure is the one the fits of :mod:`ilcdob.identification` estimate:

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
from typing import TYPE_CHECKING

import numpy as np

from .errors import SpecError

if TYPE_CHECKING:
    import control as ct

__all__ = ["MAX_POLES", "ModelStructure", "companion", "frequency_response", "multiplicative_bound"]


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
        """Number of estimated poles (``n_poles - n_integrators``)."""
        return self.n_poles - self.n_integrators

    @property
    def n_params(self) -> int:
        """Number of transfer-function parameters (free denominator + numerator)."""
        return self.n_free_poles + self.n_zeros + 1

    @property
    def parameter_names(self) -> list[str]:
        """Names of the parameters in their order: ``a_{k-1} .. a0`` (free denominator), then ``b_m .. b0``."""
        return [f"a{i}" for i in range(self.n_free_poles - 1, -1, -1)] + [f"b{i}" for i in range(self.n_zeros, -1, -1)]

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Parameters -> polynomials.

        Parameters
        ----------
        theta : array_like
            Free denominator coefficients ``a_{n-1}..a_0`` then numerator ``b_m..b_0``.

        Returns
        -------
        den : numpy.ndarray
            ``s^K A(s)``: monic, with the integrators' trailing zeros; s-polynomial, highest
            power first.
        num : numpy.ndarray
            ``B(s)``, highest power first.
        """
        theta = np.asarray(theta, dtype=float)
        a = np.concatenate([[1.0], theta[: self.n_free_poles]])
        den = np.concatenate([a, np.zeros(self.n_integrators)])
        num = theta[self.n_free_poles:]
        return den, num

    def join(self, num: np.ndarray, den: np.ndarray) -> np.ndarray:
        """Polynomials -> parameters (the inverse of :meth:`split`).

        Parameters
        ----------
        num : array_like
            Numerator, s-polynomial, highest power first (leading zeros ignored; a shorter
            one is padded).
        den : array_like
            Denominator of degree ``n_poles`` ending in ``n_integrators`` zeros; normalised to
            monic (``num`` is scaled with it).

        Returns
        -------
        numpy.ndarray
            ``theta``.

        Raises
        ------
        SpecError
            The degrees or the integrators do not fit the structure.
        """
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
        """The model as a python-control transfer function.

        Parameters
        ----------
        theta : array_like
            Parameters (see :meth:`split`).

        Returns
        -------
        control.TransferFunction
            ``B(s) / (s^K A(s))``, continuous time, without the delay.
        """
        den, num = self.split(theta)
        import control as ct

        return ct.tf(num, den)


def companion(den: np.ndarray, num: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Controllable companion form of a strictly proper transfer function.

    Parameters
    ----------
    den : numpy.ndarray
        Monic denominator, s-polynomial, highest power first (degree ``n``).
    num : numpy.ndarray
        Numerator, highest power first, degree below ``n``.

    Returns
    -------
    a : numpy.ndarray
        ``n x n`` companion matrix (last row ``-den[1:]`` reversed).
    b : numpy.ndarray
        ``n x 1``, the last unit vector.
    c : numpy.ndarray
        ``1 x n``, the numerator coefficients, lowest power first.
    """
    n = len(den) - 1
    a = np.zeros((n, n))
    a[:-1, 1:] = np.eye(n - 1)
    a[-1, :] = -den[1:][::-1]
    b = np.zeros((n, 1))
    b[-1, 0] = 1.0
    c = np.zeros((1, n))
    c[0, : len(num)] = num[::-1]
    return a, b, c


def frequency_response(structure: ModelStructure, theta: np.ndarray, delay: float, w: np.ndarray) -> np.ndarray:
    """``G(jw)`` of a model, its delay included.

    Parameters
    ----------
    structure : ModelStructure
        The model's orders.
    theta : array_like
        Its parameters (see :meth:`ModelStructure.split`).
    delay : float
        Input delay, s.
    w : array_like
        Frequencies, rad/s.

    Returns
    -------
    numpy.ndarray
        Complex response, one value per frequency.
    """
    den, num = structure.split(theta)
    s = 1j * np.asarray(w, float)
    return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * delay)


def multiplicative_bound(structure: ModelStructure, theta: np.ndarray, covariance: np.ndarray, delay: float,
                         delay_estimated: bool, w: np.ndarray, k: float = 3.0) -> np.ndarray:
    """Frequency-wise multiplicative uncertainty ``|Delta(jw)|`` at ``k`` sigma.

    Linearised: ``Delta = dG/G``, ``dG = (dG/dtheta) dtheta``; the bound is
    ``k * sqrt(g_re' Cov g_re + g_im' Cov g_im) / |G|``, the RMS magnitude of the linearised
    relative error, scaled by ``k`` (3: about 99 % for a Gaussian estimate); the gradients
    are analytic (those of ``B / (s^K A) e^{-s delay}`` in each coefficient and the delay). This bound defines the Delta set of an identified model
    (docs/theory.md section 3, docs/identification.md).

    Parameters
    ----------
    structure : ModelStructure
        The model's orders.
    theta : array_like
        Its parameters.
    covariance : array_like
        Covariance of ``theta`` and, last, of the delay when ``delay_estimated``.
    delay : float
        Input delay, s.
    delay_estimated : bool
        Whether the delay was estimated (then it is uncertain too).
    w : array_like
        Frequencies, rad/s.
    k : float
        Number of standard deviations.

    Returns
    -------
    numpy.ndarray
        ``|Delta(jw)|``, one value per frequency.
    """
    w = np.asarray(w, float)
    cov = np.asarray(covariance, float)
    g0 = frequency_response(structure, theta, delay, w)
    den, num = structure.split(theta)
    s = 1j * w
    a = np.polyval(den[: structure.n_free_poles + 1], s)  # A(s), without the integrators
    base = np.exp(-s * delay) / np.polyval(den, s)  # e^{-s delay} / (s^K A(s))
    # analytic gradient: dG/da_i = -G s^i / A, dG/db_i = s^i e^{-s delay} / (s^K A), dG/d delay = -s G
    n_a, n_b = structure.n_free_poles, num.size
    grads = [-g0 * s ** i / a for i in range(n_a - 1, -1, -1)] + [base * s ** i for i in range(n_b - 1, -1, -1)]
    if delay_estimated:
        grads.append(-s * g0)
    grads = np.array(grads)
    var = (np.einsum("iw,ij,jw->w", grads.real, cov, grads.real)
           + np.einsum("iw,ij,jw->w", grads.imag, cov, grads.imag))
    return k * np.sqrt(np.clip(var, 0, None)) / np.abs(g0)
