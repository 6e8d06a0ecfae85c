"""Small, fully consistent downlinks built in memory, for tests anywhere in the suite.

    from tests.io.builders import make_small_downlink, make_rover_config
    dl = make_small_downlink()                      # 10 products, 64x48, 2 positions, targets, truth
    write_downlink(dl, tmp_path / "dl.mcap")

Geometry (rover frame: x forward, y right, z down):

* mast head: pan about +z through (0.3, 0, -1.0); tilt about +y through
  (0.3, 0, -1.5) (positive tilt looks up);
* ``navcam`` (mast, CAHVOR, f 45 px, baseline 0.20 m), ``pancam`` (mast,
  CAHV, f 150 px, baseline 0.30 m), ``hazcam`` (body, CAHVORE type 3,
  linearity 0.37, f 30 px, 45 deg down, baseline 0.12 m);
* each position: navcam and hazcam stereo pairs; position 0 also a pancam pair;
* targets are site-frame points on the ground ahead of the first position,
  marked by projecting them with the *true* pose and model wherever they fall
  inside an image.
"""

from __future__ import annotations

import base64
import io
import json

import numpy as np

from scipctl.core.camera import CameraModel, cahv_from_intrinsics
from scipctl.core.kinematics import CameraSpec, JointAxis, MastGeometry, RoverConfig, RoverPose, StereoCamera
from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix, euler_zyx_to_matrix
from scipctl.io.images import encode_png
from scipctl.io.downlink_mcap import TOPIC_SCHEMAS
from scipctl.model import Downlink, ImageProduct, ImageTruth, Mark, MastAngles, TargetMarks, TargetTruth

# camera frame (x right, y down, z forward) -> rover frame (x fwd, y right, z down), looking forward
R_ROVER_CAMFWD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

NAVCAM_POINTING = (0.10, -0.50)  # (pan_rad, tilt_rad)
PANCAM_POINTING = (0.05, -0.45)


def _cam_pose(C, down_rad=0.0) -> RigidTransform:
    R = axis_angle_to_matrix([0, 1, 0], -down_rad) @ R_ROVER_CAMFWD
    return RigidTransform(R, np.array(C, float))


def _model(kind, f_px, width, height, C, down_rad=0.0) -> CameraModel:
    m = cahv_from_intrinsics(f_px, f_px, (width - 1) / 2 + 0.3, (height - 1) / 2 - 0.2, _cam_pose(C, down_rad))
    if kind == "CAHV":
        return m
    if kind == "CAHVOR":
        return CameraModel("CAHVOR", m.C, m.A, m.H, m.V, O=m.A, R=[0.0, -0.05, 0.01])
    return CameraModel("CAHVORE", m.C, m.A, m.H, m.V, O=m.A, R=[0.0, -0.02, 0.004], E=[0.0005, 0.004, -0.002],
                       cahvore_type=3, linearity=0.37)


def make_rover_config(width: int = 64, height: int = 48, name: str = "test-rover") -> RoverConfig:
    """Rover configuration with pancam, navcam (mast) and hazcam (body); all eyes ``width`` x ``height``."""
    mast = MastGeometry(JointAxis(np.array([0.3, 0.0, -1.0]), np.array([0.0, 0.0, 1.0])),
                        JointAxis(np.array([0.3, 0.0, -1.5]), np.array([0.0, 1.0, 0.0])))

    def pair(mount, kind, f_px, C, half_base, down=0.0):
        l_C = np.array(C) + [0, -half_base, 0]
        r_C = np.array(C) + [0, half_base, 0]
        return StereoCamera(mount, CameraSpec(_model(kind, f_px, width, height, l_C, down), width, height),
                            CameraSpec(_model(kind, f_px, width, height, r_C, down), width, height))

    cams = {
        "pancam": pair("mast", "CAHV", 150.0 * width / 64, (0.35, 0.0, -1.50), 0.15),
        "navcam": pair("mast", "CAHVOR", 45.0 * width / 64, (0.35, 0.0, -1.55), 0.10),
        "hazcam": pair("body", "CAHVORE", 30.0 * width / 64, (0.60, 0.0, -0.60), 0.06, down=np.pi / 4),
    }
    return RoverConfig(name, mast, cams)


