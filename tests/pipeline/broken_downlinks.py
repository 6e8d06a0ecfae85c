"""Deliberately broken copies of a simulated downlink, made in memory (issue #14 item 6), and a cheap way to run
``scip`` on them.

Each ``*_copy`` function returns a new :class:`~scipctl.model.Downlink` that shares every product it does not
break with the original (products are dataclasses: a broken one is a ``replace``-d copy, the original is never
modified). Broken pixels are set as the product's decoded pixels (``_pixels``); its ``png`` bytes stay the
original's, so a broken copy is for in-memory runs only (:func:`encode_pixels` makes it writable).

:func:`setup_reusing` builds the handoff setup of a broken copy and reuses, from the unbroken setup, every
stereo view (with its dense stereo) and every whole handoff case (with its registration and cached steps) whose
products are the very same objects: their results are the ones the command would compute again, bit for bit,
so a test pays only for what the break changes.

Truth: the simulator's downlinks carry the true camera models and poses (``Downlink.truth_images``) and the
targets' true site points (``Downlink.truth_targets``); the breaks that must know where a target is in an image
project its true point through the true model of that image.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from scipctl.core.handoff import HandoffCase
from scipctl.model import Downlink, ImageProduct, MastAngles
from scipctl.pipeline.handoff import HandoffSetup, build_setup

DEG = math.pi / 180.0


def _dn_max(p: ImageProduct) -> float:
    return 65535.0 if p.pixels.dtype == np.uint16 else 255.0


def with_pixels(p: ImageProduct, px: np.ndarray) -> ImageProduct:
    """A copy of ``p`` whose decoded pixels are ``px`` (float DN, rounded and clipped to the product's type)."""
    px = np.clip(np.rint(px), 0, _dn_max(p)).astype(p.pixels.dtype)
    return replace(p, _pixels=px)


def encode_pixels(dl: Downlink) -> Downlink:
    """``dl`` with every product's ``png`` re-encoded from its (possibly broken) pixels, to write it out."""
    from scipctl.io.images import encode_png

    return replace(dl, images=[replace(p, png=encode_png(p.pixels)) if p._pixels is not None else p
                               for p in dl.images])


def _swap(dl: Downlink, new: dict) -> Downlink:
    """``dl`` with the products of ``new`` (product id -> product) replaced."""
    return replace(dl, images=[new.get(p.product_id, p) for p in dl.images])


def pair_of(dl: Downlink, left: ImageProduct) -> list:
    """``[left, right]`` products of a stereo pair."""
    right = dl.stereo_pair(left)
    assert right is not None, left.product_id
    return [left, right]


# ------------------------------------------------------------------ washed-out images
def washed_out_copy(dl: Downlink, products: list, factor: float) -> Downlink:
    """``products`` exposed ``factor`` times too long: DN x ``factor``, clipped at the sensor's full scale (the
    simulator's ``washed_out`` error applied after the fact, without its pre-quantisation noise)."""
    return _swap(dl, {p.product_id: with_pixels(p, p.pixels.astype(float) * factor) for p in products})


def saturated_fraction(p: ImageProduct) -> float:
    return float(np.mean(p.pixels >= _dn_max(p)))


# ------------------------------------------------------------------ mast pointing error
def mast_error_copy(dl: Downlink, products: list, dtilt_rad: float = 0.0, dpan_rad: float = 0.0) -> Downlink:
    """``products`` (mast cameras) with downlinked mast angles off by ``dpan_rad`` / ``dtilt_rad``: their camera
    models are the calibrated head moved to the wrong angles (the images stay what the true head saw).

    The model moves by ``M(pan + dpan, tilt + dtilt) . M(pan, tilt)^-1`` (``MastGeometry.head_motion``), which is
    exact whatever the calibration of the head: the product's model is the calibrated head at its angles."""
    mast = dl.rover_config.mast
    new = {}
    for p in products:
        assert p.mast is not None, f"{p.product_id}: not a mast camera"
        pan, tilt = p.mast.pan_rad, p.mast.tilt_rad
        M = mast.head_motion(pan + dpan_rad, tilt + dtilt_rad) @ mast.head_motion(pan, tilt).inverse()
        new[p.product_id] = replace(p, camera_model=p.camera_model.transformed(M),
                                    mast=MastAngles(pan + dpan_rad, tilt + dtilt_rad))
    return _swap(dl, new)


# ------------------------------------------------------------------ where a target is, from the truth
def true_point_rover(dl: Downlink, p: ImageProduct, target_id: str) -> np.ndarray:
    """The target's true point (3,) in the true rover frame of ``p``'s acquisition."""
    tr = dl.truth_for(p.product_id)
    tt = dl.truth_target(target_id)
    assert tr is not None and tt is not None, (p.product_id, target_id)
    return tr.pose.T_site_rover.inverse().apply(np.asarray(tt.xyz_site_m, float)[None])[0]


def true_pixel(dl: Downlink, p: ImageProduct, target_id: str) -> np.ndarray:
    """The target's true pixel (2,) in ``p`` (its true model)."""
    X = true_point_rover(dl, p, target_id)
    return dl.truth_for(p.product_id).camera_model.project(X[None])[0]


def _disk(shape, centre_uv, radius_px: float) -> np.ndarray:
    h, w = shape
    jj, ii = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return (jj - centre_uv[0]) ** 2 + (ii - centre_uv[1]) ** 2 <= radius_px**2


def ground_radius_px(dl: Downlink, p: ImageProduct, target_id: str, radius_m: float) -> float:
    """``radius_m`` at the target, in ``p``'s pixels (its true model's focal length at the target's range)."""
    m = dl.truth_for(p.product_id).camera_model
    X = true_point_rover(dl, p, target_id)
    range_m = float(np.linalg.norm(X - m.C))
    ifov_h, ifov_v = m.ifov_rad()
    return radius_m / range_m / min(ifov_h, ifov_v)


# ------------------------------------------------------------------ textureless surface
def sim_scene(sim_json):
    """The simulator's scene of a downlink, rebuilt from the ``.sim.json`` beside it (default family only)."""
    import json

    from scipctl.sim.build import scene_for
    from scipctl.sim.scenarios import plan_run

    rec = json.loads(open(sim_json).read())
    return scene_for(plan_run(rec["scenario"], rec["run"], int(rec["seed"])))


def model_in_site(dl: Downlink, p: ImageProduct):
    """``p``'s true camera model in the site frame."""
    tr = dl.truth_for(p.product_id)
    return tr.camera_model.transformed(tr.pose.T_site_rover)


def surface_mask(scene, dl: Downlink, p: ImageProduct, target_id: str, radius_m: float) -> np.ndarray:
    """``(H, W)`` bool: the pixels of ``p`` whose first surface point (ray-cast in the true scene through the true
    model, at the pixel centre) lies within ``radius_m`` of the target's true point: the same patch of ground in
    every image, whatever the viewpoint (what a patch of uniform albedo would cover)."""
    X = np.asarray(dl.truth_target(target_id).xyz_site_m, float)
    m = model_in_site(dl, p)
    c = true_pixel(dl, p, target_id)
    half = 4.0 * ground_radius_px(dl, p, target_id, radius_m)  # slant views stretch the disk: a generous box
    u0, u1 = int(max(c[0] - half, 0)), int(min(c[0] + half + 1, p.width))
    v0, v1 = int(max(c[1] - half, 0)), int(min(c[1] + half + 1, p.height))
    U, V = np.meshgrid(np.arange(u0, u1, dtype=float), np.arange(v0, v1, dtype=float))
    o, d = m.unproject(np.stack([U.ravel(), V.ravel()], -1))
    hits = scene.cast(o, d)
    near = hits.hit & (np.linalg.norm(np.nan_to_num(hits.points) - X, axis=1) <= radius_m)
    box = near.reshape(U.shape)
    assert not (box[0].any() or box[-1].any() or box[:, 0].any() or box[:, -1].any()) or \
        (u0 == 0 or v0 == 0 or u1 == p.width or v1 == p.height), f"{p.product_id}: the patch overflows its box"
    out = np.zeros((p.height, p.width), bool)
    out[v0:v1, u0:u1] = box
    return out


def check_scene_matches(scene, dl: Downlink, p: ImageProduct, target_id: str, tol_m: float = 0.003) -> float:
    """Distance (m) from the target's true point to the scene's surface along ``p``'s true ray through the
    target's true pixel (the rebuilt scene is the one the images were rendered from when this is ~0)."""
    o, d = model_in_site(dl, p).unproject(true_pixel(dl, p, target_id)[None])
    h = scene.cast(o, d)
    dist = float(np.linalg.norm(h.points[0] - np.asarray(dl.truth_target(target_id).xyz_site_m, float)))
    assert dist <= tol_m, (p.product_id, target_id, dist)
    return dist


def sensor_noise_dn(level_dn: float, dn_max: float = 255.0) -> float:
    """The simulator's sensor noise (shot + read, its default :class:`~scipctl.sim.render.Sensor`) at ``level_dn``."""
    from scipctl.sim.render import Sensor

    s = Sensor()
    e = max(level_dn, 0.0) / dn_max * s.full_well_e
    return math.sqrt(e + s.read_noise_e**2) / s.full_well_e * dn_max


def textureless_copy(dl: Downlink, scene, products: list, target_ids: list, radius_m: float, seed: int) -> Downlink:
    """Around each target, on the surface within ``radius_m`` of its true point (:func:`surface_mask`), there
    is no texture in any of ``products`` (e.g. every navcam and hazcam image the handoff reads): the patch's
    pixels are the patch's mean in that image plus the simulator's sensor noise at that level (seeded)."""
    rng = np.random.default_rng(seed)
    new = {}
    for p in products:
        px = p.pixels.astype(float)
        for tid in target_ids:
            m = surface_mask(scene, dl, p, tid, radius_m)
            if m.any():
                level = float(px[m].mean())
                px[m] = level + rng.normal(0.0, sensor_noise_dn(level, _dn_max(p)), int(m.sum()))
        new[p.product_id] = with_pixels(p, px)
    return _swap(dl, new)


# ------------------------------------------------------------------ occluder in front of the target
def _texture(shape, seed: int) -> np.ndarray:
    """A smooth random texture in [0, 1] (blurred white noise, contrast stretched)."""
    import cv2

    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.random(shape).astype(np.float32), (0, 0), 2.0)
    return (t - t.min()) / max(float(np.ptp(t)), 1e-6)


