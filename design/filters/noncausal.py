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

Look-ahead bound. An anti-causal pole ``p`` needs the input ``n(p) = ln(1e12)/ln|p|``
samples ahead before its response falls below 1e-12 (:func:`lookahead`). Sampling zeros of
relative-degree-3 plants sit near -3.7 (about 21 samples); those of relative-degree-2 plants
approach -1 as ``Ts -> 0`` (-1.01 at 5 ms: 2777 samples, longer than most of a trial, and
on the circle for a pure double integrator), as can zeros of a fractional input delay. Such
a pole in the left half of the z-plane (an artefact of sampling, not of the vehicle) whose
look-ahead exceeds :data:`LOOKAHEAD_MAX` samples, or that lies on the unit circle, is
inverted with zero phase error instead (Tomizuka's ZPETC, docs/theory.md section 2). The
image ``e^{z Ts}`` of a continuous non-minimum-phase zero ``z`` lies near +1 and needs about
``27.6/z`` seconds of look-ahead at any sample time: that preview is physics, and such poles
are always inverted exactly (the substitute would multiply the response by
``1 + (w/z)^2`` there)::

    1/(z - p)  ->  (z^-1 - p) / (1 - p)^2

exact at DC, zero phase at every frequency, magnitude ``|e^{jw Ts} - p|^2/|1 - p|^2`` times
the exact one (between 0 and 1 for ``Re p < 0``): for ``p`` near -1 the relative error is ``sin^2(w Ts / 2)`` (2.5e-5 at 10 rad/s
and 1 ms, 6.2e-4 at 10 rad/s and 5 ms), and towards Nyquist the substitute rolls off where
the exact inverse would rise to ``1/(|p| - 1)``. With an exact model, learning through the
substitute leaves the fraction ``1 - |e^{jw Ts} - p|^2/|1 - p|^2`` (between 0 and 1) of the
error: it can fall short, it cannot amplify. :attr:`ZPKFilter.substituted` lists the poles so
treated; :meth:`ZPKFilter.exact_freqresp` is the rational filter as built,
:meth:`ZPKFilter.freqresp` and :meth:`ZPKFilter.apply` the filter as applied.
:data:`LOOKAHEAD_MAX` = 64 samples keeps the learning signal's dependence on the made-up
continuation after the trial (and the exported look-ahead taps, :mod:`.coefficients`) short: 64 ms
at 1 ms, against 14 s for the exact inverse of the relative-degree-2 zero at -1.002.

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
from functools import cached_property, partial

import numpy as np
from scipy import signal

from ilcdob.response import response
from ilcdob.signals import as_signal, extend_smoothly

__all__ = ["ZPKFilter", "as_signal", "extend_smoothly", "lookahead", "LOOKAHEAD_MAX", "LOOKAHEAD_TOL"]

_CIRCLE_TOL = 1e-8

#: Largest look-ahead (samples) of an anti-causal pole inverted exactly (module docstring).
LOOKAHEAD_MAX = 64

#: Relative size of the last term of an anti-causal pole's look-ahead.
LOOKAHEAD_TOL = 1e-12


def lookahead(p: complex, tol: float = LOOKAHEAD_TOL) -> int:
    """Samples ahead an anti-causal pole ``1/(z - p)`` needs for its response to fall below ``tol``.

    Parameters
    ----------
    p : complex
        The pole, ``|p| > 1``.
    tol : float
        Relative size of the last term (default :data:`LOOKAHEAD_TOL`).

    Returns
    -------
    int
        ``ceil(ln(1/tol) / ln|p|)``.
    """
    return int(np.ceil(-np.log(tol) / np.log(abs(p))))


def _zpk_response(zeros: np.ndarray, poles: np.ndarray, gain: complex, z: np.ndarray) -> np.ndarray:
    z = np.asarray(z, dtype=complex)
    num = np.prod(z[..., None] - zeros, axis=-1) if len(zeros) else np.ones_like(z)
    den = np.prod(z[..., None] - poles, axis=-1) if len(poles) else np.ones_like(z)
    return gain * num / den


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

    def __repr__(self) -> str:
        outside = int(np.sum(np.abs(np.asarray(self.poles)) > 1 + _CIRCLE_TOL))
        return (f"<ZPKFilter {np.size(self.zeros)} zeros, {np.size(self.poles)} poles ({outside} outside the unit "
                f"circle), gain {self.gain:.4g}, Ts {self.ts:g} s, advance {self.advance}>")

    @cached_property
    def substituted(self) -> np.ndarray:
        """Poles inverted with zero phase error instead of exactly (module docstring): in the left
        half of the z-plane (sampling zeros of the plant), on the unit circle or anti-causal with
        a look-ahead over :data:`LOOKAHEAD_MAX`."""
        p = np.asarray(self.poles, dtype=complex)
        r = np.abs(p)
        on_circle = (np.abs(r - 1) <= _CIRCLE_TOL) & (np.abs(p - 1) > 1e-6)
        far = np.array([ri > 1 + _CIRCLE_TOL and lookahead(pi) > LOOKAHEAD_MAX for pi, ri in zip(p, r)], dtype=bool)
        return p[(on_circle | far) & (p.real < 0)] if p.size else p

    @cached_property
    def realised(self) -> "ZPKFilter":
        """The filter as applied: each pole of :attr:`substituted` replaced by its ZPETC factor
        ``(z^-1 - p)/(1 - p)^2`` (a zero at ``1/p``, a pole at 0); ``self`` when there are none."""
        sub = self.substituted
        if not sub.size:
            return self
        keep = np.ones(len(self.poles), dtype=bool)
        for p in sub:
            keep[np.flatnonzero((np.abs(self.poles - p) == 0) & keep)[0]] = False
        gain = self.gain * np.prod(-sub / (1 - sub) ** 2)
        return ZPKFilter(np.concatenate([self.zeros, 1.0 / sub]), np.concatenate([self.poles[keep], np.zeros(sub.size)]),
                         float(np.real(gain)), self.ts)

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
        """Evaluate the filter as applied (:attr:`realised`) at complex points ``z``."""
        f = self.realised
        return _zpk_response(f.zeros, f.poles, f.gain, z)

    def exact_freqresp(self, w: np.ndarray) -> np.ndarray:
        """Frequency response of the rational filter exactly as built (no substitution).

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex response, the shape of ``w``.
        """
        return response((partial(_zpk_response, self.zeros, self.poles, self.gain),), w, self.ts)

    def freqresp(self, w: np.ndarray) -> np.ndarray:
        """Frequency response ``F(e^{j w Ts})`` of the filter as applied (:attr:`realised`).

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex response, the shape of ``w``.
        """
        return response((self,), w, self.ts)

    def approximation_error(self, w: np.ndarray) -> np.ndarray:
        """Relative error ``|realised / exact - 1|`` of the filter as applied (0 without substitution).

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            The error at each frequency (real, between 0 and 1).
        """
        w = np.asarray(w, dtype=float)
        if not self.substituted.size:
            return np.zeros(w.shape)
        return np.abs(self.freqresp(w) / self.exact_freqresp(w) - 1.0)

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
        f = self.realised
        x = as_signal(x, name)
        n = x.size
        k = f.advance
        delay = max(0, len(f.causal_poles) - len(f.zeros))   # a strictly proper causal part
        pu = f.anticausal_poles
        n_pad, n_pre = k + 8, 0
        if len(pu):
            # the anti-causal part answers before t = 0 to the trial's first samples: its
            # output there decays like |p|^-m and feeds the causal part, so it is computed
            # over a lead of zeros long enough for it to fall below 1e-12 of its size
            n_pre = max(lookahead(p) for p in pu)
            n_pad += n_pre
        x = np.concatenate([np.zeros(n_pre), extend_smoothly(x, n_pad)])
        # anti-causal part: prod 1/(z - p) = prod(-1/p) * prod 1/(1 - z/p), run in reversed time
        if len(pu):
            sos_u = signal.zpk2sos(np.zeros(len(pu)), 1.0 / pu, 1.0)
            scale = float(np.real(np.prod(-1.0 / pu)))
            x = scale * signal.sosfilt(sos_u, x[::-1])[::-1]
        # causal part with k extra poles at the origin, then advance by k samples
        # (scipy.signal.zpk2sos puts missing zeros at the origin: a delay is restored by shifting)
        pc = np.concatenate([f.causal_poles, np.zeros(k)])
        y = signal.sosfilt(signal.zpk2sos(f.zeros, pc, f.gain), x)
        y = np.concatenate([np.zeros(delay), y])
        return y[n_pre + k:n_pre + k + n]
