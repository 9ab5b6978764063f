"""Outputs are written atomically: a failure leaves no half-written file."""

from __future__ import annotations

import json

import pytest

from ilcdob.atomic import atomic_path, write_json_atomic


def test_failed_json_write_leaves_previous_file_and_no_temp(tmp_path):
    path = tmp_path / "results.json"
    write_json_atomic(path, {"ok": 1})
    with pytest.raises(TypeError):
        write_json_atomic(path, {"bad": object()})
    assert json.loads(path.read_text()) == {"ok": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"]


def test_crash_inside_the_block_leaves_nothing(tmp_path):
    path = tmp_path / "fig.png"
    with pytest.raises(RuntimeError):
        with atomic_path(path) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("crash")
    assert list(tmp_path.iterdir()) == []
