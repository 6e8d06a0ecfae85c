"""The chain's first pancam track (the designation at ~10 m to the approach's imaging stop at ~4.5 m) from the exact
mark, with its template drawn through the TRUE scene and through the surfaces the chain could use: a measurement aid
for docs/stereo-and-tracking.md, "The first pancam track's template: the plane against the true surface" (simulated
downlinks only: each needs its ``.sim.json`` beside it, which names the scenario, run, seed and family).

    python docs/scripts/first_track_truth.py DOWNLINK... [--half 20] [--radius 6] [--json]

For every marked target seen in the first two left pancam images, the template around its mark in the later image
is drawn from the earlier image (the true camera models and poses, so no pose or calibration error enters) through

* ``surface``: the simulator's scene mesh (each template pixel's ray cast on it): a perfect warp;
* ``plane``: the plane through the true target point with the normal the chain takes from the earlier image's
  half-resolution dense stereo (:func:`~scipctl.pipeline.plane_warp.local_normals_site`, then ``render_planes``);
* ``plane-fit-centre``, ``plane-fit-window``: the plane through the true target point whose normal is fitted (least
  squares) to the true surface points of the template's central box, or of the whole template: the best a plane
  could do with a perfect normal;
* ``stereo``: the later pair's half-resolution dense stereo as measured (each pixel's range along its true ray;
  the plane where it has none);
* ``stereo-levelled``: the same, shifted in range to the plane's at the template's central box;
* ``stereo-full-levelled``: full-resolution stereo of the later pair, levelled the same way;

and NCC-tracked into the later image (:func:`~scipctl.core.tracking.track`) from 1 px right and 1 px down of the
mark, within ``--radius`` px. Printed: per target and template, the tracked pixel minus the mark and the NCC peak
(``--json``: one JSON line per target); then per template, how many are within 0.5, 1 and 2 px and the median. A
downlink that cannot be read, or has no ``.sim.json``, is refused with one line and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

TEMPLATES = ("surface", "plane", "plane-fit-centre", "plane-fit-window", "stereo", "stereo-levelled",
             "stereo-full-levelled")


def sim_record_path(downlink: Path) -> Path:
    """The ``.sim.json`` that ``scipctl synth`` writes beside a downlink (``X.mcap`` -> ``X.sim.json``; a folder
    ``X`` -> ``X.sim.json``)."""
    p = Path(downlink)
    return p.with_suffix(".sim.json") if p.suffix == ".mcap" else p.parent / f"{p.name}.sim.json"


def scene_of(sim: dict):
    """The simulator's scene of a run from its ``.sim.json`` record (scenario, run, seed, family)."""
    from scipctl.sim.build import scene_for
    from scipctl.sim.families import family_of_run, family_rover, family_texture
    from scipctl.sim.scenarios import plan_run

    fam_name = (sim.get("family") or {}).get("name")
    if fam_name is None:
        return scene_for(plan_run(sim["scenario"], sim["run"], int(sim["seed"])))
    fam = family_of_run(fam_name, sim["scenario"], sim["run"], int(sim["seed"]))
    rover = family_rover(fam)
    return scene_for(plan_run(sim["scenario"], sim["run"], int(sim["seed"]), rover), family_texture(fam), fam)


