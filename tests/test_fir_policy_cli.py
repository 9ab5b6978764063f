"""``ilcdob design --method fir --fir-unattainable {no-harm,refuse}``: the FIR design's policy where the margin
cannot be met, chosen on the command line.

The case is UAV1 -> UAV2 of the built-in fleet with two Delta samples of ``|Delta| <= 0.6`` per system: there no
filter of any order keeps ``|Te1| <= 0.9`` for both sampled models between about 3 and 22 rad/s (tests/test_fir.py
shows the same with six samples, independently of any solver).
"""

from __future__ import annotations

import json
import re

import pytest

from ilcdob.app import cli, commands
from ilcdob.app.cli import main
from ilcdob.design.methods.fir import UNATTAINABLE
from ilcdob.errors import SpecError

FIR = ["design", "--from", "UAV1", "--to", "UAV2", "--method", "fir", "--samples", "2", "--bound", "0.6"]
#: A band as the messages write it: "3.17-22.3 rad/s" (several joined by ", ").
BAND = re.compile(r"at \d+(\.\d+)?-\d+(\.\d+)?( rad/s|, )")


def test_refuse_exits_2_naming_the_bands_and_writes_nothing(tmp_path, capsys):
    rc = main(["--quiet", *FIR, "--fir-unattainable", "refuse", "--out", str(tmp_path / "d")])
    out, err = capsys.readouterr()
    assert rc == 2, err[-3000:]
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: "), err[-3000:]
    line = lines[0]
    assert "'UAV1' -> 'UAV2'" in line and "not met by any filter" in line and BAND.search(line), line
    assert "--fir-unattainable no-harm" in line, line  # the way back, named as the command line spells it
    assert out == "" and not (tmp_path / "d").exists()


@pytest.mark.parametrize("flag", [[], ["--fir-unattainable", "no-harm"]])
def test_no_harm_default_writes_the_folder_and_warns_with_the_flag(tmp_path, capsys, flag):
    out_dir = tmp_path / "d"
    rc = main([*FIR, *flag, "--out", str(out_dir)])
    out, err = capsys.readouterr()
    # exit 1 with the folder written: at bound 0.6 the band says the improvement is not guaranteed (UAV1's set
    # reaches its loop's stability boundary), as `ilcdob check` does
    assert rc == 1 and "design written to" in err and "not guaranteed" in err, err[-3000:]
    warning = [line for line in err.splitlines() if line.startswith("ilcdob: warning: ")]
    assert len(warning) == 1 and "given up at" in warning[0] and BAND.search(warning[0]), err
    assert "--fir-unattainable refuse" in warning[0], warning[0]
    robustness = json.loads((out_dir / "filters.json").read_text(encoding="utf-8"))["robustness"]
    assert robustness["unattainable_bands"] and robustness["relaxed_bands"]
    assert json.loads(out)["method"] == "fir"


@pytest.mark.parametrize("method", ["closed-form", "robust-set", "norm-optimal"])
def test_the_flag_with_a_method_that_does_not_use_it_is_refused(tmp_path, capsys, monkeypatch, method):
    def no_work(*args, **kwargs):
        raise AssertionError("the fleet was loaded: the option was not checked up front")

    monkeypatch.setattr(commands, "fleet_and_hash", no_work)
    rc = main(["--quiet", "design", "--from", "UAV1", "--to", "UAV2", "--method", method,
               "--fir-unattainable", "refuse", "--out", str(tmp_path / "d")])
    out, err = capsys.readouterr()
    assert rc == 2, err[-3000:]
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilcdob: error: `--fir-unattainable` 'refuse': "), err
    assert f"--method {method} does not use it, only fir does" in lines[0], lines[0]
    assert out == "" and not (tmp_path / "d").exists()


def test_the_python_call_checks_the_policy_and_the_choices_are_the_designs():
    with pytest.raises(SpecError, match=r"`--fir-unattainable`: got 'ignore', expected one of \['no-harm', 'refuse'\]"):
        commands.design_to_folder("unused", "UAV1", "UAV2", method="fir", fir_unattainable="ignore")
    assert cli.FIR_UNATTAINABLE == UNATTAINABLE


def test_c_options_are_accepted_for_robust_set_and_still_refused_elsewhere():
    commands._refuse_unused("robust-set", {"--c-prefix": "abc_"})
    with pytest.raises(SpecError, match=r"`--c-float`: --method robust-set does not use it, only closed-form and "
                                        r"fir do \(the methods with L1/L2 filters to give in float\)"):
        commands._refuse_unused("robust-set", {"--c-float": True})
    with pytest.raises(SpecError, match=r"`--c-prefix` 'abc_': --method norm-optimal does not use it, only "
                                        r"closed-form, fir and robust-set do \(the methods with C code\)"):
        commands._refuse_unused("norm-optimal", {"--c-prefix": "abc_"})


