"""The HTML report (``ilcdob report``): sections from their inputs, generic JSON tables, errors,
and every figure rendering in headless Chromium.

Chromium is Debian's ``chromium`` package, installed by ``.ci/run``. Without it the browser
test is skipped, unless ``ILCDOB_REQUIRE_CHROMIUM=1`` (set by ``.ci/run``), which makes a
missing browser a failure.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

from ilcdob.app.cli import main
from ilcdob.app.commands import report_to_html, reproduce_to_folder
from ilcdob.app.html import ReportError, ReportOptions, build_report, json_tables
from ilcdob.app.output import OutputError
from ilcdob.validation.reproduce import reproduce

CHROMIUM = "/usr/bin/chromium"

# Hand-written stand-ins for the outputs of `ilcdob compare` and `ilcdob campaign`, in the two
# shapes the report documents (dict of methods; list of records). Values are arbitrary test data.
COMPARE = {"fleet": "built-in", "samples": 20, "methods": {
    "closed-form": {"ratio_median": 0.0123, "ratio_worst": 0.25, "improved": True, "solve_time_s": 0.01},
    "robust": {"ratio_median": 0.0456, "ratio_worst": 0.125, "improved": True, "solve_time_s": 3.5,
               "w": [1.0, 2.0, 3.0]}}}
CAMPAIGN = {"samples": 200, "seed": 7, "statistics": [
    {"method": "closed-form", "median": 0.0321, "p95": 0.0987, "worst": 1.75, "share_improved": 0.985},
    {"method": "robust", "median": 0.0654, "p95": 0.0876, "worst": 0.5, "share_improved": 1.0}]}


@pytest.fixture(scope="module")
def paper_dir(tmp_path_factory, fleet) -> Path:
    """A tiny ``ilcdob reproduce`` output: scenario 4 (order UAV1 -> UAV3 -> UAV2), one iteration."""
    out = tmp_path_factory.mktemp("paper")
    reproduce_to_folder(out, fleet=None, scenarios=[4], iterations=1)
    return out


@pytest.fixture(scope="module")
def json_dirs(tmp_path_factory) -> tuple[Path, Path]:
    cmp_dir, camp_dir = tmp_path_factory.mktemp("compare"), tmp_path_factory.mktemp("campaign")
    (cmp_dir / "compare.json").write_text(json.dumps(COMPARE))
    (camp_dir / "campaign.json").write_text(json.dumps(CAMPAIGN))
    return cmp_dir, camp_dir


@pytest.fixture(scope="module")
def full_report(tmp_path_factory, paper_dir, json_dirs) -> Path:
    out = tmp_path_factory.mktemp("report") / "report.html"
    assert main(["report", str(paper_dir), *map(str, json_dirs), "--out", str(out)]) == 0
    return out


class _Images(HTMLParser):
    """Collects the attributes of every <img> and the attributes of <body>."""

    def __init__(self) -> None:
        super().__init__()
        self.images: list[dict[str, str | None]] = []
        self.body: dict[str, str | None] = {}
        self.urls: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.images.append(a)
        if tag == "body":
            self.body = a
        for key in ("src", "href", "srcset", "data", "action"):
            if a.get(key):
                self.urls.append(a[key])


def _parse(html: str) -> _Images:
    p = _Images()
    p.feed(html)
    return p


def test_report_is_self_contained(full_report):
    html = full_report.read_text(encoding="utf-8")
    parsed = _parse(html)
    # every reference is an embedded image or an in-page anchor; no stylesheet/script/font is fetched
    assert parsed.urls and all(u.startswith("data:image/png;base64,") or u.startswith("#") for u in parsed.urls)
    assert not re.search(r"https?://", html)
    assert "<link" not in html and "<script" not in html
    # figures of the tiny run: identified models, 3 Bode, RMSE bars, error/disturbance of scenario 4,
    # and the Theorem-check figure written beside them by `reproduce`
    alts = [img["alt"] for img in parsed.images]
    assert alts == ["identified_models.png", "bode_loops.png", "bode_learning.png", "bode_te.png",
                    "rmse_bars.png", "error_s4.png", "disturbance_s4.png", "theorem.png"]
    umask = os.umask(0)
    os.umask(umask)
    assert full_report.stat().st_mode & 0o777 == 0o666 & ~umask  # as any new file, not the private 0600 temp


def test_sections_render_from_their_inputs(full_report, paper_dir):
    html = full_report.read_text(encoding="utf-8")
    results = json.loads((paper_dir / "results.json").read_text())
    m = results["scenarios"][0]["systems"]["UAV3"]
    assert f"{1e3 * m['rmse_dob']:.4g}" in html  # RMSE table in mm, from results.json
    assert "Order UAV1 -&gt; UAV3 -&gt; UAV2" in html  # Theorem check in the scenario's learning order
    assert "UAV3 -&gt; UAV2" in html
    # compare: rows = methods, columns = numeric fields; the list "w" is left out and counted
    for text in ("closed-form", "robust", "ratio_median", "0.0123", "0.0456", "3 list values not tabulated",
                 "share_improved", "0.985", "1.75", "0.0876"):
        assert text in html, text
    # only the nonlinear plant has no input here
    assert html.count('<span class="status-none">') == 1
    assert 'results.json with &quot;plant&quot;: &quot;nonlinear&quot;' in html


def test_missing_inputs_are_named_and_no_numbers_invented(tmp_path, json_dirs):
    html = build_report([json_dirs[1]])
    for heading in ("Fleet and identified models", "Bode figures of the paper", "Linear plant",
                    "Nonlinear plant", "Theorem check", "Design comparison"):
        row = re.search(rf'<a href="#\w+">{re.escape(heading)}[^<]*</a></td><td>(.*?)</td>', html).group(1)
        assert "no input" in row and "expected" in row, heading
    assert "<img" not in html  # no results.json: no figure at all
    compare = html[html.index('<h2 id="compare">'):html.index('<h2 id="campaign">')]
    assert "<table" not in compare and "No input" in compare
    assert "0.0654" in html  # the campaign that was given is rendered


def test_json_tables_shapes():
    (t,) = json_tables(COMPARE)
    assert t.path == "methods"
    assert [label for label, _ in t.rows] == ["closed-form", "robust"]
    assert t.columns == ("ratio_median", "ratio_worst", "improved", "solve_time_s")
    assert t.omitted == 3
    (t,) = json_tables(CAMPAIGN)
    assert t.path == "statistics" and t.columns == ("median", "p95", "worst", "share_improved")
    assert [label for label, _ in t.rows] == ["closed-form", "robust"]
    # per-pair nesting, pair labels from source/target, nested dicts flattened with dots
    nested = {"pairs": [{"source": "UAV1", "target": "UAV2",
                         "methods": {"fir": {"ratio": {"median": 0.5, "p95": 0.75}, "n": 3}}},
                        {"source": "UAV2", "target": "UAV3", "methods": {"fir": {"ratio": {"median": 0.25}, "n": 4}}}]}
    tables = json_tables(nested)
    assert [t.path for t in tables] == ["pairs[0].methods", "pairs[1].methods"]
    assert tables[0].columns == ("ratio.median", "ratio.p95", "n")
    rows = json_tables({"rows": [{"source": "A", "target": "B", "ratio": 0.5}, {"name": "x", "ratio": None}]})[0].rows
    assert [label for label, _ in rows] == ["A -> B", "x"]
    assert json_tables({"note": "nothing numeric", "list": [1, 2, 3]}) == []


def test_errors_name_the_folder_and_the_expected_files(tmp_path, paper_dir):
    with pytest.raises(ReportError, match=r"'.*nowhere': no such folder.*results\.json, compare\.json, campaign\.json"):
        build_report([tmp_path / "nowhere"])
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("x")
    with pytest.raises(ReportError, match=r"empty': none of results\.json.*holds notes\.txt"):
        build_report([tmp_path / "empty"])
    with pytest.raises(ReportError, match=r"is a file.*pass its folder"):
        build_report([paper_dir / "results.json"])
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "compare.json").write_text("{not json")
    with pytest.raises(ReportError, match=r"compare\.json: not valid JSON"):
        build_report([bad])
    wrong = tmp_path / "wrong"
    wrong.mkdir()
    (wrong / "results.json").write_text(json.dumps({"plant": "hybrid", "scenarios": []}))
    with pytest.raises(ReportError, match=r"\"plant\" is 'hybrid', expected one of \['linear', 'nonlinear'\]"):
        build_report([wrong])
    with pytest.raises(ReportError, match="got no folder"):
        build_report([])
    with pytest.raises(OutputError, match="is a folder"):
        report_to_html([paper_dir], tmp_path)
    with pytest.raises(ReportError, match="title"):
        ReportOptions(title=" ")
    # the CLI turns them into exit status 2 and leaves no file behind
    assert main(["report", str(tmp_path / "nowhere"), "--out", str(tmp_path / "r.html")]) == 2
    assert not (tmp_path / "r.html").exists()


def test_a_folder_mixing_runs_is_refused_and_old_folders_say_what_they_lack(tmp_path, paper_dir):
    mixed = tmp_path / "mixed"
    shutil.copytree(paper_dir, mixed)
    data = json.loads((mixed / "results.json").read_text())
    data["iterations"] = 7  # a results.json of another run beside these figures
    (mixed / "results.json").write_text(json.dumps(data))
    with pytest.raises(ReportError, match=r"results\.json differs from the file its run wrote.*ilcdob reproduce"):
        build_report([mixed])
    assert main(["report", str(mixed), "--out", str(tmp_path / "r.html")]) == 2
    # a folder written before manifests, fleet.json and theorem.json existed: rendered, gaps named
    old = tmp_path / "old"
    shutil.copytree(paper_dir, old)
    for name in ("manifest.json", "fleet.json", "theorem.json", "theorem.png"):
        (old / name).unlink()
    html = build_report([old])
    assert "provenance unknown" in html and "has no fleet.json" in html and "has no theorem.json" in html
    assert "min margin" not in html and "rmse_bars.png" in html  # the RMSE numbers and figures still render


_PROBE = """<img id="control" alt="control" src="data:image/png;base64,AAAA"><script>
window.addEventListener("load", function () {
  for (const img of document.images) {
    img.setAttribute("data-ok", (img.complete && img.naturalWidth > 0) ? "yes" : "no");
  }
  document.body.setAttribute("data-checked", "yes");
});
</script></body>"""


def test_every_figure_renders_in_chromium(full_report, tmp_path):
    if not os.path.exists(CHROMIUM):
        if os.environ.get("ILCDOB_REQUIRE_CHROMIUM") == "1":
            pytest.fail(f"{CHROMIUM} is missing and ILCDOB_REQUIRE_CHROMIUM=1; install Debian's chromium "
                        "package (apt-get install -y chromium), as .ci/run does")
        pytest.skip(f"{CHROMIUM} not installed (Debian package chromium; .ci/run installs it)")
    # a copy with a probe that marks every image as loaded or not; plus a broken control image
    probe = tmp_path / "probe.html"
    probe.write_text(full_report.read_text(encoding="utf-8").replace("</body>", _PROBE), encoding="utf-8")
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=5000", "--dump-dom",
           probe.as_uri()]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    dom = _parse(run.stdout)
    assert dom.body.get("data-checked") == "yes", run.stdout[:500]
    states = {img.get("alt"): img.get("data-ok") for img in dom.images}
    assert states.pop("control") == "no"  # the probe does detect a broken image
    assert len(states) == 8 and set(states.values()) == {"yes"}, states
