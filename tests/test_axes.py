"""Three axes: per-axis fleet sections ([system.y], [system.z]) and ``--axis`` on design, learn and check. Each
axis is learned independently: the y/z fleet is the x fleet with the axis's own plant, so an axis's design is
the x design of a fleet file written with that axis's plants at the top (the filters themselves are checked
against the paper's block formulas in test_closed_form.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.errors import FleetError
from ilcdob.fleet import load_fleet

FLEET = """\
sample_time = 0.01
[[system]]
name = "A"
plant = { num = [5.6], den = [1, 5.8, 1.37, 0] }
controller = { kp = 2.5, ki = 0.3, kd = 2.2, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.2 }
limits = { acceleration = 6.0 }
[system.y]
plant = { num = [5.0], den = [1, 5.0, 1.2, 0] }
[system.z]
plant = { num = [14.0], den = [1, 14.0, 0, 0] }
delay = 0.005
controller = { kp = 4.0, ki = 0.4, kd = 2.8, derivative_filter = 0.05 }

[[system]]
name = "B"
plant = { num = [11.9], den = [1, 12.3, 5.34, 0] }
controller = { kp = 2.5, ki = 0.3, kd = 2.2, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.2 }
[system.y]
plant = { num = [11.0], den = [1, 12.0, 5.0, 0] }
[system.z]
plant = { num = [16.0], den = [1, 16.0, 0, 0] }
delay = 0.005
"""


@pytest.fixture()
def fleet_file(tmp_path):
    path = tmp_path / "fleet.toml"
    path.write_text(FLEET)
    return path


def test_axis_sections_give_each_axis_its_plant_and_inherit_the_rest(fleet_file):
    """x ignores the sections; y takes its plant and inherits controller, DOB and limits; z states its own
    controller and delay; the fleets record their axis."""
    x, y, z = (load_fleet(fleet_file, ax) for ax in "xyz")
    assert [f.axis for f in (x, y, z)] == ["x", "y", "z"]
    assert x.systems[0].plant.den == (1, 5.8, 1.37, 0) and y.systems[0].plant.den == (1, 5.0, 1.2, 0)
    assert y.systems[0].controller == x.systems[0].controller and y.systems[0].dob == x.systems[0].dob
    assert y.systems[0].limits == x.systems[0].limits
    assert z.systems[0].controller.kp == 4.0 and z.systems[1].controller.kp == 2.5
    assert z.systems[0].plant.delay == 0.005 and y.systems[0].plant.delay == 0.0
    assert repr(z).endswith("; axis z>") and "; axis" not in repr(x)


@pytest.mark.parametrize("edit, match", [
    (lambda t: t.replace('[system.y]\nplant = { num = [11.0], den = [1, 12.0, 5.0, 0] }\n', ''),
     r"system 'B': no \[system.y\] section"),
    (lambda t: t.replace('[system.y]\nplant = { num = [5.0], den = [1, 5.0, 1.2, 0] }',
                         '[system.y]\ndob = { q_order = 3, q_time_constant = 0.1 }'),
     r"system 'A', \[system.y\]: missing key `plant`"),
    (lambda t: t.replace('[system.y]\nplant = { num = [5.0]', '[system.y]\nname = "C"\nplant = { num = [5.0]'),
     r"\[system.y\] key `name`"),
    (lambda t: t.replace('plant = { num = [5.0], den = [1, 5.0, 1.2, 0] }',
                         'plant = { num = [5.0], den = [1, 5.0, 1.2, 0] }\ngain = 3'),
     r"axis y\): system 'A'.*gain"),
])
def test_bad_axis_sections_name_the_system_and_key(tmp_path, edit, match):
    path = tmp_path / "bad.toml"
    path.write_text(edit(FLEET))
    with pytest.raises(FleetError, match=match):
        load_fleet(path, "y")
    load_fleet(path, "x")  # the x axis does not read the sections


def test_design_learn_and_check_per_axis(fleet_file, tmp_path):
    """``design --axis y`` designs from the y plants (filters.json says so, C names end in ``y_``), the
    filters differ from x's; ``learn --design`` of that folder refuses ``--axis z``; ``check --axis z``
    checks the z plants; the built-in fleet has no y axis."""
    out = {}
    for ax in "xy":
        out[ax] = tmp_path / f"d{ax}"
        assert main(["design", "--fleet", str(fleet_file), "--from", "A", "--to", "B", "--axis", ax,
                     "--out", str(out[ax]), "--quiet"]) == 0
    fx, fy = (json.loads((out[ax] / "filters.json").read_text()) for ax in "xy")
    assert fx["axis"] == "x" and fy["axis"] == "y"
    assert "ilcdob_a_b_y_learn" in (out["y"] / "filters.h").read_text()
    assert not np.allclose(np.asarray(fx["L1"]["sos"]), np.asarray(fy["L1"]["sos"]))
    # the y design is the x design of the file with the y plants on top
    flat = tmp_path / "flat.toml"
    flat.write_text(FLEET.replace("[1, 5.8, 1.37, 0]", "[1, 5.0, 1.2, 0]").replace("[5.6]", "[5.0]")
                    .replace("[11.9]", "[11.0]").replace("[1, 12.3, 5.34, 0]", "[1, 12.0, 5.0, 0]"))
    assert main(["design", "--fleet", str(flat), "--from", "A", "--to", "B", "--out", str(tmp_path / "f"),
                 "--quiet"]) == 0
    ff = json.loads((tmp_path / "f" / "filters.json").read_text())
    for key in ("L1", "L2"):
        np.testing.assert_array_equal(np.asarray(ff[key]["sos"]), np.asarray(fy[key]["sos"]))
    n = 300
    t = np.arange(n) * 0.01
    trial = tmp_path / "trial.csv"
    trial.write_text("time,error\n" + "\n".join(f"{a:.2f},{0.01 * np.sin(2 * a):.6f}" for a in t) + "\n")
    assert main(["learn", str(trial), "--design", str(out["y"]), "--error", "error", "--axis", "z",
                 "--out", str(tmp_path / "l"), "--quiet"]) == 2
    assert main(["learn", str(trial), "--design", str(out["y"]), "--error", "error",
                 "--out", str(tmp_path / "l"), "--quiet"]) == 0
    assert json.loads((tmp_path / "l" / "learning.json").read_text())["axis"] == "y"
    assert main(["check", "--fleet", str(fleet_file), "--axis", "z", "--bound", "0.1", "--quiet"]) in (0, 1)
    assert main(["design", "--from", "UAV1", "--to", "UAV2", "--axis", "y", "--out", str(tmp_path / "u"),
                 "--quiet"]) == 2
