"""``scipctl ingest SRC -o WS`` and ``scipctl info SRC``: read, validate and summarise a downlink.

The summary (also stored in ``WS/scipctl/workspace.json``) lists the rover
positions with their poses, which cameras and eyes were taken where (with
mast angles), per-image statistics, the target marks and whether simulation
truth is present. People get rich tables on stderr; ``--json`` prints one
JSON document on stdout instead.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..model import Downlink
from .output import emit_json, note, stderr_console


def _deg(x):
    return None if x is None else math.degrees(float(x))


def image_stats(im) -> dict:
    """Data bits, mean (fraction of full scale) and saturated fraction (pixels at full scale) of one product: 12-bit
    data in 16-bit words judged against 4095, as :meth:`~scipctl.model.ImageProduct.pixels_float` does."""
    from ..core.image import full_scale

    px = im.pixels
    top, bits = full_scale(px)
    return {
        "bit_depth": int(bits),
        "mean": float(px.mean(dtype=np.float64) / top),
        "saturated_fraction": float(np.count_nonzero(px >= top) / px.size),
    }


def summarize(dl: Downlink) -> dict:
    """Plain-data summary of a (validated) downlink."""
    from ..io.downlink import camera_model_to_plain, pose_to_plain

    positions = []
    for pos in dl.positions():
        ims = sorted(dl.images_at(pos), key=lambda i: (i.time_s, i.product_id))
        p = ims[0].pose
        yaw, pitch, roll = p.yaw_pitch_roll_rad
        cams: dict = {}
        for im in ims:
            cams.setdefault(im.camera, []).append(im.eye)
        positions.append({
            "site": pos[0],
            "drive": pos[1],
            "pose": {
                "x_m": float(p.position_m[0]), "y_m": float(p.position_m[1]), "z_m": float(p.position_m[2]),
                "yaw_deg": _deg(yaw), "pitch_deg": _deg(pitch), "roll_deg": _deg(roll),
                "source": p.source, "sigma_position_m": p.sigma_position_m, "sigma_yaw_deg": _deg(p.sigma_yaw_rad),
            },
            "time_s": [float(ims[0].time_s), float(ims[-1].time_s)],
            "cameras": {c: sorted(set(e)) for c, e in cams.items()},
            "products": [im.product_id for im in ims],
        })
    truth_ids = {t.product_id for t in dl.truth_images}
    images = []
    for im in sorted(dl.images, key=lambda i: (i.time_s, i.product_id)):
        rec = {
            "product_id": im.product_id, "camera": im.camera, "eye": im.eye, "time_s": float(im.time_s),
            "site": im.site, "drive": im.drive, "width": im.width, "height": im.height,
            "pan_deg": _deg(im.mast.pan_rad) if im.mast else None,
            "tilt_deg": _deg(im.mast.tilt_rad) if im.mast else None,
            "camera_model": camera_model_to_plain(im.camera_model),  # the full model, as in the downlink format
            "pose": pose_to_plain(im.pose), "position": {"site": im.site, "drive": im.drive},
            "exposure_ms": im.exposure_ms, "gain": im.gain, "truth": im.product_id in truth_ids,
        }
        rec.update(image_stats(im))
        images.append(rec)
    targets = []
    for t in dl.targets:
        tt = dl.truth_target(t.id)
        targets.append({
            "id": t.id, "kind": t.kind, "description": t.description,
            "marks": [{"product_id": m.product_id, "u": m.u, "v": m.v, "sigma_px": m.sigma_px} for m in t.marks],
            "truth_xyz_site_m": None if tt is None else [float(x) for x in tt.xyz_site_m],
        })
    rc = dl.rover_config
    return {
        "source": dl.source,
        "source_sha256": dl.source_sha256,
        "format_version": dl.format_version,
        "mission": dl.mission,
        "sol": dl.sol,
        "rover_config": {
            "name": rc.name,
            "cameras": {n: {"mount": c.mount, "width": c.left.width, "height": c.left.height,
                            "camera_model": c.left.model.kind} for n, c in rc.cameras.items()},
        },
        "counts": {"images": len(dl.images), "positions": len(positions), "targets": len(dl.targets)},
        "positions": positions,
        "images": images,
        "targets": targets,
        "truth": {"present": dl.has_truth, "images": len(dl.truth_images), "targets": len(dl.truth_targets)},
        "unread_files": list(dl.unread_files),  # a folder of real products: what is in it but was not read
    }


def _fmt(x, spec=".3f"):
    return "-" if x is None else format(x, spec)


def print_summary(s: dict, title: str) -> None:
    """Rich tables on stderr (user strings are escaped, never read as markup)."""
    from rich.markup import escape as esc
    from rich.table import Table

    con = stderr_console()
    con.print(f"[bold]{esc(title)}[/bold]: mission {esc(str(s['mission']))}, sol {s['sol']}, "
              f"{s['counts']['images']} images, {s['counts']['positions']} positions, {s['counts']['targets']} targets")
    eye = {"left": "L", "right": "R"}
    cams = ", ".join(f"{esc(n)} ({c['mount']}, {c['width']}x{c['height']}, {c['camera_model']})"
                     for n, c in s["rover_config"]["cameras"].items())
    cams = cams or "no cameras configured (real products carry their own models)"
    con.print(f"Rover configuration {esc(s['rover_config']['name'])}: {cams}")
    if s.get("unread_files"):
        con.print(f"Not read (not a product scipctl reads, or a picture with no label or model): "
                  f"{esc(', '.join(s['unread_files']))}")
    t = Table(title="Rover positions (site frame)")
    for c in ("site/drive", "x m", "y m", "z m", "yaw deg"):
        t.add_column(c, no_wrap=True)
    t.add_column("pose source", no_wrap=True)
    t.add_column("cameras", overflow="fold")
    for p in s["positions"]:
        q = p["pose"]
        cams = ", ".join(f"{esc(c)} {'+'.join(eye.get(e, e) for e in es)}" for c, es in p["cameras"].items())
        unknown_yaw = q.get("sigma_yaw_deg") is not None and q["sigma_yaw_deg"] >= 180.0  # position-only pose
        yaw = "unknown" if unknown_yaw else _fmt(q["yaw_deg"], ".2f")
        t.add_row(f"{p['site']}/{p['drive']}", _fmt(q["x_m"]), _fmt(q["y_m"]), _fmt(q["z_m"]), yaw,
                  esc(q["source"]), cams)
    con.print(t)
    t = Table(title="Images")
    t.add_column("product", overflow="fold", min_width=12)
    for c in ("camera", "pos", "time s", "pan/tilt°", "mean", "sat %"):
        t.add_column(c, no_wrap=True)
    for im in s["images"]:
        pt = "-" if im["pan_deg"] is None else f"{im['pan_deg']:.1f}/{im['tilt_deg']:.1f}"
        t.add_row(esc(im["product_id"]), f"{esc(im['camera'])} {eye[im['eye']]}", f"{im['site']}/{im['drive']}",
                  f"{im['time_s']:.2f}", pt, f"{im['mean']:.3f}",
                  f"{100 * im['saturated_fraction']:.2f}")
    con.print(t)
    if s["targets"]:
        t = Table(title="Targets")
        for c in ("id", "kind", "marks (product: u, v ± sigma px)"):
            t.add_column(c, overflow="fold")
        for tg in s["targets"]:
            marks = "; ".join(f"{esc(m['product_id'])}: {m['u']:.1f}, {m['v']:.1f} ± {m['sigma_px']:.2g}" for m in tg["marks"])
            t.add_row(esc(tg["id"]), esc(tg["kind"]), marks or "-")
        con.print(t)
    tr = s["truth"]
    con.print("Simulation truth: " + (f"present ({tr['images']} images, {tr['targets']} targets)" if tr["present"] else "none"))
    if s.get("products"):  # `info` only: each product with the file it is read from
        con.print("Products: " + "; ".join(f"{esc(n)} ({esc(f)})" for n, f in s["products"].items()))


def _check_paths(src: Path, out: Path) -> None:
    s, o = src.resolve(), out.resolve()
    if s == o:
        return  # re-ingesting a workspace in place: allowed (everything is read into memory first)
    if s.is_dir() and o.is_relative_to(s):
        raise InputError(str(out), "output", f"is inside the source downlink {src}; choose a workspace outside it")
    if s.is_relative_to(o):
        raise InputError(str(out), "output", f"contains the source {src}; replacing it would delete the source")


def ingest(src: Path, out: Path, json_out: bool, force: bool = False) -> None:
    """``scipctl ingest``: read and validate ``src``, write the workspace ``out``, print its summary."""
    from ..io.downlink import read_downlink
    from ..io.workspace import write_workspace

    src, out = Path(src), Path(out)
    dl = read_downlink(src)
    _check_paths(src, out)
    summary = summarize(dl)
    done = write_workspace(dl, out, summary, source_path=src, force=force)
    if done.kept_products:
        note(f"kept the products of the existing workspace {out}: {', '.join(done.kept_products)}")
    if done.superseded_dir is not None:
        note(f"{out} was made from a different downlink; its products {', '.join(done.superseded_products)} "
             f"are no longer used: set aside in {done.superseded_dir}/ (--force)")
    if json_out:
        from ..io.provenance import provenance

        emit_json({"workspace": str(out), "summary": summary, "kept_products": done.kept_products,
                   "provenance": provenance({"downlink": dl.source_sha256}),
                   "superseded_products": done.superseded_products,
                   "superseded_dir": None if done.superseded_dir is None else str(done.superseded_dir)})
    else:
        print_summary(summary, f"Ingested {src} -> workspace {out}")


def info(src: Path, json_out: bool, products_root=None) -> None:
    """``scipctl info``: summarise ``src`` and list its products (each with the file it is read from); writes nothing."""
    from ..io.workspace import open_source

    source = open_source(Path(src), products_root=products_root)
    summary = summarize(source.downlink)
    names = source.product_names()
    summary["products"] = {n: str(source.product_path(n)) for n in names}
    ws = source.workspace_info()
    if ws is not None:
        summary["workspace"] = {
            "path": str(source.workspace_dir),
            "ingested_from": ws.get("source", {}),
            "products": names,
        }
    if json_out:
        from ..io.provenance import provenance

        emit_json(dict(summary, provenance=provenance({"downlink": source.downlink.source_sha256})))
    else:
        print_summary(summary, f"{'Workspace' if ws is not None else 'Downlink'} {src}")