COMPARE = ["compare", "--scenario", "1", "--duration", "5", "--samples", "6", "--bound", "0.6", "--methods", "fir"]


@pytest.mark.parametrize("policy", ["refuse", "no-harm"])
def test_compare_takes_the_policy_a_refused_design_is_its_row(tmp_path, capsys, policy):
    """compare designs scenario 1's first pair (UAV1 -> UAV2) over its six paired samples, where no filter keeps
    the margin above about 2.3 rad/s (reports/compare): with ``refuse`` the FIR row says the design failed and
    names the bands (a comparison reports a failed design and goes on, exit 0); with ``no-harm`` it is flown."""
    rc = main(["--quiet", *COMPARE, "--fir-unattainable", policy, "--out", str(tmp_path / "c")])
    out, err = capsys.readouterr()
    assert rc == 0, err[-3000:]
    row = next(line for line in out.splitlines() if line.startswith("fir "))
    if policy == "refuse":
        assert "design failed" in row and "not met by any filter" in row and BAND.search(row), row
    else:
        assert "design failed" not in row and "improved" not in row, row


def test_compare_refuses_the_flag_without_fir_among_the_methods(tmp_path, capsys):
    rc = main(["--quiet", *COMPARE[:-1], "closed-form,robust", "--fir-unattainable", "no-harm",
               "--out", str(tmp_path / "c")])
    out, err = capsys.readouterr()
    assert rc == 2, err[-3000:]
    assert err.startswith("ilcdob: error: `--fir-unattainable` 'no-harm': none of the methods closed-form, robust "
                          "uses it, only fir does"), err
    assert out == "" and not (tmp_path / "c").exists()


#: Two third-order plants (the built-in UAV2 and UAV3 models) with a stated bound of 0.6: the FIR's sampled models
#: disagree too much between about 2 and 7 rad/s for any filter to keep |Te1| <= 0.9 there.
LEARN_FLEET = """sample_time = 0.02
[[system]]
name = "A"
plant = { num = [9.957850872], den = [1, 9.914970966, 0, 0] }
controller = { kp = 1.2, ki = 0.12, kd = 1.53, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }
uncertainty = { bound = 0.6 }

[[system]]
name = "B"
plant = { num = [7.442384984], den = [1, 7.360005403, 0, 0] }
controller = { kp = 1.9, ki = 0.19, kd = 1.93, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }
uncertainty = { bound = 0.6 }
"""


@pytest.fixture
def learn_inputs(tmp_path):
    """The fleet above and a 500-sample trial of A (error 0.01 sin t m, Ts 0.02 s)."""
    import numpy as np

    (tmp_path / "fleet.toml").write_text(LEARN_FLEET, encoding="utf-8")
    t = np.arange(500) * 0.02
    rows = "".join(f"{t[k]:.10g},{0.01 * np.sin(t[k]):.10g}\n" for k in range(t.size))
    (tmp_path / "trial.csv").write_text("# units: time=s, error=m\ntime,error\n" + rows, encoding="utf-8")
    return ["learn", str(tmp_path / "trial.csv"), "--fleet", str(tmp_path / "fleet.toml"), "--from", "A", "--to", "B",
            "--error", "error"]


@pytest.mark.parametrize("policy", ["refuse", "no-harm"])
def test_learn_designs_the_fir_with_the_policy(learn_inputs, tmp_path, capsys, policy):
    """``learn --method fir`` designs here: ``refuse`` stops (exit 2, bands named, nothing written), ``no-harm``
    writes the signal and warns."""
    rc = main([*learn_inputs, "--method", "fir", "--fir-unattainable", policy, "--out", str(tmp_path / "l")])
    out, err = capsys.readouterr()
    if policy == "refuse":
        assert rc == 2, err[-3000:]
        assert "not met by any filter" in err and BAND.search(err), err[-3000:]
        assert not (tmp_path / "l").exists()
    else:
        assert rc == 0, err[-3000:]
        assert "given up at" in err and json.loads(out)["filters"] == "designed here (fir)", err[-3000:]


@pytest.mark.parametrize("design, words", [
    (False, "--method closed-form does not use it, only fir does"),
    (True, "--fir-unattainable would be ignored"),
])
def test_learn_refuses_the_flag_where_no_fir_is_designed(learn_inputs, tmp_path, capsys, design, words):
    """With a design folder (its filters are fixed) or another method, the flag would change nothing: refused."""
    trial = learn_inputs[:2] + ["--error", "error"]
    args = [*trial, "--design", str(tmp_path / "d")] if design else [*learn_inputs, "--method", "closed-form"]
    rc = main(["--quiet", *args, "--fir-unattainable", "refuse", "--out", str(tmp_path / "l")])
    out, err = capsys.readouterr()
    assert rc == 2, err[-3000:]
    assert words in err, err
    assert out == "" and not (tmp_path / "l").exists()
