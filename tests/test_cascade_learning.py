"""Learning between two cascades (PX4's shape) on their acceleration channel: a loop that integrates.

The truth is python-control alone: an airframe ``x' = v``, ``v' = a - drag v``, ``a' = (a_c - a)/lag`` under a
position P over a velocity PI, ``a_c = kpv (v_sp - v) + kiv integral(v_sp - v) + a_ff`` with
``v_sp = kpp (r - x)``; the map from the feed-forward ``a_ff`` (and from an acceleration disturbance on the
command) to the position is ``s / (s^2 (s + drag)(lag s + 1) + (kpv s + kiv)(kpp + s))``, with its zero at
``s = 0`` from the velocity integral. Flights are simulated by python-control, identified with ``ilcdob identify
--zero-at-origin``, designed and learned on the command line, and the signal flown on the true vehicle again.
"""

from __future__ import annotations

import json
from pathlib import Path

import control as ct
import numpy as np
import pytest

from ilcdob.app.cli import main
from ilcdob.errors import SpecError
from ilcdob.fleet import fleet_from_dict, load_fleet
from ilcdob.design.pair import design_pair
from lti_truth import chirp, fly

TS = 0.01  # s
NOISE = 5e-4  # m

#: Two cascades with different gains and airframes: PX4-like defaults and a stiff, fast one.
CASCADES = {"px4-like": dict(kpp=0.95, kpv=1.8, kiv=0.4, drag=0.35, lag=0.08),
            "stiff": dict(kpp=1.6, kpv=3.5, kiv=1.5, drag=0.6, lag=0.04)}


def _map(kpp: float, kpv: float, kiv: float, drag: float, lag: float) -> ct.TransferFunction:
    """The cascade's map from the acceleration feed-forward (or a command disturbance) to the position."""
    s = ct.tf("s")
    return ct.minreal(s / (s ** 2 * (s + drag) * (lag * s + 1) + (kpv * s + kiv) * (kpp + s)), verbose=False)





@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    """Two chirp flights per cascade on its acceleration channel, identified with a zero fixed at s = 0."""
    root = tmp_path_factory.mktemp("cascades")
    t = np.arange(0.0, 60.0, TS)
    blocks = ["sample_time = 0.01"]
    for k, (name, gains) in enumerate(CASCADES.items()):
        files = []
        for flight in range(2):
            u = chirp(t, 2.0, 10 * k + flight, w0=0.05)
            y = fly(_map(**gains), t, u) + NOISE * np.random.default_rng(50 + 10 * k + flight).standard_normal(t.size)
            files.append(root / f"{name}_{flight}.csv")
            np.savetxt(files[-1], np.c_[t, u, y], delimiter=",", header="time,u,y", comments="")
        assert main(["identify", str(files[0]), "--validate", str(files[1]), "--input", "u", "--output", "y",
                     "--poles", "4", "--zeros", "1", "--zero-at-origin", "--out", str(root / f"{name}.json"),
                     "--quiet"]) == 0
        blocks.append(f'[[system]]\nname = "{name}"\nchannel = "acceleration"\n'
                      f'channel_map = {{ model = "{name}.json" }}')
    (root / "fleet.toml").write_text("\n\n".join(blocks) + "\n")
    return root


def test_the_fit_keeps_the_zero_at_the_origin(lab):
    """The conditioned fit: ``b0`` exactly 0 with no variance, held-out fit >= 95 %, the map within 5 % of the true
    one over 0.05-5 rad/s (the learning's band), and the fitted ``b0`` it replaced within 3 standard deviations
    (measured 2.8 and 0.65)."""
    w = np.geomspace(0.05, 5.0, 60)
    for name, gains in CASCADES.items():
        model = json.loads((lab / f"{name}.json").read_text())
        assert model["num"][-1] == 0.0 and model["std"][-1] == 0.0
        assert model["fit_percent"]["validation"] >= 95.0, model["fit_percent"]
        fit = ct.tf(model["num"], model["den"])
        err = np.abs(fit(1j * w) / _map(**gains)(1j * w) - 1)
        assert np.max(err) < 0.05, (name, np.max(err))
        z = model["solver"]["zero_at_origin"]
        assert abs(z["b0_fitted"]) <= 3 * z["b0_std"]
        assert load_fleet(lab / "fleet.toml").loop(name).integrates


