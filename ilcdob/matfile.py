"""MATLAB ``.mat`` files: an identified model (and, through :func:`write_mat`, a design) for MATLAB users.

:func:`write_mat` writes named variables with :func:`scipy.io.savemat` (MATLAB 5 format, which
MATLAB's ``load`` and Octave read), atomically (:func:`~ilcdob.atomic.atomic_path`: a failed
write leaves the previous file, or none, never half of one). Every file carries a variable
``description``, a character matrix with one line per variable: its meaning and unit. Numbers
are stored as doubles, vectors as rows; a value not reported is NaN.

:func:`model_to_mat` writes a ``model.json`` of ``ilcdob identify`` (or
:meth:`~ilcdob.identification.TFEstimate.to_dict`), checked by
:func:`~ilcdob.identified.model_from_dict` first; its variables are :data:`MODEL_VARIABLES`.
In MATLAB::

    m = load('model.mat');
    G = tf(m.num, m.den, 'InputDelay', m.delay);

A design's filters are written by :func:`ilcdob.design.export.objects.design_to_mat` (the design layer
checks a ``filters.json``; this module, in the kernel, cannot).
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_path, check_replaceable
from .errors import SpecError
from .identified import model_from_dict

__all__ = ["write_mat", "model_to_mat", "check_mat_path", "MODEL_VARIABLES", "MATLAB_NAME"]

#: A MATLAB variable name: a letter, then letters, digits or underscores, 63 characters at most.
MATLAB_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")

#: Variables of :func:`model_to_mat` -> their meaning and unit. ``G(s) = num(s)/den(s) exp(-delay s)``
#: maps the fitted input to the fitted output (for a fleet plant: commanded acceleration, m/s^2,
#: to position, m; the model file does not record units).
MODEL_VARIABLES = {
    "num": "numerator of G(s), powers of s, highest first (output unit per input unit, times s^k)",
    "den": "denominator of G(s), powers of s, highest first, den(1) = 1",
    "delay": "input delay of G, s (G(s) = num(s)/den(s) exp(-delay s))",
    "sample_time": "sample time of the identification data, s",
    "poles": "number of poles (integrators included)",
    "zeros": "number of zeros",
    "integrators": "number of poles fixed at s = 0",
    "parameters": "fitted parameters: free denominator coefficients a_{n-1}..a_0, then numerator b_m..b_0",
    "std": "1-sigma standard deviations of parameters (then of delay, s, when estimated)",
    "covariance": "covariance of parameters (and of delay, last row/column, s^2, when estimated)",
    "delay_estimated": "1 if the delay was estimated (it then has a row/column in covariance), 0 if fixed",
    "fit_estimation": "fit on the estimation data, % (100 (1 - |y - yhat| / |y - mean(y)|)); NaN: not reported",
    "fit_validation": "fit on held-out data, %; NaN: not reported",
    "noise_variance": "residual variance of the estimation data (output unit^2); NaN: not reported",
    "input_name": "name of the fitted input signal ('' if not reported)",
    "output_name": "name of the fitted output signal ('' if not reported)",
}


def check_mat_path(path: str | os.PathLike, what: str) -> Path:
    """The output file of a ``.mat`` export, checked before anything is computed or written.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    what : str
        What is written, for messages ("model", "design").

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    SpecError
        Not a path, a name ending in a slash or not in ``.mat``, or an existing folder.
    OutputError
        An existing device, FIFO or socket (:func:`~ilcdob.atomic.check_replaceable`).
    """
    if not isinstance(path, (str, os.PathLike)):
        raise SpecError(f"`path` of the {what} .mat file: got {path!r:.80}, expected a file name ending in .mat")
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text or text.endswith(("/", os.sep)):
        raise SpecError(f"`path` of the {what} .mat file: got {text!r}, expected a file name ending in .mat, "
                        "not a folder")
    out = Path(text)
    if out.suffix.lower() != ".mat":
        raise SpecError(f"`path` of the {what} .mat file: got {text!r}, expected a file name ending in .mat "
                        f"(MATLAB's load reads a file by its extension); e.g. {out.with_suffix('.mat').name!r}")
    if out.is_dir():
        raise SpecError(f"`path` of the {what} .mat file: {text!r} is a folder; give a file name inside it, "
                        f"e.g. {str(out / (what + '.mat'))!r}")
    check_replaceable(out, f"`path` of the {what} .mat file")
    return out


def _value(name: str, value: Any) -> Any:
    """A variable's value as MATLAB will hold it: text as a string, numbers as doubles."""
    if isinstance(value, str):
        return value
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, str) for v in value):
        return np.array(value)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(f"variable `{name}`: got {value!r:.80}, expected text or numbers") from None
    if np.any(np.isinf(arr)):
        raise SpecError(f"variable `{name}`: holds an infinite value; expected finite numbers (NaN: not reported)")
    return arr


