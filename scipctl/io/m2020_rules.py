"""The rover-specific values of the Mars 2020 rules file (``scipctl/data/rules-m2020.yaml``), derived from the
rover URDF and the static camera models (``nasa-jpl/m2020-urdf-models``, read by :mod:`.m2020_geometry`).

What is derived here (docs/sequence.md, "Rules file"; ``docs/scripts/derive_m2020_rules.py`` prints it):

* **Arm reach on the ground.** The robotic arm is the URDF chain ``Body_Chassis -> Body_RA_Base -[JOINT1_ENC
  (azimuth, about z)]-> -[JOINT2_ENC, JOINT3_ENC, JOINT4_ENC (pitch, about -y)]-> -[JOINT5_ENC (turret, about
  z)]-> Body_RA_Link5``, with the URDF joint limits. The contact instruments (``Frame_DRILL``, ``Frame_PIXL``,
  ``Frame_SHERLOC``, ``Frame_WATSON``, ``Frame_GDRT``) hang from ``Body_RA_Link5``; their boresight is the
  frame's +x (radial from the turret axis: the SHERLOC and WATSON camera models' A axes agree). An instrument is
  *placed* at a ground point (rover z = 0, flat ground under the wheels) when its frame origin is there and its
  boresight points straight down (+z). With the pitch joints parallel this fixes the pitch sum
  ``psi = q2 + q3 + q4 = +-pi/2`` and the turret angle; the pitch chain is then a planar two-link arm, solved in
  closed form over a fine grid of ``q2``. Configurations with a joint origin below the ground are dropped.
  Self-collision with the rover body is not modelled (the URDF carries no collision geometry): the footprint and
  the target keep-out bound the workspace instead.
* **Footprint.** The six wheel hubs of the URDF at zero joint angles; the wheel radius is the hubs' height above
  the rover origin (the rover frame's origin is on the ground). The URDF gives neither the wheel width nor the
  body and MMRTG beyond the wheels: the width and the length are NASA's published figures (see
  :data:`PUBLISHED_LENGTH_M`), the extra length put behind the rear wheels (the MMRTG).
* **Hazcam view.** The front hazcam pair of the simulator's configuration (:func:`.m2020_geometry.m2020_rover_config`:
  HAZFLA/HAZFRA, 1280 x 960): the ground points inside both images by the flight rule's margin.
* **Arm workspace.** The largest annulus sector ``r_min <= hypot(x, y) <= r_max, |y| <= half_width`` (the
  planner's :class:`~scipctl.pipeline.predict.ArmWorkspace` model, centred on the rover origin) in which every
  ground point (1 cm grid) is reached by every contact instrument, is inside both hazcam images and is at least
  the target keep-out from the footprint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model import InputError
from .m2020_geometry import ROVER_LINK, URDF_FILE, chain, read_urdf_joints, urdf_root, wheels_xy_from_urdf

ARM_JOINTS = ("JOINT1_ENC", "JOINT2_ENC", "JOINT3_ENC", "JOINT4_ENC", "JOINT5_ENC")
ARM_TIP_LINK = "Body_RA_Link5"
CONTACT_INSTRUMENTS = ("Frame_DRILL", "Frame_PIXL", "Frame_SHERLOC", "Frame_WATSON", "Frame_GDRT")
# NASA, mars.nasa.gov/mars2020/spacecraft/rover/: "about 3 meters long (not including the arm), 2.7 meters wide"
PUBLISHED_LENGTH_M = 3.0
PUBLISHED_WIDTH_M = 2.7


def urdf_joint_limits(path) -> dict:
    """``joint name -> (lower, upper)`` (radians or metres) of every joint of a URDF file with a ``<limit>``."""
    root = urdf_root(path)
    out = {}
    for j in root.findall("joint"):
        lim = j.find("limit")
        if lim is not None and lim.get("lower") is not None and lim.get("upper") is not None:
            out[j.get("name")] = (float(lim.get("lower")), float(lim.get("upper")))
    return out


def _rot(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N, 4, 4) homogeneous rotations about the unit ``axis`` by angles ``q`` (N,)."""
    q = np.asarray(q, float)
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    M = np.zeros((len(q), 4, 4))
    M[:, :3, :3] = np.eye(3) + np.sin(q)[:, None, None] * K + (1.0 - np.cos(q))[:, None, None] * (K @ K)
    M[:, 3, 3] = 1.0
    return M


