"""``scipctl report``: a self-contained HTML report (checked for its content and opened in headless Chromium)."""

import base64
import json
import re
import shutil
import subprocess

import numpy as np
import pytest
from typer.testing import CliRunner

from scipctl.cli import app
from scipctl.io.downlink import write_downlink
from tests.pipeline import scene as S

runner = CliRunner()
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    d = tmp_path_factory.mktemp("rep")
    _, dl = S.cached("slab")
    src = d / "sol7"
    write_downlink(dl, src, container="dir")
    out = d / "out" / "report.html"
    r = runner.invoke(app, ["report", str(src), "-o", str(out), "--json"])
    assert r.exit_code == 0, r.stderr
    return src, out, json.loads(r.stdout), r.stderr, dl


def test_report_is_self_contained_with_decodable_images(report):
    import cv2

    _, out, summary, _, _ = report
    html = out.read_text()
    srcs = re.findall(r'<img src="([^"]+)"', html)
    assert len(srcs) == summary["embedded_images"] == html.count("<img ") > 0
    for s in srcs:
        assert s.startswith("data:image/png;base64,")
        img = cv2.imdecode(np.frombuffer(base64.b64decode(s.split(",", 1)[1]), np.uint8), cv2.IMREAD_UNCHANGED)
        assert img is not None and img.size > 0
    # nothing is fetched from elsewhere
    assert not re.search(r'(src|href)="(https?:|//|file:)', html)
    assert "<link" not in html and "@import" not in html


def test_report_content_and_summary(report):
    _, out, summary, stderr, dl = report
    html = out.read_text()
    ids = [t.id for t in dl.targets]
    assert [t["id"] for t in summary["targets"]] == ids
    for tid in ids:
        assert f'id="t-{tid}"' in html
    for section in ("Handoff results (Table-1 style)", "Calibration health", "Gain and saturation",
                    "Pre-uplink prediction", "Uplink sequence and flight rules", "Expected views rendered",
                    "Systematic mast bias estimate", "Tracking chain"):
        assert section in html, section
    assert "fractions of the image's full scale" in html  # the gain table's mean/p1/p99 say their unit
    # per target: a chip for every left image where the target is marked
    for t in dl.targets:
        marked_left = [m.product_id for m in t.marks if dl.product(m.product_id).eye == "left"]
        sec = html.split(f'id="t-{t.id}"', 1)[1].split("<h2", 1)[0]
        for pid in marked_left:
            assert f"<b>{pid} (" in sec
    # the gain table has one row per image, and the handoff table covers the methods run
    gain = html.split('id="images"', 1)[1].split("<h2", 1)[0]
    assert gain.count("<tr>") == len(dl.images) + 1
    slab = next(t for t in summary["targets"] if t["id"] == "t_slab")
    assert slab["designated"] and slab["predicted_success"] is not None and slab["rules_broken"] == []
    assert "SCIP_BEGIN" in html and "ARM_PLACE_AT_TARGET" in html  # the t_slab sequence is embedded
    # exact world, no calibration error: the mast bias is nil
    assert abs(summary["mast_bias_deg"]["tilt"]) < 0.01 and abs(summary["mast_bias_deg"]["pan"]) < 0.01
    assert f"report: {out}" in stderr.replace("\n", "")
    # the --json summary carries the provenance the page embeds
    pv = summary["provenance"]
    assert pv["version"] and pv["command"] and pv["inputs"]["downlink"]["sha256"]
    assert pv["inputs"]["downlink"]["sha256"] in html


def _build_with_saved_handoff(report, rec: dict, row: dict):
    """(html, summary, data) of the report built (no prediction, no chain) with ``handoff.json`` holding ``rec``
    and the Table 1 ``row``; the file is removed afterwards."""
    from scipctl.commands.report import build
    from scipctl.io.workspace import open_source
    from scipctl.pipeline.report_data import ReportParams

    source = open_source(report[0])
    source.save_json("handoff.json", {"results": [rec], "table1": [row]})
    try:
        return build(source, params=ReportParams(run_prediction=False, run_chain=False, calib_points_per_pair=1))
    finally:
        (source.products_dir / "handoff.json").unlink()