def _texture(rng, width, height, bit_depth) -> np.ndarray:
    """Smooth random texture plus a few saturated pixels, uint8 or uint16."""
    coarse = rng.uniform(0.1, 0.9, size=(height // 8 + 2, width // 8 + 2))
    yy = np.linspace(0, coarse.shape[0] - 1.001, height)
    xx = np.linspace(0, coarse.shape[1] - 1.001, width)
    y0, x0 = yy.astype(int), xx.astype(int)
    fy, fx = (yy - y0)[:, None], (xx - x0)[None, :]
    img = ((1 - fy) * (1 - fx) * coarse[np.ix_(y0, x0)] + (1 - fy) * fx * coarse[np.ix_(y0, x0 + 1)]
           + fy * (1 - fx) * coarse[np.ix_(y0 + 1, x0)] + fy * fx * coarse[np.ix_(y0 + 1, x0 + 1)])
    img = np.clip(img + rng.normal(0, 0.02, size=img.shape), 0, 1)
    img[: max(1, height // 16), : max(1, width // 16)] = 1.0  # a saturated corner
    top = 255 if bit_depth == 8 else 65535
    return np.round(img * top).astype(np.uint8 if bit_depth == 8 else np.uint16)


def rover_pose(k: int, source: str = "wheel_odometry") -> RoverPose:
    """Estimated pose at position index ``k`` (site frame)."""
    R = euler_zyx_to_matrix(0.3 + 0.1 * k, 0.02, -0.01 + 0.005 * k)
    return RoverPose(RigidTransform(R, np.array([2.0 * k, 0.5 * k, 0.01 * k])), source, 0.05, 0.01)


def true_pose(k: int) -> RoverPose:
    """The truth differs from the estimate by a few centimetres and a few milliradians."""
    est = rover_pose(k)
    dR = euler_zyx_to_matrix(0.004 * (k + 1), -0.001, 0.002)
    return RoverPose(RigidTransform(est.T_site_rover.R @ dR, est.T_site_rover.t + np.array([0.03, -0.02, 0.0])), "truth")


def target_points_site(pose0: RoverPose) -> dict:
    """Site-frame target points on the ground ahead of the first position."""
    pts_rover = {"t_flat": [3.0, 0.2, 0.0], "t_rock": [2.6, -0.3, -0.05], "t_near": [1.4, 0.05, 0.0]}
    return {k: pose0.T_site_rover.apply(np.array(v)) for k, v in pts_rover.items()}


def make_small_downlink(
    width: int = 64,
    height: int = 48,
    n_positions: int = 2,
    bit_depth: int = 8,
    with_targets: bool = True,
    with_truth: bool = True,
    seed: int = 0,
    mission: str = "test",
    sol: int = 42,
) -> Downlink:
    """A small valid downlink: per position navcam and hazcam stereo pairs (position 0 also pancam), PNG images.

    Products are named ``<camera>_<eye>_<site>_<drive>`` (``navcam_left_1_0``);
    positions are (site 1, drive 0), (1, 12), (1, 24), ...
    """
    rng = np.random.default_rng(seed)
    rc = make_rover_config(width, height)
    images, truth_images = [], []
    t = 1000.0
    for k in range(n_positions):
        site, drive = 1, 12 * k
        pose = rover_pose(k)
        shots = [("navcam", NAVCAM_POINTING), ("hazcam", None)]
        if k == 0:
            shots.insert(0, ("pancam", PANCAM_POINTING))
        for cam, pointing in shots:
            for eye in ("left", "right"):
                mast = MastAngles(*pointing) if pointing else None
                model = rc.camera_model(cam, eye, *(pointing or (0.0, 0.0)))
                px = _texture(rng, width, height, bit_depth)
                pid = f"{cam}_{eye}_{site}_{drive}"
                images.append(ImageProduct(
                    product_id=pid, camera=cam, eye=eye, time_s=t + (0.25 if eye == "right" else 0.0),
                    site=site, drive=drive, pose=pose, camera_model=model, width=width, height=height,
                    png=encode_png(px), mast=mast, exposure_ms=12.5, gain=1.0,
                ))
                if with_truth:
                    truth_images.append(ImageTruth(pid, true_pose(k), model))
            t += 4.0
        t += 600.0

    targets, truth_targets = [], []
    if with_targets:
        pts = target_points_site(true_pose(0))
        for tid, X in pts.items():
            marks = []
            for im in images:
                k = im.drive // 12
                tr = true_pose(k)
                uv = im.camera_model.project(tr.T_site_rover.inverse().apply(X)[None])[0]
                if np.all(np.isfinite(uv)) and -0.5 <= uv[0] <= width - 0.5 and -0.5 <= uv[1] <= height - 0.5:
                    marks.append(Mark(im.product_id, float(uv[0]), float(uv[1]), 0.5))
            targets.append(TargetMarks(tid, "flat" if tid != "t_rock" else "point", f"synthetic target {tid}", marks))
            truth_targets.append(TargetTruth(tid, np.array(X)))
    return Downlink(
        mission=mission, sol=sol, rover_config=rc, images=images, targets=targets,
        truth_images=truth_images if with_truth else [], truth_targets=truth_targets if with_truth else [],
    )


META = {"format_version": "1", "mission": "test", "sol": "42"}


def write_raw_mcap(path, metadata, topics, encoding="json", extra_topics=None, writer_options=None):
    """An MCAP written directly with the mcap package (not with scipctl's writer), for producer variations.

    ``topics`` maps topic -> list of message dicts (or raw bytes); ``metadata`` is the ``scip.downlink``
    record (None: left out); ``encoding`` is the channels' message encoding; ``writer_options`` go to
    ``mcap.writer.Writer`` (e.g. ``use_chunking=False, enable_crcs=False``: records stored plain, unchecked).
    """
    from mcap.writer import Writer

    buf = io.BytesIO()
    w = Writer(buf, **(writer_options or {}))
    w.start()
    if metadata is not None:
        w.add_metadata("scip.downlink", metadata)
    w.add_metadata("other.tool", {"anything": "goes"})
    for topic, items in list(topics.items()) + list((extra_topics or {}).items()):
        sid = w.register_schema(TOPIC_SCHEMAS.get(topic, "x.Other"), "jsonschema", b"{}")
        cid = w.register_channel(topic, encoding, sid)
        for i, d in enumerate(items):
            data = d if isinstance(d, bytes) else json.dumps(d).encode()
            t = round(d["time_s"] * 1e9) if isinstance(d, dict) and "time_s" in d and isinstance(d["time_s"], float) else i
            w.add_message(cid, t, data, t)
    w.finish()
    path.write_bytes(buf.getvalue())


def plain_records(dl):
    """The records of ``dl`` per MCAP topic, as plain dicts (as scipctl's writer produces them); mutate and
    pass to :func:`write_raw_mcap` to make deliberately broken or unusual downlinks."""
    import scipctl.io.downlink as P

    imgs = []
    for im in dl.images:
        rec = P.product_to_plain(im)
        rec["image"] = {"format": "png", "data": base64.b64encode(im.png).decode()}
        imgs.append(rec)
    return {
        "/downlink/image": imgs,
        "/downlink/rover_config": [P.rover_config_to_plain(dl.rover_config)],
        "/downlink/targets": [P.target_to_plain(t) for t in dl.targets],
        "/truth/image": [P.truth_image_to_plain(t) for t in dl.truth_images],
        "/truth/targets": [P.truth_target_to_plain(t) for t in dl.truth_targets],
    }