def _hom(T_parent_child) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = T_parent_child.R, T_parent_child.t
    return M


def arm_fk(joints: dict, link: str, q_rad: np.ndarray) -> tuple:
    """Forward kinematics of the arm: ``(T_rover_link (N, 4, 4), joint origins (5, N, 3))`` for joint angles
    ``q_rad`` (N, 5) in the order of :data:`ARM_JOINTS` (rover frame; ``link`` hangs below ``Body_RA_Link5``)."""
    q = np.atleast_2d(np.asarray(q_rad, float))
    T_rover_link = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()  # down the chain, one link at a time
    origins = []
    for j in chain(joints, ROVER_LINK, link):
        T_rover_link = T_rover_link @ _hom(j.T_parent_origin)
        if j.kind in ("revolute", "continuous"):
            k = ARM_JOINTS.index(j.name)
            origins.append(T_rover_link[:, :3, 3].copy())
            T_rover_link = T_rover_link @ _rot(j.axis, q[:, k])
    return T_rover_link, np.array(origins)


def _yaw(T_parent_child) -> float:
    return math.atan2(T_parent_child.R[1, 0], T_parent_child.R[0, 0])


@dataclass(frozen=True)
class GroundReach:
    """Where one instrument can be placed on the ground, boresight straight down (rover frame, z = 0).

    ``j1_xy_m``: the azimuth joint's vertical axis; ``families``: one ``(lateral_m, s_intervals_m)`` per nadir
    family (``psi = +pi/2``, ``-pi/2``): with the azimuth at zero, the instrument lies ``lateral_m`` to the right
    of the axis and ``s`` ahead of it for ``s`` in the union of the intervals (``(K, 2)``); ``q1_limits_rad``:
    the azimuth joint's limits.
    """

    instrument: str
    j1_xy_m: np.ndarray
    q1_limits_rad: tuple
    families: tuple

    def contains(self, xy_rover) -> np.ndarray:
        """``xy_rover`` (..., 2) ground points, rover frame -> (...,) bool: the instrument can be placed there."""
        p = np.asarray(xy_rover, float)
        d = p - self.j1_xy_m
        rho2 = d[..., 0] ** 2 + d[..., 1] ** 2
        phi = np.arctan2(d[..., 1], d[..., 0])
        lo, hi = self.q1_limits_rad
        out = np.zeros(p.shape[:-1], bool)
        for lateral, iv in self.families:
            s_abs = np.sqrt(np.maximum(rho2 - lateral ** 2, 0.0))
            for s in (s_abs, -s_abs):
                in_s = np.zeros_like(out)
                for a, b in iv:
                    in_s |= (s >= a) & (s <= b)
                q1 = phi - np.arctan2(lateral, s)
                q1 = np.where(q1 < lo, q1 + 2 * np.pi, q1)
                q1 = np.where(q1 > hi, q1 - 2 * np.pi, q1)
                out |= in_s & (rho2 >= lateral ** 2) & (q1 >= lo) & (q1 <= hi)
        return out


def _intervals(s: np.ndarray, gap_m: float) -> np.ndarray:
    """Sorted samples -> ``(K, 2)`` intervals, split where two neighbours are more than ``gap_m`` apart."""
    if len(s) == 0:
        return np.zeros((0, 2))
    s = np.sort(s)
    cut = np.nonzero(np.diff(s) > gap_m)[0]
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [len(s) - 1]])
    return np.stack([s[starts], s[ends]], 1)


def _runs(s: np.ndarray, ok: np.ndarray, s_tip: np.ndarray) -> list:
    """``[(min, max), ...]`` of ``s`` over each run of consecutive ``ok`` samples, with the run's end points
    extended to ``s_tip`` where that is finite."""
    edges = np.diff(np.concatenate([[0], ok.astype(np.int8), [0]]))
    out = []
    for a, b in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]):
        vals = np.concatenate([s[a:b], [x for x in (s_tip[a], s_tip[b - 1]) if np.isfinite(x)]])
        out.append((float(vals.min()), float(vals.max())))
    return out


def _union(iv: list) -> np.ndarray:
    """``(K, 2)`` sorted disjoint union of closed intervals."""
    out = []
    for a, b in sorted(iv):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return np.array(out).reshape(-1, 2)


