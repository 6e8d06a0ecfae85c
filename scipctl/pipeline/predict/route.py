"""The downlink's own route as an approach plan: the stops the rover later imaged the target from, for validating
the prediction against the chain that ran over those stops (``PredictParams.route = "downlink"``).

Why: the prediction normally plans its own approach (:func:`~.planning.plan_approach`: its bearing, its stops, a
final arm standoff). A validation downlink was driven along the renderer's route instead, and the chain over its
later stops is what the prediction is scored against (issue #15 item 1). Scoring a prediction of one route against
the outcome of another mixes two questions; this module lets the prediction answer for the route that was driven.

What the plan is made of: every position after today's (time order) where a left image of a camera of the chain
(pancam, navcam, hazcam) was taken becomes a stop, at the rover's recorded (estimated) position there, on the
recorded ground plane, with the recorded heading -- or, at a stop with a body-fixed camera (hazcam), facing
today's designated point, as the planner's stops do -- and with the cameras imaged there shot as the planner
shoots them (pointed from that pose at the designated point). The recorded poses stand in for the commanded
route; they carry the drive's odometry error, which a prediction before the drive would not know -- the Monte
Carlo adds its own drive error per leg. The route ends at its last hazcam stop,
which is an imaging stop, not an arm standoff: ``ApproachPlan.placement`` is False and the Monte Carlo does not
check the arm workspace there (the chain's final hazcam answer, not the placement, is what is scored).
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from ...core.kinematics import RoverPose
from .geometry import pose_on_plane, tilt_of, yaw_of
from .params import ApproachParams
from .planning import ApproachPlan, PlannedStop, _plane_of, _shot, clearance_of
from .terrain import Terrain

CHAIN_CAMERAS = ("pancam", "navcam", "hazcam")
_KIND = {frozenset({"pancam"}): "pancam", frozenset({"pancam", "navcam"}): "pancam-navcam-handoff",
         frozenset({"navcam"}): "navcam", frozenset({"navcam", "hazcam"}): "navcam-hazcam-handoff",
         frozenset({"hazcam"}): "hazcam", frozenset({"pancam", "navcam", "hazcam"}): "navcam-hazcam-handoff"}


def stop_kind(cameras) -> str:
    """The planner's stop kind for the set of chain cameras imaged at a position (see ``planning._cameras_for``).

    A stop with pancam and hazcam but no navcam has no kind the chain knows: ValueError."""
    key = frozenset(cameras) & frozenset(CHAIN_CAMERAS)
    if key not in _KIND:
        raise ValueError(f"no chain stop images {sorted(key)}")
    return _KIND[key]


def route_from_downlink(dl, start: RoverPose, start_position: tuple, target_site_m, terrain: Optional[Terrain],
                        params: ApproachParams, chain_params, designation_camera: str = "pancam") -> ApproachPlan:
    """The approach plan of the downlink's own later stops (module docstring).

    ``start``: today's pose (the designation image's); ``start_position``: its ``(site, drive)``;
    ``target_site_m`` (3,): the designated point, site frame. Raises ``InputError`` (downlink, positions) when no
    later position imaged the target with a chain camera.
    """
    from ...model import InputError

    X = np.asarray(target_site_m, float).reshape(3)
    positions = dl.positions()
    later = positions[positions.index(tuple(start_position)) + 1:] if tuple(start_position) in positions else []
    stops = [PlannedStop(0, "start", float(np.linalg.norm(X[:2] - start.T_site_rover.t[:2])), start.T_site_rover,
                         yaw_of(start.T_site_rover), 0.0, 0.0, tilt_rad=tilt_of(start.T_site_rover))]
    prev = start.T_site_rover
    path = [prev.t[:2].copy()]
    cams = [[]]
    for pos in later:
        lefts = [im for im in dl.images_at(pos, eye="left") if im.camera in CHAIN_CAMERAS]
        if not lefts:
            continue
        recorded = lefts[0].pose.T_site_rover
        xy, heading = recorded.t[:2], yaw_of(recorded)
        names = sorted({im.camera for im in lefts}, key=CHAIN_CAMERAS.index)
        if any(dl.rover_config.cameras[c].mount != "mast" for c in names if c in dl.rover_config.cameras):
            # a body-fixed camera's stop faces the target, as the planner's do: the recorded heading carries the
            # drive's odometry error, which the Monte Carlo adds itself (and which would put the designated
            # point outside a hazcam the rover in fact pointed at the target)
            heading = math.atan2(X[1] - xy[1], X[0] - xy[0])
        T_site_rover = pose_on_plane(xy, heading, _plane_of(recorded))
        leg = float(np.linalg.norm(xy - prev.t[:2]))
        drive_yaw = math.atan2(xy[1] - prev.t[1], xy[0] - prev.t[0]) if leg > 1e-9 else yaw_of(prev)
        turn = math.remainder(heading - drive_yaw, math.tau)
        st = PlannedStop(len(stops), stop_kind({im.camera for im in lefts}), float(np.linalg.norm(X[:2] - xy)),
                         T_site_rover, heading, leg, float(turn), tilt_rad=tilt_of(T_site_rover), terrain_known=False,
                         path_from_previous=[prev.t[:2].tolist(), xy.tolist()])
        stops.append(st)
        cams.append(names)
        path.append(xy.copy())
        prev = T_site_rover
    if len(stops) < 2:
        raise InputError(dl.source or "downlink", "positions",
                         "no later position imaged the target with a pancam, navcam or hazcam: no route to predict")
    for st, names in zip(stops[1:], cams[1:]):
        st.cameras = [_shot(dl.rover_config, st, c, X, params, chain_params) for c in names]
    path_xy = np.array(path)
    rocks = (terrain.rock_cells(params.rock_cell_m, params.ground_window_m, params.rock_height_m)
             if terrain is not None else np.zeros((0, 2)))
    cl = clearance_of([(st.T_site_rover.t[:2], st.heading_rad) for st in stops[1:]], rocks, X[:2], params.body)
    cl["blocked"] = False  # the route was driven; keep-out is the planner's question, not this one's
    cl["terrain_known_fraction"] = terrain.known_fraction_along(path_xy) if terrain is not None else 0.0
    cl["rock_cells"] = int(len(rocks))
    final = stops[-1]
    bearing = math.atan2(X[1] - final.T_site_rover.t[1], X[0] - final.T_site_rover.t[0])
    length = float(sum(st.leg_m for st in stops[1:]))
    return ApproachPlan(X, start, bearing, 0.0, stops, path_xy, length, cl, params, designation_camera,
                        placement=False)

