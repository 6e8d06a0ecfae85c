"""Cross-record rules of the downlink format (docs/downlink-format.md, "Validation").

Single-record rules (types, missing keys, unit quaternions, camera models)
are checked while parsing (:mod:`.downlink`); this module checks what needs
the whole downlink. The first violation raises :class:`InputError`
``(product or target id, field, message)``.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..model import Downlink, ImageProduct, InputError, same_pointing
from .images import png_size

POSE_TOL_M = 1e-6  # products at one (site, drive) must agree on the pose to this (metres) ...
POSE_TOL_RAD = 1e-6  # ... and this (radians)


def _check_size(im: ImageProduct) -> None:
    w, h = png_size(im.png, im.product_id)  # the header, before decoding: a damaged or oversized PNG is not decoded
    if (w, h) == (im.width, im.height):
        px = im.pixels  # decodes once and caches; InputError naming the product if corrupt
        h, w = px.shape[:2]
    if (h, w) != (im.height, im.width):
        raise InputError(im.product_id, "image", f"PNG is {w}x{h} pixels, but width x height says {im.width}x{im.height}")


def decode_all(images: list) -> None:
    """Decode every product's PNG once (in threads; OpenCV releases the GIL) and check its size."""
    workers = min(4, os.cpu_count() or 1, max(1, len(images)))
    if workers <= 1:
        for im in images:
            _check_size(im)
        return
    with ThreadPoolExecutor(max_workers=workers) as ex:
        for fut in [ex.submit(_check_size, im) for im in images]:
            fut.result()  # re-raises the first error in product order


def _rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def _same_pointing(a: ImageProduct, b: ImageProduct) -> bool:
    if a.mast is None or b.mast is None:
        return a.mast is None and b.mast is None
    return same_pointing(a.mast, b.mast)  # model.SAME_POINTING_RAD, as Downlink.stereo_pair pairs the eyes


def validate_downlink(dl: Downlink, check_pixels: bool = True) -> None:
    """Check the cross-record rules; with ``check_pixels`` also decode every PNG once and check its size."""
    rc = dl.rover_config
    by_id: dict = {}
    for im in dl.images:
        if im.product_id in by_id:
            raise InputError(im.product_id, "product_id", "duplicate product id")
        by_id[im.product_id] = im
        if im.eye not in ("left", "right"):
            raise InputError(im.product_id, "eye", f"must be 'left' or 'right', got {im.eye!r}")
        if im.width < 1 or im.height < 1:
            raise InputError(im.product_id, "width", f"image size must be positive, got {im.width}x{im.height}")
        cam = rc.cameras.get(im.camera)
        if cam is not None:
            if cam.mount == "mast" and im.mast is None:
                raise InputError(im.product_id, "mast", f"missing: {im.camera} is a mast camera, its pan_rad/tilt_rad are required")
            spec = getattr(cam, im.eye)
            if (spec.width, spec.height) != (im.width, im.height):
                raise InputError(im.product_id, "width",
                                 f"{im.width}x{im.height} differs from the rover configuration's {im.camera} {im.eye} "
                                 f"size {spec.width}x{spec.height}")

    # one pose per rover position
    first_at: dict = {}
    for im in sorted(dl.images, key=lambda i: i.time_s):
        ref = first_at.setdefault(im.position, im)
        if ref is im:
            continue
        with np.errstate(over="ignore"):  # positions of 1e308 m: the distance is inf (an error), without a warning
            dt = float(np.linalg.norm(im.pose.T_site_rover.t - ref.pose.T_site_rover.t))
        dr = _rotation_angle(im.pose.T_site_rover.R, ref.pose.T_site_rover.R)
        if not (dt <= POSE_TOL_M and dr <= POSE_TOL_RAD):
            raise InputError(im.product_id, "pose",
                             f"differs from {ref.product_id} at the same position (site {im.site}, drive {im.drive}) "
                             f"by {dt:.3g} m and {np.degrees(dr):.3g} deg")

    # stereo pairs: same camera, position and pointing, left + right
    for left in dl.images:
        if left.eye != "left":
            continue
        cands = [im for im in dl.images if im.eye == "right" and im.camera == left.camera
                 and im.position == left.position and _same_pointing(im, left)]
        if not cands:
            continue
        # no limit on the time between the eyes: at one (site, drive) the rover has not moved (the contract), and
        # with the same mast angles the pair sees the scene from the same place however long apart it was taken
        right = min(cands, key=lambda im: abs(im.time_s - left.time_s))
        if (right.width, right.height) != (left.width, left.height):
            raise InputError(right.product_id, "width",
                             f"{right.width}x{right.height} differs from its stereo partner {left.product_id} "
                             f"({left.width}x{left.height})")

    # target marks
    seen_targets = set()
    for t in dl.targets:
        if t.id in seen_targets:
            raise InputError(t.id, "id", "duplicate target id")
        seen_targets.add(t.id)
        marked = set()
        for i, m in enumerate(t.marks):
            f = f"marks[{i}]"
            if m.product_id not in by_id:
                raise InputError(t.id, f"{f}.product_id", f"unknown product {m.product_id!r}")
            if m.product_id in marked:
                raise InputError(t.id, f"{f}.product_id", f"marked twice in {m.product_id}")
            marked.add(m.product_id)
            if not (np.isfinite(m.u) and np.isfinite(m.v)):
                raise InputError(t.id, f"{f}.u", "mark coordinates must be finite")
            if not (m.sigma_px >= 0):
                raise InputError(t.id, f"{f}.sigma_px", f"must be >= 0, got {m.sigma_px!r}")

    # truth
    seen = set()
    for tr in dl.truth_images:
        if tr.product_id not in by_id:
            raise InputError(tr.product_id, "truth.product_id", "truth for an unknown product")
        if tr.product_id in seen:
            raise InputError(tr.product_id, "truth.product_id", "more than one truth record")
        seen.add(tr.product_id)
    seen = set()
    for tt in dl.truth_targets:
        if tt.id in seen:
            raise InputError(tt.id, "truth.id", "more than one truth record for this target")
        seen.add(tt.id)

    if check_pixels:
        decode_all(dl.images)