def test_report_reuses_saved_handoff_results(report):
    rec = {"downlink": "x", "target": "t_slab", "method": "pure-geometric", "navcam": "near", "source_product": "p",
           "source_uv": [1.0, 2.0], "predicted_uv": [100.0, 50.0], "truth_uv": [103.0, 54.0], "error_px": 5.0,
           "success": False, "ok": True, "reason": "", "diagnostics": {}, "seconds": 0.1}
    row = {"method": "pure-geometric", "navcam": "near", "paper_method": True, "cases": 1, "answered": 1,
           "success_rate": 0.0, "all": {"n": 1, "mean_px": 5.0, "std_px": 0.0, "min_px": 5.0, "max_px": 5.0},
           "successes": None, "failures": {"n": 1, "mean_px": 5.0, "std_px": 0.0, "min_px": 5.0, "max_px": 5.0}, "refined": False}
    html, summary, data = _build_with_saved_handoff(report, rec, row)
    assert data["handoff"]["source"].startswith("handoff.json")
    assert data["handoff"]["table1"] == [row]
    assert "100.0, 50.0" in html and "5.0±0.0 (5.0-5.0)" in html
    assert next(t for t in summary["targets"] if t["id"] == "t_slab")["best_near_handoff"] == {
        "method": "pure-geometric", "error_px": 5.0}