def ground_reach(joints: dict, limits: dict, instrument: str, n_q2: int = 20001) -> GroundReach:
    """:class:`GroundReach` of ``instrument`` (a frame below ``Body_RA_Link5``) from the URDF ``joints`` and joint
    ``limits`` (:func:`urdf_joint_limits`), sampling the shoulder pitch ``q2`` at ``n_q2`` angles."""
    for name in ARM_JOINTS:
        if name not in limits:
            raise InputError(URDF_FILE, name, "no joint limits for an arm joint")
    lim = [limits[n] for n in ARM_JOINTS]
    zero = np.zeros((1, 5))
    _, o0 = arm_fk(joints, instrument, zero)
    j1, j2, j3, j4 = o0[0, 0], o0[1, 0], o0[2, 0], o0[3, 0]
    l2, l3 = float(np.linalg.norm(j3 - j2)), float(np.linalg.norm(j4 - j3))
    # the closed form: at zero angles the upper arm and forearm lie along rover x, the pitch axes along y and the
    # azimuth and turret axes along z (as in the nasa-jpl URDF); anything else is refused, not approximated
    axes = {j.name: j.T_parent_origin.R @ j.axis for j in chain(joints, ROVER_LINK, instrument) if j.name in ARM_JOINTS}
    want = {"JOINT1_ENC": 2, "JOINT2_ENC": 1, "JOINT3_ENC": 1, "JOINT4_ENC": 1, "JOINT5_ENC": 2}
    if (np.abs((j3 - j2)[1:]).max() > 1e-9 or np.abs((j4 - j3)[1:]).max() > 1e-9
            or any(abs(abs(axes[n][k]) - 1.0) > 1e-9 for n, k in want.items())):
        raise InputError(URDF_FILE, "arm joints", "not the planar pitch chain of the Mars 2020 arm (links along x, "
                         "pitch axes along y, azimuth and turret along z at zero angles)")
    yaw_i = _yaw(joints[instrument].T_parent_origin)
    q2 = np.linspace(lim[1][0], lim[1][1], n_q2)
    families = []
    for psi, alpha in ((0.5 * np.pi, 0.0), (-0.5 * np.pi, np.pi)):
        q5 = (alpha - yaw_i - lim[4][0]) % (2 * np.pi) + lim[4][0]
        T_rover_instrument, o = arm_fk(joints, instrument, np.array([[0.0, 0.0, 0.0, psi, q5]]))
        c = T_rover_instrument[0, :3, 3] - j4  # instrument from the wrist joint, constant for this family (link 1 frame)
        c5 = o[4, 0] - j4  # the turret joint from the wrist joint
        runs = []
        v = (-c[2] - j2[2] - l2 * np.sin(q2)) / l3  # sin(q2 + q3) for the instrument at z = 0
        ok_v = np.abs(v) <= 1.0
        for branch in (np.arcsin(np.clip(v, -1, 1)), np.pi - np.arcsin(np.clip(v, -1, 1))):
            q3 = (branch - q2 + np.pi) % (2 * np.pi) - np.pi
            q4 = psi - q2 - q3
            q4 = np.where(q4 < lim[3][0], q4 + 2 * np.pi, q4)
            q4 = np.where(q4 > lim[3][1], q4 - 2 * np.pi, q4)
            z3 = j2[2] + l2 * np.sin(q2)
            z4 = z3 + l3 * np.sin(q2 + q3)
            ok = (ok_v & (q3 >= lim[2][0]) & (q3 <= lim[2][1]) & (q4 >= lim[3][0]) & (q4 <= lim[3][1])
                  & (z3 <= 0.0) & (z4 <= 0.0) & (z4 + c5[2] <= 0.0))
            s = j2[0] - j1[0] + l2 * np.cos(q2) + l3 * np.cos(q2 + q3) + c[0]
            # where the forearm turns vertical (|v| -> 1) the two branches meet: the run reaches that point exactly
            # (v interpolated linearly between the samples either side; cos(q2 + q3) = 0 there)
            s_tip = np.full_like(s, np.nan)
            for i, j in ((np.arange(len(v) - 1), np.arange(1, len(v))), (np.arange(1, len(v)), np.arange(len(v) - 1))):
                edge = ok_v[i] & ~ok_v[j]
                t = (1.0 - np.abs(v[i][edge])) / (np.abs(v[j][edge]) - np.abs(v[i][edge]))
                q2_tip = q2[i][edge] + t * (q2[j][edge] - q2[i][edge])
                s_tip[i[edge]] = j2[0] - j1[0] + l2 * np.cos(q2_tip) + c[0]
            runs += _runs(s, ok, s_tip)  # along one branch the solution is continuous in q2: a run is an interval
        families.append((float(j2[1] - j1[1] + c[1]), _union(runs)))
    return GroundReach(instrument, j1[:2].copy(), tuple(lim[0]), tuple(families))


