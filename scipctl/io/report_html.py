"""Self-contained HTML diagnostic report: every image is an embedded PNG (data URI), plots by matplotlib (Agg
canvas, no global backend change), no external resources (docs/report.md)."""

from __future__ import annotations

import base64
import html
import math
from typing import Optional

import numpy as np

# marker styles: kind -> (BGR colour, OpenCV marker, CSS colour)
STYLE = {
    "true": ((60, 200, 60), "tilted", "#3cc83c"),
    "designated": ((0, 220, 255), "cross", "#ffdc00"),
    "tracked": ((255, 255, 0), "square", "#00ffff"),
    "expected": ((0, 140, 255), "diamond", "#ff8c00"),
}
# handoff predictions: one BGR colour per method, in the registry's order (core/handoff/registry.ALL_METHODS), none
# of them a STYLE colour; then spares for names the registry does not know. The navcam a prediction started from is
# the marker's shape (NAVCAM_MARKERS)
METHOD_COLOURS = [(75, 25, 230),     # pure-kinematic: red #e6194b
                  (216, 99, 67),     # alt-pure-kinematic: blue #4363d8
                  (230, 50, 240),    # refined-kinematic: magenta #f032e6
                  (180, 30, 145),    # pure-geometric: purple #911eb4
                  (255, 190, 220),   # refined-geometric: lavender #dcbeff
                  (36, 99, 154),     # mesh-registration: brown #9a6324
                  (212, 190, 250),   # coarse-fine-geometric: pink #fabed4
                  (144, 153, 70),    # consensus: teal #469990
                  (255, 255, 255),   # scip: white
                  (0, 0, 128), (117, 0, 0), (0, 128, 128)]  # spares: maroon, navy, olive
# navcam -> (OpenCV marker, the glyph beside its label on the page)
NAVCAM_MARKERS = {"near": ("triangle", "&#9650;"), "far": ("triangle_down", "&#9660;")}
CHIP_PX = 264  # displayed chip size


def png_bytes(img: np.ndarray) -> bytes:
    """(h, w) float [0, 1] (NaN: dark blue) or uint8 (h, w[, 3] BGR) -> PNG bytes."""
    import cv2

    a = np.asarray(img)
    if a.dtype != np.uint8:
        f = np.asarray(a, np.float32)
        nan = ~np.isfinite(f)
        g = np.clip(np.nan_to_num(f, nan=0.0) * 255, 0, 255).astype(np.uint8)
        if nan.any():
            g = cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)
            g[nan] = (60, 20, 20)
        a = g
    ok, buf = cv2.imencode(".png", a)
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def method_colour(method: str, palette: dict) -> tuple:
    """The BGR colour of a handoff method's predictions: its own for every registered method, whatever else the page
    shows; a name the registry does not know gets the next spare colour (``palette``: the page's such names)."""
    from ..core.handoff.registry import ALL_METHODS

    if method in ALL_METHODS:
        return METHOD_COLOURS[ALL_METHODS.index(method)]
    if method not in palette:
        spare = METHOD_COLOURS[len(ALL_METHODS):]
        palette[method] = spare[len(palette) % len(spare)]
    return palette[method]


def prediction_colour(m, palette: dict) -> tuple:
    """The BGR colour of a handoff prediction's marker (a ``ChipMarker`` of kind "predicted"): its method's
    (:func:`method_colour`), the page's and the Foxglove annotations' alike; a marker without a method by its label."""
    return method_colour(m.method or m.label, palette)


def _marker_style(m, palette: dict) -> tuple:
    """(BGR colour, marker kind, glyph for the page) of a chip marker: :data:`STYLE`'s for its kind, else a
    handoff prediction's (colour by method, shape by navcam)."""
    if m.kind in STYLE:
        col, mk, _ = STYLE[m.kind]
        return col, mk, ""
    mk, glyph = NAVCAM_MARKERS.get(m.navcam or "", NAVCAM_MARKERS["near"])
    return prediction_colour(m, palette), mk, glyph


