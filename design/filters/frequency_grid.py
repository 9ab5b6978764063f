"""Frequency grids, fit weights and option checks shared by the FIR designs.

:class:`~ilcdob.design.methods.fir.FIROptions` (the FIR fit to the closed-form filters) and
:class:`~ilcdob.design.methods.robust_set.RobustSetOptions` (the robustness FIR over a Delta set) both
design a non-causal FIR on log-spaced frequencies joined with a linear grid
(:func:`log_linear_grid`), emphasise their fit inside a band and penalise the taps
(:class:`FitWeighting`), and check the option fields they have in common with the same words
(:func:`check_count`, :func:`check_advance`, :func:`check_w_min`). The export's check grid
(:func:`~ilcdob.design.filters.coefficients.direct_form_grid`) is a :func:`log_linear_grid` with exact ends.

Units: frequencies in rad/s, look-aheads (advances) in samples.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ilcdob.errors import SpecError

__all__ = ["log_linear_grid", "FitWeighting", "check_count", "check_advance", "check_w_min"]


def log_linear_grid(w_lo: float, w_hi: float, n_log: int, linear: ArrayLike,
                    exact_ends: bool = False) -> np.ndarray:
    """``n_log`` log-spaced frequencies from ``w_lo`` to ``w_hi`` joined with ``linear``, sorted, once each.

    Parameters
    ----------
    w_lo, w_hi : float
        Ends of the log-spaced part, rad/s (> 0).
    n_log : int
        Number of log-spaced frequencies.
    linear : array_like
        The other frequencies, rad/s (usually linearly spaced; any order).
    exact_ends : bool
        False (default): the log-spaced part is ``10^linspace(log10 w_lo, log10 w_hi)``, whose
        ends may differ from ``w_lo`` and ``w_hi`` in the last digit. True: its ends are exactly
        ``w_lo`` and ``w_hi`` (``numpy.geomspace``; the interior is the same).

    Returns
    -------
    numpy.ndarray
        The sorted unique frequencies, rad/s.
    """
    if exact_ends:
        log = np.geomspace(w_lo, w_hi, n_log)
    else:
        log = np.logspace(np.log10(w_lo), np.log10(w_hi), n_log)
    return np.unique(np.concatenate([log, linear]))


def check_count(name: str, value: object, least: int, least_text: str | None = None) -> None:
    """Refuse an option that is not an integer ``>= least``.

    Parameters
    ----------
    name : str
        The option's name, for the message.
    value : object
        Its value (an ``int`` or a numpy integer).
    least : int
        The smallest value allowed.
    least_text : str, optional
        How the message states ``least`` (default: its number), e.g. ``"n_grid = 150"``.

    Raises
    ------
    SpecError
        ``value`` not an integer or below ``least``.
    """
    if not (isinstance(value, (int, np.integer)) and value >= least):
        bound = least if least_text is None else least_text
        raise SpecError(f"`{name}`: got {value!r}, expected an integer >= {bound}")


def check_advance(advance: object, n_taps: int, optional: bool = False) -> None:
    """Refuse a FIR look-ahead outside ``[0, n_taps - 1]`` samples.

    Parameters
    ----------
    advance : object
        The option ``advance`` (an integer number of samples, or None where ``optional``).
    n_taps : int
        The FIR's number of taps.
    optional : bool
        None is allowed (the design chooses).

    Raises
    ------
    SpecError
        ``advance`` not an integer in ``[0, n_taps - 1]`` (nor None where allowed).
    """
    if optional and advance is None:
        return
    if not (isinstance(advance, (int, np.integer)) and 0 <= advance <= n_taps - 1):
        raise SpecError(f"`advance`: got {advance!r}, expected {'None or ' if optional else ''}an integer in "
                        f"[0, n_taps - 1 = {n_taps - 1}]")


def check_w_min(w_min: float, why: str = "") -> None:
    """Refuse a lowest design frequency that is not a finite frequency > 0 rad/s.

    Parameters
    ----------
    w_min : float
        The option ``w_min``, rad/s.
    why : str
        Appended to the message (e.g. ``" (a FIR cannot match the integrator of L1 at DC)"``).

    Raises
    ------
    SpecError
        ``w_min`` not finite or not > 0.
    """
    if not (np.isfinite(w_min) and w_min > 0):
        raise SpecError(f"`w_min`: got {w_min!r}, expected a frequency > 0 rad/s{why}")


class FitWeighting:
    """Mixin of an options dataclass whose FIR fit is weighted by frequency and regularised.

    The dataclass has the fields ``weight_band`` (``(lo, hi)``, rad/s), ``band_weight`` (the
    weight inside that band, 1 elsewhere) and ``ridge`` (the weight of the taps' penalty); the
    mixin adds no field.
    """

    weight_band: tuple[float, float]
    band_weight: float
    ridge: float

    def weights(self, w: np.ndarray) -> np.ndarray:
        """Weight of the fit per frequency: ``band_weight`` inside ``weight_band`` (ends included), else 1.

        Parameters
        ----------
        w : numpy.ndarray
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            The weights, the shape of ``w``.
        """
        lo, hi = self.weight_band
        return np.where((w >= lo) & (w <= hi), self.band_weight, 1.0)

    def _check_weighting(self, band_unit: str = "") -> None:
        """Refuse a ``weight_band`` that is not ``(lo, hi)`` with ``0 <= lo < hi``, a ``band_weight``
        not > 0 or a ``ridge`` below 0 (in that order); ``band_unit`` ends the band's message."""
        lo_hi = tuple(self.weight_band)
        if len(lo_hi) != 2 or not (0 <= lo_hi[0] < lo_hi[1]):
            raise SpecError(f"`weight_band`: got {self.weight_band!r}, expected (lo, hi) with 0 <= lo < hi{band_unit}")
        if not (np.isfinite(self.band_weight) and self.band_weight > 0):
            raise SpecError(f"`band_weight`: got {self.band_weight!r}, expected > 0")
        if not (np.isfinite(self.ridge) and self.ridge >= 0):
            raise SpecError(f"`ridge`: got {self.ridge!r}, expected >= 0")
