"""The face every learning filter shows, whatever its form (docs/theory.md section 2).

A learning filter is a linear, time-invariant and possibly non-causal map of one trial to another
at sample time ``ts``: its output at sample ``k`` may use later inputs (how many, its ``advance``,
is the form's: a ZPK filter's surplus of zeros, with its anti-causal poles looking ahead without
end, against the finite look-ahead of their truncated series in the coefficient form). Its
frequency response is taken on the unit circle, ``z = e^{j w Ts}`` (:mod:`ilcdob.response`), and
applied to a trial it treats the samples before the trial as zero and continues the input past
its end as the form says. The forms:

* :class:`~.noncausal.ZPKFilter`: zeros, poles and gain, inverted with zero phase error where the
  Theorem's filters need it (the closed form);
* :class:`~ilcdob.design.methods.fir.FIRFilter`: taps with an advance (the FIR design);
* :class:`~ilcdob.design.export.objects.LearningFilterTF`: the coefficient form of ``filters.json``
  (:mod:`.coefficients`) as python-control sections, a view of what the file and the C code run.

Each satisfies :class:`Filter`; a ZPK filter and its coefficient form give the same response and
the same trial (``tests/test_objects.py``).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Filter"]


@runtime_checkable
class Filter(Protocol):
    """A learning filter (module docstring): a structural type, not instantiated.

    Parameters
    ----------
    *args, **kwargs
        None: a protocol is not instantiated.

    Attributes
    ----------
    ts : float
        Sample time, s.
    """

    ts: float

    def freqresp(self, w: np.ndarray) -> np.ndarray:
        """The response on ``z = e^{j w Ts}``.

        Parameters
        ----------
        w : array_like
            Frequencies, rad/s.

        Returns
        -------
        numpy.ndarray
            Complex, the shape of ``w``.
        """

    def apply(self, x: object) -> np.ndarray:
        """The filter run over a whole trial.

        Parameters
        ----------
        x : array_like
            The trial, one sample per ``ts``.

        Returns
        -------
        numpy.ndarray
            The filtered trial, the length of ``x``.
        """
