"""Pre-uplink prediction of tomorrow's single-cycle approach from today's downlink (docs/sequence.md).

From today's stereo (pancam/navcam pairs at the rover's current position) and
a designated 3-D target this module

1. builds a textured terrain mesh (:class:`Terrain`): each dense-stereo grid
   is triangulated (organised grid, long edges and grazing triangles dropped,
   :func:`grid_mesh`); a ray hit is textured by projecting the hit point into
   the source pair's original left image (full resolution); rocks are the
   cells that rise ``rock_height_m`` above a morphological-opening ground
   estimate (:meth:`Terrain.rock_cells`);
2. plans the approach (:func:`plan_approach`): stops every ``stop_fraction``
   of the remaining distance, pancam until the pancam->navcam handoff at
   ``pancam_handoff_m``, navcam stops, the turn to face the target and the
   navcam->hazcam handoff at ``hazcam_handoff_m``, hazcam stops and the final
   pose at ``standoff_m`` (target at the centre of the arm workspace); each
   stop's pose sits on the stereo terrain (plane fit under the footprint);
   straight approach first, detours to other approach bearings when rocks
   block it;
3. renders the expected view of every stop and camera (:meth:`Terrain.render`)
   and scores visibility: field of view, occlusion, texture, obliqueness;
4. runs a Monte Carlo over the pose-estimate error (:func:`monte_carlo`):
   per-leg position/yaw errors (random walk), the stereo re-estimate of the
   target at each stop, pointing from the estimate; gives P(in field of view),
   P(inside the tracker's search region), P(not occluded), P(in the arm
   workspace at the final pose) and the chain probability;
5. runs the tracking and handoff chain on rendered views for a few of those
   samples (:func:`simulate_chain`): NCC tracking with the chain's window
   sizes (``scipctl.pipeline.chain``), the pancam->navcam window scaling, and
   a navcam->hazcam handoff (kinematic point refined by an expected window
   draped from the navcam view), scored against the projection of the
   target's surface point;
6. names the stops and handoffs at risk and why (:func:`assess_risks`).

Frames: site frame (+x north, +y east, +z down) for the terrain, the target
and the planned poses; rover frame at each pose (+x forward, +y right, +z
down). Headings (yaw) are about +z down: from north towards east.
Everything numeric here is pure (arrays in, arrays out); Open3D and OpenCV
are imported inside functions.

The package follows those steps, one concept per module: ``params`` (the
parameter dataclasses), ``geometry`` (poses on the ground), ``terrain``,
``planning``, ``views`` (nominal view checks), ``montecarlo``, ``chain_sim``
(the chain on rendered views), ``risks``, ``from_downlink`` (what is read
from today's downlink) and ``prediction`` (the orchestration:
:func:`run_prediction`, :func:`predict_target`). The public names are
re-exported here: ``from scipctl.pipeline import predict as P; P.Terrain``.
"""

from .params import (
    ApproachParams,
    ArmWorkspace,
    PredictParams,
    RoverBody,
    UncertaintyParams,
)
from .geometry import perturb_pose, pose_on_plane, scaled_model, tilt_of, yaw_of
from .terrain import RayHits, RenderedView, Terrain, TerrainSource, grid_mesh, smooth_grid
from .planning import (
    ApproachPlan,
    CameraShot,
    PlannedStop,
    camera_model_at,
    clearance_of,
    plan_approach,
    standoff_candidates,
    stop_distances,
)
from .approach_search import ApproachSearch
from .views import check_views
from .montecarlo import McResult, McView, monte_carlo, pointing_offset_p90, sample_pose_errors
from .chain_sim import ChainResult, ChainSample, simulate_chain, success_px
from .risks import Risk, assess_risks, foreshortening_changes
from .from_downlink import STEREO_CAMERAS, TargetContext, resolve_target, sigmas_for, target_context, terrain_sources
from .prediction import PoseSigmas, Prediction, confidence_of, predict_target, run_prediction

__all__ = [
    "ApproachParams", "ArmWorkspace", "PredictParams", "RoverBody", "UncertaintyParams",
    "perturb_pose", "pose_on_plane", "scaled_model", "tilt_of", "yaw_of",
    "RayHits", "RenderedView", "Terrain", "TerrainSource", "grid_mesh", "smooth_grid",
    "ApproachPlan", "CameraShot", "PlannedStop", "camera_model_at", "clearance_of", "plan_approach", "stop_distances",
    "standoff_candidates", "ApproachSearch",
    "check_views",
    "McResult", "McView", "monte_carlo", "pointing_offset_p90", "sample_pose_errors",
    "ChainResult", "ChainSample", "simulate_chain", "success_px",
    "Risk", "assess_risks", "foreshortening_changes",
    "STEREO_CAMERAS", "TargetContext", "resolve_target", "sigmas_for", "target_context", "terrain_sources",
    "PoseSigmas", "Prediction", "confidence_of", "predict_target", "run_prediction",
]