@dataclass(frozen=True)
class Footprint:
    """The rover footprint rectangle, rover frame: ``rear_m <= x <= front_m``, ``|y| <= half_width_m``, with
    what it was made of (``wheels_xy_m`` (6, 2) hubs, ``wheel_radius_m``)."""

    front_m: float
    rear_m: float
    half_width_m: float
    wheels_xy_m: np.ndarray
    wheel_radius_m: float


def footprint_from_urdf(joints: dict) -> Footprint:
    """The footprint: front = the front hubs + the wheel radius (the hubs' height above the rover origin, on the
    ground); rear = front - :data:`PUBLISHED_LENGTH_M`; half width = :data:`PUBLISHED_WIDTH_M` / 2 (the URDF
    gives no wheel width). :class:`InputError` if the published width does not cover the URDF's hubs."""
    from ..core.transforms import RigidTransform

    wheels = wheels_xy_from_urdf(joints)
    z = []
    for link in ("Body_WheelLeftFront", "Body_WheelLeftMiddle", "Body_WheelLeftRear"):
        T_rover_wheel = RigidTransform.identity()
        for j in chain(joints, ROVER_LINK, link):
            T_rover_wheel = T_rover_wheel @ j.T_parent_child(0.0)
        z.append(-T_rover_wheel.t[2])
    radius = float(np.mean(z))
    front = float(wheels[:, 0].max()) + radius
    half_width = 0.5 * PUBLISHED_WIDTH_M
    if half_width <= float(np.abs(wheels[:, 1]).max()):
        raise InputError(URDF_FILE, "wheels", "the published width does not cover the wheel hubs")
    return Footprint(front, front - PUBLISHED_LENGTH_M, half_width, wheels, radius)


def hazcam_margin_px(rover_config, xyz_rover: np.ndarray) -> np.ndarray:
    """(N,) the smaller distance (px) of rover-frame points ``(N, 3)`` from the edges of the two hazcam images
    (-inf where a point does not project), as the ``hazcam-fov-final`` rule measures it
    (:func:`scipctl.core.image_margin.pair_margin_px`)."""
    from ..core.image_margin import pair_margin_px

    return pair_margin_px(rover_config, "hazcam", xyz_rover)


@dataclass(frozen=True)
class Workspace:
    """An annulus sector ``r_min_m <= hypot(x, y) <= r_max_m``, ``x > 0``, ``|y| <= half_width_m`` (rover frame)."""

    r_min_m: float
    r_max_m: float
    half_width_m: float


def largest_sector(ok, cell_m: float, r_max_limit_m: float) -> Workspace:
    """The annulus sector of largest area whose every point on a ``cell_m`` grid (x > 0) satisfies ``ok`` (a
    function ``(N, 2) xy -> (N,) bool``); radii are whole cells (a cell belongs to the ring of its rounded radius),
    ``r_max <= r_max_limit_m``. :class:`ValueError` if no sector of one cell fits."""
    n = int(round(r_max_limit_m / cell_m))
    x = np.arange(1, n + 1) * cell_m
    y = np.arange(-n, n + 1) * cell_m
    X, Y = np.meshgrid(x, y, indexing="ij")
    good = ok(np.stack([X, Y], -1).reshape(-1, 2)).reshape(X.shape)
    ring = np.rint(np.hypot(X, Y) / cell_m).astype(int)
    # per ring: the smallest |y| of a cell that fails (inf: none)
    worst = np.full(n + 2, np.inf)
    np.minimum.at(worst, np.minimum(ring[~good], n + 1), np.abs(Y[~good]))
    best = (0.0, None)
    for i in range(1, n + 1):
        hw_cap = np.inf
        for j in range(i, n + 1):
            hw_cap = min(hw_cap, worst[j])
            hw = min(hw_cap - cell_m, j * cell_m)
            if hw < cell_m:
                break
            area = _sector_area(i * cell_m, j * cell_m, hw)
            if area > best[0]:
                best = (area, Workspace(round(i * cell_m, 6), round(j * cell_m, 6), round(float(hw), 6)))
    if best[1] is None:
        raise ValueError("no annulus sector fits the reachable ground")
    return best[1]


