"""Design comparison (`ilcdob compare`): the orderings theory promises, on a scenario."""

from __future__ import annotations

import json

import numpy as np
import pytest

from matplotlib.figure import Figure

from ilcdob.app.cli import main
from ilcdob.design.methods.robust import RobustOptions
from ilcdob.errors import SpecError
from ilcdob.validation.compare import CompareOptions, compare_designs
from ilcdob.validation.figures import comparison_figure


@pytest.fixture(scope="module")
def identified_run(fleet):
    """Hover scenario (first 20 s), identified uncertainty, 4 samples: every design can be made.

    Returns the comparison and its progress calls."""
    calls = []
    cmp = compare_designs(fleet, 1, options=CompareOptions(samples=4, duration=20.0),
                          progress=lambda *call: calls.append(call))
    return cmp, calls


@pytest.fixture(scope="module")
def identified(identified_run):
    return identified_run[0]


def test_progress_reports_every_design_and_every_case(identified_run):
    _, calls = identified_run
    # 4 designs built, then the nominal case and 4 Delta samples flown
    assert [(d, t) for d, t, _ in calls] == [(k, 9) for k in range(1, 10)]
    assert "closed-form" in calls[0][2] and "Delta sample 4" in calls[-1][2]


def test_files_are_the_report_content(identified):
    assert list(identified.files()) == ["compare.json", "compare.txt"]
    files = identified.files({"compare_ratios.png": comparison_figure(identified, 0.95)})
    assert list(files) == ["compare.json", "compare.txt", "compare_ratios.png"]
    assert files["compare.json"] == identified.to_dict()
    json.dumps(files["compare.json"], allow_nan=False)  # standard JSON
    assert files["compare.txt"] == identified.table() and "ratio worst" in files["compare.txt"]
    fig = files["compare_ratios.png"]
    assert isinstance(fig, Figure) and "robust rho = 0.95" in fig.axes[0].get_legend_handles_labels()[1]


def test_norm_optimal_equals_closed_form_in_its_limit(identified):
    cf, no = identified.row("closed-form"), identified.row("norm-optimal")
    # default lam = 1e-8, mu = 1e-6 (near the limit lam, mu -> 0): the same flights; measured max |diff| 2.2e-7
    # over the nominal case and the 4 samples, bound ~10x
    np.testing.assert_allclose(no.ratios, cf.ratios, rtol=0, atol=2e-6)
    assert no.ratio_nominal < 5e-3  # exact models: learning removes > 99 % of the error (measured 5.4e-4)


def test_fir_within_tolerance_of_closed_form_on_nominal(identified):
    cf, fir = identified.row("closed-form"), identified.row("fir")
    # tolerance 0.06 of the DOB-only error: an 80-tap FIR has no integrator, so it cannot follow the
    # closed form's |L1| at the lowest frequencies (measured 0.045)
    assert fir.ratio_nominal <= cf.ratio_nominal + 0.06
    assert fir.improved_share == 1.0 and fir.order.startswith("L1: 79/0")


def test_every_design_improves_inside_the_identified_uncertainty(identified):
    for m in identified.methods:
        assert m.error is None and m.improved_share == 1.0 and m.ratio_worst < 0.1, m.method
        assert len(m.ratios) == 5 and m.design_time_s > 0


@pytest.mark.slow  # > 15 s on 2 cores: the default suite stays under 10 minutes
def test_robust_never_worse_than_its_bound_on_its_own_sample_set(fleet):
    """Large errors (|Delta| <= 0.6): the closed form's worst case exceeds rho, the robust design's does not
    (both learn through their learning band, which the 0.6 bound closes at a few rad/s).

    rho = 0.13 is just above the smallest rho feasible for every case's trial (0.1286 by bisection), so the
    improvement constraint is active (the minimax design alone reaches 0.139)."""
    rho = 0.13
    cmp = compare_designs(fleet, 1, ["closed-form", "norm-optimal", "robust"],
                          CompareOptions(samples=6, bound=0.6, duration=20.0, robust=RobustOptions(rho=rho)))
    cf, rb = cmp.row("closed-form"), cmp.row("robust")
    assert cf.ratio_worst > rho + 0.01  # measured 0.146 (0.23 without the learning band)
    # the robust predictions hold exactly (<= rho); the flights differ from them only by the two
    # systems' own noises (0.03 m/s^2 at 2-3 Hz), hence the 0.005 allowance (measured max 0.1300)
    assert rb.ratio_worst <= rho + 0.005
    # both pay for robustness on the nominal plants (Case I, where the unfiltered closed form reaches ~1e-8):
    # the closed form through the band that the 0.6 bound closes (measured 0.074), robust through its SOCP (0.066)
    assert min(rb.ratio_nominal, cf.ratio_nominal) > 0.02


def test_compare_cli_writes_outputs(tmp_path, capsys):
    out = tmp_path / "cmp"
    assert main(["compare", "--scenario", "3", "--methods", "closed-form,robust", "--samples", "2",
                 "--duration", "25", "--out", str(out)]) == 0
    data = json.loads((out / "compare.json").read_text())
    assert set(data["methods"]) == {"closed-form", "robust"} and data["scenario"] == 3
    assert (out / "compare_ratios.png").stat().st_size > 1000
    assert "ratio worst" in capsys.readouterr().out


def test_compare_bad_inputs(fleet, capsys):
    with pytest.raises(SpecError, match="magic"):
        compare_designs(fleet, 1, ["closed-form", "magic"])
    with pytest.raises(SpecError, match="samples"):
        CompareOptions(samples=0)
    assert main(["compare", "--scenario", "7", "--methods", "closed-form"]) == 2
    assert "7" in capsys.readouterr().err