def target_rows(dl, scene, half: int, radius_px: float) -> list:
    """One dict per marked target: ``{"target", "templates": {name: [du, dv, peak] or None}}``."""
    from scipctl.core.expected import bilinear_sample
    from scipctl.core.tracking import track
    from scipctl.pipeline.plane_warp import local_normals_site, near_dense_stereo, render_planes

    ims = sorted((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    if len(ims) < 2:
        return []
    p, q = ims[0], ims[1]
    tp, tq = dl.truth_for(p.product_id), dl.truth_for(q.product_id)
    if tp is None or tq is None:
        raise ValueError("no truth for its pancam images (not a simulated downlink)")
    Mp, Mq = tp.camera_model.transformed(tp.pose.T_site_rover), tq.camera_model.transformed(tq.pose.T_site_rover)
    rows = []
    for t in dl.targets:
        mp, mq = t.mark_in(p.product_id), t.mark_in(q.product_id)
        if mp is None or mq is None:
            continue
        truth = dl.truth_target(t.id)
        if truth is None:
            continue
        X = np.asarray(truth.xyz_site_m, float)
        # the chain's plane: normals from the earlier image's dense stereo at the target (its frames are the
        # downlink's; the normal is carried into the true site frame through the stop's two attitudes)
        X_p = tp.pose.T_site_rover.inverse().apply(X)
        rng_p = float(np.linalg.norm(X_p - p.camera_model.C))
        # around this target's own range, as the chain makes it
        _, n_est = render_planes(p, *local_normals_site(p, X_p, rng_p, near_dense_stereo(dl, p, rng_p)))
        n = tp.pose.T_site_rover.rotate(p.pose.T_site_rover.inverse().rotate(n_est))
        rng_q = float(np.linalg.norm(tq.pose.T_site_rover.inverse().apply(X) - q.camera_model.C))
        stereo_q = {ds: near_dense_stereo(dl, q, rng_q, downsample=ds) for ds in (2, 1)}
        c = np.round([mq.u, mq.v])
        g = np.arange(-half, half + 1, dtype=float)
        uv = np.stack(np.meshgrid(c[0] + g, c[1] + g), -1).reshape(-1, 2)
        o, d = Mq.unproject(uv)
        with np.errstate(divide="ignore", invalid="ignore"):
            P_plane = o + (((X - o) @ n) / (d @ n))[:, None] * d
        centre = np.abs(uv - c).max(axis=1) <= max(1, half // 4)
        P_true = scene.cast(o, d).points
        out = {}
        for name in TEMPLATES:
            if name == "surface":
                P = P_true
            elif name == "plane":
                P = P_plane
            elif name.startswith("plane-fit"):
                sel = np.isfinite(P_true).all(1) & (centre if name == "plane-fit-centre" else True)
                if sel.sum() < 3:
                    out[name] = None
                    continue
                Q = P_true[sel] - P_true[sel].mean(0)
                nf = np.linalg.svd(Q, full_matrices=False)[2][-1]
                with np.errstate(divide="ignore", invalid="ignore"):
                    P = o + (((X - o) @ nf) / (d @ nf))[:, None] * d
            else:
                st = stereo_q[1 if name == "stereo-full-levelled" else 2]
                if st is None:
                    out[name] = None
                    continue
                r = np.linalg.norm(st.xyz_at_left_uv(uv) - q.camera_model.C, axis=1)
                if name.endswith("levelled"):
                    ok_c = centre & np.isfinite(r)
                    if not ok_c.any():
                        out[name] = None
                        continue
                    r = r - np.median(r[ok_c]) + np.median(np.linalg.norm(P_plane - o, axis=1)[ok_c])
                P = np.where(np.isfinite(r)[:, None], o + r[:, None] * d, P_plane)
            tpl = bilinear_sample(p.pixels_float(), Mp.project(P)).reshape(2 * half + 1, 2 * half + 1)
            if not np.isfinite(tpl).any():
                out[name] = None
                continue
            tpl = np.where(np.isfinite(tpl), tpl, np.nanmean(tpl)).astype(np.float32)
            tr = track(tpl, q.pixels_float(), [mq.u + 1.0, mq.v + 1.0], radius_px,
                       template_center_uv=np.array([mq.u, mq.v]) - (c - half), min_score=0.1)
            out[name] = [float(tr.uv[0] - mq.u), float(tr.uv[1] - mq.v), float(tr.score)]
        rows.append({"target": t.id, "templates": out})
    return rows


def summary(rows: list) -> dict:
    """Per template: how many tracks are within 0.5, 1 and 2 px of the mark, and the median error (px); a template
    that could not be drawn counts as missed."""
    out = {}
    for name in TEMPLATES:
        e = np.array([np.hypot(*r["templates"][name][:2]) if r["templates"].get(name) else np.inf for r in rows])
        e[~np.isfinite(e)] = np.inf  # a track that found nothing (NaN) is a miss
        out[name] = {"n": int(len(e)), "within_0.5": int((e <= 0.5).sum()), "within_1": int((e <= 1).sum()),
                     "within_2": int((e <= 2).sum()), "median_px": float(np.median(e)) if len(e) else None}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="first_track_truth.py", description=__doc__.splitlines()[0])
    ap.add_argument("downlinks", nargs="+", type=Path)
    ap.add_argument("--half", type=int, default=20, help="template half-size, px of the later image (the chain's)")
    ap.add_argument("--radius", type=float, default=6.0, help="NCC search radius, px")
    ap.add_argument("--json", action="store_true", help="one JSON line per target, then the summary")
    a = ap.parse_args(argv)
    from scipctl.io.downlink import read_downlink

    rows = []
    for path in a.downlinks:
        sim_path = sim_record_path(path)
        try:
            sim = json.loads(sim_path.read_text())
        except (OSError, ValueError) as e:
            ap.error(f"{path}: its simulator record {sim_path.name} cannot be read ({getattr(e, 'strerror', None) or e})")
        try:
            dl = read_downlink(path)
        except (OSError, ValueError) as e:
            ap.error(f"{path}: {e}")
        try:
            found = target_rows(dl, scene_of(sim), a.half, a.radius)
        except (KeyError, ValueError) as e:
            ap.error(f"{path}: {e}")
        for r in found:
            r["downlink"] = str(path)
            rows.append(r)
            if a.json:
                print(json.dumps(r), flush=True)
            else:
                cells = "  ".join(f"{k} " + ("-" if v is None else f"{np.hypot(*v[:2]):.2f} ({v[2]:.2f})")
                                  for k, v in r["templates"].items())
                print(f"{path} {r['target']}: {cells}", flush=True)
    s = summary(rows)
    if a.json:
        print(json.dumps({"summary": s}))
    else:
        for k, v in s.items():
            print(f"{k}: within 0.5 / 1 / 2 px {v['within_0.5']} / {v['within_1']} / {v['within_2']} of {v['n']}, "
                  f"median {v['median_px']:.2f} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