def annotate_chip(chip, palette: dict, size: int = CHIP_PX) -> np.ndarray:
    """The chip enlarged to ``size`` px (nearest neighbour) with its markers drawn; BGR uint8."""
    import cv2

    h, w = chip.image.shape
    zoom = size / max(h, w)
    f = np.nan_to_num(chip.image, nan=0.0)
    g = np.clip(f * 255, 0, 255).astype(np.uint8)
    big = cv2.resize(g, (int(round(w * zoom)), int(round(h * zoom))), interpolation=cv2.INTER_NEAREST)
    out = cv2.cvtColor(big, cv2.COLOR_GRAY2BGR)
    nan = cv2.resize((~np.isfinite(chip.image)).astype(np.uint8), (out.shape[1], out.shape[0]),
                     interpolation=cv2.INTER_NEAREST).astype(bool)
    out[nan] = (60, 20, 20)
    kinds = {"tilted": cv2.MARKER_TILTED_CROSS, "cross": cv2.MARKER_CROSS, "square": cv2.MARKER_SQUARE,
             "diamond": cv2.MARKER_DIAMOND, "triangle": cv2.MARKER_TRIANGLE_UP,
             "triangle_down": cv2.MARKER_TRIANGLE_DOWN}
    for m in chip.markers:
        uv = (np.asarray(m.uv, float) + 0.5) / chip.scale - 0.5 - np.asarray(chip.origin_uv, float)
        p = ((uv + 0.5) * zoom).astype(float)
        if not np.all(np.isfinite(p)):
            continue
        col, mk, _ = _marker_style(m, palette)
        x, y = int(round(p[0])), int(round(p[1]))
        if -20 <= x <= out.shape[1] + 20 and -20 <= y <= out.shape[0] + 20:
            cv2.drawMarker(out, (x, y), (0, 0, 0), kinds[mk], 17, 4, cv2.LINE_AA)
            cv2.drawMarker(out, (x, y), col, kinds[mk], 17, 2, cv2.LINE_AA)
    return out


def _bgr_css(c) -> str:
    return f"#{c[2]:02x}{c[1]:02x}{c[0]:02x}"


# ----------------------------------------------------------------------------- plots
def _figure(w_in=7.0, h_in=3.2):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=100)
    FigureCanvasAgg(fig)
    return fig


def _fig_png(fig) -> bytes:
    import io

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def plot_methods(rows: list) -> Optional[bytes]:
    """Mean handoff error per method (near / far), min-max whiskers, log scale."""
    rows = [r for r in rows if r.get("all")]
    if not rows:
        return None
    methods = []
    for r in rows:
        if r["method"] not in methods:
            methods.append(r["method"])
    fig = _figure(8.0, 3.6)
    ax = fig.add_subplot(111)
    x = np.arange(len(methods))
    # scip answers from either navcam (its row's navcam is "any"): a third series, present only when it is
    series = [("near", "#2f7ed8"), ("far", "#f28f43")] + ([("any", "#2e8b57")] if any(r["navcam"] == "any" for r in rows) else [])
    width = 0.76 / len(series)
    for k, (nc, col) in enumerate(series):
        mean, lo, hi = [], [], []
        for m in methods:
            r = next((r for r in rows if r["method"] == m and r["navcam"] == nc), None)
            if r is None or r["all"] is None:
                mean.append(np.nan), lo.append(0), hi.append(0)
                continue
            s = r["all"]
            mean.append(max(s["mean_px"], 0.05))
            lo.append(max(s["mean_px"] - s["min_px"], 0))
            hi.append(max(s["max_px"] - s["mean_px"], 0))
        ax.bar(x + (k - (len(series) - 1) / 2) * width, mean, width, yerr=[lo, hi], color=col,
               label="either navcam (scip)" if nc == "any" else f"{nc} navcam", capsize=2)
    ax.set_yscale("log")
    ax.set_xticks(x)
    ax.set_xticklabels(methods, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("hazcam error (px)")
    ax.axhline(4.0, color="k", lw=0.8, ls=":")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))  # beside the axes: over them it hid bars
    ax.set_title("navcam -> hazcam handoff error per method (bars: mean, whiskers: range; dotted: 4 px)", fontsize=9)
    return _fig_png(fig)


