"""Learning laws (paper, exact-reference, multi-source) through reproduce, design, compare, campaign and report.

Acceptance of the exact-reference law: with exact models, iteration 1 of every system in every
scenario stays at or below 0.5 % of its DOB-only RMSE, on the built-in fleet (with its noise)
and on two fleets with unequal plants (``unequal_fleet`` with an input delay and a fourth-order
Q, ``feedforward_fleet`` with mixed acceleration feed-forward; both in ``conftest.py``, no
noise). Case I (wind only, exact models, no noise, hover) is exact for every law.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

import ilcdob
from ilcdob.app.cli import main
from ilcdob.design.law.laws import LAWS, ExactReference, check_law, reference_terms
from ilcdob.design.pair import design_pair, with_law
from ilcdob.errors import SpecError
from ilcdob.app.html import build_report
from ilcdob.signals import FlightData
from ilcdob.identification.loaders import load_csv
from ilcdob.app.output import OutputFolder, Provenance
from ilcdob.specs import NoiseSpec
from ilcdob.validation.campaign import CampaignError, CampaignOptions, campaign_settings, run_sample
from ilcdob.validation.compare import CompareOptions, compare_designs
from ilcdob.validation.reproduce import reproduce, run_scenario
from ilcdob.validation.scenarios import scenario
from ilcdob.validation.simulate import rmse, simulate_flight

FLEETS = ["fleet", "unequal_fleet", "feedforward_fleet"]
#: Largest iteration-1 ratio of the exact-reference law measured per fleet, and the bound asserted
#: (built-in: the acceptance 0.5 %, measured 0.241 %, set by the vehicles' own noises, which differ from
#: system to system; the noise-free fleets: ~10x the measured maximum, trial-boundary effects)
EXACT_REFERENCE_BOUND = {"fleet": 5e-3, "unequal_fleet": 2e-3, "feedforward_fleet": 2.5e-4}
# measured: fleet 2.41e-3 (scenario 3, UAV1), unequal_fleet 1.94e-4 (scenario 3, A3),
# feedforward_fleet 2.29e-5 (scenario 3, B3)


def _ratios(result: dict) -> dict[tuple[int, str], float]:
    """Iteration-1 RMSE over DOB-only RMSE per (scenario, system)."""
    return {(sc["id"], name): m["rmse_learning"][0] / m["rmse_dob"]
            for sc in result["scenarios"] for name, m in sc["systems"].items()}


@pytest.fixture(scope="module")
def runs(request) -> dict[tuple[str, str], dict[tuple[int, str], float]]:
    """Iteration-1 ratios of scenarios 1-4 per (fleet fixture, law) for the paper and exact-reference laws."""
    out = {}
    for name in FLEETS:
        fleet = request.getfixturevalue(name)
        for law in ("paper", "exact-reference"):
            out[(name, law)] = _ratios(reproduce(fleet, [1, 2, 3, 4], 1, law=law).to_dict())
    return out


@pytest.mark.parametrize("fleet_name", FLEETS)
def test_exact_reference_law_acceptance(runs, fleet_name):
    ratios = runs[(fleet_name, "exact-reference")]
    assert len(ratios) == 12  # 4 scenarios x 3 systems
    worst = max(ratios, key=ratios.get)
    assert ratios[worst] <= 5e-3, (worst, ratios[worst])  # acceptance: 0.5 % of the DOB-only RMSE
    assert ratios[worst] <= EXACT_REFERENCE_BOUND[fleet_name], (worst, ratios[worst])


@pytest.mark.parametrize("fleet_name", ["unequal_fleet", "feedforward_fleet"])
def test_the_paper_law_leaves_the_reference_term_that_exact_reference_removes(runs, fleet_name):
    paper, exact = runs[(fleet_name, "paper")], runs[(fleet_name, "exact-reference")]
    for key in paper:
        if key[0] == 1:  # hover: no reference term, the laws coincide
            assert exact[key] == pytest.approx(paper[key], rel=1e-9, abs=1e-15)
            continue
        # moving scenarios: the paper's law leaves >= 1.6 % (measured: unequal_fleet 1.61-8.88 %, feedforward_fleet
        # 39-175 %, worse than the DOB alone where only some controllers feed the acceleration forward), all of it
        # the reference term: exact-reference is >= 178x smaller (measured), bound 50x
        assert paper[key] >= 1e-2, (key, paper[key])
        assert exact[key] <= paper[key] / 50, (key, paper[key], exact[key])


@pytest.fixture(scope="module")
def quiet_builtin(fleet) -> ilcdob.Fleet:
    """The built-in fleet without its vehicles' noises."""
    return ilcdob.fleet_from_systems([replace(s, noise=NoiseSpec()) for s in fleet.systems], fleet.sample_time,
                                     "built-in without noise")


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("fleet_name", ["quiet_builtin", "unequal_fleet", "feedforward_fleet"])
def test_case_one_is_exact_for_every_law(request, fleet_name, law):
    """Wind only, exact models, no noise, no reference motion (scenario 1): every learning flight cancels the
    disturbance; measured max 4.9e-8 of the DOB-only RMSE (unequal_fleet, A1 learning from the delayed A3)."""
    fleet = request.getfixturevalue(fleet_name)
    res = run_scenario(fleet, scenario(1), 1, law=law)
    for name, sr in res.systems.items():
        assert sr.learning[0].rmse <= 1e-6 * sr.dob.rmse, (name, sr.learning[0].rmse / sr.dob.rmse)


