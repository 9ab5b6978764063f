"""Outputs are written atomically: a failure leaves no half-written file."""

from __future__ import annotations

import json
import os
import stat

import pytest

from ilcdob.atomic import atomic_path, write_json_atomic
from ilcdob.errors import OutputError


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


@pytest.mark.skipif(not hasattr(os, "mknod"), reason="needs os.mknod / os.mkfifo")
@pytest.mark.parametrize("kind", ["fifo", "char device", "folder", "link to a fifo"])
def test_a_special_file_is_never_replaced(kind, tmp_path):
    # every writer of the Python API goes through atomic_path, so none replaces a device, FIFO or
    # folder given as its output (the command line's --out refuses them too)
    path = tmp_path / "x.json"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "char device":
        if os.geteuid() != 0:
            pytest.skip("making a device node needs root")
        os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # the same device as /dev/null
    elif kind == "folder":
        path.mkdir()
    else:
        os.mkfifo(tmp_path / "pipe")
        path.symlink_to(tmp_path / "pipe")
    before = os.lstat(path)
    expected = {"fifo": "a FIFO", "char device": "a character device", "folder": "a folder",
                "link to a fifo": "a FIFO"}[kind]
    with pytest.raises(OutputError, match=rf"output file .*x\.json: is {expected}.*, not a regular file"):
        write_json_atomic(path, {"ok": 1})
    after = os.lstat(path)
    assert (after.st_mode, after.st_ino) == (before.st_mode, before.st_ino)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({"x.json", *(["pipe"] if "link" in kind else [])})


@pytest.mark.skipif(not hasattr(os, "mknod"), reason="needs os.mknod")
def test_design_to_mat_refuses_a_device_before_computing(tmp_path):
    from ilcdob.design.export.objects import design_to_mat

    if os.geteuid() != 0:
        pytest.skip("making a device node needs root")
    path = tmp_path / "design.mat"
    os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    with pytest.raises(OutputError, match=r"design .mat file.*design\.mat: is a character device"):
        design_to_mat({"from": "A"}, path)  # refused on the path, before the (invalid) design is read
    assert stat.S_ISCHR(os.lstat(path).st_mode)


def test_library_mode_is_set_whatever_the_umask(tmp_path):
    path = tmp_path / "lib.so"
    previous = os.umask(0)
    try:
        with atomic_path(path, mode=0o644) as tmp:
            tmp.write_bytes(b"x")
        write_json_atomic(tmp_path / "plain.json", {})
    finally:
        os.umask(previous)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert stat.S_IMODE((tmp_path / "plain.json").stat().st_mode) == 0o666  # the default: 0666 less the umask
