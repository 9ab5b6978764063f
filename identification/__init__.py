"""System identification from step and chirp flight data.

* :mod:`.data` - ``FlightData``: named signals on a uniform time grid, CSV/Parquet writers;
* :mod:`.loaders` - CSV, Parquet, PX4 ULog (pyulog), ArduPilot DataFlash (pymavlink);
* :mod:`.excitation` - step sequences, chirps, suggested band, setpoint CSV export;
* :mod:`.model`, :mod:`.srivc`, :mod:`.tfest`, :mod:`.results` - continuous-time
  transfer-function fits (output error, variable projection with exact sensitivities by
  filtering, :mod:`.oe`) with covariance, residual tests and a
  multiplicative uncertainty bound;
* :mod:`.quadrotor` - a nonlinear 6-DOF quadrotor for synthetic flights;
* :mod:`.synthetic` - closed-loop flights of a linear plant under a PID (synthetic data with
  known truth);
* :mod:`.fleet_id` - identify a whole fleet from synthetic flights;
* :mod:`.plots` - compare / residual / Bode-with-uncertainty figures.
"""

from .data import FlightData
from .excitation import Chirp, StepSequence, suggest_band, suggest_band_for_loop, write_setpoint_csv
from .loaders import load_csv, load_dataflash, load_flight, load_parquet, load_ulog
from .model import ModelStructure, simulate_zoh
from .results import ResidualTest, TFEstimate, fit_percent, multiplicative_bound
from .tfest import FitOptions, tfest

__all__ = [
    "FlightData", "Chirp", "StepSequence", "suggest_band", "suggest_band_for_loop", "write_setpoint_csv",
    "load_csv", "load_dataflash", "load_flight", "load_parquet", "load_ulog",
    "ModelStructure", "simulate_zoh", "ResidualTest", "TFEstimate", "fit_percent", "multiplicative_bound",
    "FitOptions", "tfest",
]
