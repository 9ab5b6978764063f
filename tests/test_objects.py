"""Designs and models as python-control objects, short reprs, .mat export and the py.typed marker.

The learning filters of a design, read back from its ``filters.json``, must have the response of
the coefficients as written (``coefficients_freqresp``) and of the paper's block formula
``L1 = -(1 - Q_j) Gd_{j-1}^{-1}``, ``L2 = L1 Gf_{j-1}`` evaluated on ``z = e^{jw Ts}`` with
python-control from the loops' maps (not through the export). The .mat files must hold the
source numbers exactly (scipy.io.loadmat) and be enough to recompute the learning law.
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import json

import control as ct
import numpy as np
import pytest
import scipy.io

import ilcdob
from ilcdob.design.filters.coefficients import apply_coefficients, coefficients_freqresp
from ilcdob.design.law import apply_learning
from ilcdob.design.export.objects import LearningFilterTF, design_to_mat, filter_tf, filters_tf, load_design
from ilcdob.design.maps.closed_form import closed_form_filters
from ilcdob.design.pair import design_pair, fleet_delta_sets
from ilcdob.errors import ModelFileError, NumericalError, SpecError
from ilcdob.identified import model_from_dict
from ilcdob.identification import FitOptions, tfest
from ilcdob.identification.oe import simulate_zoh
from ilcdob.loop import freqresp
from ilcdob.matfile import MODEL_VARIABLES, model_to_mat
from ilcdob.signals import FlightData
from ilcdob.uncertainty import ModelStructure


@pytest.fixture(scope="module")
def closed_form():
    return design_pair(ilcdob.default_fleet(), "UAV1", "UAV2", "closed-form")


@pytest.fixture(scope="module")
def estimate():
    """A fit of G(s) = (2 s + 3)/(s^2 + 1.4 s + 4) e^{-0.05 s} from signals named thrust (N) and alt (m)."""
    structure, ts, n = ModelStructure(2, 1, 0), 0.02, 1500
    rng = np.random.default_rng(0)
    u = np.repeat(rng.choice([-1.0, 1.0], size=n // 50 + 1), 50)[:n]
    y = simulate_zoh(structure, structure.join([2.0, 3.0], [1.0, 1.4, 4.0]), u, ts, 0.05)
    data = FlightData(np.arange(n) * ts, {"thrust": u, "alt": y + 0.01 * rng.standard_normal(n)},
                      units={"thrust": "N", "alt": "m"}, source="step test")
    return data, tfest(data, "thrust", "alt", structure, FitOptions(delay="auto"))


def _design_folder(tmp_path, filters):
    folder = tmp_path / "design"
    folder.mkdir()
    (folder / "filters.json").write_text(json.dumps(filters), encoding="utf-8")
    return folder


def test_design_folder_filters_are_control_objects_with_the_papers_response(closed_form, tmp_path):
    fleet = ilcdob.default_fleet()
    filters = load_design(_design_folder(tmp_path, closed_form.filters))
    ts = closed_form.filters["sample_time"]
    w = np.geomspace(0.01, np.pi / ts, 300)
    # the paper's formula from the loops' maps, evaluated by python-control at z = e^{jw Ts}
    src, tgt = fleet.loop("UAV1").nominal, fleet.loop("UAV2")
    paper = {"L1": -(1 - freqresp(tgt.Q, w)) / freqresp(src.G_d, w)}
    paper["L2"] = paper["L1"] * freqresp(src.G_f, w)
    z = np.exp(1j * w * ts)
    for key in ("L1", "L2"):
        f = filters[key]
        assert isinstance(f, LearningFilterTF) and f.advance == closed_form.filters[key]["advance"]
        assert all(isinstance(s, ct.TransferFunction) and s.dt == ts for s in f.sections)
        h = f.freqresp(w)
        np.testing.assert_allclose(h, coefficients_freqresp(closed_form.filters[key], w, ts), rtol=1e-9)
        np.testing.assert_allclose(h, paper[key], rtol=1e-8)
        sys, advance = f.to_control()
        assert isinstance(sys, ct.StateSpace) and sys.dt == ts and advance == f.advance
        np.testing.assert_allclose(np.asarray(sys(z)).ravel() * z ** advance, paper[key], rtol=1e-8)
    assert filters["L1"].advance == 24 and filters["L1"].unit == "(m/s^2)/m"


def test_the_causal_part_run_by_python_control_is_the_filter_as_applied(closed_form):
    f = filters_tf(closed_form.filters)["L1"]
    x = np.sin(np.linspace(0.0, 6.0, 400)) ** 2  # starts at rest
    sys, advance = f.to_control()
    y = ct.forced_response(sys, U=x).outputs[advance:]
    want = apply_coefficients(closed_form.filters["L1"], x)[:x.size - advance]
    np.testing.assert_allclose(y, want, rtol=0, atol=1e-9 * np.max(np.abs(want)))
    np.testing.assert_array_equal(f.apply(x), apply_coefficients(closed_form.filters["L1"], x))


def test_to_tf_refuses_a_product_that_loses_the_response(closed_form):
    filters = filters_tf(closed_form.filters)
    with pytest.raises(NumericalError, match=r"L1: .* disagree .* use to_control\(\)"):
        filters["L1"].to_tf()
    tf, advance = filters["L2"].to_tf()  # one section: exact
    w = np.geomspace(0.1, 100.0, 50)
    np.testing.assert_allclose(freqresp(tf, w), filters["L2"].freqresp(w), rtol=1e-12)
    assert advance == 0


def test_num_den_filters_and_bad_entries():
    fir = filter_tf({"advance": 2, "num": [0.5, 0.3, 0.2], "den": [1.0]}, 0.01, "L2", "1")
    iir = filter_tf({"advance": 0, "num": [0.2], "den": [1.0, -0.8]}, 0.01, "L1")
    w = np.linspace(1.0, 300.0, 40)
    for f in (fir, iir):
        np.testing.assert_allclose(f.freqresp(w), coefficients_freqresp(f.coefficients, w, 0.01), rtol=1e-12)
        tf, _ = f.to_tf()
        assert tf.dt == 0.01
    assert "num/den" in repr(fir) and "z^2" in repr(fir)
    with pytest.raises(SpecError, match=r"`L1.sos`: got an array of shape \(1, 5\)"):
        filter_tf({"advance": 0, "sos": [[1, 0, 0, 1, 0]]}, 0.02, "L1")
    with pytest.raises(SpecError, match=r"`ts`: got 0, expected the sample time"):
        filter_tf({"advance": 0, "num": [1.0], "den": [1.0]}, 0)


def test_load_design_names_the_file_and_what_is_wrong(closed_form, tmp_path):
    with pytest.raises(SpecError, match="filters.json"):
        load_design(tmp_path)  # no filters.json
    lifted = {"method": "norm-optimal", "from": "UAV1", "to": "UAV2", "sample_time": 0.02, "n": 500}
    with pytest.raises(SpecError, match=r"no L1 and L2 filter\(s\) \(method 'norm-optimal'\): .*lifted.npz"):
        load_design(_design_folder(tmp_path, lifted))
    bad = json.loads(json.dumps(closed_form.filters))
    bad["L2"]["advance"] = -1
    (tmp_path / "bad.json").write_text(json.dumps(bad), encoding="utf-8")
    with pytest.raises(SpecError, match=r"bad.json: `L2.advance`: got -1"):
        load_design(tmp_path / "bad.json")


def test_tfestimate_model_keeps_signal_names_and_delay(estimate):
    _, est = estimate
    g = est.model
    assert g.input_labels == ["thrust"] and g.output_labels == ["alt"]
    assert g.input_delay == est.delay and abs(est.delay - 0.05) < 0.005
    sys, delay = est.to_control()
    assert delay == est.delay and sys.input_labels == ["thrust"]
    w = np.geomspace(0.1, 50.0, 20)
    np.testing.assert_allclose(np.asarray(sys(1j * w)).ravel() * np.exp(-1j * w * delay), est.frequency_response(w),
                               rtol=1e-10)
    ulog = dataclasses.replace(est, input="vehicle_acceleration.xyz[0]", output="vehicle_local_position.x")
    assert ulog.model.input_labels == ["vehicle_acceleration_xyz[0]"]  # python-control refuses '.' in names
    assert ulog.model.output_labels == ["vehicle_local_position_x"]


def test_reprs_are_one_short_line(estimate, closed_form):
    data, est = estimate
    fleet = ilcdob.default_fleet()
    l1 = filters_tf(closed_form.filters)["L1"]
    for obj, needles in [(fleet.loop("UAV1"), ["'UAV1'", "0.02 s", "d_f [m/s^2]", "y [m]", "11 states"]),
                         (data, ["'step test'", "1500 samples", "0.02 s", "thrust [N]", "alt [m]"]),
                         (est, ["thrust -> alt", "fit 9"]),
                         (l1, ["L1", "z^24", "23-tap", "6 sections", "0.02 s"]),
                         (closed_form_filters(fleet.loop("UAV1"), fleet.loop("UAV2")), ["'UAV1' -> 'UAV2'", "L2"]),
                         (closed_form_filters(fleet.loop("UAV1"), fleet.loop("UAV2")).L1, ["poles", "advance"]),
                         (fleet_delta_sets(fleet, ["UAV1"])["UAV1"], ["'UAV1'", "sampled loops", "rad/s"]),
                         (closed_form.learning(0.01 * np.sin(np.arange(500) * 0.02), np.zeros(500)),
                          ["500 samples", "m/s^2"]),
                         (model_from_dict(json.loads(json.dumps(est.to_dict())), "uav4.json"),
                          ["'uav4.json'", "G(s) = (", "Ts 0.02 s"])]:
        text = repr(obj)
        assert "\n" not in text and len(text) <= 200, text
        assert all(n in text for n in needles), (needles, text)
    many = FlightData(np.arange(3) * 0.1, {f"a_very_long_signal_name_number_{i}": np.zeros(3) for i in range(50)},
                      source="x" * 300)
    assert len(repr(many)) <= 200 and "+4" in repr(many) and "50 signals" in repr(many)
    # notebooks: a table each, the numbers of the object
    html = data._repr_html_()
    assert html.startswith("<table>") and "1500 samples" in html and "<td>thrust</td><td>N</td>" in html
    model = model_from_dict(json.loads(json.dumps(est.to_dict())), "uav4.json")
    assert model._repr_html_().startswith("<table>") and f"{model.std[0]:.4g}" in model._repr_html_()


def test_design_to_mat_holds_the_numbers_and_the_law(tmp_path):
    design = design_pair(ilcdob.default_fleet(), "UAV1", "UAV2", "closed-form", band=5.0,
                         disturbance="airframe")
    f = design.filters
    path = design_to_mat(f, tmp_path / "out" / "design.mat")
    m = scipy.io.loadmat(path)
    assert m["sample_time"].item() == f["sample_time"] and str(m["source_system"][0]) == "UAV1"
    for key in ("L1", "L2"):
        assert int(m[f"{key}_advance"].item()) == f[key]["advance"]
        np.testing.assert_array_equal(m[f"{key}_sos"], np.array(f[key]["sos"]))
    np.testing.assert_array_equal(m["L1_lookahead"].ravel(), f["L1"]["lookahead"])
    np.testing.assert_array_equal(m["L2_num"].ravel(), f["L2"]["num"])
    assert m["L1_num"].size == 0  # filters.json left the lossy polynomials out
    np.testing.assert_array_equal(m["band_sos"], np.array(f["band"]["sos"]))
    np.testing.assert_array_equal(m["W_sos"], np.array(f["disturbance"]["W"]["sos"]))
    assert m["limit_acceleration_m_s2"].item() == f["limit"]["acceleration_m_s2"]
    described = [line.split(":")[0] for line in m["description"]]
    assert described == [k for k in m if not k.startswith("__") and k != "description"]
    # the variables alone recompute the learning law
    rebuilt = {"from": "UAV1", "to": "UAV2", "sample_time": m["sample_time"].item(),
               **{k: {"advance": int(m[f"{k}_advance"].item()), "sos": m[f"{k}_sos"].tolist(),
                      **({"lookahead": m[f"{k}_lookahead"].ravel().tolist()} if m[f"{k}_lookahead"].size else {})}
                  for k in ("L1", "L2")},
               "band": {"sos": m["band_sos"].tolist(), "zi": m["band_zi"].tolist(), "pad": int(m["band_pad"].item()),
                        "end_fit": int(m["band_end_fit"].item()), "start": str(m["band_start"][0]),
                        "output_start": str(m["band_output_start"][0])},
               "disturbance": {"W": {"sos": m["W_sos"].tolist()}}}
    e = np.sin(np.linspace(0.0, 8.0, 300)) * np.linspace(0.0, 1.0, 300)
    np.testing.assert_array_equal(apply_learning(rebuilt, e, 0.1 * e), apply_learning(f, e, 0.1 * e))


def test_a_design_folder_writes_its_mat_and_design_to_mat_reads_a_folder(tmp_path):
    """``ilcdob design`` writes ``filters.mat`` beside ``filters.json`` (closed form and fir); ``design_to_mat``
    takes the folder as well as the parsed file, and refuses ``load_design``'s python-control filters with the
    route that works (they leave the band, the correction and the limit out)."""
    from ilcdob.app.cli import main

    out = tmp_path / "d"
    assert main(["--quiet", "design", "--from", "UAV1", "--to", "UAV2", "--out", str(out)]) == 0
    f = json.loads((out / "filters.json").read_text())
    written = scipy.io.loadmat(out / "filters.mat")
    from_folder = scipy.io.loadmat(design_to_mat(out, tmp_path / "folder.mat"))
    from_file = scipy.io.loadmat(design_to_mat(f, tmp_path / "file.mat"))
    for m in (written, from_folder):
        assert sorted(m) == sorted(from_file) and str(m["target_system"][0]) == "UAV2"
        for key in (k for k in from_file if not k.startswith("__")):
            np.testing.assert_array_equal(m[key], from_file[key], err_msg=key)
    np.testing.assert_array_equal(written["L1_sos"], np.array(f["L1"]["sos"]))
    with pytest.raises(SpecError, match=r"python-control filters of load_design .*pass the design folder itself"):
        design_to_mat(load_design(out), tmp_path / "x.mat")
    assert not (tmp_path / "x.mat").exists()


def test_model_to_mat_holds_the_model(estimate, tmp_path):
    _, est = estimate
    model = json.loads(json.dumps(est.to_dict()))  # as model.json holds it
    m = scipy.io.loadmat(model_to_mat(model, tmp_path / "model.mat"))
    np.testing.assert_array_equal(m["num"].ravel(), est.num)
    np.testing.assert_array_equal(m["den"].ravel(), est.den)
    np.testing.assert_array_equal(m["covariance"], est.covariance)
    assert m["delay"].item() == est.delay and m["delay_estimated"].item() == 1.0
    assert str(m["input_name"][0]) == "thrust" and str(m["output_name"][0]) == "alt"
    assert [line.split(":")[0] for line in m["description"]] == list(MODEL_VARIABLES)


def test_mat_export_refuses_bad_input_and_never_leaves_half_a_file(estimate, tmp_path, monkeypatch):
    model = estimate[1].to_dict()
    with pytest.raises(SpecError, match=r"got '.*model.txt', expected a file name ending in .mat"):
        model_to_mat(model, tmp_path / "model.txt")
    (tmp_path / "folder.mat").mkdir()
    with pytest.raises(SpecError, match="is a folder"):
        model_to_mat(model, tmp_path / "folder.mat")
    with pytest.raises(ModelFileError, match=r"uav4: missing key\(s\) \['covariance'\]"):
        model_to_mat({k: v for k, v in model.items() if k != "covariance"}, tmp_path / "m.mat", source="uav4")
    with pytest.raises(SpecError, match="no L1 and L2 filter"):
        design_to_mat({"method": "robust", "from": "A", "to": "B", "sample_time": 0.02}, tmp_path / "d.mat")
    target = tmp_path / "keep.mat"
    model_to_mat(model, target)
    before = target.read_bytes()

    def fail(fh, *args, **kwargs):
        fh.write(b"MATLAB 5.0 half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(scipy.io, "savemat", fail)
    with pytest.raises(OSError, match="No space"):
        model_to_mat(model, target)
    assert target.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["folder.mat", "keep.mat"]


def test_the_package_is_marked_typed():
    marker = importlib.resources.files("ilcdob") / "py.typed"
    assert marker.is_file() and marker.read_bytes() == b""


def test_identified_model_transfer_function_keeps_signal_names_and_delay(estimate, tmp_path):
    _, est = estimate
    ulog = dataclasses.replace(est, input="vehicle_acceleration.xyz[0]", output="vehicle_local_position.x")
    path = tmp_path / "uav4.json"
    path.write_text(json.dumps(ulog.to_dict()), encoding="utf-8")  # as `ilcdob identify` writes model.json
    model = ilcdob.load_model(path)
    g = model.transfer_function
    assert isinstance(g, ct.TransferFunction) and g.dt == 0
    assert g.input_labels == ["vehicle_acceleration_xyz[0]"] and g.output_labels == ["vehicle_local_position_x"]
    assert g.name == "uav4"
    assert g.input_delay == model.delay == est.delay and est.delay > 0.04
    # the response with the delay applied by hand: num/den by numpy at s = jw, times e^{-jw delay}
    w = np.geomspace(0.1, 50.0, 25)
    s = 1j * w
    want = np.polyval(model.num, s) / np.polyval(model.den, s) * np.exp(-s * model.delay)
    np.testing.assert_allclose(np.asarray(g(s)).ravel() * np.exp(-s * g.input_delay), want, rtol=1e-12)
    np.testing.assert_allclose(want, est.frequency_response(w), rtol=1e-9)
    # signals not reported: python-control's own labels, never empty ones; a model built in memory: its default name
    data = ulog.to_dict()
    del data["signals"]
    bare = model_from_dict(json.loads(json.dumps(data))).transfer_function
    assert bare.input_labels == ["u[0]"] and bare.output_labels == ["y[0]"] and bare.input_delay == est.delay
    assert bare.name.startswith("sys[")


def test_fir_design_repr_is_one_line_of_the_facts():
    from ilcdob.design.methods.fir import FIRGuaranteeWarning, FIROptions, design_fir

    fleet = ilcdob.default_fleet()
    deltas = fleet_delta_sets(fleet, ["UAV1", "UAV2"], k=2, bound=0.6)
    with pytest.warns(FIRGuaranteeWarning):
        design = design_fir(fleet.loop("UAV1"), fleet.loop("UAV2"), deltas["UAV1"], deltas["UAV2"],
                            FIROptions(n_taps=40, advance=6))
    assert design.unattainable_bands and design.relaxed_bands
    text = repr(design)
    assert "\n" not in text and len(text) < 200, text
    for needle in ("'UAV1' -> 'UAV2'", "40 taps", f"worst |Te1| {design.worst_te1:.3g} at {design.worst_w:.3g} rad/s",
                   design.solver_status, f"{len(design.unattainable_bands)} unattainable",
                   f"{len(design.relaxed_bands)} relaxed"):
        assert needle in text, (needle, text)
    l1 = repr(design.L1)
    assert "\n" not in l1 and len(l1) < 200 and "40 taps" in l1 and "advance 6" in l1 and "0.02 s" in l1, l1


def test_every_filter_form_shows_one_face():
    """ZPK, FIR and the file's coefficient form satisfy the one filter protocol, and the closed form's L1
    as ZPK and as its file's view agree on the unit circle and on a trial (1e-9 of the peak: the look-ahead
    series is truncated at 1e-12, the sections run in double precision)."""
    from ilcdob.design.filters.filter import Filter
    from ilcdob.design.methods.fir import FIRFilter

    fleet = ilcdob.default_fleet()
    zpk = closed_form_filters(fleet.loop("UAV1"), fleet.loop("UAV2")).L1
    view = filter_tf(design_pair(fleet, "UAV1", "UAV2", band=None).filters["L1"], fleet.sample_time)
    fir = FIRFilter(np.array([0.25, 0.5, 0.25]), 1, fleet.sample_time)
    assert all(isinstance(f, Filter) for f in (zpk, view, fir))
    assert zpk.ts == view.ts
    w = np.logspace(-1, np.log10(np.pi / fleet.sample_time) - 0.01, 200)
    a, b = zpk.freqresp(w), view.freqresp(w)
    assert np.max(np.abs(a - b)) <= 1e-9 * np.max(np.abs(a))
    x = np.sin(0.7 * np.arange(1500) * fleet.sample_time) + 0.2 * np.sin(9.0 * np.arange(1500) * fleet.sample_time)
    ya, yb = zpk.apply(x), view.apply(x)
    assert np.max(np.abs(ya - yb)) <= 1e-9 * np.max(np.abs(ya))
    assert not isinstance(np.zeros(3), Filter)
