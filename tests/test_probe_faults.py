"""The fault probe (``tests/probe_faults.py``) keeps working: it holds the cases it promises, its
classifier names each outcome correctly, and a representative subset of its cases (one or two
per family) runs against the command line and behaves."""

from __future__ import annotations

import collections
import signal
from pathlib import Path

import pytest

import probe_faults as probe

#: One or two cases per family, each a different kind of check (about 20 s on 2 cores).
SUBSET = {
    "baseline/design": "ACCEPTED",  # a complete folder, C code that compiles
    "names/fleet-file/backslash-newline": "CLEAR_ERROR",
    "names/fleet-add/script": "CLEAR_ERROR",  # and the fleet file unchanged
    "names/c-prefix/splice": {"ACCEPTED", "CLEAR_ERROR"},  # compiled when accepted
    "documents/fleet/deep-nesting-100000": "CLEAR_ERROR",
    "documents/model/nan-literal": "CLEAR_ERROR",
    "documents/run-report/added-notes": "CLEAR_ERROR",
    "special/input-check-fleet/fifo": "CLEAR_ERROR",  # no hang
    "special/output-check/socket": "CLEAR_ERROR",
    "outputs/overwrite-git/design": "CLEAR_ERROR",
    "outputs/input/identify-out-is-input": "CLEAR_ERROR",
    "options/reproduce/iterations-1e6": "CLEAR_ERROR",
    "options/identify/min-fit-100": "CHECK_FAILED",
    "races/fleet-add-two/round-0": "ACCEPTED",  # both edits land
    "disk/file-size-limit/design": "CLEAR_ERROR",
    "kills/design-fir/SIGKILL-1.0s": {"INTERRUPTED", "ACCEPTED"},
    "encodings/ascii/bad-fleet-non-ascii-path": "CLEAR_ERROR",
    "encodings/ulog/header-ff-0/identify": "CLEAR_ERROR",  # bounded parse of a damaged log
}


def test_the_probe_holds_every_family_and_at_least_300_distinct_cases():
    cases = probe.build_cases()
    assert len(cases) >= 300 and len({c.name for c in cases}) == len(cases)
    per_family = collections.Counter(c.family for c in cases)
    assert set(per_family) == set(probe.FAMILIES) and min(per_family.values()) >= 10, per_family
    for c in cases:
        assert c.expect and c.expect <= set(probe.GOOD), c.name
    assert set(SUBSET) <= {c.name for c in cases}
    assert probe.select(cases, "names/fleet-file/*") and probe.select(cases, "fifo") \
        and not probe.select(cases, "no such case")


@pytest.mark.slow  # > 15 s on 2 cores: the default suite stays under 10 minutes
def test_the_subset_runs_and_behaves(tmp_path):
    cases = [c for c in probe.build_cases() if c.name in SUBSET]
    outcomes = probe.run_cases(cases, tmp_path / "probe", jobs=2)
    failing = [o for o in outcomes if probe.is_failure(o)]
    assert not failing, probe.format_failures(failing)
    for o in outcomes:
        wanted = SUBSET[o.name]
        assert o.klass in ({wanted} if isinstance(wanted, str) else wanted) or o.klass == probe.SKIPPED, (o.name, o)
    table = probe.table(outcomes)
    assert table.splitlines()[-1].split()[-1] == str(len(SUBSET))  # the total row counts every case


# ------------------------------------------------------------------ the classifier, without subprocesses

@pytest.fixture()
def ctx(tmp_path) -> probe.Ctx:
    outer = tmp_path / "case" / "outer"
    (outer / "work").mkdir(parents=True)
    (outer / probe.SENTINEL).write_text("x")
    return probe.Ctx(tmp_path / "case", outer, outer / "work", tmp_path / "fixtures", probe.Options())


def _judge(ctx: probe.Ctx, rc: int | None, stderr: str = "", expect=probe.E, change=None, **kw) -> tuple[str, str]:
    case = probe.Case(name="t/x", family="t", expect=expect, **kw)
    before, outside = probe.snapshot(ctx.work), probe.outside_state(ctx)
    if change is not None:
        change(ctx)
    run = probe.Run(["-m", "ilcdob"], rc, "", stderr, 0.1, rc is None)
    return probe.judge(case, ctx, run, before, probe.snapshot(ctx.work), outside)


