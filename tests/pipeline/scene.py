"""A small synthetic world with exact truth for the prediction / sequence / report tests.

* a flat textured ground (site z = 0; site +z is down), a box "rock" with the
  target on its front face, optional extra boxes (obstacles, occluders) and an
  optional uniform (texture-free) patch;
* a MER/Rocky8-like rover (mast pancam/navcam, body hazcam; CAHV/CAHVOR/CAHVORE)
  at reduced resolution (``SIZE`` px) so dense stereo and rendering stay fast;
* :func:`render` ray-casts a camera model (site frame) with Open3D, 2x2
  supersampled; the albedo is a smooth function of the 3-D point;
* :func:`make_downlink` gives today's downlink (pancam, navcam and hazcam
  stereo pairs at one position, pointed at the target) with marks and truth;
* :func:`oracle_sources` gives exact "dense stereo" grids (the true surface
  along each left pixel ray) for tests that must not depend on SGBM.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scipctl.core.camera import CameraModel, cahv_from_intrinsics
from scipctl.core.kinematics import CameraSpec, JointAxis, MastGeometry, RoverConfig, RoverPose, StereoCamera
from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix
from scipctl.io.images import encode_png
from scipctl.model import Downlink, ImageProduct, ImageTruth, Mark, MastAngles, TargetMarks, TargetTruth

SIZE = 256
R_ROVER_CAMFWD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _mast_pose(x, y, z):
    return RigidTransform(R_ROVER_CAMFWD, np.array([x, y, z], float))


def _haz_pose(y):
    R = axis_angle_to_matrix([0, 1, 0], -math.radians(45.0)) @ R_ROVER_CAMFWD
    return RigidTransform(R, np.array([0.62, y, -0.50]))


def rover_config(size: int = SIZE) -> RoverConfig:
    s = size / 1024.0
    c = (size - 1) / 2.0
    f_pan, f_nav, f_haz = s / 0.28e-3, s / 0.82e-3, s / 2.1e-3

    def cahvor(f, T, R):
        m = cahv_from_intrinsics(f, f, c, c, T)
        return CameraModel("CAHVOR", m.C, m.A, m.H, m.V, O=m.A, R=list(R))

    def cahvore(f, T):
        m = cahv_from_intrinsics(f, f, c, c, T)
        return CameraModel("CAHVORE", m.C, m.A, m.H, m.V, O=m.A, R=[0.0, -0.046, 0.002], E=[0.0005, 0.004, -0.002],
                           cahvore_type=3, linearity=0.37)

    pan = StereoCamera("mast", CameraSpec(cahv_from_intrinsics(f_pan, f_pan, c, c, _mast_pose(0.36, -0.15, -1.52)), size, size),
                       CameraSpec(cahv_from_intrinsics(f_pan, f_pan, c, c, _mast_pose(0.36, 0.15, -1.52)), size, size))
    nav = StereoCamera("mast", CameraSpec(cahvor(f_nav, _mast_pose(0.38, -0.10, -1.48), (0, -0.018, 0.003)), size, size),
                       CameraSpec(cahvor(f_nav, _mast_pose(0.38, 0.10, -1.48), (0, -0.018, 0.003)), size, size))
    haz = StereoCamera("body", CameraSpec(cahvore(f_haz, _haz_pose(-0.05)), size, size),
                       CameraSpec(cahvore(f_haz, _haz_pose(0.05)), size, size))
    mast = MastGeometry(JointAxis(np.array([0.30, 0.0, -1.30]), np.array([0.0, 0.0, 1.0])),
                        JointAxis(np.array([0.30, 0.0, -1.50]), np.array([0.0, 1.0, 0.0])))
    return RoverConfig("scene-test", mast, {"pancam": pan, "navcam": nav, "hazcam": haz})


@dataclass
class World:
    boxes: list = field(default_factory=list)  # (min (3,), max (3,)) site frame, z down (heights negative)
    quads: list = field(default_factory=list)  # (4, 3) corners (site frame), two triangles each (both faces)
    flat_patch: tuple = None  # ((x0, y0), (x1, y1)) uniform albedo on the ground
    extent_m: float = 40.0
    seed: int = 3
    _scene: object = None

    def _mesh(self):
        import open3d as o3d

        e = self.extent_m
        V = [np.array([[-e, -e, 0], [e, -e, 0], [e, e, 0], [-e, e, 0]], float)]
        T = [np.array([[0, 1, 2], [0, 2, 3]])]
        off = 4
        for q in self.quads:
            V.append(np.asarray(q, float))
            T.append(np.array([[0, 1, 2], [0, 2, 3]]) + off)
            off += 4
        for lo, hi in self.boxes:
            lo, hi = np.asarray(lo, float), np.asarray(hi, float)
            b = o3d.geometry.TriangleMesh.create_box(*(hi - lo))
            V.append(np.asarray(b.vertices) + lo)
            T.append(np.asarray(b.triangles) + off)
            off += 8
        return np.concatenate(V), np.concatenate(T)

    def scene(self):
        if self._scene is None:
            import open3d as o3d

            V, T = self._mesh()
            sc = o3d.t.geometry.RaycastingScene()
            sc.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(T.astype(np.uint32)))
            self._scene = sc
        return self._scene

    def cast(self, o, d):
        import open3d as o3d

        rays = np.concatenate([o, d], axis=-1).reshape(-1, 6).astype(np.float32)
        r = self.scene().cast_rays(o3d.core.Tensor(rays))
        t = r["t_hit"].numpy().astype(float)
        return t.reshape(o.shape[:-1])

    def albedo(self, P):
        P = np.asarray(P, float)
        rng = np.random.default_rng(self.seed)
        k = 24
        dirs = rng.normal(size=(k, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        lam = np.exp(rng.uniform(np.log(0.06), np.log(0.8), k))
        ph = rng.uniform(0, 2 * np.pi, k)
        val = np.zeros(P.shape[:-1])
        for i in range(k):
            val += np.sin(P @ dirs[i] * (2 * np.pi / lam[i]) + ph[i]) * (lam[i] ** 0.3)
        val = 0.5 + 0.12 * val / np.sqrt(k) * 3.0
        if self.flat_patch is not None:
            (x0, y0), (x1, y1) = self.flat_patch
            inside = (P[..., 0] >= x0) & (P[..., 0] <= x1) & (P[..., 1] >= y0) & (P[..., 1] <= y1) & (np.abs(P[..., 2]) < 1e-3)
            val = np.where(inside, 0.5, val)
        return np.clip(val, 0.05, 0.95)


def render(world: World, model_site: CameraModel, width: int, height: int, ss: int = 2) -> np.ndarray:
    """(height, width) float32 in [0, 1]; sky (no hit) is 0."""
    off = (np.arange(ss) + 0.5) / ss - 0.5
    us = (np.arange(width)[:, None] + off[None]).ravel()
    vs = (np.arange(height)[:, None] + off[None]).ravel()
    U, V = np.meshgrid(us, vs)
    o, d = model_site.unproject(np.stack([U, V], -1).reshape(-1, 2))
    t = world.cast(o, d)
    P = o + np.where(np.isfinite(t), t, 0)[:, None] * d
    val = np.where(np.isfinite(t), world.albedo(P), 0.0)
    return val.reshape(height, ss, width, ss).mean(axis=(1, 3)).astype(np.float32)


def surface_point(world: World, model_site: CameraModel, uv) -> np.ndarray:
    o, d = model_site.unproject(np.asarray(uv, float)[None])
    t = world.cast(o, d)[0]
    return o[0] + t * d[0]


ROCK = (np.array([9.8, -0.25, -0.30]), np.array([10.3, 0.25, 0.0]))
TARGET_ROCK_SITE = np.array([9.8, 0.05, -0.15])  # on the rock's front face
TARGET_FLAT_SITE = np.array([9.3, -0.6, 0.0])


# a 45-degree slab facing the rover (rising away from it), its foot 9.4 m ahead; the target on it
SLAB = np.array([[9.4, -0.4, 0.0], [9.4, 0.4, 0.0], [9.8, 0.4, -0.4], [9.8, -0.4, -0.4]])
TARGET_SLAB_SITE = np.array([9.6, 0.1, -0.2])


def slab_world(**kw) -> World:
    return World(quads=[SLAB], **kw)


def default_world(**kw) -> World:
    return World(boxes=[ROCK] + list(kw.pop("extra_boxes", [])), **kw)


def make_downlink(world: World = None, pose: RigidTransform = None, targets: dict = None, size: int = SIZE,
                  sigma_position_m: float = 0.03, sigma_yaw_rad: float = 0.005) -> Downlink:
    """Today's downlink at one position: pancam and navcam pairs pointed at the first target, a hazcam pair."""
    world = world or default_world()
    rc = rover_config(size)
    T = pose if pose is not None else RigidTransform.identity()
    rp = RoverPose(T, "wheel_odometry", sigma_position_m, sigma_yaw_rad)
    targets = targets if targets is not None else {"t_rock": TARGET_ROCK_SITE, "t_flat": TARGET_FLAT_SITE}
    aim = T.inverse().apply(np.asarray(next(iter(targets.values())), float))
    images, truth = [], []
    t = 1000.0
    for cam in ("pancam", "navcam", "hazcam"):
        pan = tilt = None
        if rc.cameras[cam].mount == "mast":
            pan, tilt = rc.point_at(cam, aim)
        for eye in ("left", "right"):
            m = rc.camera_model(cam, eye, pan or 0.0, tilt or 0.0)
            img = render(world, m.transformed(T), size, size)
            pid = f"{cam}_{eye}_1_0"
            images.append(ImageProduct(pid, cam, eye, t + (0.2 if eye == "right" else 0.0), 1, 0, rp, m, size, size,
                                       encode_png(np.round(img * 255).astype(np.uint8)),
                                       MastAngles(pan, tilt) if pan is not None else None, exposure_ms=10.0, gain=1.0))
            truth.append(ImageTruth(pid, RoverPose(T, "truth"), m))
        t += 5.0
    marks = []
    for tid, X in targets.items():
        X = np.asarray(X, float)
        mk = []
        for im in images:
            ms = im.camera_model.transformed(T)
            uv = ms.project(X[None])[0]
            if not np.all(np.isfinite(uv)) or not (0 <= uv[0] <= size - 1 and 0 <= uv[1] <= size - 1):
                continue
            # visible: the surface along the ray is the target itself
            Xs = surface_point(world, ms, uv)
            if np.linalg.norm(Xs - X) < 0.02:
                mk.append(Mark(im.product_id, float(uv[0]), float(uv[1]), 0.0))
        marks.append(TargetMarks(tid, "point", f"synthetic {tid}", mk))
    return Downlink("test", 7, rc, images, marks, truth, [TargetTruth(k, np.asarray(v, float)) for k, v in targets.items()])


