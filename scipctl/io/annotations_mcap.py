"""The report's image annotations as an MCAP file for Foxglove (JSON encoding, Foxglove schema names).

For every left image that carries a report chip: a ``foxglove.CompressedImage``
(the downlinked PNG) on ``/scipctl/<camera>_left/image`` and a
``foxglove.ImageAnnotations`` on ``/scipctl/<camera>_left/annotations`` at the
same time (``log_time = round(time_s * 1e9)``), with a circle and a label per
position: true (mark), designated, tracked, chain prediction and each handoff
method's prediction (in the method's colour on the report's page), for every target. Foxglove's image coordinates put the
origin at the top-left corner of the top-left pixel, so a scipctl pixel
``(u, v)`` (pixel centres) is written as ``(u + 0.5, v + 0.5)``.
"""

from __future__ import annotations

import base64
import io
import json

from .. import __version__

COLOURS = {  # r, g, b in [0, 1]
    "true": (0.24, 0.78, 0.24), "designated": (1.0, 0.86, 0.0), "tracked": (0.0, 1.0, 1.0),
    "expected": (1.0, 0.55, 0.0),
}  # a handoff prediction ("predicted"): its method's colour, _predicted_rgb
_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
_POINT = {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}}}
_COLOR = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
SCHEMAS = {
    "foxglove.CompressedImage": {
        "title": "foxglove.CompressedImage", "type": "object",
        "properties": {"timestamp": _TIME, "frame_id": {"type": "string"},
                       "data": {"type": "string", "contentEncoding": "base64"}, "format": {"type": "string"}},
    },
    "foxglove.ImageAnnotations": {
        "title": "foxglove.ImageAnnotations", "type": "object",
        "properties": {
            "circles": {"type": "array", "items": {"type": "object", "properties": {
                "timestamp": _TIME, "position": _POINT, "diameter": {"type": "number"}, "thickness": {"type": "number"},
                "fill_color": _COLOR, "outline_color": _COLOR}}},
            "points": {"type": "array", "items": {"type": "object"}},
            "texts": {"type": "array", "items": {"type": "object", "properties": {
                "timestamp": _TIME, "position": _POINT, "text": {"type": "string"}, "font_size": {"type": "number"},
                "text_color": _COLOR, "background_color": _COLOR}}},
        },
    },
}


def _colour(rgb, a=1.0):
    return {"r": rgb[0], "g": rgb[1], "b": rgb[2], "a": a}


def _predicted_rgb(m, palette: dict) -> tuple:
    """A handoff prediction's colour, r, g, b in [0, 1]: its method's on the report's page (one per method)."""
    from .report_html import prediction_colour

    b, g, r = prediction_colour(m, palette)
    return (r / 255.0, g / 255.0, b / 255.0)


def _stamp(ns: int) -> dict:
    return {"sec": int(ns // 1_000_000_000), "nsec": int(ns % 1_000_000_000)}


def annotation_messages(dl, data) -> list:
    """[(topic base, product, log_time_ns, image message, annotations message)] for the report's chips."""
    per_product = {}
    for t in data["targets"]:
        for ch in t["chips"]:
            per_product.setdefault(ch.product_id, []).extend((t["id"], m) for m in ch.markers)
    out = []
    palette: dict = {}  # the report page's colours of methods the registry does not know
    for pid in sorted(per_product, key=lambda p: (dl.product(p).time_s, p)):
        im = dl.product(pid)
        ns = int(round(im.time_s * 1e9))
        ts = _stamp(ns)
        circles, texts = [], []
        for tid, m in per_product[pid]:
            rgb = COLOURS.get(m.kind) or _predicted_rgb(m, palette)
            pos = {"x": float(m.uv[0]) + 0.5, "y": float(m.uv[1]) + 0.5}
            circles.append({"timestamp": ts, "position": pos, "diameter": 12.0, "thickness": 2.0,
                            "fill_color": _colour(rgb, 0.0), "outline_color": _colour(rgb)})
            texts.append({"timestamp": ts, "position": {"x": pos["x"] + 8.0, "y": pos["y"] - 8.0},
                          "text": f"{tid}: {m.label}", "font_size": 12.0, "text_color": _colour(rgb),
                          "background_color": _colour((0, 0, 0), 0.5)})
        img = {"timestamp": ts, "frame_id": pid, "data": base64.b64encode(im.png).decode("ascii"), "format": "png"}
        ann = {"circles": circles, "points": [], "texts": texts}
        out.append((f"/scipctl/{im.camera}_{im.eye}", pid, ns, img, ann))
    return out


def annotations_bytes(dl, data, prov=None) -> bytes:
    """The annotation MCAP. ``prov``: the provenance record of the report it goes with (the same inputs: the
    downlink and the products and rules file the report read); None: one naming the downlink only."""
    from mcap.writer import CompressionType, Writer

    buf = io.BytesIO()
    w = Writer(buf, compression=CompressionType.ZSTD)
    w.start(profile="", library=f"scipctl {__version__}")
    sids = {name: w.register_schema(name, "jsonschema", json.dumps(s, sort_keys=True).encode()) for name, s in SCHEMAS.items()}
    channels = {}
    for base, _, ns, img, ann in annotation_messages(dl, data):
        if base not in channels:
            channels[base] = (w.register_channel(f"{base}/image", "json", sids["foxglove.CompressedImage"]),
                              w.register_channel(f"{base}/annotations", "json", sids["foxglove.ImageAnnotations"]))
        ci, ca = channels[base]
        w.add_message(ci, ns, json.dumps(img, sort_keys=True).encode(), ns)
        w.add_message(ca, ns, json.dumps(ann, sort_keys=True).encode(), ns)
    w.add_metadata("scipctl.report", {"mission": str(data["mission"]), "sol": str(data["sol"]),
                                      "source_sha256": str(data["sha256"])})
    if prov is None:
        from .provenance import provenance

        prov = provenance({"downlink": str(data["sha256"])})
    # as every written artifact: tool version, command line, input hashes (MCAP metadata values are strings)
    w.add_metadata("scipctl.provenance", {"json": json.dumps(prov, sort_keys=True)})
    w.finish()
    return buf.getvalue()

