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
from html import escape
from html.parser import HTMLParser
from pathlib import Path

import pytest

from ilcdob.app.cli import main
from ilcdob.app.commands import compare_to_folder, report_to_html, reproduce_to_folder
from ilcdob.app.html import ReportError, ReportOptions, build_report, json_tables
from ilcdob.app.output import OutputError
from ilcdob.design.methods.fir import FIROptions
from ilcdob.validation.compare import CompareOptions
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
    """A tiny ``ilcdob reproduce`` output: scenario 4 (order UAV1 -> UAV3 -> UAV2), two iterations (exact
    models: they coincide)."""
    out = tmp_path_factory.mktemp("paper")
    reproduce_to_folder(out, fleet=None, scenarios=[4], iterations=2)
    return out


def _png(path: Path, text: str) -> None:
    """A small stand-in figure (a PNG as the commands write them)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 2))
    fig.subplots().plot([1, 2, 3], label=text)
    fig.savefig(path, format="png", dpi=110)


@pytest.fixture(scope="module")
def json_dirs(tmp_path_factory) -> tuple[Path, Path]:
    cmp_dir, camp_dir = tmp_path_factory.mktemp("compare"), tmp_path_factory.mktemp("campaign")
    (cmp_dir / "compare.json").write_text(json.dumps(COMPARE))
    (camp_dir / "campaign.json").write_text(json.dumps(CAMPAIGN))
    _png(cmp_dir / "compare_ratios.png", "compare")
    _png(camp_dir / "campaign_ratios.png", "campaign")
    return cmp_dir, camp_dir


@pytest.fixture(scope="module")
def failed_compare(tmp_path_factory) -> Path:
    """A real ``ilcdob compare`` folder where the FIR design fails: a convergence margin of 0.95
    (|Te1| <= 0.05) that 8 taps cannot meet under a 60 % bound, refused rather than relaxed."""
    out = tmp_path_factory.mktemp("failed") / "compare"
    fir = FIROptions(n_taps=8, advance=2, max_iter=5, n_grid=20, margin=0.95, unattainable="refuse")
    cmp = compare_to_folder(out, 1, CompareOptions(samples=1, bound=0.6, duration=5.0, fir=fir),
                            methods=["closed-form", "fir"])
    assert cmp.row("fir").error and cmp.row("closed-form").error is None
    return out


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
    # and the Theorem-check figure written beside them by `reproduce`; then the compare and campaign figures
    alts = [img["alt"] for img in parsed.images]
    assert alts == ["identified_models.png", "bode_loops.png", "bode_learning.png", "bode_te.png",
                    "rmse_bars.png", "error_s4.png", "disturbance_s4.png", "theorem.png",
                    "compare_ratios.png", "campaign_ratios.png"]
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
    # compare: rows = methods, columns = numeric fields (human labels); the list "w" is left out and counted
    for text in ("closed-form", "robust", ">ratio median<", "0.0123", "0.0456", "3 list values not tabulated",
                 ">improved<", "98.5 %", "1.75", "0.0876"):
        assert text in html, text
    # only the nonlinear and rotorpy plants have no input here: left out, and named once
    assert '<span class="status-none">' not in html and 'class="missing"' not in html
    (note,) = re.findall(r'<p class="not-included">(.*?)</p>', html)
    assert "Nonlinear plant (<code>ilcdob reproduce --plant nonlinear --out DIR</code>)" in note
    assert "Rotorpy plant (<code>ilcdob reproduce --plant rotorpy --out DIR</code>)" in note
    assert '<h2 id="nonlinear">' not in html and '<h2 id="rotorpy">' not in html


def test_sections_not_run_are_listed_once_and_no_numbers_invented(tmp_path, json_dirs):
    html = build_report([json_dirs[1]])
    # one short list of what was not included, no "no input" box per section, no empty section
    (note,) = re.findall(r'<p class="not-included">(.*?)</p>', html)
    for heading, command in (("Fleet and identified models", "ilcdob reproduce"),
                             ("Bode figures of the paper", "ilcdob reproduce"), ("Linear plant", "ilcdob reproduce"),
                             ("Nonlinear plant", "--plant nonlinear"), ("Rotorpy plant", "--plant rotorpy"),
                             ("Theorem check", "ilcdob reproduce"), ("Design comparison", "ilcdob compare")):
        assert note.count(heading) == 1 and command in note, heading
        assert f">{heading}" not in html.replace(note, ""), heading  # no heading, no contents row
    assert "No input" not in html and 'class="missing"' not in html and 'class="status-none"' not in html
    assert re.findall(r'<h2 id="(\w+)">', html) == ["contents", "campaign"]
    # no results.json: no figure but the campaign's own
    assert [img["alt"] for img in _parse(html).images] == ["campaign_ratios.png"]
    assert "0.0654" in html  # the campaign that was given is rendered


def _figures(html: str) -> dict[str, str]:
    """Caption of every embedded figure, by its alt text."""
    return dict(re.findall(r'<img src="data:image/png;base64,[^"]+" alt="([^"]+)"><figcaption>(.*?)</figcaption>',
                           html))


def test_compare_and_campaign_figures_are_embedded_in_their_sections(full_report, json_dirs):
    html = full_report.read_text(encoding="utf-8")
    compare = html[html.index('<h2 id="compare">'):html.index('<h2 id="campaign">')]
    campaign = html[html.index('<h2 id="campaign">'):]
    assert list(_figures(compare)) == ["compare_ratios.png"]
    assert list(_figures(campaign)) == ["campaign_ratios.png"]
    # the figure follows its tables, and its caption says what it shows and where it comes from
    assert compare.index("<img") > compare.index("ratio_median")
    caption = _figures(compare)["compare_ratios.png"]
    assert "Improvement ratio" in caption and "nominal" in caption and "Delta set" in caption
    assert str(json_dirs[0] / "compare_ratios.png") in caption
    caption = _figures(campaign)["campaign_ratios.png"]
    assert "Distribution of the improvement ratio" in caption and "quartiles" in caption
    assert str(json_dirs[1] / "campaign_ratios.png") in caption


def test_every_figure_caption_says_what_it_shows(full_report):
    captions = _figures(full_report.read_text(encoding="utf-8"))
    assert len(captions) == 10
    for alt, caption in captions.items():
        text = caption.split(" (/")[0]  # without the file's path
        assert len(text) > 40 and alt not in text, (alt, caption)
    assert "every learning iteration" in captions["rmse_bars.png"]
    assert "every learning iteration" in captions["error_s4.png"] and "(m)" in captions["error_s4.png"]
    assert "every learning" in captions["disturbance_s4.png"] and "m/s^2" in captions["disturbance_s4.png"]


def test_a_failed_design_shows_its_reason(failed_compare):
    html = build_report([failed_compare])
    reason = json.loads((failed_compare / "compare.json").read_text())["methods"]["fir"]["error"]
    assert "not met" in reason
    row = re.search(r'<tr class="failed"><td>fir</td><td colspan="(\d+)">(.*?)</td></tr>', html)
    assert row, "no row with the failed design's reason"
    assert row.group(2) == f"<strong>no result</strong>: {escape(reason)}"
    # it spans the value columns of the table: one cell instead of a row of nulls
    header = re.search(r"<thead><tr><th>method</th>(.*?)</tr></thead>\n<tbody>\n<tr><td>closed-form", html)
    assert int(row.group(1)) == header.group(1).count("<th")
    # the design that was made keeps its numbers; the figure of the real folder is embedded
    assert re.search(r"<tr><td>closed-form</td><td>[0-9.e-]+</td>", html)
    assert list(_figures(html)) == ["compare_ratios.png"]
    (table,) = json_tables(json.loads((failed_compare / "compare.json").read_text()))
    assert table.failed == (("fir", reason),) and "error" not in table.columns


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
    # a row with a text "error" has no result: its reason is kept, the column is not
    (t,) = json_tables({"methods": {"a": {"x": 1.0, "error": None}, "b": {"x": None, "error": " boom "}}})
    assert t.columns == ("x",) and t.failed == (("b", "boom"),)
    assert COMPARE and json_tables(COMPARE)[0].failed == ()


def test_columns_have_human_labels_with_units(tmp_path):
    data = {"samples": 3, "sample_cpu_s": 4.25, "wall_time_s": 12.5, "duration": None,
            "methods": {"closed-form": {"runs": 3, "median": 0.02, "p95": 0.04, "share_improved": 1.0,
                                        "rmse_nominal": 0.0123, "settle_time_s": 1.5, "ratio": {"median": 0.5}},
                        "fir": {"runs": 3, "median": 0.03, "p95": 0.05, "share_improved": 0.985,
                                "rmse_nominal": 0.0456, "settle_time_s": 2.5, "ratio": {"median": 0.25}}}}
    (tmp_path / "campaign.json").write_text(json.dumps(data))
    html = build_report([tmp_path])
    head = re.search(r"<thead><tr><th>method</th>(.*?)</tr></thead>", html).group(1)
    labels = dict(re.findall(r'<th title="([^"]+)">([^<]+)</th>', head))
    assert labels == {"runs": "runs", "median": "median", "p95": "95th percentile", "share_improved": "improved",
                      "rmse_nominal": "RMSE nominal (mm)", "settle_time_s": "settle time (s)",
                      "ratio.median": "ratio median"}
    rows = re.findall(r"<tr><td>(closed-form|fir)</td>(.*?)</tr>", html)
    cells = {name: re.findall(r"<td>([^<]*)</td>", row) for name, row in rows}
    assert cells["closed-form"] == ["3", "0.02", "0.04", "100 %", "12.3", "1.5", "0.5"]  # share in %, RMSE in mm
    assert cells["fir"][3] == "98.5 %" and cells["fir"][4] == "45.6"
    # the run's settings: labels with units, a null as "-"
    meta = dict(re.findall(r"<tr><td>([^<]+)</td><td>([^<]*)</td></tr>", html.split('<table class="meta">')[1]
                           .split("</table>")[0]))
    assert meta == {"samples": "3", "CPU per sample (s)": "4.25", "wall time (s)": "12.5", "trial duration (s)": "-"}
    for raw in (">sample_cpu_s<", ">share_improved<", ">wall_time_s<", "null"):
        assert raw not in html, raw


def test_coinciding_learning_iterations_are_said_in_words(full_report):
    html = full_report.read_text(encoding="utf-8")
    assert ("The learning iterations coincide for every system of every scenario: all 2 leave the same tracking "
            "RMSE (within 0.1 %).") in html
    captions = _figures(html)
    for name in ("bode_loops.png", "bode_learning.png", "bode_te.png"):
        assert "wrapped to (-180, 180]" in captions[name] and "drawn once" in captions[name], name


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
    with pytest.raises(ReportError, match=r"\"plant\" is 'hybrid', expected one of \['linear', 'nonlinear', 'rotorpy'\]"):
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


def _forged(paper_dir: Path, folder: Path, name: str, change) -> Path:
    """A copy of ``paper_dir`` with ``change(data)`` applied to its ``name`` and the manifest's SHA-256 of it
    recomputed, so that only the type checks stand between the edit and the report."""
    import hashlib

    shutil.copytree(paper_dir, folder)
    data = json.loads((folder / name).read_text())
    change(data)
    (folder / name).write_text(json.dumps(data))
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["files"][name] = hashlib.sha256((folder / name).read_bytes()).hexdigest()
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


@pytest.mark.parametrize("name, change, key, value", [
    ("theorem.json", lambda d: d["orders"][0]["pairs"][0].update(worst_w="abc"), "orders[0].pairs[0].worst_w",
     "'abc'"),
    ("theorem.json", lambda d: d["orders"][0]["pairs"][1].update(delta_source=5), "orders[0].pairs[1].delta_source",
     "5"),
    ("results.json", lambda d: d["scenarios"][0].update(duration_s="abc"), "scenarios[0].duration_s", "'abc'"),
    ("results.json", lambda d: d["scenarios"][0]["systems"]["UAV2"].update(peak_d_f_learning=[1.0, "x"]),
     "scenarios[0].systems.UAV2.peak_d_f_learning", "[1.0, 'x']"),
    ("results.json", lambda d: d.update(sensor_noise_std_m=True), "sensor_noise_std_m", "True"),
])
def test_a_forged_result_number_is_refused_naming_the_file_key_and_value(tmp_path, paper_dir, name, change, key,
                                                                        value):
    """A number of a result file that is not one (the manifest recomputed, as a forger would) was accepted."""
    folder = _forged(paper_dir, tmp_path / "forged", name, change)
    with pytest.raises(ReportError) as info:
        build_report([folder])
    assert f'{folder / name}: key "{key}": got {value}, expected ' in str(info.value)
    assert main(["--quiet", "report", str(folder), "--out", str(tmp_path / "r.html")]) == 2
    assert not (tmp_path / "r.html").exists()


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
    assert len(states) == 10 and set(states.values()) == {"yes"}, states


# ---- the Theorem check that reproduce writes for the report (theorem.json) -----------------------------

ORDERS = [["UAV1", "UAV2", "UAV3"], ["UAV1", "UAV3", "UAV2"]]  # the reproduction's (scenario 4 the second)


def test_theorem_json_is_the_check_on_sampled_sets_without_sampling(fleet, monkeypatch):
    """The report's check reads the Delta sets' bounds only: theorem.json is that of the sets of 8 sampled
    plants it names, and no sampled plant's loop is built."""
    import ilcdob
    import ilcdob.design.sets.delta as delta
    from ilcdob.app.html import THEOREM_SAMPLES, _theorem_pair, report_files
    from ilcdob.app.output import json_text
    from ilcdob.design.pair import fleet_delta_sets, pair_band
    from ilcdob.design.checks.theorem import format_theorem_table, learning_pairs, theorem_check

    want = {"samples": THEOREM_SAMPLES, "seed": 0, "orders": []}
    for order in ORDERS:  # the check as it was built: sampled sets per order
        deltas = fleet_delta_sets(fleet, order, k=THEOREM_SAMPLES, seed=0)
        bands = {(a, b): pair_band(fleet, a, b, deltas=deltas) for a, b in learning_pairs(fleet.names, order)}
        checks = theorem_check(fleet, order, deltas, bands=bands)
        want["orders"].append({"order": order, "table": format_theorem_table(checks),
                               "pairs": [_theorem_pair(c) for c in checks]})

    def no_sampling(*args, **kwargs):
        raise AssertionError("a sampled plant's loop was built")

    monkeypatch.setattr(delta, "build_loop", no_sampling)
    got = report_files(ilcdob.default_fleet(), ORDERS + [ORDERS[0]], figures=False)
    assert json_text(got["theorem.json"], "theorem.json") == json_text(want, "theorem.json")


