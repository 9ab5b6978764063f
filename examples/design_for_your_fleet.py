"""Describe your own fleet in Python, check the Theorem's condition and design learning filters.

``python examples/design_for_your_fleet.py [OUT_FOLDER]`` (default ``my_design/``): two
vehicles unlike the built-in ones (a heavy and a light one, with their own PID gains and DOB
filters), a 20 % model-error bound on each, the Theorem's condition per frequency (paper
Sec. III) beside the law with its learning band, then the closed-form filters with which the
light vehicle learns from the heavy one, written with their C code.
"""

import sys
from pathlib import Path

import control as ct

import ilcdob
from ilcdob.app.commands import check_to_json, design_to_folder
from ilcdob.design.checks.theorem import format_theorem_table

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("my_design")

heavy = ilcdob.SystemSpec(
    name="heavy", plant=ilcdob.PlantSpec(ct.tf([1.0], [0.25, 1.0, 0.0, 0.0])),  # 1 / (s^2 (0.25 s + 1))
    controller=ilcdob.PIDSpec(kp=1.5, ki=0.1, kd=1.6, derivative_filter=0.05),
    dob=ilcdob.DOBSpec(q_order=3, q_time_constant=0.3), uncertainty=ilcdob.UncertaintySpec(bound=0.2))
light = ilcdob.SystemSpec(
    name="light", plant=ilcdob.PlantSpec(ct.tf([1.0], [0.06, 1.0, 0.0, 0.0]), delay=0.02),
    controller=ilcdob.PIDSpec(kp=6.0, ki=0.8, kd=3.5, derivative_filter=0.03),
    dob=ilcdob.DOBSpec(q_order=3, q_time_constant=0.1), uncertainty=ilcdob.UncertaintySpec(bound=0.2))
fleet = ilcdob.fleet_from_systems([heavy, light], sample_time=0.01)
print(fleet)

fleet_file = out.parent / f"{out.name}_fleet.toml"
fleet_file.parent.mkdir(parents=True, exist_ok=True)
fleet_file.write_text(ilcdob.fleet_to_toml(fleet.sample_time, fleet.systems))
print(format_theorem_table(check_to_json(None, fleet=fleet_file)))

design, written = design_to_folder(out, "heavy", "light", fleet=fleet_file, overwrite=True)
print(design)
print(f"filters and C code ({', '.join(written['c']['functions'])}) in {out}/")
