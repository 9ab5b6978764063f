"""Identify a continuous-time model from a real PX4 flight log and look at the fit.

Run from anywhere: ``python examples/identify_a_log.py [LOG.ulg] [OUT_FOLDER]``. Without
arguments it uses the small public PX4 sample log shipped with the tests (BSD-3-Clause, see
tests/data/README.md) and writes into ``identified_log/``.

The model: vertical velocity (m/s) -> vertical position (m), one pole fixed at s = 0 (the
integration), one free pole and one zero, fitted by output error (docs/identification.md).
"""

import sys
from pathlib import Path

from ilcdob.app.commands import IdentifyInputs, identify_to_json
from ilcdob.identification import FitOptions
from ilcdob.uncertainty import ModelStructure

HERE = Path(__file__).resolve().parent
log = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parent / "tests" / "data" / "px4_sample_log_small_filtered.ulg"
out = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("identified_log")

inputs = IdentifyInputs(input="vehicle_local_position.vz", output="vehicle_local_position.z")
est, data, _ = identify_to_json([log], inputs, ModelStructure(n_poles=2, n_zeros=1, n_integrators=1), FitOptions(),
                                out / "model.json", plot=out / "figures")
print(est)                       # a short summary; est.summary() has the residual tests too
for fd in data:
    for start, stop in fd.metadata.get("gaps") or []:
        print(f"{fd.source}: logger dropout from {start:.3f} s to {stop:.3f} s, fitted piecewise")
print(f"fit {est.fit_estimation:.1f} %, model and figures in {out}/")
