"""What a prediction reads from today's downlink: the designated target (from targets.json or its mark),
the stereo terrain sources at the rover's position and the pose-error sigmas."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from ...core.kinematics import RoverPose
from ..designate import Designation
from .params import UncertaintyParams
from .terrain import TerrainSource


STEREO_CAMERAS = ("pancam", "navcam", "hazcam")
_PRIORITY = {"pancam": 0, "navcam": 1, "hazcam": 2}


def resolve_target(dl, target_id: str, designations, with_normal: bool = True) -> tuple:
    """The :class:`~scipctl.pipeline.designate.Designation` of ``target_id``: from ``designations`` (read from
    ``targets.json``, :func:`~scipctl.pipeline.designate.designations_from_doc`) if designated there, else
    designated on the fly from its mark in the first left pancam image (or navcam if there is no pancam), with the
    packaged designation trust model's verdict as ``designate`` gives it.

    Returns ``(designation, designated_now: bool)``. Raises ``InputError`` when the id is neither designated nor
    marked, or the mark is in no usable image.
    """
    from dataclasses import replace

    from ...model import InputError

    designations = list(designations or [])
    for rec in designations:
        if rec.id == target_id:
            return rec, False
    known = sorted({r.id for r in designations} | {t.id for t in dl.targets})
    marks = next((t for t in dl.targets if t.id == target_id), None)
    if marks is None:
        raise InputError(target_id, "--target", "not designated (targets.json) and not a marked target in the downlink"
                         + (f"; known: {', '.join(str(k) for k in known)}" if known else ""))
    from ...io.trust_model import PACKAGED_DESIGNATION, load_packaged_trust_model
    from ..designate import designate

    found = _marked_left(dl, marks)
    if found is None:
        raise InputError(target_id, "marks", "the target is marked in no left pancam/navcam image with a stereo pair")
    im, mk = found
    # the mark is only the pixel an operator would click: the designation gets the same verdict (p_ok, go) as
    # `designate` and the chain give it
    rec = designate(dl, im, [mk.u, mk.v], target_id=target_id, with_normal=with_normal,
                    trust=load_packaged_trust_model(PACKAGED_DESIGNATION))
    return replace(rec, designated_from="mark"), True


def _marked_left(dl, marks) -> Optional[tuple]:
    """``(left image, mark)`` a marked target is designated from: its mark in the first left pancam image with a
    stereo pair (navcam when the downlink has no left pancam); None when there is none."""
    for cam in ("pancam", "navcam"):
        lefts = sorted((im for im in dl.images if im.camera == cam and im.eye == "left"), key=lambda i: i.time_s)
        for im in lefts:
            mk = marks.mark_in(im.product_id)
            if mk is not None and dl.stereo_pair(im) is not None:
                return im, mk
        if lefts:
            break
    return None


def designation_position(dl, target_id: str, designations) -> Optional[tuple]:
    """The rover position (``ImageProduct.position``) of the product :func:`resolve_target` designates
    ``target_id`` from: today's stop, whose stereo pairs the prediction reads. None when :func:`resolve_target`
    would refuse the id (or a saved designation names a product the downlink lacks)."""
    for rec in designations or []:
        if rec.id == target_id:
            im = next((i for i in dl.images if i.product_id == rec.product_id), None)
            return None if im is None else im.position
    marks = next((t for t in dl.targets if t.id == target_id), None)
    found = None if marks is None else _marked_left(dl, marks)
    return None if found is None else found[0].position


def terrain_sources(dl, position, cameras=STEREO_CAMERAS, downsample: int = 2, target_range_m: Optional[float] = None):
    """Dense stereo of every left/right pair of ``cameras`` at ``position`` -> list of :class:`TerrainSource` (site frame)."""
    from ...core.dense_stereo import dense_stereo

    out = []
    for im in sorted(dl.images_at(position, eye="left"), key=lambda i: (_PRIORITY.get(i.camera, 9), i.time_s)):
        if im.camera not in cameras:
            continue
        right = dl.stereo_pair(im)
        if right is None or (right.width, right.height) != (im.width, im.height):
            continue
        if im.camera == "pancam":
            r = target_range_m or 10.0
            lo, hi = max(1.0, 0.3 * r), 2.5 * r + 5.0
        elif im.camera == "hazcam":
            lo, hi = 0.3, 6.0
        else:
            lo, hi = 0.8, 40.0
        L = im.pixels_float()
        ds = dense_stereo(L, right.pixels_float(), im.camera_model, right.camera_model,
                          min_range_m=lo, max_range_m=hi, downsample=downsample)
        T_site_rover = im.pose.T_site_rover
        xyz = ds.xyz
        flat = xyz.reshape(-1, 3)
        ok = np.all(np.isfinite(flat), axis=1)
        xs = np.full_like(flat, np.nan)
        xs[ok] = T_site_rover.apply(flat[ok])
        out.append(TerrainSource(im.product_id, im.camera, xs.reshape(xyz.shape), L, im.camera_model.transformed(T_site_rover),
                                 T_site_rover.apply(ds.rectified.left_model.C), _PRIORITY.get(im.camera, 9)))
    return out


def sigmas_for(product, params: UncertaintyParams) -> tuple:
    """(sigma_position_m, sigma_yaw_rad, source text): the per-stop pose-estimate noise of the Monte Carlo, the
    operator's override, else the defaults.

    The downlinked pose's own ``sigma_position_m`` / ``sigma_yaw_rad`` are not used: they are the pose's
    absolute uncertainty in the site frame, accumulated since the site's origin (0.56 m and 6.0 deg on the
    bundled ``paper-s1-straight``), and cancel in the stop-to-stop motion the approach relies on (the target is
    designated, planned and re-estimated in the rover's own estimated frame at each stop). Used as a per-leg
    increment they made every view of the approach look hundreds of pixels off (issue #15). The source text
    quotes them for the record.
    """
    src = [f"position: {'parameter' if params.sigma_position_m is not None else 'per-stop default'}",
           f"yaw: {'parameter' if params.sigma_yaw_rad is not None else 'per-stop default'}"]
    sp, sy = params.per_stop_sigmas()
    dp, dy = product.pose.sigma_position_m, product.pose.sigma_yaw_rad
    if dp is not None or dy is not None:
        src.append("downlink pose sigma (absolute, not used per stop): "
                   + (f"{dp:.3g} m" if dp is not None else "-") + ", "
                   + (f"{math.degrees(dy):.3g} deg" if dy is not None else "-"))
    return float(sp), float(sy), ", ".join(src)


@dataclass
class TargetContext:
    """What a prediction needs from the downlink for one target."""

    record: Designation
    designated_now: bool
    product: object  # ImageProduct of the designation
    start: RoverPose
    target_site_m: np.ndarray


def target_context(dl, record: Designation, designated_now: bool = False) -> TargetContext:
    from ...model import InputError

    if not record.has_position:
        raise InputError(str(record.id), "designation", f"the target has no 3-D position ({record.reason or 'no stereo'})")
    prod = dl.product(record.product_id)
    return TargetContext(record, designated_now, prod, prod.pose, np.asarray(record.xyz_site_m, float))
