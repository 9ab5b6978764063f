"""Identified models straight into fleets and the Python API.

``plant = { model = "x.json" }`` in fleet files, ``ilcdob fleet add``, ``ilcdob.load_model``,
python-control systems as plants, the fleet writer, and the README's Python example.
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import control as ct
import numpy as np
import pytest

import ilcdob
from ilcdob import FleetError, ModelFileError, SpecError
from ilcdob.app.cli import main
from ilcdob.design.pair import fleet_delta_sets
from ilcdob.examples import EXAMPLE_VEHICLES
from ilcdob.fleet_io import fleet_to_toml, model_reference
from ilcdob.loop import freqresp

TS = 0.02
W = np.logspace(-1, np.log10(0.9 * np.pi / TS), 40)  # rad/s

CONTROLLER = "controller = { kp = 1.2, ki = 0.12, kd = 1.53, derivative_filter = 0.05 }"
DOB = "dob = { q_order = 3, q_time_constant = 0.15 }"


def _model_dict(a0: float = 7.2, b0: float = 7.4, delay: float = 0.03, delay_estimated: bool = True,
                ts: float = 0.01) -> dict:
    """A model.json as `ilcdob identify` writes it: b0 / (s^2 (s + a0)) e^{-s delay}."""
    cov = [[4e-4, 3.5e-4], [3.5e-4, 3.8e-4]]
    if delay_estimated:
        cov = [row + [0.0] for row in cov] + [[0.0, 0.0, 1e-6]]
    return {"num": [b0], "den": [1.0, a0, 0.0, 0.0], "delay": delay,
            "structure": {"poles": 3, "zeros": 0, "integrators": 2}, "parameters": [a0, b0],
            "std": list(np.sqrt(np.diag(cov))), "delay_estimated": delay_estimated,
            "fit_percent": {"estimation": 98.5, "validation": 97.25}, "covariance": cov,
            "noise_variance": 1e-6, "sample_time": ts,
            "residuals": {"whiteness_inside_99": 1.0, "input_correlation_inside_99": 1.0},
            "signals": {"input": "acc_cmd", "output": "x"}, "solver": {"status": "converged"},
            "files": {"estimation": ["chirp.csv"], "validation": []}}


def _write_model(path: Path, **kw) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_model_dict(**kw)), encoding="utf-8")
    return path


def _fleet_text(system: str) -> str:
    return f'sample_time = {TS}\n[[system]]\nname = "UAV4"\n{system}\n{CONTROLLER}\n{DOB}\n'


def _write_fleet(path: Path, system: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(_fleet_text(system), encoding="utf-8")
    return path


# ------------------------------------------------------------------ plant = { model = ... }

def test_plant_from_model_file_carries_the_identification(tmp_path, monkeypatch):
    _write_model(tmp_path / "models" / "uav4.json")
    fleet_path = _write_fleet(tmp_path / "fleets" / "fleet.toml", 'plant = { model = "../models/uav4.json" }')
    monkeypatch.chdir(tmp_path / "models")  # the path is relative to the fleet file, not the working directory
    fleet = ilcdob.load_fleet(fleet_path)
    spec = fleet.systems[0]
    assert spec.plant == ilcdob.PlantSpec((7.4,), (1.0, 7.2, 0.0, 0.0), 0.03)
    assert spec.model is None
    ident = spec.identification
    assert (ident.poles, ident.zeros, ident.integrators) == (3, 0, 2)
    assert ident.parameters == (7.2, 7.4)
    assert ident.covariance == tuple(tuple(r) for r in _model_dict()["covariance"])
    assert ident.delay_estimated is True
    assert (ident.fit_estimation, ident.fit_validation) == (98.5, 97.25)
    assert ident.source == "../models/uav4.json"


def test_delta_set_of_a_model_file_is_the_identified_one(tmp_path):
    """The Delta set equals that of the same identification written inline (identify-fleet form)."""
    from ilcdob.uncertainty import ModelStructure
    from ilcdob.uncertainty import multiplicative_bound

    _write_model(tmp_path / "uav4.json")
    by_file = ilcdob.load_fleet(_write_fleet(tmp_path / "a.toml", 'plant = { model = "uav4.json" }'))
    inline_text = fleet_to_toml(TS, by_file.systems)  # num/den/delay + identification table, no file
    assert "identification = {" in inline_text and "uav4.json\" }" not in inline_text.split("source")[0]
    (tmp_path / "b.toml").write_text(inline_text)
    inline = ilcdob.load_fleet(tmp_path / "b.toml")
    assert inline.systems == by_file.systems
    ds = fleet_delta_sets(by_file, ["UAV4"], k=6, seed=3)["UAV4"]
    ref = fleet_delta_sets(inline, ["UAV4"], k=6, seed=3)["UAV4"]
    assert ds.source == "identification" and len(ds.loops) == 6
    for a, b in zip(ds.loops, ref.loops):
        assert a.spec.plant == b.spec.plant
    cov = np.asarray(_model_dict()["covariance"])
    expected = multiplicative_bound(ModelStructure(3, 0, 2), np.array([7.2, 7.4]), cov, 0.03, True, ds.w)
    np.testing.assert_allclose(ds.bound, expected, rtol=1e-12)
    # samples scatter around the model with the file's standard deviations (within 5 sigma, not zero)
    dev = np.array([[lp.spec.plant.den[1] - 7.2, lp.spec.plant.num[0] - 7.4, lp.spec.plant.delay - 0.03]
                    for lp in ds.loops]) / np.sqrt(np.diag(cov))
    assert np.all(np.abs(dev) < 5) and np.all(np.std(dev, axis=0) > 0.1)
    for lp in ds.loops:  # the model used by DOB and learning filters stays the identified one
        assert lp.spec.nominal_plant == by_file.systems[0].plant


def test_nominal_model_from_a_file(tmp_path):
    _write_model(tmp_path / "uav4.json")
    system = 'plant = { num = [7.0], den = [1.0, 7.0, 0.0, 0.0] }\nmodel = { model = "uav4.json" }'
    spec = ilcdob.load_fleet(_write_fleet(tmp_path / "f.toml", system)).systems[0]
    assert spec.plant == ilcdob.PlantSpec((7.0,), (1.0, 7.0, 0.0, 0.0), 0.0)
    assert spec.model == ilcdob.PlantSpec((7.4,), (1.0, 7.2, 0.0, 0.0), 0.03)
    assert spec.identification.parameters == (7.2, 7.4)  # the identification of the nominal model
    # a plant file with a hand-written nominal model: the file's covariance is not about P_hat
    system = 'plant = { model = "uav4.json" }\nmodel = { num = [7.0], den = [1.0, 7.0, 0.0, 0.0] }'
    spec = ilcdob.load_fleet(_write_fleet(tmp_path / "g.toml", system)).systems[0]
    assert spec.plant.delay == 0.03 and spec.identification is None


@pytest.mark.parametrize(
    "system, model_text, must_name",
    [
        ('plant = { model = "missing.json" }', None, ["missing.json", "plant.model", "cannot read"]),
        ('plant = { model = "uav4.json" }', "{ not json", ["uav4.json", "plant.model", "not valid JSON"]),
        ('plant = { model = "uav4.json" }', "drop:covariance", ["uav4.json", "plant.model", "covariance", "missing"]),
        ('plant = { model = "uav4.json" }', "set:covariance=[[1.0]]", ["uav4.json", "covariance", "(1, 1)", "3 x 3"]),
        ('plant = { model = "uav4.json" }', "set:num=[9.0]", ["uav4.json", "num", "9.0", "parameters"]),
        ('plant = { model = "uav4.json", num = [1.0] }', "", ["`plant`", "uav4.json", "num", "[1.0]"]),
        ('model = { model = "uav4.json", den = [1.0, 2.0] }\nplant = { num = [1.0], den = [1.0, 1.0, 0.0, 0.0] }',
         "", ["`model`", "uav4.json", "den"]),
        ('plant = { model = "uav4.json" }\ndelay = 0.1', "", ["`delay`", "0.1", "uav4.json"]),
        ('plant = { model = "uav4.json" }\nidentification = { poles = 3, zeros = 0, integrators = 2, '
         "parameters = [1.0, 1.0], covariance = [[1.0, 0.0], [0.0, 1.0]] }", "", ["`identification`", "uav4.json"]),
        ("plant = { model = 4 }", "", ["plant.model", "4"]),
    ],
)
def test_bad_model_files_name_fleet_system_key_and_value(tmp_path, system, model_text, must_name):
    if model_text is not None:
        data = _model_dict()
        if model_text.startswith("drop:"):
            del data[model_text[5:]]
            model_text = json.dumps(data)
        elif model_text.startswith("set:"):
            key, value = model_text[4:].split("=", 1)
            data[key] = json.loads(value)
            model_text = json.dumps(data)
        elif not model_text:
            model_text = json.dumps(data)
        (tmp_path / "uav4.json").write_text(model_text, encoding="utf-8")
    path = _write_fleet(tmp_path / "fleet.toml", system)
    with pytest.raises(FleetError) as info:
        ilcdob.load_fleet(path)
    msg = str(info.value)
    for part in [str(path), "'UAV4'", *must_name]:
        assert part in msg, msg


# ------------------------------------------------------------------ load_model

def test_load_model(tmp_path):
    path = _write_model(tmp_path / "uav4.json")
    m = ilcdob.load_model(path)
    assert isinstance(m, ilcdob.IdentifiedModel)
    assert (m.num, m.den, m.delay, m.sample_time) == ((7.4,), (1.0, 7.2, 0.0, 0.0), 0.03, 0.01)
    assert (m.poles, m.zeros, m.integrators) == (3, 0, 2)
    assert m.structure.n_params == 2
    assert m.parameters == (7.2, 7.4) and m.delay_estimated
    np.testing.assert_array_equal(np.asarray(m.covariance), _model_dict()["covariance"])
    np.testing.assert_allclose(m.std, [0.02, np.sqrt(3.8e-4), 1e-3], rtol=1e-12)
    assert (m.fit_estimation, m.fit_validation, m.input, m.output) == (98.5, 97.25, "acc_cmd", "x")
    tf = m.transfer_function
    assert isinstance(tf, ct.TransferFunction) and tf.dt == 0
    s = 1j * W
    np.testing.assert_allclose(tf(s), 7.4 / (s**2 * (s + 7.2)), rtol=1e-12)
    assert m.plant_spec() == ilcdob.PlantSpec((7.4,), (1.0, 7.2, 0.0, 0.0), 0.03)
    assert m.identification_spec().source == str(path)
    pid, dob = ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.05), ilcdob.DOBSpec(3, 0.15)
    fleet = ilcdob.fleet_from_systems([m.system_spec("UAV4", pid, dob)], TS)
    assert fleet.systems[0].identification.covariance == m.covariance
    # a fit without validation data writes null; a fixed delay has no variance
    data = _model_dict(delay_estimated=False)
    data["fit_percent"]["validation"] = None
    path.write_text(json.dumps(data))
    m = ilcdob.load_model(path)
    assert np.isnan(m.fit_validation) and np.asarray(m.covariance).shape == (2, 2)


def test_load_model_errors_name_file_key_and_value(tmp_path):
    with pytest.raises(ModelFileError, match="cannot read"):
        ilcdob.load_model(tmp_path / "none.json")
    path = tmp_path / "m.json"
    data = _model_dict()
    data["structure"]["poles"] = 2.5
    path.write_text(json.dumps(data))
    with pytest.raises(ModelFileError) as info:
        ilcdob.load_model(path)
    assert all(p in str(info.value) for p in (str(path), "structure.poles", "2.5")), info.value
    path.write_text(json.dumps([1, 2]))
    with pytest.raises(ModelFileError, match="expected a JSON object"):
        ilcdob.load_model(path)
    assert issubclass(ModelFileError, ValueError) and issubclass(ModelFileError, ilcdob.IlcdobError)


# ------------------------------------------------------------------ ilcdob fleet add

def _add(fleet: Path, name: str, model: str, *extra: str, kp: str = "1.2") -> int:
    return main(["fleet", "add", str(fleet), "--name", name, "--model", model, "--kp", kp, "--ki", "0.12",
                 "--kd", "1.53", "--q-order", "3", "--q-time-constant", "0.15", *extra])


def test_fleet_add_creates_appends_and_refuses(tmp_path, monkeypatch, capsys):
    _write_model(tmp_path / "models" / "uav4.json", ts=0.01)
    _write_model(tmp_path / "models" / "uav5.json", a0=9.0, b0=9.5, delay=0.0, delay_estimated=False)
    monkeypatch.chdir(tmp_path)
    fleet_path = tmp_path / "fleets" / "fleet.toml"
    # create: the sample time comes from the model file, and the message says so
    assert _add(fleet_path, "UAV4", "models/uav4.json") == 0
    assert "sample time 0.01 s (from the sample_time of models/uav4.json)" in capsys.readouterr().err
    data = tomllib.loads(fleet_path.read_text())
    assert data["sample_time"] == 0.01
    assert data["system"][0]["plant"] == {"model": "../models/uav4.json"}  # relative to the fleet file
    # append, with the controller written as given
    assert _add(fleet_path, "UAV5", "models/uav5.json", "--derivative-filter", "0.04") == 0
    fleet = ilcdob.load_fleet(fleet_path)
    assert fleet.names == ["UAV4", "UAV5"]
    assert fleet.systems[1].controller == ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.04)
    assert fleet.systems[1].plant == ilcdob.PlantSpec((9.5,), (1.0, 9.0, 0.0, 0.0), 0.0)
    assert fleet.systems[1].identification.parameters == (9.0, 9.5)
    before = fleet_path.read_bytes()
    capsys.readouterr()
    # refused, each with nothing written: duplicate name, unstable loop, invalid gain, sample-time conflict
    for args, kw, words in [(("UAV4", "models/uav5.json"), {}, ["UAV4", "exists"]),
                            (("UAV6", "models/uav5.json"), {"kp": "300"}, ["UAV6", "unstable"]),
                            (("UAV6", "models/uav5.json"), {"kp": "-1"}, ["UAV6", "controller.kp", "-1.0"]),
                            (("UAV6", "models/uav5.json", "--sample-time", "0.02"), {}, ["sample_time", "0.02"]),
                            (("UAV6", "models/none.json"), {}, ["none.json", "cannot read"])]:
        assert _add(fleet_path, *args, **kw) == 2
        err = capsys.readouterr().err
        assert all(w in err for w in words), err
        assert fleet_path.read_bytes() == before
    assert sorted(p.name for p in fleet_path.parent.iterdir()) == ["fleet.toml"]  # no temporary files left


def test_fleet_add_invalid_first_system_writes_nothing(tmp_path, capsys):
    model = _write_model(tmp_path / "uav4.json")
    fleet_path = tmp_path / "new.toml"
    assert _add(fleet_path, "UAV4", str(model), kp="300") == 2
    assert "unstable" in capsys.readouterr().err
    assert not fleet_path.exists()
    assert _add(fleet_path, "UAV4", str(model), "--sample-time", "0.02") == 0
    assert "from --sample-time" in capsys.readouterr().err
    assert ilcdob.load_fleet(fleet_path).sample_time == 0.02


def test_add_system_keeps_the_existing_text(tmp_path):
    fleet_path = tmp_path / "fleet.toml"
    fleet_path.write_text("# my comment\n" + (Path(ilcdob.fleet.DEFAULT_FLEET_PATH).read_text()).rstrip("\n"))
    original = fleet_path.read_text()
    model = _write_model(tmp_path / "m" / "uav4.json")
    fleet = ilcdob.add_system(fleet_path, "UAV4", model, ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.05),
                              ilcdob.DOBSpec(3, 0.15), uncertainty=ilcdob.UncertaintySpec(0.3))
    assert fleet_path.read_text().startswith(original + "\n")
    assert fleet.names == ["UAV1", "UAV2", "UAV3", "UAV4"]
    assert fleet.systems[3].uncertainty.bound == 0.3
    assert ilcdob.load_fleet(fleet_path).systems == fleet.systems
    assert model_reference(model, fleet_path) == "m/uav4.json"


def test_fleet_to_toml_round_trips(fleet, tmp_path):
    description = 'copy of "UAV1..3" \\ tab\t newline\n del\x7f'
    text = fleet_to_toml(fleet.sample_time, fleet.systems, description=description, header="copied")
    assert text.startswith("# copied\n")
    assert tomllib.loads(text)["description"] == description
    again = ilcdob.fleet_from_dict(tomllib.loads(text))
    assert again.systems == fleet.systems and again.sample_time == fleet.sample_time
    model = _write_model(tmp_path / "uav4.json")
    spec = ilcdob.load_model(model).system_spec("UAV4", ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.05),
                                                 ilcdob.DOBSpec(3, 0.15), noise=ilcdob.NoiseSpec(0.02, 3.0, 0.5))
    text = fleet_to_toml(TS, [spec], model_files={"UAV4": "uav4.json"})
    assert 'plant = { model = "uav4.json" }' in text and "identification" not in text
    loaded = ilcdob.fleet_from_dict(tomllib.loads(text), base_dir=tmp_path).systems[0]
    assert loaded.plant == spec.plant and loaded.noise == spec.noise
    assert loaded.identification.covariance == spec.identification.covariance


# ------------------------------------------------------------------ python-control systems

PID = ilcdob.PIDSpec(3.0, 0.3, 2.4, 0.05)
Q = ilcdob.DOBSpec(3, 0.15)


def test_lti_plants_give_the_same_loops():
    tf = ct.tf([1.0], [0.1, 1.0, 0.0, 0.0])
    assert ilcdob.PlantSpec(tf) == ilcdob.PlantSpec((1.0,), (0.1, 1.0, 0.0, 0.0))
    assert ilcdob.PlantSpec.from_lti(tf, delay=0.03).delay == 0.03
    ss = ct.ss(tf)
    from_ss = ilcdob.PlantSpec.from_lti(ss, delay=0.03)
    np.testing.assert_allclose(np.polyval(from_ss.num, 1j * W) / np.polyval(from_ss.den, 1j * W),
                               1.0 / ((1j * W) ** 2 * (0.1j * W + 1)), rtol=1e-10)
    systems = [ilcdob.SystemSpec("by_poly", ilcdob.PlantSpec((1.0,), (0.1, 1.0, 0.0, 0.0), 0.03), PID, Q),
               ilcdob.SystemSpec("by_tf", ilcdob.PlantSpec(tf, delay=0.03), PID, Q),
               ilcdob.SystemSpec("by_ss", from_ss, PID, Q),
               ilcdob.SystemSpec(name="tf_direct", plant=ct.tf([10.0], [1.0, 10.0, 0.0, 0.0]), controller=PID, dob=Q),
               ilcdob.SystemSpec(name="ss_direct", plant=ct.ss(tf), controller=PID, dob=Q)]
    fleet = ilcdob.fleet_from_systems(systems, TS)
    ref = fleet.loop("by_poly")
    for name in ("by_tf", "by_ss"):
        for attr in ("G_r", "G_d", "G_f", "Omega"):
            np.testing.assert_allclose(freqresp(getattr(fleet.loop(name), attr), W),
                                       freqresp(getattr(ref, attr), W), rtol=1e-8, err_msg=f"{name} {attr}")
    no_delay = fleet.loop("tf_direct")
    for attr in ("G_r", "G_d"):
        np.testing.assert_allclose(freqresp(getattr(fleet.loop("ss_direct"), attr), W),
                                   freqresp(getattr(no_delay, attr), W), rtol=1e-8)
    # a python-control nominal model, differing from the plant
    spec = ilcdob.SystemSpec("m", plant=tf, controller=PID, dob=Q, model=ct.tf([9.0], [1.0, 9.0, 0.0, 0.0]))
    assert spec.model == ilcdob.PlantSpec((9.0,), (1.0, 9.0, 0.0, 0.0))


@pytest.mark.parametrize(
    "sys, must_name",
    [
        (ct.tf([1.0], [0.1, 1.0, 0.0, 0.0], 0.02), ["discrete-time", "dt = 0.02"]),
        (ct.tf([[[1.0]], [[2.0]]], [[[1.0, 1.0, 0.0]], [[1.0, 2.0, 0.0]]]), ["2 output(s)", "SISO"]),
        (ct.tf([1.0, 0.0, 1.0], [1.0, 1.0, 0.0]), ["strictly proper", "num=[1.0, 0.0, 1.0]"]),
        (ct.ss([[-1.0]], [[1.0]], [[1.0]], [[0.5]]), ["D = 0.5", "strictly proper"]),
        (ct.frd([1.0, 0.5], [1.0, 2.0]), ["FrequencyResponseData", "TransferFunction or StateSpace"]),
    ],
)
def test_bad_lti_plants_are_refused(sys, must_name):
    with pytest.raises(SpecError) as info:
        ilcdob.PlantSpec.from_lti(sys)
    for part in must_name:
        assert part in str(info.value), info.value
    with pytest.raises(SpecError) as info:
        ilcdob.SystemSpec(name="X", plant=sys, controller=PID, dob=Q)
    assert "'X'" in str(info.value) and "`plant`" in str(info.value)


def test_plant_spec_argument_errors():
    with pytest.raises(SpecError, match="`plant.den`: missing"):
        ilcdob.PlantSpec((1.0,))
    with pytest.raises(SpecError, match="either the system alone"):
        ilcdob.PlantSpec(ct.tf([1.0], [1.0, 1.0, 0.0]), (1.0, 2.0))
    with pytest.raises(SpecError, match="expected a python-control"):
        ilcdob.PlantSpec.from_lti([1.0, 2.0])
    with pytest.raises(SpecError, match="expected a PlantSpec"):
        ilcdob.SystemSpec(name="X", plant=[1.0], controller=PID, dob=Q)


# ------------------------------------------------------------------ the README example

def _readme_block() -> str:
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    section = readme.split("## From flight logs to learning filters in Python", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert len(blocks) == 1, "the section holds one Python example"
    return blocks[0]


TRUTH = {name: (v.a0, v.b0, v.delay, v.controller) for name, v in EXAMPLE_VEHICLES.items()}


def test_readme_example_runs_and_identifies_the_vehicles(tmp_path, monkeypatch):
    """The README's block, verbatim, in an empty folder, twice in one process (as in a notebook):
    the same fleet both times, each vehicle identified close to the truth of its example flight."""
    monkeypatch.chdir(tmp_path)
    runs = []
    for _ in range(2):
        namespace: dict = {}
        exec(compile(_readme_block(), "README.md", "exec"), namespace)
        runs.append(namespace)
    fleet, design = runs[-1]["fleet"], runs[-1]["design"]
    assert runs[0]["fleet"].names == fleet.names and runs[0]["design"].filters == design.filters
    assert fleet.names == ["UAV1", "UAV4"] and fleet.sample_time == TS
    for spec in fleet.systems:
        a0, b0, delay, pid = TRUTH[spec.name]
        model = ilcdob.load_model(tmp_path / f"{spec.name}.json")
        assert spec.plant == model.plant_spec() and spec.controller == pid
        assert spec.identification.covariance == model.covariance and model.delay_estimated
        # 1 mm noise on a ~10 cm response: parameters within 2 %, delay within half a sample
        np.testing.assert_allclose(spec.plant.den, [1.0, a0, 0.0, 0.0], rtol=0.02, atol=1e-9)
        np.testing.assert_allclose(spec.plant.num, [b0], rtol=0.02)
        assert abs(spec.plant.delay - delay) < TS / 2
    assert {"L1", "L2"} <= set(design.filters)
    # the learning signal of UAV4 from the identified models is that of the true models, within 5 %
    true_fleet = ilcdob.fleet_from_systems(
        [ilcdob.SystemSpec(n, ilcdob.PlantSpec.from_lti(ct.tf([b], [1.0, a, 0.0, 0.0]), delay=d), pid,
                           ilcdob.DOBSpec(3, 0.15)) for n, (a, b, d, pid) in TRUTH.items()], TS)
    from ilcdob.design.pair import design_pair

    true_design = design_pair(true_fleet, "UAV1", "UAV4", "closed-form")
    t = np.arange(1000) * TS
    e_prev = 0.02 * np.sin(2 * np.pi * 0.3 * t) * np.minimum(t / 2.0, 1.0)  # m
    df_prev = np.zeros_like(t)
    got, want = design.learn(e_prev, df_prev), true_design.learn(e_prev, df_prev)
    assert np.linalg.norm(got - want) < 0.05 * np.linalg.norm(want)


def test_a_model_at_another_rate_is_named_and_an_unstable_loop_names_its_sample_time(tmp_path):
    """Adding a model identified at 0.01 s to a 0.02 s fleet warns with both rates and the option that fits at the
    fleet's; a loop that is unstable says at which sample time (gains tuned at one rate can fail at a slower one)."""
    fleet_path = tmp_path / "fleet.toml"
    fleet_path.write_text(Path(ilcdob.fleet.DEFAULT_FLEET_PATH).read_text())
    model = _write_model(tmp_path / "uav4.json", ts=0.01)
    with pytest.warns(UserWarning, match=r"system 'UAV4': its model was identified at a sample time of 0.01 s, the "
                                         r"fleet flies at 0.02 s.*identify --resample 0.02"):
        ilcdob.add_system(fleet_path, "UAV4", model, ilcdob.PIDSpec(1.2, 0.12, 1.53, 0.05), ilcdob.DOBSpec(3, 0.15))
    with pytest.raises(ilcdob.errors.FleetError, match=r"unstable at the sample time 0.02 s.*check the sample time"):
        ilcdob.add_system(fleet_path, "UAV5", model, ilcdob.PIDSpec(300.0, 0.12, 1.53, 0.05), ilcdob.DOBSpec(3, 0.15))