def test_multi_source_first_flight_is_the_paper_law_then_uses_every_trial(unequal_fleet):
    sc = scenario(2)
    paper = run_scenario(unequal_fleet, sc, 1)
    multi = run_scenario(unequal_fleet, sc, 1, law="multi-source")
    first, second, third = paper.order
    # one earlier trial: the same operator factored differently (measured 1.8e-7 relative difference of RMSE)
    assert multi.systems[second].learning[0].rmse == pytest.approx(paper.systems[second].learning[0].rmse, rel=1e-6)
    # the third system learns from both earlier trials: a different signal (measured 0.252 % against 1.606 % of
    # its DOB-only RMSE: the first system's reconstruction carries less of the reference term)
    assert multi.systems[third].learning[0].rmse < 0.5 * paper.systems[third].learning[0].rmse
    assert multi.chain == paper.chain


def test_results_record_the_law_and_paper_stays_the_default(fleet, tmp_path):
    default = reproduce(fleet, [1], 1)
    assert default.law == "paper" and default.to_dict()["law"] == "paper"
    multi = reproduce(fleet, [1], 1, law="multi-source")
    assert multi.to_dict()["law"] == "multi-source" and multi.filters == {}  # no single pair's filters
    with OutputFolder(tmp_path, Provenance("reproduce"), overwrite=True) as folder:
        folder.add_all(multi.files())
    assert "Learning law: **multi-source**" in (tmp_path / "README.md").read_text()
    html = build_report([tmp_path])
    assert "learning law <strong>multi-source</strong>" in html


def test_bad_laws_are_refused_with_the_valid_ones(fleet):
    for call in (lambda: check_law("ilc"), lambda: reproduce(fleet, [1], 1, law="ilc"),
                 lambda: run_scenario(fleet, scenario(1), 1, law="ilc"), lambda: design_pair(fleet, "UAV1", "UAV2",
                                                                                               law="ilc")):
        with pytest.raises(SpecError, match="'paper', 'exact-reference', 'multi-source'"):
            call()
    with pytest.raises(SpecError, match="every earlier system"):
        design_pair(fleet, "UAV1", "UAV2", law="multi-source")
    with pytest.raises(SpecError, match="reference trajectory"):
        design_pair(fleet, "UAV1", "UAV2", law="exact-reference")
    with pytest.raises(SpecError, match="reference trajectory"):
        design_pair(fleet, "UAV1", "UAV2", law=ExactReference(None))
    with pytest.raises(SpecError, match="acceleration_feedforward"):  # the built-in controllers feed it forward
        reference_terms(fleet.loop("UAV1"), fleet.loop("UAV2"), np.zeros(10))
    with pytest.raises(SpecError, match="single DOB-only trial"):
        CompareOptions(law="multi-source")
    with pytest.raises(CampaignError, match="single DOB-only trial"):
        CampaignOptions(law="multi-source")
    with pytest.raises(CampaignError, match="valid learning laws"):
        CampaignOptions(law="ilc")
    d = design_pair(fleet, "UAV1", "UAV2")
    exact = with_law(d, fleet, "UAV1", "UAV2", "exact-reference", np.zeros(10), np.zeros(10))
    with pytest.raises(SpecError, match="already learns"):
        with_law(exact, fleet, "UAV1", "UAV2", "exact-reference", np.zeros(10), np.zeros(10))