def write_mat(path: str | os.PathLike, variables: Mapping[str, Any], descriptions: Mapping[str, str],
              what: str = "data") -> Path:
    """Write named variables to a ``.mat`` file atomically, with a ``description`` variable.

    Parameters
    ----------
    path : str or os.PathLike
        The file, ending in ``.mat`` (its folder is created if missing).
    variables : mapping of str to object
        MATLAB name (:data:`MATLAB_NAME`) -> value: text, a number or an array of numbers
        (NaN allowed, infinities refused). Vectors become rows.
    descriptions : mapping of str to str
        MATLAB name -> meaning and unit, for every variable (the ``description`` variable lists them).
    what : str
        What the file holds, for messages.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    SpecError
        A bad path (:func:`check_mat_path`), a name MATLAB refuses, ``description`` used as a
        name, a variable without a description, or a value that is not text or finite numbers.
    """
    from scipy.io import savemat

    out = check_mat_path(path, what)
    data: dict[str, Any] = {}
    for name, value in variables.items():
        if not isinstance(name, str) or not MATLAB_NAME.fullmatch(name) or name == "description":
            raise SpecError(f"variable name {name!r}: expected a MATLAB name (a letter, then letters, digits or "
                            "underscores, at most 63 characters) other than `description`")
        if name not in descriptions:
            raise SpecError(f"variable `{name}`: no description given; every variable of a .mat file of ilcdob "
                            "states its meaning and unit")
        data[name] = _value(name, value)
    data["description"] = np.array([f"{name}: {descriptions[name]}" for name in variables])
    with atomic_path(out) as tmp, open(tmp, "wb") as fh:
        savemat(fh, data, format="5", oned_as="row", do_compression=True)
    return out


def model_to_mat(model: Mapping[str, Any], path: str | os.PathLike, source: str = "model") -> Path:
    """Write an identified model (a ``model.json``'s content) as a ``.mat`` file (module docstring).

    Parameters
    ----------
    model : mapping
        The parsed ``model.json`` of ``ilcdob identify``, or
        :meth:`~ilcdob.identification.TFEstimate.to_dict`; checked by
        :func:`~ilcdob.identified.model_from_dict`.
    path : str or os.PathLike
        The file, ending in ``.mat``.
    source : str
        Where the model came from, first in messages.

    Returns
    -------
    pathlib.Path
        The file written; its variables are :data:`MODEL_VARIABLES` (and ``description``).

    Raises
    ------
    ModelFileError
        The model misses a key or holds an invalid value (the message names ``source`` and the key).
    SpecError
        A bad ``path`` (:func:`check_mat_path`).
    """
    check_mat_path(path, "model")
    m = model_from_dict(model, source)
    variables = {
        "num": m.num, "den": m.den, "delay": m.delay, "sample_time": m.sample_time,
        "poles": m.poles, "zeros": m.zeros, "integrators": m.integrators,
        "parameters": m.parameters, "std": m.std, "covariance": np.asarray(m.covariance, dtype=float),
        "delay_estimated": float(m.delay_estimated), "fit_estimation": m.fit_estimation,
        "fit_validation": m.fit_validation, "noise_variance": m.noise_variance,
        "input_name": m.input, "output_name": m.output,
    }
    return write_mat(path, variables, MODEL_VARIABLES, "model")