def oracle_sources(world: World, dl: Downlink, cameras=("pancam", "navcam", "hazcam"), step: int = 2):
    """Exact "dense stereo": for every left image of ``cameras``, the true surface point of every ``step``-th pixel."""
    from scipctl.pipeline.predict import TerrainSource

    out = []
    prio = {"pancam": 0, "navcam": 1, "hazcam": 2}
    for im in dl.images:
        if im.eye != "left" or im.camera not in cameras:
            continue
        ms = im.camera_model.transformed(im.pose.T_site_rover)
        us, vs = np.meshgrid(np.arange(0, im.width, step, dtype=float), np.arange(0, im.height, step, dtype=float))
        uv = np.stack([us, vs], -1).reshape(-1, 2)
        o, d = ms.unproject(uv)
        t = world.cast(o, d)
        rng_max = 40.0
        P = o + np.where(np.isfinite(t) & (t < rng_max), t, np.nan)[:, None] * d
        out.append(TerrainSource(im.product_id, im.camera, P.reshape(us.shape + (3,)), im.pixels_float(), ms,
                                 ms.C.copy(), prio[im.camera]))
    return out


_CACHE = {}


def cached(name: str):
    """(world, downlink) for ``"rock"`` (box rock: t_rock on its face, t_flat on the ground) or ``"slab"``
    (t_slab on a 45-degree slab, t_flat), rendered once per test session."""
    if name not in _CACHE:
        if name == "rock":
            w = default_world()
            _CACHE[name] = (w, make_downlink(w, targets={"t_rock": TARGET_ROCK_SITE, "t_flat": TARGET_FLAT_SITE}))
        elif name == "slab":
            w = slab_world()
            _CACHE[name] = (w, make_downlink(w, targets={"t_slab": TARGET_SLAB_SITE, "t_flat": TARGET_FLAT_SITE}))
        else:
            raise KeyError(name)
    return _CACHE[name]


def designation_record(dl: Downlink, target_id: str, world: World = None):
    """An exact :class:`~scipctl.pipeline.designate.Designation` (as ``scipctl designate`` makes it) from the
    target's mark in the left pancam."""
    from scipctl.pipeline.designate import Designation

    tm = dl.target(target_id)
    left = dl.product("pancam_left_1_0")
    mk = tm.mark_in(left.product_id)
    X = next(t.xyz_site_m for t in dl.truth_targets if t.id == target_id)
    Xr = left.pose.T_site_rover.inverse().apply(X)
    return Designation(id=target_id, ok=True, product_id=left.product_id, camera="pancam", pixel_uv=(mk.u, mk.v),
                       xyz_site_m=tuple(np.asarray(X).tolist()), xyz_rover_m=tuple(Xr.tolist()),
                       range_m=float(np.linalg.norm(Xr - left.camera_model.C)), range_sigma_m=0.01, position=(1, 0))
