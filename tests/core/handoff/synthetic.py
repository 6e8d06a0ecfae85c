"""A tiny synthetic navcam -> hazcam handoff with exact truth, shared by the tests of scipctl/core/handoff/
(through the fixtures of conftest.py).

The world of tests/pipeline/scene.py (ray-cast, 256 x 256 px MER-like
cameras): the ground plane and a 12 cm box rock in front of the hazcams. Two
rover positions: the hazcams and the near navcams at the origin, the far
navcams 1.5 m back. Models and poses are exact (no calibration or pose
error), so the hazcam truth of each target is its true 3-D point projected
through the true hazcam model, and what is left of a method's error is its
own (stereo ranges, tracking).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scipctl.core.handoff import HandoffCase, HandoffParams, StereoView
from scipctl.core.kinematics import T_roverB_roverA
from scipctl.core.transforms import RigidTransform
from tests.pipeline import scene as S

ROCK = (np.array([1.15, -0.15, -0.12]), np.array([1.45, 0.15, 0.0]))  # site frame, z down
# more relief in the hazcams' view, all different, so that registering the clouds is well posed (a plane alone
# is not, nor a row of equal boxes): a tall post and two slabs tilted different ways
OTHER_ROCKS = [(np.array([1.7, 0.35, -0.35]), np.array([1.8, 0.45, 0.0]))]
SLABS = [np.array([[1.6, -0.7, 0.0], [1.6, -0.35, 0.0], [2.0, -0.35, -0.3], [2.0, -0.7, -0.3]]),
         np.array([[0.9, 0.3, 0.0], [1.2, 0.3, 0.0], [1.2, 0.6, -0.2], [0.9, 0.6, -0.2]])]
TARGETS = {
    "t_top": np.array([1.30, 0.02, -0.12]),  # on the rock's top face
    "t_ground": np.array([1.00, -0.30, 0.0]),  # on the ground beside it
}
FAR_BACK_M = 1.5


@dataclass
class Target:
    id: str
    xyz_site_m: np.ndarray  # (3,)
    nav_uv: dict  # "near"/"far" -> navcam-left pixel (2,) (exact projection)
    haz_uv: np.ndarray  # (2,) hazcam-left truth


@dataclass
class HandoffScene:
    cases: dict  # "near"/"far" -> HandoffCase
    targets: list  # [Target]


def _view(dl, camera, min_range_m, max_range_m) -> StereoView:
    left = dl.product(f"{camera}_left_1_0")
    right = dl.product(f"{camera}_right_1_0")
    return StereoView(left.pixels_float(), right.pixels_float(), left.camera_model, right.camera_model,
                      left.width, left.height, min_range_m=min_range_m, max_range_m=max_range_m)


def _uv(dl, product_id, target_id):
    mk = dl.target(target_id).mark_in(product_id)
    return None if mk is None else np.array([mk.u, mk.v])


def build_scene(params: HandoffParams = None) -> HandoffScene:
    """Fresh cases (nothing cached) for the scene; the rendering is done once per session."""
    near_dl, far_dl = _downlinks()
    params = params or HandoffParams()
    haz = _view(near_dl, "hazcam", 0.3, 6.0)  # the ranges of pipeline.handoff.build_setup
    T_far = T_roverB_roverA(near_dl.product("hazcam_left_1_0").pose, far_dl.product("navcam_left_1_0").pose)
    cases = {
        "near": HandoffCase("near", _view(near_dl, "navcam", 0.8, 30.0), haz, RigidTransform.identity(), params),
        "far": HandoffCase("far", _view(far_dl, "navcam", 0.8, 30.0), haz, T_far, params),
    }
    targets = []
    for tid, X in TARGETS.items():
        nav = {"near": _uv(near_dl, "navcam_left_1_0", tid), "far": _uv(far_dl, "navcam_left_1_0", tid)}
        targets.append(Target(tid, X, nav, _uv(near_dl, "hazcam_left_1_0", tid)))
    assert all(t.haz_uv is not None and t.nav_uv["near"] is not None and t.nav_uv["far"] is not None
               for t in targets), "every target must be visible in every left image"
    return HandoffScene(cases, targets)


_DOWNLINKS = {}


def _downlinks():
    if not _DOWNLINKS:
        world = S.World(boxes=[ROCK] + OTHER_ROCKS, quads=SLABS, seed=5)
        back = RigidTransform(np.eye(3), np.array([-FAR_BACK_M, 0.0, 0.0]))  # T_site_rover of the far position
        _DOWNLINKS["near"] = S.make_downlink(world, targets=TARGETS)
        _DOWNLINKS["far"] = S.make_downlink(world, pose=back, targets=TARGETS)
    return _DOWNLINKS["near"], _DOWNLINKS["far"]
