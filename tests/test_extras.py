"""Optional packages: the core runs without them, and a command that needs one names its extra."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.extras import MissingExtraError, require
from ilcdob.identification.loaders import load_flight

DATA = Path(__file__).resolve().parent / "data"


def _without(monkeypatch, *modules: str) -> None:
    """Make ``modules`` unimportable, as when their extra is not installed."""
    for name in list(sys.modules):
        if any(name == m or name.startswith(m + ".") for m in modules):
            monkeypatch.delitem(sys.modules, name)
    for m in modules:
        monkeypatch.setitem(sys.modules, m, None)


def test_require_names_the_extra(monkeypatch):
    _without(monkeypatch, "pyulog")
    with pytest.raises(MissingExtraError, match=r"pip install 'ilcdob\[logs\]'"):
        require("pyulog", "logs", "reading a PX4 ULog file")


@pytest.mark.parametrize("argv, extra", [
    (["identify", str(DATA / "px4_sample_log_small_filtered.ulg"), "--input", "vehicle_attitude_setpoint.thrust_body[0]",
      "--output", "vehicle_local_position.x", "--poles", "2"], "logs"),
    (["identify", str(DATA / "ardupilot_pymavlink_test.BIN"), "--input", "ATT.DesRoll", "--output", "ATT.Roll",
      "--poles", "2"], "logs"),
])
def test_a_command_needing_a_missing_extra_says_which(tmp_path, capsys, monkeypatch, argv, extra):
    _without(monkeypatch, "pyulog", "pymavlink")
    rc = main(["--quiet", *argv, "--out", str(tmp_path / "m.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and f"pip install 'ilcdob[{extra}]'" in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_campaign_without_dask_names_the_extra_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    _without(monkeypatch, "distributed")
    rc = main(["--quiet", "campaign", "--samples", "1", "--scenarios", "1", "--methods", "closed-form",
               "--duration", "2", "--workers", "1", "--out", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert rc == 2 and "pip install 'ilcdob[campaign]'" in err, err
    assert list(tmp_path.iterdir()) == []


def test_csv_reads_the_same_without_pyarrow(tmp_path, monkeypatch):
    """pyarrow only speeds CSV reading up: without it the line-by-line parser gives the same data."""
    rng = np.random.default_rng(1)
    path = tmp_path / "f.csv"
    u, y = rng.standard_normal(300), rng.standard_normal(300)
    rows = "".join(f"{0.01 * k:.2f},{float(u[k])!r},{float(y[k])!r}\n" for k in range(300))
    path.write_text("# units: time=s, u=m/s^2, y=m\ntime,u,y\n" + rows, encoding="utf-8")
    fast = load_flight(path, {"u": "u", "y": "y"})
    _without(monkeypatch, "pyarrow")
    plain = load_flight(path, {"u": "u", "y": "y"})
    assert plain.ts == fast.ts and plain.units == fast.units
    np.testing.assert_array_equal(plain["u"], u)
    np.testing.assert_array_equal(plain["y"], fast["y"])