def test_design_cli_exact_reference_from_a_trial_with_the_reference(fleet, tmp_path, capsys):
    sc = scenario(4)
    t = sc.time(fleet.sample_time)[:1500]  # 30 s of the diamond
    r, a, d = sc.reference(t), sc.acceleration(t), sc.disturbance(t)
    prev = simulate_flight(fleet.loop("UAV1"), r, d, a_ref=a)
    trial = tmp_path / "trial.csv"
    FlightData(t, {"error": prev.e, "learning": prev.d_f, "reference": r, "acceleration": a},
               {"error": "m", "learning": "m/s^2", "reference": "m", "acceleration": "m/s^2"}).to_csv(trial)
    base = simulate_flight(fleet.loop("UAV3"), r, d, a_ref=a)
    ratio = {}
    for law in ("paper", "exact-reference"):
        out = tmp_path / law
        assert main(["design", "--from", "UAV1", "--to", "UAV3", "--law", law, "--trial", str(trial),
                     "--out", str(out)]) == 0
        assert json.loads((out / "filters.json").read_text())["law"] == law
        df = load_csv(out / "learning_signal.csv", {"d_f": "learning"})["d_f"]
        ratio[law] = rmse(simulate_flight(fleet.loop("UAV3"), r, d, d_f=df, a_ref=a).e) / rmse(base.e)
    # measured: paper 3.1e-2 (the reference term), exact-reference 1.3e-9 (the CSV's 10 significant digits)
    assert ratio["paper"] > 1e-2 and ratio["exact-reference"] < 1e-7
    terms = load_csv(tmp_path / "exact-reference" / "reference_terms.csv", ["e_ref_source", "correction"])
    assert len(terms) == t.size
    assert "reference_terms.csv" in (tmp_path / "exact-reference" / "README.md").read_text()
    # refusals, each naming why
    capsys.readouterr()
    assert main(["design", "--from", "UAV1", "--to", "UAV3", "--law", "multi-source", "--out", str(tmp_path)]) == 2
    assert "every earlier system" in capsys.readouterr().err
    assert main(["design", "--from", "UAV1", "--to", "UAV3", "--law", "exact-reference", "--out", str(tmp_path)]) == 2
    assert "reference" in capsys.readouterr().err
    no_acc = tmp_path / "no_acc.csv"
    FlightData(t, {"error": prev.e, "learning": prev.d_f, "reference": r}).to_csv(no_acc)
    assert main(["design", "--from", "UAV1", "--to", "UAV3", "--law", "exact-reference", "--trial", str(no_acc),
                 "--out", str(tmp_path / "x")]) == 2
    assert "acceleration" in capsys.readouterr().err


def test_compare_with_the_exact_reference_law(fleet):
    opts = dict(samples=1, duration=20.0)
    paper = compare_designs(fleet, 2, ["closed-form", "norm-optimal"], CompareOptions(**opts),)
    exact = compare_designs(fleet, 2, ["closed-form", "norm-optimal"], CompareOptions(**opts, law="exact-reference"),)
    assert exact.to_dict()["law"] == "exact-reference" and paper.to_dict()["law"] == "paper"
    assert "law exact-reference" in exact.table()
    for m in ("closed-form", "norm-optimal"):
        # circle: measured nominal ratios 1.76e-3 (paper) and 5.36e-4 (exact-reference: 0.31x; the rest is the
        # two vehicles' different noises)
        assert exact.row(m).ratio_nominal < 0.5 * paper.row(m).ratio_nominal


def test_campaign_sample_with_the_exact_reference_law(fleet):
    small = dict(samples=1, scenarios=(2,), methods=("closed-form",), duration=10.0)
    paper, exact = CampaignOptions(**small), CampaignOptions(**small, law="exact-reference")
    s_paper, s_exact = campaign_settings(fleet, paper), campaign_settings(fleet, exact)
    assert "law" not in s_paper and s_exact["law"] == "exact-reference" and s_paper["id"] != s_exact["id"]
    r_paper = run_sample(fleet, paper, s_paper["id"], 0)["scenarios"]["2"]["ratios"]["closed-form"]
    r_exact = run_sample(fleet, exact, s_exact["id"], 0)["scenarios"]["2"]["ratios"]["closed-form"]
    # sampled true plants (identified uncertainty): the reference term is still most of what the paper's law
    # leaves (measured 6.5e-4 against 1.64e-3: 0.40x; the rest is the two vehicles' different noises)
    assert r_exact < 0.6 * r_paper


def test_reproduce_cli_law(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["reproduce", "--scenarios", "2", "--iterations", "1", "--law", "exact-reference", "--no-figures",
                 "--out", str(out)]) == 0
    data = json.loads((out / "results.json").read_text())
    assert data["law"] == "exact-reference"
    assert "--law exact-reference" in (out / "README.md").read_text()
    capsys.readouterr()
    assert main(["reproduce", "--law", "ilc", "--out", str(tmp_path / "y")]) == 2
    assert "valid learning laws" in capsys.readouterr().err
    assert main(["reproduce", "--plant", "nonlinear", "--law", "multi-source", "--out", str(tmp_path / "z")]) == 2
    assert "nonlinear" in capsys.readouterr().err and not (tmp_path / "z").exists()
