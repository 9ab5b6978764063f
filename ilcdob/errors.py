"""Exception hierarchy of ilcdob.

Every error raised on purpose by ilcdob derives from :class:`IlcdobError`; each also
derives from the built-in exception a caller would expect (``ValueError`` for bad input),
so ``except ValueError`` keeps working. Messages name the input, the value received,
what is valid and, where there is one, the next step.
"""

from __future__ import annotations

__all__ = ["IlcdobError", "SpecError", "FleetError", "ModelFileError", "UnstableLoopError", "SignalError",
           "NumericalError", "NativeBuildError", "OutputError", "LearningLimitError", "LearningLimitWarning"]


class IlcdobError(Exception):
    """Base class of every error ilcdob raises on purpose."""


class SpecError(IlcdobError, ValueError):
    """A system, controller, DOB or scenario parameter is invalid."""


class FleetError(IlcdobError, ValueError):
    """A fleet file is malformed; the message names the file, the system and the key."""


class ModelFileError(IlcdobError, ValueError):
    """A model file (the ``model.json`` of ``ilcdob identify``) is unreadable or malformed;
    the message names the file, the key and the value."""


class UnstableLoopError(IlcdobError, ValueError):
    """A closed loop (PID + DOB around the plant) is not asymptotically stable."""


class SignalError(IlcdobError, ValueError):
    """A signal has the wrong shape, length or contains non-finite values."""


class NumericalError(IlcdobError, ArithmeticError):
    """A computation produced no usable number: overflow, a non-finite result, a solver that
    failed (the command exits with status 3, not as bad input)."""


class OutputError(IlcdobError, ValueError):
    """An output location cannot be written: a device, FIFO or socket where a file is expected,
    not a folder, not writable, or not ilcdob's to replace."""


class NativeBuildError(IlcdobError, RuntimeError):
    """A CasADi function could not be compiled to native code or loaded (:mod:`ilcdob.native`);
    the message names the function, the compiler and its first line of output."""


class LearningLimitError(IlcdobError, ValueError):
    """A learning signal exceeds the learning vehicle's acceleration limit and was refused
    (a check that ran and did not hold: the command exits with status 1)."""


class LearningLimitWarning(UserWarning):
    """A learning signal exceeded the learning vehicle's acceleration limit and was clipped."""


class LearningEndWarning(UserWarning):
    """A learning signal's first or last samples rise far above its interior peak (an artefact of the trial's
    ends, not of the disturbance)."""
