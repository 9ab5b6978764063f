"""The per-sample control law (:class:`ilcdob.controller.OuterLoopController`) against the transfer
functions it must realise, built with python-control from the loop's C, Q and M (no shared stepping code)."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

import ilcdob
from ilcdob.controller import OuterLoopController
from ilcdob.errors import SpecError

FLEET = ilcdob.default_fleet()


def _response(sys, u):
    return np.asarray(ct.forced_response(sys, U=np.asarray(u, float)).outputs, float).ravel()


@pytest.mark.parametrize("name", ["UAV1", "UAV3"])
def test_commands_are_the_law_as_transfer_functions(name):
    """Arbitrary reference, measurement, feedforward and learning sequences (the loop open at the
    vehicle): ``u2 = (1 - Q)^-1 {C{r - y} + a_ff - M{y} - d_f}`` and ``d_hat = M{y} - Q{u2}``.
    Rounding-level agreement (measured ~1e-15 of the signals' size): tolerance 1e-9."""
    loop = FLEET.loop(name)
    rng = np.random.default_rng(1)
    n = 400
    r, y, aff, df = (np.cumsum(rng.normal(size=n)) * s for s in (0.1, 0.1, 0.01, 0.01))
    ctl = OuterLoopController(loop)
    u2, dh = np.zeros(n), np.zeros(n)
    for k in range(n):
        u2[k] = ctl.step(r[k], y[k], feedforward=aff[k], learning=df[k])
        dh[k] = ctl.d_hat
    inv_1mq = ct.feedback(ct.ss([], [], [], 1.0, dt=loop.ts), loop.Q, sign=1)  # (1 - Q)^-1
    expected = _response(inv_1mq, _response(loop.C, r - y) + aff - _response(loop.M, y) - df)
    scale = np.max(np.abs(expected))
    np.testing.assert_allclose(u2, expected, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(dh, _response(loop.M, y) - _response(loop.Q, u2), rtol=0, atol=1e-9 * scale)


def test_the_dob_sees_the_applied_command_and_no_dob_is_the_pid():
    loop = FLEET.loop("UAV2")
    rng = np.random.default_rng(2)
    n = 200
    r, y = rng.normal(size=n), rng.normal(size=n)
    ctl = OuterLoopController(loop)
    applied, dh = np.zeros(n), np.zeros(n)
    for k in range(n):
        u = ctl.command(r[k], y[k])
        dh[k] = ctl.d_hat
        applied[k] = float(np.clip(u, -2.0, 2.0))  # the vehicle's limit
        ctl.update(applied[k])
    assert np.any(np.abs(applied) == 2.0)
    np.testing.assert_allclose(dh, _response(loop.M, y) - _response(loop.Q, applied), rtol=0, atol=1e-9)
    pid = OuterLoopController(loop, dob=False)
    np.testing.assert_allclose([pid.step(a, b) for a, b in zip(r, y)], _response(loop.C, r - y), rtol=0, atol=1e-9)
    assert pid.d_hat == 0.0


def test_misuse_is_refused():
    loop = FLEET.loop("UAV1")
    ctl = OuterLoopController(loop)
    ctl.command(0.0, 0.0)
    with pytest.raises(SpecError, match="not followed by update"):
        ctl.command(0.0, 0.0)
    ctl.update()
    with pytest.raises(SpecError, match="call command"):
        ctl.update()
    with pytest.raises(SpecError, match="needs the DOB"):
        OuterLoopController(loop, dob=False).command(0.0, 0.0, learning=0.1)
    with pytest.raises(SpecError, match="`loop`"):
        OuterLoopController("UAV1")
    ctl.step(1.0, 0.0)
    ctl.reset()
    assert ctl.step(1.0, 0.0) == OuterLoopController(loop).step(1.0, 0.0)