@pytest.mark.parametrize("source, target", [("px4-like", "stiff"), ("stiff", "px4-like")])
def test_cascades_learn_from_each_other(lab, tmp_path, source, target):
    """design -> learn on a recorded hover trial in the paper's disturbance -> the true target flies it: <= 0.1 of
    its error without learning (the acceptance's iteration-1 figure; measured 0.0018 and 0.0010). Without the fixed
    zero the same fits leave it at s = +1.9e-5 rad/s and the design is refused (the next test)."""
    t = np.arange(0.0, 30.0, TS)
    d = 0.3 + 0.5 * np.sin(0.94 * t) + 0.2 * np.sin(1.41 * t + 0.5)
    e = -fly(_map(**CASCADES[source]), t, d) + NOISE * np.random.default_rng(7).standard_normal(t.size)
    trial = tmp_path / "trial.csv"
    np.savetxt(trial, np.c_[t, e, np.zeros_like(t)], delimiter=",", header="time,error,learning", comments="")
    design, learned = tmp_path / "design", tmp_path / "learned"
    assert main(["design", "--fleet", str(lab / "fleet.toml"), "--from", source, "--to", target, "--trial",
                 str(trial), "--out", str(design), "--quiet"]) == 0
    assert main(["learn", str(trial), "--design", str(design), "--error", "error", "--learning", "learning",
                 "--out", str(learned), "--quiet"]) == 0
    u = np.loadtxt(learned / "learning_signal.csv", delimiter=",", skiprows=2)[:, 1]
    g = _map(**CASCADES[target])
    base = fly(g, t, d)
    ratio = np.sqrt(np.mean((base + fly(g, t, u)) ** 2)) / np.sqrt(np.mean(base ** 2))
    assert ratio <= 0.1, ratio


def test_a_zero_off_the_origin_is_named_and_a_single_loop_refuses_the_constraint(tmp_path):
    """A map whose fit left the zero at s = +1e-4 rad/s is refused with the remedy; a single PD loop's map (no
    zero at s = 0 in its data) refuses --zero-at-origin."""
    flt = fleet_from_dict({"sample_time": TS, "system": [
        {"name": "a", "channel": "acceleration",
         "channel_map": {"num": [1.0, -1e-4], "den": [0.08, 1.0, 2.0, 1.5, 0.4]}},
        {"name": "b", "channel": "acceleration", "channel_map": {"num": [1.0], "den": [0.1, 1.0, 3.0, 4.0]}}]})
    with pytest.raises(SpecError, match="--zero-at-origin"):
        design_pair(flt, "a", "b")
    t = np.arange(0.0, 40.0, TS)
    single = ct.tf([1.0], [0.06, 1.0, 3.4, 4.0])  # a PD loop: no integral, no zero at s = 0
    files = []
    for flight in range(2):
        u = chirp(t, 2.0, flight, w0=0.05)
        y = fly(single, t, u) + NOISE * np.random.default_rng(flight).standard_normal(t.size)
        files.append(tmp_path / f"f{flight}.csv")
        np.savetxt(files[-1], np.c_[t, u, y], delimiter=",", header="time,u,y", comments="")
    assert main(["identify", str(files[0]), "--input", "u", "--output", "y", "--poles", "3", "--zeros", "1",
                 "--zero-at-origin", "--out", str(tmp_path / "m.json"), "--quiet"]) == 2
    assert not (tmp_path / "m.json").exists()
