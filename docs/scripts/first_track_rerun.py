"""The chain's first pancam track (the designation at ~10 m to the approach's imaging stop at ~4.5 m) run again
from each recorded designation, with variants of its settings (docs/stereo-and-tracking.md, "The first pancam
track's error, and its template (session 28; measured)").

    python docs/scripts/first_track_rerun.py run CAMP OUT.jsonl [NAME=JSON ...] [--workers N]
    python docs/scripts/first_track_rerun.py score OUT.jsonl [--json]

``run``: for every chain of the campaign folder CAMP (``scipctl campaign ... --chain``) with a first pancam track
whose feature step ran, and a mark there, the feature step of that track
(:func:`~scipctl.pipeline.feature_track.feature_track`) as ``run_chain`` makes it from the recorded designation
(its pixel and stereo point, the plane from its dense stereo), once per variant. A variant is ``NAME=JSON`` with
``{"half": N}`` (the NCC template's half-size, new pixels) and/or ``{"params": {ChainParams field: value}}``;
``default={}`` is always run first and must give the recorded pixel back wherever the feature step answered
(``reproduced``/``moved`` on stderr, exit 1 if any moved). One JSON line per chain: the recorded step and, per
variant, the feature step's status, pixel and error against the mark in mm (pixels times the step's own
``px_mm``; the track's image plane, v roughly along the line of sight on the ground). ``score``: per variant,
the tracks within 2, 4 and 8 mm, the confirmed ones, and the tracks won and lost at 4 mm against ``default``;
the error's horizontal and vertical parts.

Only the feature step is run: a track whose feature step fails falls back in ``run_chain`` to NCC over the search
region (reported unverified), which this does not repeat. A folder without ``records/`` or a malformed variant
is refused with one line and exit code 2.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # campaign_chains, beside this script
from campaign_chains import recorded_chains, rerun_main, rerun_parser, score_main  # noqa: E402

VARIANTS: dict = {}


def first_track(dl, steps, params, half: int, feats: dict):
    """``run_chain``'s feature step for the first pancam track after the designation ``steps[0]``:
    ``(TrackResult or None, info dict)``."""
    from scipctl.core.point_stereo import on_left_ray
    from scipctl.core.windows import window_scale_for_handoff
    from scipctl.pipeline.feature_track import feature_track
    from scipctl.pipeline.plane_warp import local_normals_site, near_dense_stereo, render_planes

    S0 = steps[0]
    S1 = next(s for s in steps if s.camera == "pancam" and s.kind == "track")
    start, prod = dl.product(S0.product_id), dl.product(S1.product_id)
    # as run_chain keeps the designation: its stereo point moved onto its pixel's ray
    X0_rover = start.pose.T_site_rover.inverse().apply(np.asarray(S0.xyz_site_m, float))
    X_site = start.pose.T_site_rover.apply(on_left_ray(start.camera_model, np.asarray(S0.tracked_uv, float), X0_rover))
    range_m = float(S0.range_m)
    X_prev = start.pose.T_site_rover.inverse().apply(X_site)
    stereo = near_dense_stereo(dl, start, range_m)
    planes, n_view = render_planes(start, *local_normals_site(start, X_prev, range_m, stereo))
    X_rover = prod.pose.T_site_rover.inverse().apply(X_site)
    pred = prod.camera_model.project(X_rover[None])[0]
    rng_new = float(np.linalg.norm(X_rover - prod.camera_model.C))
    scale = window_scale_for_handoff(1.0 / start.camera_model.hs, range_m, 1.0 / prod.camera_model.hs, rng_new)
    return feature_track(start, prod, X_site, planes, n_view, pred, scale, half, feats, params, None)


def run_file(path: str) -> tuple[list, int, int]:
    """The rows of one campaign records file: ``(rows, reproduced, moved)``."""
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.chain import ChainParams

    header, chains = recorded_chains(path)
    rows, same, moved = [], 0, 0
    dl, feats = None, {}
    for record, steps in chains:
        S1 = next((s for s in steps if s.camera == "pancam" and s.kind == "track"), None)
        if S1 is None or S1.mark_uv is None or steps[0].kind != "designate" or "feature_status" not in S1.extra:
            continue  # no such track, no mark, or the chain did not run its feature step (e.g. behind the camera)
        dl = dl or read_downlink(header["job"]["path"])
        px_mm = S1.extra.get("px_mm")
        row = {"downlink": header["job"]["path"], "family": header.get("family"), "target": record["target"],
               "recorded_uv": S1.tracked_uv, "recorded_status": S1.extra.get("feature_status"), "px_mm": px_mm}
        for name, spec in VARIANTS.items():
            params = dataclasses.replace(ChainParams(), **spec.get("params", {})).check()
            half = int(spec.get("half", params.template_half("pancam")))
            tr, info = first_track(dl, steps, params, half, feats)
            r = {"status": info.get("feature_status")}
            if tr is not None and np.all(np.isfinite(tr.uv)):
                r["uv"] = [float(x) for x in tr.uv]
                r["err_mm"] = [float(d) * px_mm for d in np.subtract(tr.uv, S1.mark_uv)]
            row[name] = r
        d = row["default"]
        if d["status"] != row["recorded_status"] or (d.get("uv") is not None and (
                row["recorded_uv"] is None or float(np.max(np.abs(np.subtract(d["uv"], row["recorded_uv"])))) > 1e-9)):
            moved += 1
        else:
            same += 1
        rows.append(row)
    return rows, same, moved


def _init(variants):
    VARIANTS.update(variants)


def _err(r: dict) -> float:
    return float(np.hypot(*r["err_mm"])) if r.get("err_mm") is not None else float("inf")


def score(rows: list) -> dict:
    """The tables of ``score`` as a dict (see the module docstring)."""
    names = [k for k in rows[0] if isinstance(rows[0][k], dict)] if rows else []
    out = {"tracks": len(rows), "variants": {}}
    for n in names:
        e = [_err(r[n]) for r in rows]
        conf = [_err(r[n]) for r in rows if r[n]["status"] == "confirmed"]
        near = [r[n]["err_mm"] for r in rows if _err(r[n]) < 20.0]
        v = {"within_2mm": sum(x <= 2 for x in e), "within_4mm": sum(x <= 4 for x in e),
             "within_8mm": sum(x <= 8 for x in e), "confirmed": len(conf),
             "confirmed_within_4mm": sum(x <= 4 for x in conf), "confirmed_over_8mm": sum(x > 8 for x in conf),
             "confirmed_median_mm": float(np.median(conf)) if conf else None,
             "status": dict(Counter(r[n]["status"] for r in rows)),
             # the error's parts where it is under 20 mm: horizontal (u) and vertical (v) in the image
             "median_abs_u_mm": float(np.median([abs(x[0]) for x in near])) if near else None,
             "median_abs_v_mm": float(np.median([abs(x[1]) for x in near])) if near else None,
             "v_larger": sum(abs(x[1]) > abs(x[0]) for x in near), "under_20mm": len(near)}
        if n != "default" and "default" in names:
            v["won_4mm"] = sum(_err(r[n]) <= 4 < _err(r["default"]) for r in rows)
            v["lost_4mm"] = sum(_err(r["default"]) <= 4 < _err(r[n]) for r in rows)
        out["variants"][n] = v
    return out


def _print(s: dict) -> None:
    print(f"first pancam tracks: {s['tracks']}")
    for n, v in s["variants"].items():
        med = "-" if v["confirmed_median_mm"] is None else f"{v['confirmed_median_mm']:.2f}"
        vs = f"; against default: won {v['won_4mm']}, lost {v['lost_4mm']}" if "won_4mm" in v else ""
        print(f"  {n}: within 2 / 4 / 8 mm {v['within_2mm']} / {v['within_4mm']} / {v['within_8mm']}; confirmed "
              f"{v['confirmed']} ({v['confirmed_within_4mm']} within 4 mm, {v['confirmed_over_8mm']} over 8 mm, median "
              f"{med} mm){vs}; under 20 mm: median |u| {v['median_abs_u_mm']:.2f}, |v| {v['median_abs_v_mm']:.2f} mm, "
              f"|v| > |u| in {v['v_larger']} of {v['under_20mm']}")


def main(argv=None) -> int:
    ap, r = rerun_parser(Path(__file__).name, __doc__.splitlines()[0])
    r.add_argument("variants", nargs="*", metavar="NAME=JSON")
    a = ap.parse_args(argv)
    if a.cmd == "run":
        from scipctl.pipeline.chain import ChainParams

        variants = {"default": {}}
        for v in a.variants:
            name, _, spec = v.partition("=")
            try:
                variants[name] = json.loads(spec)
                if not isinstance(variants[name], dict) or set(variants[name]) - {"half", "params"}:
                    raise ValueError('a JSON object with "half" and/or "params"')
                dataclasses.replace(ChainParams(), **variants[name].get("params", {})).check()
            except (ValueError, TypeError) as e:
                ap.error(f"variant {v!r}: {e}")
        return rerun_main(ap, a, run_file, "tracks", _init, (variants,))
    return score_main(ap, a, score, _print)


if __name__ == "__main__":
    sys.exit(main())