def test_bad_output_path_is_one_line_exit_2(tmp_path, report):
    src = report[0]
    r = runner.invoke(app, ["report", str(src), "-o", str(tmp_path)])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and "directory" in r.stderr


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (Debian package `chromium`; .ci/setup installs it)")
def test_report_renders_with_its_images_in_headless_chromium(tmp_path, report):
    import cv2

    _, out, summary, _, _ = report
    base = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}"]
    dom = subprocess.run(base + ["--dump-dom", out.resolve().as_uri()], capture_output=True, text=True, timeout=180)
    assert dom.returncode == 0, dom.stderr[-2000:]
    ok = re.search(r'data-images-ok="(\d+)"', dom.stdout)
    total = re.search(r'data-images-total="(\d+)"', dom.stdout)
    assert ok and total, "the report's load script did not run"
    assert int(ok.group(1)) == int(total.group(1)) == summary["embedded_images"] > 0
    shot = tmp_path / "shot.png"
    r = subprocess.run(base + [f"--screenshot={shot}", "--window-size=1200,2000", out.resolve().as_uri()],
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0 and shot.exists(), r.stderr[-2000:]
    img = cv2.imread(str(shot), cv2.IMREAD_GRAYSCALE)
    assert img.shape == (2000, 1200) and float(img.std()) > 10  # not a blank page


def test_foxglove_annotations_mcap_matches_the_marks(report):
    from mcap.reader import make_reader

    _, out, summary, _, dl = report
    path = out.with_suffix(".annotations.mcap")
    assert summary["annotations_mcap"] == str(path)
    with open(path, "rb") as f:
        msgs = [(sch.name, ch.topic, m.log_time, json.loads(m.data)) for sch, ch, m in make_reader(f).iter_messages()]
    images = {d["frame_id"]: (topic, t) for name, topic, t, d in msgs if name == "foxglove.CompressedImage"}
    anns = [(topic, t, d) for name, topic, t, d in msgs if name == "foxglove.ImageAnnotations"]
    assert len(anns) == len(images) > 0
    for pid, (topic, t) in images.items():
        im = dl.product(pid)
        assert topic == f"/scipctl/{im.camera}_{im.eye}/image" and t == round(im.time_s * 1e9)
    # every mark of every target in an annotated image is there, in Foxglove's corner-origin pixels
    for topic, t, d in anns:
        pid = next(p for p, (tp, tt) in images.items() if tt == t and tp.rsplit("/", 1)[0] == topic.rsplit("/", 1)[0])
        for tm in dl.targets:
            mk = tm.mark_in(pid)
            if mk is None:
                continue
            hits = [c for c, x in zip(d["circles"], d["texts"]) if x["text"] == f"{tm.id}: true (mark)"]
            assert len(hits) == 1
            assert hits[0]["position"] == {"x": pytest.approx(mk.u + 0.5), "y": pytest.approx(mk.v + 0.5)}


def test_a_downlink_without_targets_says_so(tmp_path):
    """Real products carry no marks: the summary said nothing under its headings."""
    from scipctl.io.downlink import write_downlink
    from tests.io.builders import make_small_downlink

    dl = make_small_downlink()
    dl.targets, dl.truth_targets = [], []
    src = write_downlink(dl, tmp_path / "none.mcap")
    r = runner.invoke(app, ["report", str(src), "-o", str(tmp_path / "r.html"), "--json"])
    assert r.exit_code == 0, r.stderr
    html = (tmp_path / "r.html").read_text()
    assert "No targets: the downlink marks none and none has been designated" in html
    assert json.loads(r.stdout)["targets"] == []


def test_the_report_and_its_annotations_say_how_they_were_made_and_from_what(report):
    from mcap.reader import make_reader

    from scipctl.io.downlink import read_downlink

    src, out, summary, _, _ = report
    sha = read_downlink(src).source_sha256
    prov = summary["provenance"]
    assert prov["tool"] == "scipctl" and prov["inputs"]["downlink"]["sha256"] == sha
    assert "rules_file" in prov["inputs"]  # the rules the page's sequences were checked against
    assert [f["right"] for f in prov["stereo_selfcal"]] == [  # every pair self-calibrated first (the default)
        im.product_id for im in read_downlink(src).images if im.eye == "right"]
    with open(out.with_suffix(".annotations.mcap"), "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    ann_prov = json.loads(meta["scipctl.provenance"]["json"])
    assert ann_prov["tool"] == "scipctl" and ann_prov["inputs"]["downlink"]["sha256"] == sha
    assert ann_prov["command"]
    # the annotations show the designations and handoff answers the report read: the same inputs as the page's
    # (it recorded the downlink alone)
    assert ann_prov == prov


def test_the_report_hashes_the_saved_products_it_read(tmp_path, report):
    src0, *_ = report
    src = tmp_path / "sol7"
    shutil.copytree(src0, src)
    side = tmp_path / "sol7.scipctl"
    side.mkdir()
    (side / "handoff.json").write_text(json.dumps({"results": [], "table1": []}))
    out = tmp_path / "r.html"
    r = runner.invoke(app, ["report", str(src), "-o", str(out), "--json"])
    assert r.exit_code == 0, r.stderr
    inputs = json.loads(r.stdout)["provenance"]["inputs"]
    assert inputs["handoff.json"]["path"] == str(side / "handoff.json") and len(inputs["handoff.json"]["sha256"]) == 64


def test_the_report_may_not_overwrite_its_input(tmp_path, report):
    src0, *_ = report
    src = tmp_path / "sol7"
    shutil.copytree(src0, src)
    before = (src / "downlink.yaml").read_bytes()
    # -o naming the downlink's own file replaced it with the HTML page (exit 0)
    r = runner.invoke(app, ["report", str(src), "-o", str(src / "downlink.yaml")])
    assert r.exit_code == 2 and "would overwrite the input" in r.stderr and r.stderr.count("\n") == 1
    assert (src / "downlink.yaml").read_bytes() == before


def test_the_summary_shows_scips_answer_with_its_trust(report):
    # the page showed every method's error but never scip's own answer, p_success and GO: the Summary named the
    # best near handoff by truth only (a NO-GO answer among them)
    from scipctl.io.report_html import _f

    rec = {"downlink": "x", "target": "t_slab", "method": "scip", "navcam": "near", "source_product": "p",
           "source_uv": [1.0, 2.0], "predicted_uv": [100.0, 50.0], "truth_uv": [101.0, 50.0], "error_px": 1.0,
           "success": True, "ok": True, "reason": "", "diagnostics": {}, "seconds": 0.1, "p_success": 0.97,
           "go": True}
    row = {"method": "scip", "navcam": "any", "paper_method": False, "cases": 1, "answered": 1,
           "success_rate": 1.0, "all": {"n": 1, "mean_px": 1.0, "std_px": 0.0, "min_px": 1.0, "max_px": 1.0},
           "successes": {"n": 1, "mean_px": 1.0, "std_px": 0.0, "min_px": 1.0, "max_px": 1.0}, "failures": None, "refined": False}
    html, summary, _ = _build_with_saved_handoff(report, rec, row)
    assert next(t for t in summary["targets"] if t["id"] == "t_slab")["scip"] == {
        "navcam": "near", "error_px": 1.0, "p_success": 0.97, "go": True}
    assert "scip (recommended): error, p_success, GO" in html
    assert '1.0 px, p 0.97, <span class="ok">GO</span>' in html
    assert _f(-0.0004) == "0.00" and _f(-0.004, 3, " m") == "-0.004 m" and _f(None, 1, " cm") == "-"


def _tables(html: str) -> list:
    """[(headers, rows of cell texts)] of every table of the page (tags inside cells dropped)."""
    out = []
    for t in re.findall(r"<table>(.*?)</table>", html, re.S):
        trs = re.findall(r"<tr>(.*?)</tr>", t, re.S)
        head = [re.sub(r"<[^>]+>", "", h) for h in re.findall(r"<th>(.*?)</th>", trs[0], re.S)]
        rows = [[re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td>(.*?)</td>", tr, re.S)] for tr in trs[1:]]
        out.append((head, rows))
    return out


def test_every_pixel_column_says_px(report):
    # the chain table's "chain prediction", "tracked" and "mark", the handoff table's "predicted" and "true", the
    # designation's "pixel" and the prediction check's "mark" and "expected" held pixels with no unit in their header
    _, out, _, _, _ = report
    pixel_pair = re.compile(r"-?\d+\.\d, -?\d+\.\d")  # io/report_html._uv: an image pixel (u, v)
    seen = set()
    for head, rows in _tables(out.read_text()):
        for j, h in enumerate(head):
            if any(j < len(r) and pixel_pair.fullmatch(r[j]) for r in rows):
                seen.add(h)
    assert len(seen) >= 7, seen  # the designation, chain, handoff, prediction and mast-bias tables
    assert [h for h in sorted(seen) if "px" not in h.split()] == []


def test_the_chain_error_plot_has_its_table(report):
    # docs/report.md promises the tracking-chain error per stop as a plot and a table: the page had the plot only,
    # its x an unnamed step index
    _, out, _, _, dl = report
    html = out.read_text()
    sec = html.split("<h3>Tracking chain error per stop</h3>", 1)[1].split("<h2", 1)[0]
    (head, rows), = _tables(sec)
    assert head[0] == "step" and [r[0] for r in rows] == [str(i) for i in range(len(rows))]
    n = 0
    for j, h in enumerate(head[1:], 1):
        tid = h.split(":")[0]
        # each target's own chain table, step by step: stop, camera, kind, error
        chain = next(t for hd, t in _tables(html.split(f'id="t-{tid}"', 1)[1].split("<h2", 1)[0]) if hd[0] == "stop")
        want = [f"{r[6]} ({r[0]} {r[1]} {r[2]})" for r in chain]
        assert [r[j] for r in rows][:len(want)] == want and all(r[j] == "" for r in rows[len(want):])
        n += 1
    assert n == sum(1 for t in dl.targets) >= 1


def test_foxglove_handoff_predictions_have_their_methods_colours(report):
    # every handoff prediction was drawn in one red in Foxglove, whatever its method; the page gives each its own
    from mcap.reader import make_reader

    from scipctl.core.handoff.registry import ALL_METHODS
    from scipctl.io.report_html import method_colour

    _, out, _, _, _ = report
    with open(out.with_suffix(".annotations.mcap"), "rb") as f:
        anns = [json.loads(m.data) for sch, _, m in make_reader(f).iter_messages()
                if sch.name == "foxglove.ImageAnnotations"]
    colours = {}
    for d in anns:
        for c, x in zip(d["circles"], d["texts"]):
            label = x["text"].split(": ", 1)[1]
            method = label.split(" (")[0]
            if method in ALL_METHODS:
                rgb = tuple(round(c["outline_color"][k], 6) for k in "rgb")
                assert rgb == tuple(round(x["text_color"][k], 6) for k in "rgb")
                colours.setdefault(method, set()).add(rgb)
    assert len(colours) >= 2, colours  # the report ran several methods
    for method, seen in colours.items():
        b, g, r = method_colour(method, {})
        assert seen == {(round(r / 255, 6), round(g / 255, 6), round(b / 255, 6))}, method


def test_the_stereo_self_calibration_is_shown_beside_the_calibration_health(report):
    """The page shows each pair's fit that the provenance records (the default: on), in the same order."""
    _, out, summary, _, _ = report
    fits = summary["provenance"]["stereo_selfcal"]
    table = next(rows for head, rows in _tables(out.read_text()) if "median residual before px" in head)
    assert [r[0] for r in table] == [f["left"] for f in fits] and len(fits) >= 1
    assert [r[2] for r in table] == ["yes" if f["applied"] else "no" for f in fits]
    assert [r[6] for r in table] == [f"{f['residual_px_before']:.2f}" for f in fits]


def test_the_report_takes_simulate_handoffs_chains_and_shows_the_same(tmp_path, report):
    """After `simulate-handoff --chain`, the report takes each marked target's chain from handoff.json (by its key:
    pipeline/chain_key.py) instead of running it, and the page is the one running them gives: equal, line for line,
    but for the time, the command line, handoff.json's hash (a different file) and the line that says where the
    chains came from."""
    src0 = report[0]
    src = tmp_path / "sol7"
    shutil.copytree(src0, src, ignore=shutil.ignore_patterns("scipctl"))
    r = runner.invoke(app, ["simulate-handoff", str(src), "--chain", "--json"])
    assert r.exit_code in (0, 1), r.stderr  # 1: a NO-GO answer, handoff.json written all the same
    saved = tmp_path / "sol7.scipctl" / "handoff.json"  # a raw downlink's products: beside it
    doc = json.loads(saved.read_text())
    assert doc["chains"] and all(len(c["key"]) == 64 for c in doc["chains"])
    pages = {}
    for mode in ("taken", "run"):
        if mode == "run":  # the same handoff.json without its chains: the report runs them
            saved.write_text(json.dumps(dict(doc, chains=[]), indent=1))
        out = tmp_path / f"{mode}.html"
        r = runner.invoke(app, ["report", str(src), "-o", str(out), "--json"])
        assert r.exit_code == 0, r.stderr
        summary = json.loads(r.stdout)
        chained = [t for t in summary["targets"] if t["chain_source"] is not None]
        assert chained and all(t["chain_source"].startswith("from handoff.json" if mode == "taken" else "run by")
                               for t in chained), summary["targets"]
        pages[mode] = out.read_text().splitlines()
    differ = [(a, b) for a, b in zip(pages["taken"], pages["run"]) if a != b]
    assert len(pages["taken"]) == len(pages["run"])
    allowed = ("Generated by scipctl", "chains: ", "&quot;command&quot;", "&quot;sha256&quot;", "&quot;time_utc&quot;",
               "&quot;chain&quot;:", "&quot;calibration&quot;:", "&quot;designate&quot;:", "&quot;prediction&quot;:",
               "&quot;handoff&quot;:", "@METADATA &quot;provenance&quot;")
    assert [a for a, _ in differ if not any(k in a for k in allowed)] == [] and len(differ) <= 16, differ