def _sector_area(a: float, b: float, hw: float) -> float:
    """Area of ``{a <= hypot(x, y) <= b, x > 0, |y| <= hw}``."""
    def disk_band(r):  # area of {hypot <= r, x > 0, |y| <= min(hw, r)}
        h = min(hw, r)
        return h * math.sqrt(r * r - h * h) + r * r * math.asin(h / r) if r > 0 else 0.0
    return disk_band(b) - disk_band(a)


@dataclass(frozen=True)
class M2020Derived:
    """The values of ``rules-m2020.yaml`` derived here, and the numbers they came from."""

    arm_workspace: Workspace
    rover_body: Footprint
    reach_centreline_m: dict  # instrument -> (K, 2) intervals of ground x reached on y = 0 (x > front)
    hazcam_view_x_m: tuple  # (near, far) ground x inside both hazcam images on y = 0, within 6 m
    hazcam_pair_x_m: float  # rover x of the hazcam pair's centre
    inputs: tuple = field(default=())  # ((file, sha256), ...)

    def to_dict(self) -> dict:
        w, f = self.arm_workspace, self.rover_body
        return {"arm_workspace": {"r_min_m": w.r_min_m, "r_max_m": w.r_max_m, "half_width_m": w.half_width_m},
                "rover_body": {"front_m": round(f.front_m, 4), "rear_m": round(f.rear_m, 4),
                               "half_width_m": round(f.half_width_m, 4)},
                "wheel_radius_m": round(f.wheel_radius_m, 4), "wheels_xy_m": np.round(f.wheels_xy_m, 4).tolist(),
                "reach_centreline_m": {k: np.round(v, 3).tolist() for k, v in self.reach_centreline_m.items()},
                "hazcam_view_x_m": [round(v, 3) for v in self.hazcam_view_x_m],
                "hazcam_pair_x_m": round(self.hazcam_pair_x_m, 4),
                "inputs": [{"file": n, "sha256": h} for n, h in self.inputs]}


def derive_m2020(folder, target_keep_out_m: float, hazcam_fov_margin_px: float, cell_m: float = 0.01) -> M2020Derived:
    """The Mars 2020 arm workspace and footprint from the URDF and camera models in ``folder``, for the rules
    file's target keep-out and hazcam margin."""
    from .m2020_geometry import MODELS_FILE, m2020_rover_config
    from .provenance import sha256_file

    folder = Path(folder)
    joints = read_urdf_joints(folder / URDF_FILE)
    limits = urdf_joint_limits(folder / URDF_FILE)
    config = m2020_rover_config(folder)
    reach = [ground_reach(joints, limits, name) for name in CONTACT_INSTRUMENTS]
    body = footprint_from_urdf(joints)

    def ok(xy):
        good = np.ones(len(xy), bool)
        for r in reach:
            good &= r.contains(xy)
        dx = np.maximum(np.maximum(body.rear_m - xy[:, 0], xy[:, 0] - body.front_m), 0.0)
        dy = np.maximum(np.abs(xy[:, 1]) - body.half_width_m, 0.0)
        good &= np.hypot(dx, dy) >= target_keep_out_m
        idx = np.nonzero(good)[0]
        good[idx] = hazcam_margin_px(config, np.c_[xy[idx], np.zeros(len(idx))]) >= hazcam_fov_margin_px
        return good

    r_lim = float(max(np.hypot(*r.j1_xy_m) + max(iv[:, 1].max() for _, iv in r.families if len(iv)) for r in reach))
    ws = largest_sector(ok, cell_m, math.ceil(r_lim / cell_m) * cell_m)
    xs = np.arange(body.front_m, r_lim, 0.001)
    line = np.c_[xs, np.zeros_like(xs)]
    centre = {r.instrument: _intervals(xs[r.contains(line)], 0.0015) for r in reach}
    xv = np.arange(0.0, 6.0, 0.001)
    vis = xv[hazcam_margin_px(config, np.c_[xv, np.zeros((len(xv), 2))]) >= hazcam_fov_margin_px]
    haz_x = 0.5 * (config.camera_model("hazcam", "left", 0, 0).C[0] + config.camera_model("hazcam", "right", 0, 0).C[0])
    inputs = tuple((n, sha256_file(folder / n)) for n in (MODELS_FILE, URDF_FILE))
    return M2020Derived(ws, body, centre, (float(vis.min()), float(vis.max())), float(haz_x), inputs)
