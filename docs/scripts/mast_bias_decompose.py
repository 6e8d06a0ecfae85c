"""What the report's mast-bias estimate holds on a simulated downlink (a measurement aid for docs/report.md, "What the
pan estimate holds"; simulated downlinks only, the ``.sim.json`` beside them).

    .venv/bin/python docs/scripts/mast_bias_decompose.py DOWNLINK.mcap

Printed, in degrees: the simulator's injected mast errors; the estimate from the downlink's marks
(``pipeline/report_data.mast_bias``, as the report computes it) with the true navcam-hazcam rotation the page shows
beside it; then the estimate from exact marks made by the simulator's own true geometry
(``sim/errors.true_rover_config``) holding one injected mast error at a time, and all four together (no right-eye
vibration), on the same products, targets and true rover pose.
"""

import argparse
import json
import math
from dataclasses import replace

import numpy as np

from scipctl.io.downlink import read_downlink
from scipctl.model import Mark
from scipctl.pipeline.report_data import mast_bias
from scipctl.sim.errors import ErrorSettings, true_rover_config

D = math.degrees


def products_used(dl) -> set:
    """The products the estimate reads: each left hazcam and the navcam pairs at its position."""
    used = set()
    for haz in dl.images:
        if haz.camera == "hazcam" and haz.eye == "left":
            used.add(haz.product_id)
            for nl in dl.images_at(haz.position, camera="navcam", eye="left"):
                nr = dl.stereo_pair(nl)
                used |= {nl.product_id} | ({nr.product_id} if nr is not None else set())
    return used


def with_exact_marks(dl, e: ErrorSettings, used: set):
    """``dl`` with the marks of ``used`` products where the true geometry of ``e`` (mast errors only) sees the
    targets' true positions from the true rover pose; no truth models (they hold the downlink's own errors)."""
    true_rc = true_rover_config(dl.rover_config, e)
    targets = []
    for t in dl.targets:
        X_site = np.asarray(dl.truth_target(t.id).xyz_site_m, float)
        marks = []
        for mk in t.marks:
            if mk.product_id not in used:
                marks.append(mk)
                continue
            im = dl.product(mk.product_id)
            X = dl.truth_for(im.product_id).pose.T_site_rover.inverse().apply(X_site[None])[0]
            angles = (im.mast.pan_rad, im.mast.tilt_rad) if im.mast is not None else (0.0, 0.0)
            uv = true_rc.camera_model(im.camera, im.eye, *angles).project(X[None])[0]
            marks.append(Mark(mk.product_id, float(uv[0]), float(uv[1])))
        targets.append(replace(t, marks=marks))
    return replace(dl, targets=targets, truth_images=[])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("downlink")
    a = ap.parse_args()
    dl = read_downlink(a.downlink)
    E = json.loads(open(a.downlink[: -len(".mcap")] + ".sim.json").read())["errors"]
    print(f"{a.downlink}: {dl.rover_config.name}")
    print(f"injected: pan {D(E['mast_pan_offset_rad']):+.3f}, tilt {D(E['mast_tilt_offset_rad']):+.3f}, "
          f"tilt axis {D(E['mast_tilt_axis_error_rad']):+.3f} deg; head offset {E['mast_head_offset_m']} m")
    mb = mast_bias(dl)
    tr = mb["truth"] or {}
    print(f"downlink marks ({mb['cases']} cases): pan {D(mb['dpan_rad']):+.4f} tilt {D(mb['dtilt_rad']):+.4f}, "
          f"rms {mb['rms_before_px']:.2f} -> {mb['rms_after_px']:.3f} px; true navcam-hazcam rotation about z "
          f"{D(tr.get('about_rover_z_rad', math.nan)):+.3f}, about y {D(tr.get('about_rover_y_rad', math.nan)):+.3f}")
    used = products_used(dl)
    z = ErrorSettings.none()
    pan, tilt = E["mast_pan_offset_rad"], E["mast_tilt_offset_rad"]
    axis, head = E["mast_tilt_axis_error_rad"], tuple(E["mast_head_offset_m"])
    for name, e in (("pan offset only", replace(z, mast_pan_offset_rad=pan)),
                    ("tilt offset only", replace(z, mast_tilt_offset_rad=tilt)),
                    ("pan + tilt offsets", replace(z, mast_pan_offset_rad=pan, mast_tilt_offset_rad=tilt)),
                    ("tilt-axis error only", replace(z, mast_tilt_axis_error_rad=axis)),
                    ("head offset only", replace(z, mast_head_offset_m=head)),
                    ("all four", replace(z, mast_pan_offset_rad=pan, mast_tilt_offset_rad=tilt,
                                         mast_tilt_axis_error_rad=axis, mast_head_offset_m=head))):
        mb = mast_bias(with_exact_marks(dl, e, used))
        print(f"exact marks, {name + ':':22s} pan {D(mb['dpan_rad']):+.4f} tilt {D(mb['dtilt_rad']):+.4f}, "
              f"rms {mb['rms_before_px']:.2f} -> {mb['rms_after_px']:.3f} px")


if __name__ == "__main__":
    main()
