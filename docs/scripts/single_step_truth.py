"""Single tracking steps from the exact marks, with templates made from the TRUE geometry (a measurement aid for
docs/stereo-and-tracking.md; simulated downlinks only).

    .venv/bin/python docs/scripts/single_step_truth.py DOWNLINK SCENARIO RUN TARGET CAMERA [--seed 1]

For each pair of consecutive left images of CAMERA that both mark TARGET, the template of the later image around
the mark is rendered from the earlier image in two ways, and NCC-tracked into the later image (start 2 px off,
8 px search); printed: tracked - mark (px) and the peak, for half-sizes 10 and 20 px:

* ``surface``: each template pixel's ray (true model, true pose) is cast against the simulator's scene mesh,
  the hit is projected into the earlier image (true model, true pose) and sampled: a perfect warp;
* ``plane``: the same through the plane at the true target with the true terrain normal (the chain's model).

The difference between the two is the bias of the planar warp.
"""

import argparse

import numpy as np

from scipctl.core.expected import bilinear_sample
from scipctl.core.tracking import track
from scipctl.io.downlink import read_downlink
from scipctl.sim.build import scene_for
from scipctl.sim.scenarios import plan_run


def main():
    ap = argparse.ArgumentParser()
    for k in ("downlink", "scenario", "run", "target", "camera"):
        ap.add_argument(k)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    dl = read_downlink(a.downlink)
    scene = scene_for(plan_run(a.scenario, a.run, a.seed))
    t = dl.target(a.target)
    X = np.asarray(dl.truth_target(a.target).xyz_site_m, float)
    n = scene.field.normal_site(X[None, :2])[0]
    ims = sorted((im for im in dl.images if im.camera == a.camera and im.eye == "left"), key=lambda i: i.time_s)

    def site_model(im):
        tr = dl.truth_for(im.product_id)
        return tr.camera_model.transformed(tr.pose.T_site_rover)

    for p, q in zip(ims[:-1], ims[1:]):
        mp, mq = t.mark_in(p.product_id), t.mark_in(q.product_id)
        if mp is None or mq is None:
            continue
        Mp, Mq = site_model(p), site_model(q)
        out = []
        for how in ("surface", "plane"):
            for half in (10, 20):
                c = np.round([mq.u, mq.v])
                us, vs = np.meshgrid(np.arange(c[0] - half, c[0] + half + 1), np.arange(c[1] - half, c[1] + half + 1))
                o, d = Mq.unproject(np.stack([us, vs], -1).reshape(-1, 2).astype(float))
                if how == "surface":
                    P = scene.cast(o, d).points
                else:
                    P = o + ((X - o) @ n / (d @ n))[:, None] * d
                tpl = bilinear_sample(p.pixels_float(), Mp.project(P)).reshape(2 * half + 1, 2 * half + 1)
                tpl = np.where(np.isfinite(tpl), tpl, np.nanmean(tpl)).astype(np.float32)
                tr = track(tpl, q.pixels_float(), [mq.u + 2, mq.v + 2], 8,
                           template_center_uv=np.array([mq.u, mq.v]) - (c - half), min_score=0.1)
                out.append(f"{how} {half}: {np.round(tr.uv - [mq.u, mq.v], 2).tolist()} ({tr.score:.2f})")
        print(p.position, "->", q.position, "; ".join(out))


if __name__ == "__main__":
    main()