def test_report_files_without_figures_builds_no_figure(fleet, monkeypatch):
    from matplotlib.figure import Figure

    from ilcdob.app.html import report_files
    from ilcdob.validation.figures import PendingFigure

    assert isinstance(report_files(fleet, ORDERS)["theorem.png"], Figure)
    assert isinstance(report_files(fleet, ORDERS, pending=True)["theorem.png"], PendingFigure)

    def no_figure(self, *args, **kwargs):
        raise AssertionError("a figure was built for --no-figures")

    monkeypatch.setattr(Figure, "__init__", no_figure)
    files = report_files(fleet, ORDERS, figures=False)
    assert list(files) == ["fleet.json", "theorem.json"]


def test_bound_only_delta_sets_refuse_what_needs_samples(fleet):
    from ilcdob.design.checks.theorem import bound_delta_sets, theorem_check
    from ilcdob.errors import SpecError

    sets = bound_delta_sets(fleet)
    assert list(sets) == fleet.names and all(s.loops == () and s.source == "identification" for s in sets.values())
    with pytest.raises(SpecError, match=r"`deltas\['UAV1'\]`: holds the bound only .*source='bound'"):
        theorem_check(fleet, None, sets, source="samples")
    with pytest.raises(SpecError, match=r"`names`: got \['UAV1', 'UAV9'\], expected system names of the fleet"):
        bound_delta_sets(fleet, ["UAV1", "UAV9"])