def plot_chain(targets: list) -> Optional[bytes]:
    """Tracking-chain error (px, against marks) per stop, one line per target (``t["chain"]``: chain steps)."""
    fig = _figure()
    ax = fig.add_subplot(111)
    any_line = False
    for t in targets:
        pts = [(i, s.error_px) for i, s in enumerate(t["chain"]) if s.error_px is not None]
        if pts:
            i, e = zip(*pts)
            ax.plot(i, e, "o-", label=t["id"])
            any_line = True
    if not any_line:
        return None
    ax.set_xlabel("chain step (stop and camera, in time order)")
    ax.set_ylabel("error vs mark (px)")
    ax.legend(fontsize=8)
    ax.set_title("tracking chain error per stop", fontsize=9)
    return _fig_png(fig)


def plot_prediction(pred) -> Optional[bytes]:
    """Per planned view: P(in field of view), P(in search region), P(visible), P(kept by tracking) and the pointing offset
    (90th percentile over the samples in view)."""
    if pred.mc is None or not pred.mc.views:
        return None
    fig = _figure(8.0, 3.2)
    ax = fig.add_subplot(111)
    labels = [f"{v.stop}:{v.camera[0]}" for v in pred.mc.views]
    x = np.arange(len(labels))
    kept = {(v["stop"], v["camera"]): v.get("p_kept_given_visible") for v in (pred.chain.per_view if pred.chain else [])}
    ax.plot(x, [v.p_in_fov for v in pred.mc.views], "o-", label="P in view")
    ax.plot(x, [v.p_in_search for v in pred.mc.views], "s-", label="P in search region")
    ax.plot(x, [v.p_visible for v in pred.mc.views], "^-", label="P not occluded")
    ax.plot(x, [kept.get((v.stop, v.camera)) if kept.get((v.stop, v.camera)) is not None else np.nan
                for v in pred.mc.views], "d-", label="P kept (tracking on expected views)")
    ax.set_ylim(-0.05, 1.05)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, fontsize=7)
    ax.set_xlabel("stop:camera")
    ax2 = ax.twinx()
    ax2.bar(x, [v.offset_px_p90 for v in pred.mc.views], 0.5, color="#cccccc", alpha=0.5)
    ax2.set_ylabel("pointing offset, p90 in view (px)", fontsize=8)
    ax.set_zorder(ax2.get_zorder() + 1)
    ax.patch.set_visible(False)
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(f"pre-uplink prediction for {pred.target_id}: P(success) {pred.confidence:.2f}", fontsize=9)
    return _fig_png(fig)


# ----------------------------------------------------------------------------- HTML
CSS = """
body{font-family:system-ui,sans-serif;margin:1.2em;color:#222;background:#fafafa}
h1{font-size:1.5em}h2{font-size:1.25em;border-bottom:1px solid #bbb;margin-top:1.6em}h3{font-size:1.05em}
table{border-collapse:collapse;margin:.5em 0;font-size:.85em}td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}
th{background:#eee}.bad{color:#b00;font-weight:bold}.ok{color:#070}.warn{color:#a60}
.chips{display:flex;flex-wrap:wrap;gap:10px}.chip{background:#fff;border:1px solid #ddd;padding:4px;width:272px;font-size:.75em}
.chip img{display:block;width:264px;height:auto}pre{background:#fff;border:1px solid #ddd;padding:6px;font-size:.75em;overflow-x:auto}
.sw{display:inline-block;width:.9em;height:.9em;border:1px solid #333;vertical-align:middle;margin-right:3px}
.small{font-size:.8em;color:#555}
"""


def _e(x) -> str:
    return html.escape(str(x))


def _f(x, nd=2, unit="") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    text = f"{x:.{nd}f}"
    if text.startswith("-") and not text.strip("-0."):  # -0.00: a value that rounds to zero is shown as zero
        text = text[1:]
    return text + unit


def _img(png: bytes, alt: str, width: Optional[int] = None) -> str:
    w = f' width="{width}"' if width else ""
    return f'<img src="{data_uri(png)}" alt="{_e(alt)}"{w}>'