def occluded_copy(dl: Downlink, haz_left: ImageProduct, target_ids: list, radius_m: float, range_frac: float,
                  seed: int) -> Downlink:
    """A fronto-parallel textured disk (radius ``radius_m``) on each target's line of sight from the left hazcam,
    at ``range_frac`` of the target's range: it hides the target from the left hazcam, and it is seen by both
    hazcams with the stereo disparity of its own range (drawn in each eye at the projection of its centre through
    that eye's true model), so hazcam stereo sees a real object, closer than the target."""
    haz_right = dl.stereo_pair(haz_left)
    assert haz_right is not None
    px = {p.product_id: p.pixels.astype(float) for p in (haz_left, haz_right)}
    mL = dl.truth_for(haz_left.product_id).camera_model
    for k, tid in enumerate(target_ids):
        X = true_point_rover(dl, haz_left, tid)
        Xo = mL.C + range_frac * (X - mL.C)  # the occluder's centre, true rover frame of the hazcam stop
        tex = None
        for p in (haz_left, haz_right):
            m = dl.truth_for(p.product_id).camera_model
            c = m.project(Xo[None])[0]
            r_px = radius_m / float(np.linalg.norm(Xo - m.C)) / min(m.ifov_rad())
            img = px[p.product_id]
            if tex is None:
                n = int(2 * math.ceil(r_px) + 1)
                tex = _texture((n, n), seed + k)
                lo, hi = np.percentile(img, [5, 95])
                tex = lo + (hi - lo) * tex  # the scene's own contrast range
            disk = _disk(img.shape, c, r_px)
            ii, jj = np.nonzero(disk)
            # the same texture in both eyes, anchored at the disk's centre (a plane facing the cameras)
            ti = np.clip(np.rint(ii - c[1] + tex.shape[0] // 2).astype(int), 0, tex.shape[0] - 1)
            tj = np.clip(np.rint(jj - c[0] + tex.shape[1] // 2).astype(int), 0, tex.shape[1] - 1)
            img[ii, jj] = tex[ti, tj]
    return _swap(dl, {p.product_id: with_pixels(p, px[p.product_id]) for p in (haz_left, haz_right)})


def occluder_miss_m(dl: Downlink, haz_left: ImageProduct, target_id: str, range_frac: float) -> float:
    """The larger, over both hazcam eyes, of the distance from :func:`occluded_copy`'s occluder centre to that
    eye's line of sight to the target: the target is hidden from both eyes when this is below the radius."""
    X = true_point_rover(dl, haz_left, target_id)
    mL = dl.truth_for(haz_left.product_id).camera_model
    Xo = mL.C + range_frac * (X - mL.C)
    out = 0.0
    for p in pair_of(dl, haz_left):
        C = dl.truth_for(p.product_id).camera_model.C
        d = (X - C) / np.linalg.norm(X - C)
        out = max(out, float(np.linalg.norm(np.cross(Xo - C, d))))
    return out


# ------------------------------------------------------------------ the setup, reusing what did not change
def setup_reusing(dl: Downlink, base_dl: Downlink, base: HandoffSetup) -> HandoffSetup:
    """:func:`~scipctl.pipeline.handoff.build_setup` of ``dl`` (a broken copy of ``base_dl``, whose setup is
    ``base``; same products chosen, same parameters) where every stereo view whose two products are the very
    objects of ``base``'s is ``base``'s view (dense stereo computed once), and every case whose navcam and hazcam
    views are both reused is ``base``'s case itself (registration and cached steps too)."""
    params = next(iter(base.cases.values())).params
    new = build_setup(dl, params, hazcam=base.hazcam.product_id,
                      near=base.near.product_id if base.near else None, far=base.far.product_id if base.far else None)

    def unchanged(p_new, p_old) -> bool:
        return p_new is p_old and dl.stereo_pair(p_new) is base_dl.stereo_pair(p_old)

    haz_same = unchanged(new.hazcam, base.hazcam)
    haz_view = next(iter(base.cases.values())).haz if haz_same else next(iter(new.cases.values())).haz
    for label, case in list(new.cases.items()):
        old = base.cases[label]
        nav_same = unchanged(new.near if label == "near" else new.far, base.near if label == "near" else base.far)
        if nav_same and haz_same:
            new.cases[label] = old
        else:
            new.cases[label] = HandoffCase(label, old.nav if nav_same else case.nav, haz_view, case.T_haz_nav,
                                           case.params)
    return new