OWN_CONTROLLER = Path(__file__).parents[1] / "reports" / "own_controller"


def test_the_report_shows_a_run_on_the_vehicles_own_controllers(tmp_path):
    """The committed own-controller run (reports/own_controller) in the report: its section holds every vehicle,
    every acceptance row with its verdict and every learning ratio of results.json as the report formats it, and
    its figure; a results.json missing a field the section reads is refused by key."""
    html = build_report([OWN_CONTROLLER])
    data = json.loads((OWN_CONTROLLER / "results.json").read_text())
    start = html.index('<h2 id="own"')
    section = html[start:html.find("<h2 ", start + 1)]
    text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", section))
    for v in data["settings"]["vehicles"]:
        assert f" {v['name']} " in text
    for row in data["acceptance"]:  # formatted as the report's tables do: 4 significant digits
        cells = [escape(row["what"]), f"{row['value']:.4g}", f"{row['limit']:.4g}", "yes" if row["passed"] else "NO"]
        assert "<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>" in section, row
    first = data["runs"][0]
    name = first["order"][0]
    assert f"{first['ratios'][name][0]:.4g}" in text
    assert "data:image/png;base64," in section
    broken = tmp_path / "own"
    shutil.copytree(OWN_CONTROLLER, broken)
    (broken / "manifest.json").unlink()
    del data["runs"][0]["ratios"]
    (broken / "results.json").write_text(json.dumps(data))
    with pytest.raises(ReportError, match='key "runs\\[0\\].ratios"'):
        build_report([broken])


def test_the_report_names_each_section_as_it_renders_it(paper_dir, json_dirs, tmp_path):
    """``report`` takes seconds per section (figures embedded): the progress names each of them once, in the
    order they appear; the HTML is the same with or without it."""
    from ilcdob.app.html import build_report

    seen = []
    with_progress = build_report([paper_dir, *json_dirs], progress=lambda *step: seen.append(step))
    assert [d for d, _, _ in seen] == list(range(len(seen))) and all(t == len(seen) for _, t, _ in seen)
    assert seen[0][2] == "report section: fleet and identified models"
    assert seen[-1][2] == "report section: campaign statistics"
    assert with_progress == build_report([paper_dir, *json_dirs])