ONE = "ilcdob: error: `--out` (x): is a FIFO\n"


def test_the_classifier_names_each_outcome(ctx):
    assert _judge(ctx, 2, ONE)[0] == "CLEAR_ERROR"
    assert _judge(ctx, None)[0] == "HANG"
    assert _judge(ctx, 3, "Traceback (most recent call last):\n  File ...\nValueError: x\n")[0] == "TRACEBACK"
    assert _judge(ctx, 3, "ilcdob: error: internal error: TypeError: x\n") == (
        "WRONG_EXIT", "exit 3 (an internal error: a bug)")
    assert _judge(ctx, 0)[0] == "SILENT"  # accepted what must be refused
    assert _judge(ctx, 2, ONE + ONE)[0] == "SILENT"  # not exactly one error line
    assert _judge(ctx, 2, "ilcdob: error:   \n")[0] == "SILENT"  # an empty message
    assert _judge(ctx, 2, ONE, expect=probe.A)[0] == "WRONG_EXIT"
    assert _judge(ctx, -signal.SIGSEGV)[0] == "WRONG_EXIT"
    assert _judge(ctx, 1, "ilcdob: check: no\n", expect=probe.C)[0] == "CHECK_FAILED"
    assert _judge(ctx, 2, ONE, change=lambda c: c.write("half.json", "{"))[0] == "LEFTOVER"
    assert _judge(ctx, 2, ONE, change=lambda c: c.write("m.json", "{}"), allow_changes=("m.json",))[0] \
        == "CLEAR_ERROR"
    staging = lambda c: c.write(".out.ilcdob-staging-1-x/a", "")  # noqa: E731
    assert _judge(ctx, 0, expect=probe.A, change=staging)[0] == "LEFTOVER"


def test_the_classifier_sees_injections_and_incomplete_outputs(ctx):
    assert _judge(ctx, 2, ONE, change=lambda c: (c.outer / "evil").write_text("x"))[0] == "INJECTION"
    assert _judge(ctx, 2, ONE, change=lambda c: (c.outer / probe.SENTINEL).unlink())[0] == "INJECTION"
    macro = f"/* a */\n#define {probe.INJECTED_MACRO} 42\n"
    assert _judge(ctx, 0, expect=probe.A, change=lambda c: c.write("o/filters.h", macro))[0] == "INJECTION"
    page = "<html><p>UAV</p><SCRIPT>alert(1)</SCRIPT></html>"
    assert _judge(ctx, 0, expect=probe.A, change=lambda c: c.write("r.html", page))[0] == "INJECTION"
    assert _judge(ctx, 0, expect=probe.A, change=lambda c: c.write("r.html", "<p>&lt;script&gt;</p>"))[0] \
        == "ACCEPTED"
    if probe.available("cc"):
        broken = "/* x*/ int evil */\nint f(void);\n"
        assert _judge(ctx, 0, expect=probe.A, change=lambda c: c.write("o/l.h", broken))[0] == "INJECTION"
    # an accepted folder must be complete: every file its manifest lists, with that hash, and no other
    def folder(c: probe.Ctx, extra: bool = False) -> None:
        c.write("out/a.txt", "a")
        c.write("out/manifest.json", '{"files": {"a.txt": "%s"}}' % probe.sha256(c.p("out/a.txt")))
        if extra:
            c.write("out/b.txt", "b")

    assert _judge(ctx, 0, expect=probe.A, change=folder, out="out")[0] == "ACCEPTED"
    (ctx.p("out/b.txt")).write_text("b")
    assert probe.folder_problem(ctx.p("out")) == "out: files not in its manifest: ['b.txt']"


def test_special_files_are_made_and_snapshots_never_open_them(ctx):
    for kind in ("fifo", "socket", "loop", "dangling", "folder"):
        probe.make_special(ctx.p(kind), kind)
    snap = probe.snapshot(ctx.work)  # a FIFO opened for reading would block here
    assert snap["fifo"][0] == "special" and snap["socket"][0] == "special"
    assert snap["loop"] == ("link", "loop.2") and snap["dangling"] == ("link", "missing/dangling")
    assert snap["folder"][0] == "dir" and ctx.p("fifo").is_fifo()
    assert Path(ctx.p("loop.2")).is_symlink()
