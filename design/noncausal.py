"""Non-causal application of rational discrete filters to whole trials (stable inversion).

ILC runs between flights, so a learning filter may look ahead. A discrete filter
``F(z) = k * prod(z - z_i) / prod(z - p_i)`` with poles outside the unit circle and more
zeros than poles (the inverse of a ZOH plant with relative degree and sampling zeros) is
applied as the exact stable inversion of docs/theory.md section 2:

* poles with ``|p| <= 1`` (stable, plus the integrator at z = 1) form a causal part run
  forwards from rest, in second-order sections (robust for clustered poles);
* poles with ``|p| > 1`` form an anti-causal part ``prod 1/(z - p)`` run backwards from
  the end of the trial (stable in reversed time);
* surplus zeros become an advance of ``k`` samples (non-causal lead).

Boundary effects: the trial is taken as zero before ``t = 0``; the anti-causal part's answer
there (to the trial's first samples) is computed over a lead of zeros and passed on to the
causal part, which starts at rest before that lead. The
anti-causal and advance parts need the input a little beyond the trial; it is continued by
a cubic fitted to the last samples (:func:`extend_smoothly`), long enough for the
anti-causal response to decay below 1e-12 of its size. Padding with zeros instead would put
a step at the end, which an inverse plant (high-frequency gain ~1e5) turns into a spike of
thousands of m/s^2 in the last samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from ilcdob.errors import SpecError
from ilcdob.signals import as_signal, extend_smoothly

__all__ = ["ZPKFilter", "as_signal", "extend_smoothly"]

_CIRCLE_TOL = 1e-8


@dataclass(frozen=True)
class ZPKFilter:
    """A (possibly improper, non-causal) discrete filter in zero-pole-gain form.

    Attributes
    ----------
    zeros, poles : numpy.ndarray
        Complex roots in the z-plane (conjugate pairs complete).
    gain : float
        Real gain ``k``.
    ts : float
        Sample time, s.
    """

    zeros: np.ndarray
    poles: np.ndarray
    gain: float
    ts: float

    def __post_init__(self) -> None:
        on_circle = [p for p in self.poles if abs(abs(p) - 1) < _CIRCLE_TOL and abs(p - 1) > 1e-6]
        if on_circle:
            raise SpecError(f"`poles`: {on_circle} lie on the unit circle away from z = 1; "
                            "such a filter has no bounded non-causal realisation")

    @property
    def causal_poles(self) -> np.ndarray:
        """Poles with ``|p| <= 1`` (the integrator at z = 1 included): run forwards."""
        return self.poles[np.abs(self.poles) <= 1 + _CIRCLE_TOL]

    @property
    def anticausal_poles(self) -> np.ndarray:
        """Poles with ``|p| > 1``: run backwards from the end of the trial."""
        return self.poles[np.abs(self.poles) > 1 + _CIRCLE_TOL]

    @property
    def advance(self) -> int:
        """Samples of non-causal lead of the causal part (surplus zeros over causal poles)."""
        return max(0, len(self.zeros) - len(self.causal_poles))

    def __call__(self, z: np.ndarray) -> np.ndarray:
        """Evaluate ``F(z)`` at complex points ``z``."""
        z = np.asarray(z, dtype=complex)
        num = np.prod(z[..., None] - self.zeros, axis=-1) if len(self.zeros) else np.ones_like(z)
        den = np.prod(z[..., None] - self.poles, axis=-1) if len(self.poles) else np.ones_like(z)
        return self.gain * num / den

    def freqresp(self, w: np.ndarray) -> np.ndarray:
        """Frequency response ``F(e^{j w Ts})``.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex response, the shape of ``w``.
        """
        return self(np.exp(1j * np.asarray(w, dtype=float) * self.ts))

    def apply(self, x: object, name: str = "x") -> np.ndarray:
        """Apply the filter to a whole trial non-causally (stable inversion, module docstring).

        Parameters
        ----------
        x : array_like
            The trial, one sample per sample time, starting at rest.
        name : str
            The signal's name, for error messages.

        Returns
        -------
        numpy.ndarray
            The filtered trial, same length as ``x``.
        """
        x = as_signal(x, name)
        n = x.size
        k = self.advance
        pu = self.anticausal_poles
        n_pad, n_pre = k + 8, 0
        if len(pu):
            # the anti-causal part answers before t = 0 to the trial's first samples: its
            # output there decays like |p|^-m and feeds the causal part, so it is computed
            # over a lead of zeros long enough for it to fall below 1e-12 of its size
            n_pre = int(np.ceil(12.0 / np.log10(float(np.min(np.abs(pu))))))
            n_pad += n_pre
        x = np.concatenate([np.zeros(n_pre), extend_smoothly(x, n_pad)])
        # anti-causal part: prod 1/(z - p) = prod(-1/p) * prod 1/(1 - z/p), run in reversed time
        if len(pu):
            sos_u = signal.zpk2sos(np.zeros(len(pu)), 1.0 / pu, 1.0)
            scale = float(np.real(np.prod(-1.0 / pu)))
            x = scale * signal.sosfilt(sos_u, x[::-1])[::-1]
        # causal part with k extra poles at the origin, then advance by k samples
        pc = np.concatenate([self.causal_poles, np.zeros(k)])
        sos_c = signal.zpk2sos(self.zeros, pc, self.gain)
        return signal.sosfilt(sos_c, x)[n_pre + k:n_pre + k + n]
