"""Nominal view checks of a planned approach: occlusion, incidence, texture and terrain coverage of each
planned shot, and reduced-size expected views for the report."""

from __future__ import annotations

import math

import numpy as np

from ...core.kinematics import RoverConfig
from .geometry import scaled_model
from .params import PredictParams
from .planning import ApproachPlan, camera_model_at
from .terrain import Terrain


def check_views(plan: ApproachPlan, terrain: Terrain, rover_config: RoverConfig, surface_point_site,
                params: PredictParams, render: bool = True, target_normal_site=None) -> dict:
    """Fill each stop's shots with occlusion, incidence, texture and coverage figures; render nominal views.

    ``surface_point_site`` (3,): the target's point on the terrain surface; ``target_normal_site`` (3,) or None:
    the terrain's normal there (:meth:`Terrain.occluded`).
    Returns ``{(stop index, camera): RenderedView}`` of reduced-size views
    (``render_width_px`` wide) when ``render``.
    """
    X = np.asarray(surface_point_site, float)
    views = {}
    for st in plan.stops[1:]:
        for sh in st.cameras:
            if sh.uv is None:
                continue
            m_full = camera_model_at(rover_config, sh.camera, "left", sh.pan_rad, sh.tilt_rad, st.T_site_rover)
            C = m_full.C
            sh.occluded = bool(terrain.occluded(C[None], X[None], params.occlusion_tol_m, target_normal_site)[0])
            ray = (X - C) / np.linalg.norm(X - C)
            hit = terrain.cast(C[None], ray[None])
            if hit.hit[0]:
                n = hit.normals[0]
                sh.incidence_rad = float(math.acos(min(1.0, abs(float(np.dot(n, ray))))))
            # texture and coverage of the window the tracker will use
            k = sh.template_half_px
            c = np.round(np.asarray(sh.uv))
            win = terrain.render(m_full, 0, 0, roi=(int(c[0] - k), int(c[1] - k), 2 * k + 1, 2 * k + 1))
            vals = win.image[np.isfinite(win.image)]
            sh.coverage = win.coverage
            sh.texture_std = float(vals.std()) if vals.size > 8 else 0.0
            if render:
                spec = rover_config.spec(sh.camera, "left")
                s = params.render_width_px / spec.width
                ms = scaled_model(m_full, s)
                views[(st.index, sh.camera)] = terrain.render(ms, int(round(spec.width * s)), int(round(spec.height * s)))
    return views
