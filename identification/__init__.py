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

# Re-exported lazily (PEP 562): ``import ilcdob.identification.tfest`` does not load the loaders'
# pandas, the excitation tools' loop models or python-control.
_EXPORTS = {
    "FlightData": "ilcdob.signals", "ModelStructure": "ilcdob.uncertainty",
    "frequency_response": "ilcdob.uncertainty", "multiplicative_bound": "ilcdob.uncertainty",
    **dict.fromkeys(("Chirp", "StepSequence", "suggest_band", "suggest_band_for_loop", "write_setpoint_csv"),
                    ".excitation"),
    **dict.fromkeys(("load_csv", "load_dataflash", "load_flight", "load_parquet", "load_ulog"), ".loaders"),
    "simulate_zoh": ".oe", **dict.fromkeys(("ResidualTest", "TFEstimate", "fit_percent"), ".results"),
    "FitOptions": ".tfest", "tfest": ".tfest",
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
