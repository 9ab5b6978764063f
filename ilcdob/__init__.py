"""ilcdob: disturbance observers plus learning among systems with mismatched dynamics.

Implements Modi, Chen, Liang, Zheng (2024), "Improving Disturbance Estimation and
Suppression via Learning among Systems with Mismatched Dynamics".

Signal convention (stated once, checked at every entry): a signal is a 1-D NumPy array of
samples on a uniform grid ``t = k * Ts``, ``k = 0..N-1``; positions in m, accelerations in
m/s^2, time in s.
"""

from .errors import FleetError, IlcdobError, ModelFileError, SignalError, SpecError, UnstableLoopError
from .fleet import Fleet, default_fleet, fleet_from_dict, fleet_from_systems, load_fleet
from .fleet_io import add_system, fleet_to_toml
from .identified import IdentifiedModel, load_model
from .loop import LoopSystem, build_loop, freqresp
from .specs import DOBSpec, IdentificationSpec, NoiseSpec, PIDSpec, PlantSpec, SystemSpec, UncertaintySpec

__version__ = "0.1.0"

__all__ = [
    "IlcdobError", "SpecError", "FleetError", "ModelFileError", "UnstableLoopError", "SignalError",
    "Fleet", "load_fleet", "default_fleet", "fleet_from_dict", "fleet_from_systems", "add_system", "fleet_to_toml",
    "IdentifiedModel", "load_model",
    "LoopSystem", "build_loop", "freqresp",
    "PlantSpec", "PIDSpec", "DOBSpec", "NoiseSpec", "SystemSpec", "IdentificationSpec", "UncertaintySpec",
]
