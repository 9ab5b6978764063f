"""System identification from step and chirp flight data.

The flight-data object (``FlightData``) lives in :mod:`ilcdob.signals` and the model
structure and its uncertainty in :mod:`ilcdob.uncertainty` (both re-exported here).

* :mod:`.loaders` - CSV, Parquet, PX4 ULog (pyulog), ArduPilot DataFlash (pymavlink);
* :mod:`.excitation` - step sequences, chirps, suggested band, setpoint CSV export;
* :mod:`.srivc`, :mod:`.tfest`, :mod:`.results` - continuous-time
  transfer-function fits (output error, variable projection with exact sensitivities by
  filtering, :mod:`.oe`) with covariance, residual tests and a
  multiplicative uncertainty bound;
* :mod:`.synthetic` - closed-loop flights of a linear plant under a PID (synthetic data with
  known truth);
* :mod:`.fleet_id` - identify a whole fleet from synthetic flights;
* :mod:`.plots` - compare / residual / Bode-with-uncertainty figures.
"""

import importlib
from typing import Any

from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure, frequency_response, multiplicative_bound

from .oe import simulate_zoh
from .results import ResidualTest, TFEstimate, fit_percent
from .tfest import FitOptions, tfest  # eager: the function, not its module, is ``identification.tfest``

# The rest re-exported lazily (PEP 562): a fit does not load the loaders' pandas, the excitation tools'
# loop models or python-control.
_EXPORTS = {
    **dict.fromkeys(("Chirp", "StepSequence", "suggest_band", "suggest_band_for_loop", "write_setpoint_csv"),
                    ".excitation"),
    **dict.fromkeys(("load_csv", "load_dataflash", "load_flight", "load_parquet", "load_ulog"), ".loaders"),
}


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


__all__ = [
    "FlightData", "Chirp", "StepSequence", "suggest_band", "suggest_band_for_loop", "write_setpoint_csv",
    "load_csv", "load_dataflash", "load_flight", "load_parquet", "load_ulog",
    "ModelStructure", "simulate_zoh", "ResidualTest", "TFEstimate", "fit_percent", "multiplicative_bound",
    "frequency_response",
    "FitOptions", "tfest",
]
