"""FIR learning filters with the Q-filter bandwidth of the learning system chosen jointly."""

from __future__ import annotations

import pytest

from ilcdob.design.fir import FIROptions
from ilcdob.design.joint_q import design_fir_joint_q
from ilcdob.design.pair import fleet_delta_sets
from ilcdob.errors import SpecError


def test_joint_q_is_never_worse_than_the_fleet_tau(fleet):
    ds = fleet_delta_sets(fleet, ["UAV1", "UAV2"], k=2)
    opts = FIROptions(n_taps=60, n_grid=80)
    res = design_fir_joint_q(fleet.loop("UAV1"), fleet.loop("UAV2"), ds["UAV1"], ds["UAV2"], opts,
                             tau_bounds=(0.08, 0.4), max_evaluations=6)
    current = dict(res.evaluations)[fleet.loop("UAV2").spec.dob.q_time_constant]
    assert current is not None and res.objective <= current
    assert 0.08 <= res.q_time_constant <= 0.4 and res.design.worst_te1 <= 1 - opts.margin + 1e-6


def test_joint_q_bad_inputs(fleet):
    ds = fleet_delta_sets(fleet, ["UAV1", "UAV2"], k=1)
    with pytest.raises(SpecError, match="tau_bounds"):
        design_fir_joint_q(fleet.loop("UAV1"), fleet.loop("UAV2"), ds["UAV1"], ds["UAV2"], tau_bounds=(0.3, 0.1))
    with pytest.raises(SpecError, match="max_evaluations"):
        design_fir_joint_q(fleet.loop("UAV1"), fleet.loop("UAV2"), ds["UAV1"], ds["UAV2"], max_evaluations=1)
