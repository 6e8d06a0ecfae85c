"""Building a simulated run: plan, scene, products, targets, marks, pixels -> an in-memory downlink with truth.

:func:`build_run` is the entry point (``scipctl synth`` writes its result); :func:`scene_for` caches
the scene the runs of one scenario scene share. The scenarios themselves are defined in
:mod:`.scenarios`. Nothing here touches files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional, Union

import numpy as np

from ..core.kinematics import RoverPose
from ..model import Downlink, ImageProduct, ImageTruth, MastAngles, TargetTruth
from . import rover as rover_mod
from .errors import ErrorSettings
from .families import FAMILIES, SceneFamily, family_of_run, family_rover, family_texture
from .marks import compute_marks
from .products import check_error_draw, error_stream, estimated_pose, plan_products
from .scenarios import RunPlan, _rng, default_errors, list_runs, plan_run
from .scene import Scene, make_scene
from .targets import choose_targets

MISSION = "scip-sim"
DEFAULT_BITS = {"pancam": 8, "navcam": 8, "hazcam": 8}
EXPOSURE_MS_PER_UNIT = {"pancam": 40.0, "navcam": 25.0, "hazcam": 15.0}


# ----------------------------------------------------------------------------- scene cache
_SCENES: dict = {}
DEFAULT_SCENE_KEY = FAMILIES["default"].scene_key


def scene_for(plan: RunPlan, texture=None, family: Optional[SceneFamily] = None) -> Scene:
    """The plan's scene (cached per scene seed, rover, texture and family: both runs of a scene share it).

    ``texture``: a :class:`~scipctl.sim.texture.TextureSources` to drape on the terrain (None: procedural albedo);
    its atlas is built from the scene seed, so the texture is a property of the scene. ``family``: a realised
    :class:`~scipctl.sim.families.SceneFamily` whose terrain, rock shape and sun range make the scene (None: today's).
    """
    scene_key = None if family is None or family.scene_key == DEFAULT_SCENE_KEY else family.scene_key
    rover_key = None if plan.rover is None or plan.rover.is_default else (plan.rover.key, plan.rover.corridor_extra_m,
                                                                          plan.rover.mast_ref_x_m, plan.rover.navcam_ref_x_m,
                                                                          plan.rover.hazcam_ref_x_m)
    key = (plan.scenario, plan.scene_seed)
    if rover_key is not None or texture is not None or scene_key is not None:
        key = key + (rover_key, None if texture is None else texture.digest, scene_key)
    if key not in _SCENES:
        if len(_SCENES) >= 4:  # ~170 MB each
            _SCENES.pop(next(iter(_SCENES)))
        # corridors of both runs of the scene (they share the scene)
        keep = []
        for r in list_runs(plan.scenario):
            if r.split("-")[0] == f"s{plan.scene_index}":
                keep += plan_run(plan.scenario, r, plan.seed, plan.rover).keep_clear
        surface_texture = None
        if texture is not None:
            from .texture import build_surface_texture

            surface_texture = build_surface_texture(texture, plan.scene_seed)
        terrain, rocks, sun_range, specks = DEFAULT_SCENE_KEY if scene_key is None else scene_key
        _SCENES[key] = make_scene(plan.scene_seed, keep_clear=keep, sun_azimuth_rad=plan.sun_azimuth_rad,
                                  texture=surface_texture, terrain=terrain, rock_shape=rocks, sun_elevation_range_deg=sun_range,
                                  specks=specks)
    return _SCENES[key]


# ----------------------------------------------------------------------------- build
@dataclass
class SimRun:
    """A simulated run: the downlink, the full simulation record (JSON-able), the scene and the plan."""

    plan: RunPlan
    downlink: Downlink
    record: dict
    scene: Scene = field(repr=False)
    products: list = field(repr=False, default_factory=list)  # list[ProductPlan]
    targets: list = field(repr=False, default_factory=list)  # list[Target]


def build_run(scenario: str, run: str, seed: int, errors: Optional[ErrorSettings] = None, image_scale: float = 1.0,
              supersample: int = 2, render: bool = True, bits: Optional[dict] = None,
              progress: Optional[Callable[[int, int, str], None]] = None,
              rover: Optional[rover_mod.SimRover] = None, texture=None,
              family: Union[SceneFamily, str, None] = None, error_draw: int = 0) -> SimRun:
    """Simulate one run into an in-memory :class:`~scipctl.model.Downlink` with truth.

    ``errors`` defaults to :func:`default_errors` (all errors on); ``image_scale`` resamples every camera
    (e.g. 0.125: 1024 -> 128 px for the default rover; it must give whole sizes for every camera of the rover);
    ``render=False`` skips the pixels (black images, still exact marks and truth); ``bits`` maps camera -> 8 or 12;
    ``progress(done, total, product_id)`` is called per image. ``rover``: a :class:`~scipctl.sim.rover.SimRover`
    (None: the default ``rocky8-sim``; e.g. ``commands.synth.m2020_sim_rover(folder)``); ``texture``: a
    :class:`~scipctl.sim.texture.TextureSources` draped on the terrain (None: procedural albedo). The record gains
    ``rover`` / ``texture`` entries only when they are not the defaults.

    ``family``: a :class:`~scipctl.sim.families.SceneFamily` or a name of
    :data:`~scipctl.sim.families.FAMILIES` (None: today's scenes, as ``"default"``). It sets the terrain, rock
    shape and sun range of the scene, the error scale (when ``errors`` is None: the scenario's default errors
    scaled), and loads the rover and texture it needs from ``shared/real`` when ``rover`` / ``texture`` are None
    (given ones must agree with it). A randomised family (``mixed``) is realised per scene. The record gains
    ``family`` (the realised family) when a family is given.
    """
    from ..io.images import encode_png
    from .render import Sensor, auto_exposure, expose, render_radiance

    error_draw = check_error_draw(error_draw)
    fam = None if family is None else family_of_run(family, scenario, run, seed)
    if fam is not None:
        if rover is None:
            rover = family_rover(fam)
        elif rover.key != fam.rover:
            raise ValueError(f"rover {rover.key!r} given for family {fam.name} whose rover is {fam.rover!r}")
        if texture is None:
            texture = family_texture(fam)
        elif fam.texture != "real":
            raise ValueError(f"a texture given for family {fam.name} whose texture is {fam.texture!r}")
        if errors is None:
            errors = default_errors(scenario).scaled(fam.error_scale)
    errors = default_errors(scenario) if errors is None else errors
    plan = plan_run(scenario, run, seed, rover)
    scene = scene_for(plan, texture, fam)
    calibrated = rover_mod.default_rover_config() if rover is None else rover.config
    if image_scale != 1.0:
        calibrated = rover_mod.scale_rover_config(calibrated, image_scale)
    products, geo_rec = plan_products(plan, scene, calibrated, errors, error_draw)
    targets, tgt_rec = choose_targets(scene, plan, products, _rng(seed, scenario, run, "targets"))
    marks = compute_marks(scene, products, targets)
    bits = dict(DEFAULT_BITS, **(bits or {}))

    images, truths, img_rec = [], [], []
    exposure_of = {}
    total = len(products)
    for i, p in enumerate(products):
        sensor = Sensor(bits=bits.get(p.camera, 8))
        washed = errors.is_washed_out(run, p.stop, p.camera)
        resp = errors.responsivity_of(p.camera, p.eye)
        if render:
            rad = render_radiance(scene, p.model_true_site, p.width, p.height, supersample)
            key = (p.stop, p.camera)
            if p.eye == "left" or key not in exposure_of:
                exposure_of[key] = auto_exposure(rad, sensor) * (errors.washed_out_factor if washed else 1.0)
            exposure = exposure_of[key]
            rng = error_stream(plan, "sensor", p.stop_index > 0, error_draw, p.product_id) if errors.sensor_noise else None
            px = expose(rad, exposure, resp, sensor, rng)
        else:
            exposure = 1.0
            px = np.zeros((p.height, p.width), np.uint8 if sensor.bits == 8 else np.uint16)
        png = encode_png(px)
        exposure_ms = round(exposure * EXPOSURE_MS_PER_UNIT.get(p.camera, 25.0), 3)
        mast = MastAngles(p.pan_rad, p.tilt_rad) if p.pan_rad is not None else None
        est = estimated_pose(p.T_site_rover_est, p.cumulative_path_m, p.stop_index, errors)
        images.append(ImageProduct(p.product_id, p.camera, p.eye, float(p.time_s), 1, p.stop_index, est, p.model_cal,
                                   p.width, p.height, png, mast=mast, exposure_ms=exposure_ms, gain=1.0))
        truths.append(ImageTruth(p.product_id, RoverPose(p.T_site_rover_true, "truth"), p.model_true))
        img_rec.append({"product_id": p.product_id, "exposure_ms": exposure_ms, "responsivity": resp, "washed_out": washed,
                        "bits": sensor.bits, "vibration_rotvec_rad": p.vibration_rotvec})
        if progress is not None:
            progress(i + 1, total, p.product_id)

    dl = Downlink(MISSION, plan.sol, calibrated, images, marks, truths,
                  [TargetTruth(t.id, np.array(t.xyz_site_m, float)) for t in targets])
    record = {
        "scenario": scenario, "run": run, "seed": int(seed), "scene_index": plan.scene_index, "scene_seed": plan.scene_seed,
        "image_scale": image_scale, "supersample": supersample, "rendered": render,
        "errors": errors.to_dict(), "bearing_rad": plan.bearing_rad, "sun_dir_site": scene.sun_dir_site.tolist(),
        "target_rock": {"size_m": scene.target_rock.size_m.tolist(), "aim_point_site_m": scene.target_rock.aim_point_site().tolist()},
        "targets": [{"id": t.id, "kind": t.kind, "xyz_site_m": t.xyz_site_m.tolist(),
                     "n_marks": len(m.marks)} for t, m in zip(targets, marks)],
        "target_selection": tgt_rec, "images": img_rec, **geo_rec,
    }
    if rover is not None and not rover.is_default:
        record["rover"] = rover.to_record()
    if texture is not None:
        record["texture"] = dict(texture.to_record(), **scene.appearance.texture.to_record())
    if fam is not None:
        record["family"] = fam.to_dict()
    if error_draw:
        record["error_draw"] = error_draw
    return SimRun(plan, dl, record, scene, products, targets)


def render_stops(sim: SimRun, errors: ErrorSettings, stops, supersample: int = 2,
                 scene: Optional[Scene] = None) -> dict:
    """PNG bytes of every product of ``sim`` (built with ``render=False``, or to be rendered again) at ``stops`` (stop
    labels), rendered and exposed as :func:`build_run` does: auto-exposure per stop and camera from the left image,
    the same sensor-noise streams, the default bits. ``scene``: render in this scene instead of ``sim.scene`` (e.g.
    the same ground under another sun). Returns ``{product_id: png}``; ``sim`` is not changed."""
    from ..io.images import encode_png
    from .render import Sensor, auto_exposure, expose, render_radiance

    scene = sim.scene if scene is None else scene
    scenario, run, seed = sim.plan.scenario, sim.plan.run, sim.plan.seed
    out, exposure_of = {}, {}
    for p in sim.products:
        if p.stop not in stops:
            continue
        sensor = Sensor(bits=DEFAULT_BITS.get(p.camera, 8))
        washed = errors.is_washed_out(run, p.stop, p.camera)
        resp = errors.responsivity_of(p.camera, p.eye)
        rad = render_radiance(scene, p.model_true_site, p.width, p.height, supersample)
        key = (p.stop, p.camera)
        if p.eye == "left" or key not in exposure_of:
            exposure_of[key] = auto_exposure(rad, sensor) * (errors.washed_out_factor if washed else 1.0)
        rng = (error_stream(sim.plan, "sensor", p.stop_index > 0, int(sim.record.get("error_draw", 0)), p.product_id)
               if errors.sensor_noise else None)
        out[p.product_id] = encode_png(expose(rad, exposure_of[key], resp, sensor, rng))
    return out