def _table(headers: list, rows: list) -> str:
    out = ["<table><tr>" + "".join(f"<th>{_e(h)}</th>" for h in headers) + "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _chip_html(chip, palette) -> str:
    png = png_bytes(annotate_chip(chip, palette))
    true = next((m.uv for m in chip.markers if m.kind == "true"), None)
    lines = []
    for m in chip.markers:
        bgr, _, glyph = _marker_style(m, palette)
        col = STYLE[m.kind][2] if m.kind in STYLE else _bgr_css(bgr)
        err = ""
        if true is not None and m.kind != "true":
            err = f", {math.hypot(m.uv[0] - true[0], m.uv[1] - true[1]):.1f} px from true"
        lines.append(f'<span class="sw" style="background:{col}"></span>{glyph + " " if glyph else ""}{_e(m.label)}: '
                     f'({m.uv[0]:.1f}, {m.uv[1]:.1f}){err}')
    return f'<div class="chip"><b>{_e(chip.title)}</b>{_img(png, chip.title)}' + "<br>".join(lines) + "</div>"


def render_report(data: dict, sequences: dict, paper_table1: dict, provenance: dict) -> str:
    """The report HTML. ``sequences``: target id -> {"checks": [RuleCheck dicts], "text": SeqN or None}.

    ``data``: ``scipctl.pipeline.report_data.collect``'s; per target its ``record`` (the designation record, or
    None), ``chain`` (chain steps) and ``handoff`` (handoff records), read by attribute.
    """
    palette: dict = {}
    P = []
    add = P.append
    title = f"scipctl report: {data['mission']} sol {data['sol']}"
    add(f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{_e(title)}</title>"
        f"<style>{CSS}</style></head><body>")
    add(f"<h1>{_e(title)}</h1>")
    add(f"<p class=\"small\">source {_e(data['source'])} (sha256 {_e(data['sha256'][:16])}…), {data['images']} images, "
        f"positions {_e(', '.join(f'{a}/{b}' for a, b in data['positions']))}; "
        f"simulation truth: {'yes' if data['has_truth'] else 'no'}. "
        f"Generated by scipctl {_e(provenance.get('version', ''))} ({_e(provenance.get('time_utc', ''))}).</p>")
    add('<p class="small" id="img-status">images decoded: <span id="img-ok">?</span> of <span id="img-total">?</span>'
        " (counted by the page's script)</p>")

    # ---- summary
    add("<h2 id=\"summary\">Summary</h2>")
    rows = []
    for t in data["targets"]:
        rec = t["record"]
        pred = t["prediction"]
        seq = sequences.get(t["id"], {})
        bad = [c["rule"] for c in seq.get("checks", []) if c["blocking"] and not c["ok"]]
        fin = next((s for s in reversed(t["chain"]) if s.error_px is not None), None)
        best = _best_handoff(t["handoff"])
        scip = next((r for r in t["handoff"] if r.method == "scip"), None)
        rows.append([
            f'<a href="#t-{_e(t["id"])}">{_e(t["id"])}</a>',
            "-" if rec is None else _e(rec.product_id) + (" (from mark)" if rec.designated_from == "mark" else ""),
            _f(None if rec is None else rec.range_m), _f(t["designation_error_m"], 3),
            "-" if fin is None else f"{_f(fin.error_px, 1)} px ({_e(fin.camera)})",
            _scip_answer(scip),
            best,
            "-" if pred is None else _f(pred.confidence),
            "-" if pred is None else str(len(pred.risks)),
            "-" if not seq else ('<span class="ok">sequence ok</span>' if not bad else
                                 '<span class="bad">broken: ' + _e(", ".join(bad)) + "</span>"),
        ])
    if rows:
        add(_table(["target", "designated in", "range m", "3-D error m (truth)", "chain final error",
                    "scip (recommended): error, p_success, GO", "best handoff (near, by truth)",
                    "P(success) predicted (calibrated)", "risks", "sequence"], rows))
    else:
        add('<p class="small">No targets: the downlink marks none and none has been designated '
            "(<code>scipctl designate</code> adds one).</p>")
    if data["notes"]:
        add("<ul>" + "".join(f"<li class=\"warn\">{_e(n)}</li>" for n in data["notes"]) + "</ul>")

    # ---- Table 1
    h = data["handoff"]
    add("<h2 id=\"table1\">Handoff results (Table-1 style)</h2>")
    if h["table1"]:
        add(f"<p class=\"small\">source: {_e(h['source'])}; success = error within the success threshold.</p>")
        trs = []
        for r in h["table1"]:
            split = "-"
            if r.get("refined"):
                split = f"{_stats(r.get('successes'))} / {_stats(r.get('failures'))}"
            trs.append([_e(r["method"]), _e(r["navcam"]), f"{100 * r['success_rate']:.0f}%", f"{r['answered']}/{r['cases']}",
                        _stats(r.get("all")), split, _e(paper_table1.get((r["method"], r["navcam"]), "(not in paper)"))])
        add(_table(["method", "navcam", "success", "answered", "mean±std (range) px", "successes / failures px",
                    "paper (Rocky8)"], trs))
        png = plot_methods(h["table1"])
        if png:
            add(_img(png, "handoff error per method"))
    else:
        add("<p>No handoff results (no hazcam/navcam pairs, or no marked targets).</p>")
    png = plot_chain(data["targets"])
    if png:
        add("<h3>Tracking chain error per stop</h3>" + _img(png, "chain error per stop"))
        add(_chain_error_table(data["targets"]))
    sources = data.get("chain_sources") or {}
    if sources:
        add("<p class=\"small\">chains: " + "; ".join(
            f"{_e(', '.join(t for t in sources if sources[t] == src))} {_e(src)}" for src in dict.fromkeys(sources.values()))
            + "</p>")

    # ---- per target
    for t in data["targets"]:
        add(f"<h2 id=\"t-{_e(t['id'])}\">Target {_e(t['id'])}</h2>")
        rec = t["record"]
        if rec is None:
            add("<p>Not designated.</p>")
        else:
            xyz = rec.xyz_site_m
            add(_table(["designated in", "pixel (u, v) px", "site xyz m", "range m", "range σ m", "epipolar offset px", "warnings"],
                       [[_e(rec.product_id), _e(_uv(rec.pixel_uv)),
                         "-" if xyz is None else _e(", ".join(f"{v:.3f}" for v in xyz)), _f(rec.range_m),
                         _f(rec.range_sigma_m, 3), _f(rec.epipolar_offset_px),
                         _e("; ".join(rec.warnings or []) or "none")]]))
        add("<h3>Image chips: designated, predicted (per method), tracked and true positions</h3>")
        add('<p class="small">' + " ".join(f'<span class="sw" style="background:{v[2]}"></span>{_e(k)}'
                                           for k, v in STYLE.items()) +
            "; handoff methods (triangles): one colour per method, &#9650; from the near navcam, &#9660; from the far</p>")
        add('<div class="chips">' + "".join(_chip_html(c, palette) for c in t["chips"]) + "</div>")
        if t["chain"]:
            add("<h3>Tracking chain through the downlink's stops</h3>")
            add(_table(["stop", "camera", "kind", "chain prediction px", "tracked px", "mark px", "error px", "NCC", "range m",
                        "3-D error m", "p_success", "GO", "note"],
                       [[f"{s.position[0]}/{s.position[1]}", _e(s.camera), _e(s.kind), _uv(s.predicted_uv),
                         _uv(s.tracked_uv), _uv(s.mark_uv), _f(s.error_px, 2), _f(s.ncc_peak),
                         _f(s.range_m), _f(s.error_3d_m, 3), _f(s.p_success),
                         '<span class="ok">GO</span>' if s.go else
                         '<span class="bad">NO-GO: ' + _e(s.advice or "") + "</span>",
                         _e(s.reason or "")] for s in t["chain"]]))
        if t["handoff"]:
            add("<h3>Handoff predictions for this target</h3>")
            add(_table(["method", "navcam", "predicted px", "true px", "error px", "success", "note"],
                       [[_e(r.method), _e(r.navcam), _uv(r.predicted_uv), _uv(r.truth_uv),
                         _f(r.error_px, 1), _yes(r.success), _e(r.reason or "")]
                        for r in t["handoff"]]))
        pred = t["prediction"]
        if pred is not None:
            add(_prediction_html(pred, t.get("expected_chips", []), palette))
        if t.get("prediction_check"):
            add("<h3>Prediction against the later images of this downlink</h3>")
            add("<p class=\"small\">Expected pixel: the designated 3-D target through each later image's model and "
                "downlinked (estimated) pose. Render check: today's stereo terrain rendered through the same model, "
                "NCC-matched to the real image around the mark (best shift within ±150 px): the NCC measures how well the "
                "expected appearance matches, the shift how far today's geometry (calibration) puts it.</p>")
            add(_table(["image", "camera", "position", "mark px", "expected px (downlinked pose)", "error px",
                        "error px at the true pose", "rendered at pose", "terrain coverage", "render NCC", "render shift px"],
                       [[_e(r["product_id"]), _e(r["camera"]), f"{r['position'][0]}/{r['position'][1]}", _uv(r["mark_uv"]),
                         _uv(r["expected_uv"]), _f(r["expected_error_px"], 1), _f(r.get("expected_error_true_pose_px"), 1),
                         _e(r.get("render_pose", "")), _f(r["coverage"]), _f(r["ncc"]), _uv(r["shift_px"])]
                        for r in t["prediction_check"]]))
            add('<details><summary>actual vs expected chips</summary><div class="chips">'
                + "".join(_chip_html(c, palette) for c in t["prediction_check_chips"]) + "</div></details>")
        seq = sequences.get(t["id"])
        if seq:
            add("<h3>Uplink sequence and flight rules</h3>")
            add(_table(["rule", "result", "detail"],
                       [[_e(c["rule"]), ('<span class="ok">ok</span>' if c["ok"] else
                                         ('<span class="bad">BROKEN</span>' if c["blocking"] else '<span class="warn">advisory</span>')),
                         _e(c["message"])] for c in seq["checks"]]))
            if seq.get("text"):
                add(f"<details><summary>SeqN-style sequence ({seq['text'].count(chr(10))} lines, notional command stems)</summary>"
                    f"<pre>{_e(seq['text'])}</pre></details>")
            else:
                add("<p class=\"bad\">No sequence: flight rules broken.</p>")
            if seq.get("error"):
                add(f"<p class=\"bad\">{_e(seq['error'])}</p>")

    # ---- calibration
    cal = data["calibration"]
    add("<h2 id=\"calibration\">Calibration health</h2>")
    add("<p class=\"small\">Epipolar offset: signed distance of the right-image match from the epipolar curve of the "
        "left pixel (point stereo on textured points; and from the marks where present). The paper saw up to ~4 px on "
        "pancams (mast vibration, unsynchronised cameras).</p>")
    add(_table(["pair", "camera", "position", "point-stereo offsets px", "median px", "from marks px"],
               [[_e(p["left"]), _e(p["camera"]), f"{p['position'][0]}/{p['position'][1]}",
                 _e(", ".join(f"{o:+.2f}" for o in p["point_stereo_offsets_px"]) or "-"), _f(p["median_offset_px"]),
                 _e(", ".join(f"{m['target']}: {m['offset_px']:+.2f}" for m in p["mark_offsets"]) or "-")]
                for p in cal["pairs"]]))
    fits = data.get("stereo_selfcal")
    add("<h3>Stereo self-calibration</h3>")
    if fits is None:
        add("<p>Off (--no-stereo-selfcal): every stereo pair on this page read the downlinked camera models.</p>")
    else:
        add("<p class=\"small\">Before anything on this page ran, each stereo pair's right eye was turned onto the "
            "pair's own feature matches (rows and roll; docs/stereo-and-tracking.md, \"Stereo self-calibration\"), "
            "so the offsets above are measured on the turned models. The median epipolar residual of the matches "
            "before is the downlinked models' misalignment; after, the matches' own noise. A pair with too few "
            "matches keeps its downlinked model.</p>")
        add(_table(["pair", "camera", "applied", "rows px", "roll px", "matches / inliers", "median residual before px",
                    "after px", "why not applied"],
                   [[_e(f["left"]), _e(f["camera"]), "yes" if f["applied"] else "no", _f(f["rows_px"]),
                     _f(f["roll_px"]), f"{f['n_matches']} / {f['n_inliers']}", _f(f["residual_px_before"]),
                     _f(f["residual_px_after"]), _e(f["reason"]) or "-"] for f in fits]))
    mb = cal.get("mast_bias")
    add("<h3>Systematic mast bias estimate</h3>")
    if mb:
        tr = mb.get("truth")
        add(_table(["cases", "mean hazcam residual (du, dv) px", "rms before px", "pan bias deg", "tilt bias deg",
                    "rms after px", "truth: navcam-hazcam rotation error deg (about z, y)"],
                   [[str(mb["cases"]), _uv(mb["residual_before_px"]), _f(mb["rms_before_px"], 1),
                     _f(math.degrees(mb["dpan_rad"]), 3), _f(math.degrees(mb["dtilt_rad"]), 3), _f(mb["rms_after_px"], 1),
                     "-" if not tr else f"{math.degrees(tr['rotation_rad']):.3f} ({math.degrees(tr['about_rover_z_rad']):+.3f}, "
                                        f"{math.degrees(tr['about_rover_y_rad']):+.3f})"]]))
        add("<p class=\"small\">The mast (pan, tilt) correction that best makes navcam-triangulated marks land on their "
            "hazcam marks at the same rover position (the paper's 13-row kinematic handoff bias pointed at ~1° of mast "
            "tilt error). It takes up every mast error it can: a tilt axis off true or a displaced head shows in it "
            "too, so it is not the encoders' offsets alone (docs/report.md, \"What the pan estimate holds\").</p>")
    else:
        add("<p>Needs targets marked in a near navcam pair and the hazcam at the same position.</p>")

    # ---- images
    add("<h2 id=\"images\">Gain and saturation</h2>")
    add("<p class=\"small\">mean, p1 and p99 (the 1st and 99th percentiles) are fractions of the image's full scale "
        "(2^bits - 1).</p>")
    add(_table(["product", "camera", "eye", "position", "exposure ms", "gain", "bits", "mean", "p1", "p99", "saturated",
                "dark", "L/R ratio", "flags"],
               [[_e(s["product_id"]), _e(s["camera"]), _e(s["eye"]), f"{s['position'][0]}/{s['position'][1]}",
                 _f(s["exposure_ms"], 1), _f(s["gain"], 2), str(s["bits"]), _f(s["mean"], 3), _f(s["p1"], 3), _f(s["p99"], 3),
                 f"{100 * s['saturated_fraction']:.2f}%", f"{100 * s['dark_fraction']:.1f}%", _f(s.get("pair_ratio"), 2),
                 ('<span class="warn">' + _e("; ".join(s["flags"])) + "</span>") if s["flags"] else ""]
                for s in data["image_stats"]]))

    # ---- provenance
    add("<h2 id=\"provenance\">Provenance and timings</h2>")
    add(f"<pre>{_e(_json(provenance))}\nseconds: {_e(_json({k: round(v, 2) for k, v in data['seconds'].items()}))}</pre>")
    add("<script>window.addEventListener('load',function(){var im=document.images,n=0;"
        "for(var i=0;i<im.length;i++){if(im[i].complete&&im[i].naturalWidth>0)n++;}"
        "document.getElementById('img-ok').textContent=n;document.getElementById('img-total').textContent=im.length;"
        "document.body.setAttribute('data-images-ok',n);document.body.setAttribute('data-images-total',im.length);});"
        "</script>")
    add("</body></html>")
    return "\n".join(P) + "\n"


def _prediction_html(pred, chips, palette) -> str:
    out = ["<h3>Pre-uplink prediction (from today's downlink only)</h3>"]
    plan = pred.plan
    acc = pred.accuracy or {}
    out.append(f"<p>Planned path {plan.path_length_m:.2f} m, approach bearing {math.degrees(plan.bearing_rad):.1f}° "
               f"(detour {math.degrees(plan.detour_rad):+.0f}°), {len(plan.stops) - 1} stops. Pose-error sigma: "
               f"{_e(pred.sigma_source)} ({pred.mc.sigma_position_m:.3f} m, {math.degrees(pred.mc.sigma_yaw_rad):.2f}°); "
               f"{pred.mc.n_samples} Monte Carlo samples, {len([s for s in pred.chain.samples if s.sample >= 0]) if pred.chain else 0} "
               f"tracked on expected views: simulated P {pred.p_simulated:.2f}. <b>P(success) {pred.confidence:.2f}</b> "
               f"({_e(pred.calibration or 'not calibrated')}); P(arm reaches) "
               f"{_f(pred.mc.p_arm_workspace, 2)}; predicted final error (nominal) "
               f"{_f(None if acc.get('nominal_final_error_m') is None else 100 * acc['nominal_final_error_m'], 1, ' cm')} "
               f"(goal {_f(100 * acc.get('goal_m', 0.01), 1)} cm).</p>")
    mcv = {(v.stop, v.camera): v for v in pred.mc.views} if pred.mc else {}
    chv = {(v["stop"], v["camera"]): v for v in pred.chain.per_view} if pred.chain else {}
    risk = {(r.stop, r.camera): r for r in pred.risks}
    rows = []
    for st in plan.stops[1:]:
        for sh in st.cameras:
            v = mcv.get((st.index, sh.camera))
            c = chv.get((st.index, sh.camera), {})
            r = risk.get((st.index, sh.camera))
            rows.append([str(st.index), _e(st.kind), _f(st.distance_m), _e(sh.camera), _uv(sh.uv),
                         _f(None if v is None else v.p_in_fov), _f(None if v is None else v.p_in_search),
                         _f(None if v is None else v.p_visible), _f(c.get("p_kept_given_visible")),
                         _f(None if c.get("nominal_error_m") is None else 100 * c["nominal_error_m"], 1),
                         _f(None if sh.incidence_rad is None else math.degrees(sh.incidence_rad), 0),
                         _f(sh.texture_std, 3),
                         ('<span class="bad">' + _e("; ".join(r.reasons)) + "</span>") if r else '<span class="ok">ok</span>'])
    for r in pred.risks:
        if r.camera == "arm":
            rows.append([str(r.stop), "arm", "", "", "", "", "", "", "", "", "", "",
                         '<span class="bad">' + _e("; ".join(r.reasons)) + "</span>"])
    out.append(_table(["stop", "kind", "dist m", "camera", "expected px", "P in view", "P in search", "P visible",
                       "P kept", "nominal error cm", "incidence °", "texture σ", "risk"], rows))
    png = plot_prediction(pred)
    if png:
        out.append(_img(png, f"prediction {pred.target_id}"))
    if chips:
        out.append("<details open><summary>Expected views rendered from today's stereo terrain (orange: expected target)"
                   "</summary><div class=\"chips\">" + "".join(_chip_html(c, palette) for c in chips) + "</div></details>")
    if pred.notes:
        out.append("<ul>" + "".join(f"<li>{_e(n)}</li>" for n in pred.notes) + "</ul>")
    return "\n".join(out)


def _chain_error_table(targets: list) -> str:
    """The plot's numbers: per chain step (the plot's x) and target, the error against the mark with the step's
    stop, camera and kind (each target's own chain table has the rest)."""
    chained = [t for t in targets if t["chain"]]
    rows = []
    for i in range(max(len(t["chain"]) for t in chained)):
        row = [str(i)]
        for t in chained:
            if i >= len(t["chain"]):
                row.append("")
                continue
            s = t["chain"][i]
            where = f"{s.position[0]}/{s.position[1]} {_e(s.camera)} {_e(s.kind)}"
            row.append(f"{_f(s.error_px, 2)} ({where})" if s.error_px is not None else f"- ({where})")
        rows.append(row)
    return _table(["step"] + [f"{t['id']}: error px (stop, camera, kind)" for t in chained], rows)


def _scip_answer(r) -> str:
    """scip's answer for a target: its error against the mark (when marked), p_success and GO/NO-GO; "-" when the
    handoff results hold no scip record (computed for the report: run simulate-handoff to include it)."""
    if r is None:
        return "-"
    err = "no truth" if r.error_px is None else f"{r.error_px:.1f} px"
    verdict = '<span class="ok">GO</span>' if r.go else '<span class="bad">NO-GO</span>'
    return f"{err}, p {_f(r.p_success)}, {verdict}"


def _best_handoff(recs: list) -> str:
    ok = [r for r in recs if r.navcam == "near" and r.error_px is not None]
    if not ok:
        return "-"
    r = min(ok, key=lambda r: r.error_px)
    return f"{_e(r.method)} {r.error_px:.1f} px"


def _stats(s) -> str:
    """A Table-1 row's error statistics (``{n, mean_px, std_px, min_px, max_px}``) as ``mean±std (min-max)``."""
    if not s:
        return "-"
    return f"{s['mean_px']:.1f}±{s['std_px']:.1f} ({s['min_px']:.1f}-{s['max_px']:.1f})"


def _uv(uv) -> str:
    if uv is None:
        return "-"
    try:
        return f"{float(uv[0]):.1f}, {float(uv[1]):.1f}"
    except (TypeError, ValueError, IndexError):
        return "-"


def _yes(b) -> str:
    if b is None:
        return "-"
    return '<span class="ok">yes</span>' if b else '<span class="bad">no</span>'


def _json(o) -> str:
    import json

    return json.dumps(o, indent=1, sort_keys=True, default=str)