def test_fleet_add_states_the_vehicles_limit_and_sensor(tmp_path, capsys):
    """``fleet add --tilt/--thrust-to-weight/--acceleration-limit --sensor-noise`` write the system's ``limits`` and
    ``sensor`` tables, which the fleet then checks learning signals against (g tan 30 deg = 5.66 m/s^2); an
    invalid one is refused with nothing written."""
    model = str(_write_model(tmp_path / "uav4.json", ts=0.02))
    fleet_path = tmp_path / "fleet.toml"
    assert _add(fleet_path, "UAV4", model, "--tilt", "30", "--sensor-noise", "0.0005") == 0
    assert _add(fleet_path, "UAV5", model, "--acceleration-limit", "4.5") == 0
    a, b = ilcdob.load_fleet(fleet_path).systems
    assert a.limits == ilcdob.LimitSpec(tilt=30.0) and a.sensor == ilcdob.SensorSpec(0.0005)
    assert a.limits.max_acceleration == pytest.approx(9.80665 * np.tan(np.radians(30.0)))
    assert b.limits == ilcdob.LimitSpec(acceleration=4.5) and b.sensor is None
    before = fleet_path.read_bytes()
    capsys.readouterr()
    assert _add(fleet_path, "UAV6", model, "--tilt", "95") == 2
    err = capsys.readouterr().err
    assert "system 'UAV6'" in err and "limits.tilt" in err and "95" in err and "nothing written" in err
    assert fleet_path.read_bytes() == before
