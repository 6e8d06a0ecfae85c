"""Synthetic stereo scenes with exact truth, shared by the stereo tests (tests/core/test_epipolar.py,
test_point_stereo.py, test_dense_stereo.py, test_bench_stereo.py).

The scene is a ground plane (rover frame, z down: the plane z = 0) with an
optional box (a "rock"), textured by an analytic function of the 3-D point.
Images are rendered by intersecting each pixel's ray (2x2 supersampled)
with the scene, so the 3-D point behind every pixel is known exactly.
"""

from functools import lru_cache

import numpy as np

from scipctl.core.camera import CameraModel, T_model_cam, cahv_from_intrinsics
from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix
from tests.models import pose

W, H = 512, 384
F_PX = 560.0
BASELINE_M = 0.2


class Scene:
    """Ground plane ``z = 0`` plus an optional axis-aligned box; texture ``sum a cos(2 pi k.P + phi)``."""

    def __init__(self, box=None, seed=0, n=48, wavelength_m=(0.04, 0.5)):
        r = np.random.default_rng(seed)
        lam = np.exp(r.uniform(np.log(wavelength_m[0]), np.log(wavelength_m[1]), n))
        dirs = r.normal(size=(n, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        self.k = dirs / lam[:, None]  # cycles per metre
        self.phase = r.uniform(0, 2 * np.pi, n)
        self.amp = r.uniform(0.5, 1.0, n) * np.sqrt(lam / lam.max())  # less power at short wavelengths
        self.amp /= np.sqrt(0.5 * np.sum(self.amp**2))
        self.box = None if box is None else (np.asarray(box[0], float), np.asarray(box[1], float))

    def texture(self, P):
        """Texture at points ``P`` (N, 3); float32 phases (ample for images), in chunks to bound memory."""
        k = (2 * np.pi * self.k.T).astype(np.float32)
        ph0 = self.phase.astype(np.float32)
        amp = self.amp.astype(np.float32)
        out = np.empty(len(P))
        for i in range(0, len(P), 65536):
            ph = P[i : i + 65536].astype(np.float32) @ k
            ph += ph0
            out[i : i + 65536] = np.cos(ph, out=ph) @ amp
        return out

    def intersect(self, o, d):
        """Nearest hit along rays ``o + t d`` ``(N, 3)`` -> ``(t (N,), P (N, 3))``; NaN for no hit."""
        o = np.broadcast_to(o, d.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -o[:, 2] / d[:, 2]
        t = np.where(t > 0, t, np.inf)
        if self.box is not None:
            lo, hi = self.box
            with np.errstate(divide="ignore", invalid="ignore"):
                t1 = (lo - o) / d
                t2 = (hi - o) / d
            tn = np.nanmax(np.minimum(t1, t2), axis=1)
            tf = np.nanmin(np.maximum(t1, t2), axis=1)
            hit = (tn <= tf) & (tn > 0)
            t = np.where(hit & (tn < t), tn, t)
        t = np.where(np.isfinite(t), t, np.nan)
        return t, o + t[:, None] * d

    def render(self, model, width=W, height=H, ss=2, gain=20.0, offset=120.0):
        v, u = np.mgrid[0:height, 0:width].astype(float)
        acc = np.zeros((height, width))
        for i in range(ss):
            for j in range(ss):
                uv = np.stack([u + (i + 0.5) / ss - 0.5, v + (j + 0.5) / ss - 0.5], -1).reshape(-1, 2)
                o, d = model.unproject(uv)
                _, P = self.intersect(o, d)
                val = self.texture(np.nan_to_num(P))
                val[~np.isfinite(P[:, 0])] = 0.0
                acc += val.reshape(height, width)
        return offset + gain * acc / (ss * ss)

    def point_at(self, model, uv):
        o, d = model.unproject(np.asarray(uv, float).reshape(-1, 2))
        return self.intersect(o, d)[1]


def _distorted(m: CameraModel, R=(0.0, -0.12, 0.04), tilt=0.004) -> CameraModel:
    T_rover_cam = T_model_cam(m)
    o = np.array([np.sin(tilt), -0.5 * np.sin(tilt), 1.0])
    return CameraModel("CAHVOR", m.C, m.A, m.H, m.V, O=T_rover_cam.R @ (o / np.linalg.norm(o)), R=list(R))


def _cahvore(m: CameraModel, tilt=0.004, e=(0.0005, 0.004, -0.002)) -> CameraModel:
    """A wide-angle, non-central CAHVORE (type 3, linearity 0.37) from a CAHV model."""
    T_rover_cam = T_model_cam(m)
    o = np.array([np.sin(tilt), -0.5 * np.sin(tilt), 1.0])
    return CameraModel("CAHVORE", m.C, m.A, m.H, m.V, O=T_rover_cam.R @ (o / np.linalg.norm(o)), R=[0.0, -0.02, 0.004],
                       E=list(e), cahvore_type=3, linearity=0.37)


def make_pair(kind="CAHV", f_px=F_PX, width=W, height=H, baseline_m=BASELINE_M, tilt_down_rad=0.5,
              toe_in_rad=0.0, C=(0.4, 0.1, -1.5)):
    """A navcam-like pair in the rover frame: left at ``C``, right ``baseline_m`` along the camera x axis."""
    T_l = pose(tilt_down_rad=tilt_down_rad, yaw_rad=0.1, C=C)
    T_r = T_l @ RigidTransform(axis_angle_to_matrix([0, 1, 0], -toe_in_rad), np.array([baseline_m, 0.0, 0.0]))
    cx, cy = (width - 1) / 2 + 3.7, (height - 1) / 2 - 2.1
    left = cahv_from_intrinsics(f_px, f_px * 1.002, cx, cy, T_l)
    right = cahv_from_intrinsics(f_px * 0.999, f_px * 1.001, cx - 1.3, cy + 0.8, T_r)
    if kind == "CAHVOR":
        left, right = _distorted(left), _distorted(right, R=(0.0, -0.10, 0.03), tilt=-0.003)
    elif kind == "CAHVORE":
        left, right = _cahvore(left), _cahvore(right, tilt=-0.003, e=(0.0004, 0.003, -0.001))
    return left, right


@lru_cache(maxsize=None)
def rendered(kind="CAHV", with_box=False, seed=0):
    box = ((3.0, -0.35, -0.45), (3.5, 0.35, 0.0)) if with_box else None
    scene = Scene(box=box, seed=seed)
    left, right = make_pair(kind, f_px=300.0 if kind == "CAHVORE" else F_PX)  # CAHVORE: hazcam-like wide angle
    return scene, left, right, scene.render(left), scene.render(right)


def to_uint8(img):
    """``img`` rounded to uint8; asserts it lies strictly between 0 and 255 (nothing clipped)."""
    assert img.min() > 0 and img.max() < 255
    return np.round(img).astype(np.uint8)
