"""Shared fixtures: the built-in fleet and a writer for fleet files."""

from __future__ import annotations

from pathlib import Path

import pytest

import ilcdob


@pytest.fixture(scope="session")
def fleet() -> ilcdob.Fleet:
    return ilcdob.default_fleet()


GOOD_FLEET = """\
sample_time = 0.02
[[system]]
name = "A"
plant = { num = [1.0], den = [0.1, 1.0, 0.0, 0.0] }
delay = 0.0
controller = { kp = 3.0, ki = 0.3, kd = 2.4, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }

[[system]]
name = "B"
plant = { num = [1.0], den = [0.12, 1.0, 0.0, 0.0] }
controller = { kp = 1.2, ki = 0.12, kd = 1.53, derivative_filter = 0.05 }
dob = { q_order = 3, q_time_constant = 0.15 }
"""


@pytest.fixture
def good_fleet_text() -> str:
    """A valid two-system fleet file in the schema of the foundation issue."""
    return GOOD_FLEET


@pytest.fixture
def fleet_file(tmp_path: Path):
    """Write a fleet file from text; returns its path."""

    def write(text: str = GOOD_FLEET, name: str = "fleet.toml") -> Path:
        path = tmp_path / name
        path.write_text(text, encoding="utf-8")
        return path

    return write
