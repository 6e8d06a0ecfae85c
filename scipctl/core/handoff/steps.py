"""Steps several handoff methods share: the target's 3-D point from the navcams, projection into and NCC
tracking in the hazcam-left image (pure numerics)."""

from __future__ import annotations

from typing import Optional

import numpy as np

from ..camera import CameraModel
from ..expected import bilinear_sample
from .case import HandoffCase
from .result import NoAnswer, f


def nav_point(case: HandoffCase, nav_uv):
    """Navcam point stereo at ``nav_uv`` (2,) (cached by the case); :class:`NoAnswer` when it fails."""
    ps = case.point_stereo(nav_uv)
    if not ps.ok:
        raise NoAnswer(f"navcam point stereo: {ps.reason}", {"stereo_score": f(getattr(ps, "score", np.nan))})
    return ps


def dense_point(case: HandoffCase, nav_uv) -> np.ndarray:
    """Navcam dense-stereo point ``(3,)`` (navcam rover frame) at ``nav_uv`` (2,); :class:`NoAnswer` when none."""
    X = case.nav.xyz_at(np.asarray(nav_uv, float)[None])[0]
    if not np.all(np.isfinite(X)):
        raise NoAnswer("no dense-stereo range at the navcam target")
    return X


def project_haz(case: HandoffCase, X_haz) -> np.ndarray:
    """Hazcam-left pixel ``(2,)`` of the point ``X_haz`` (3,) (hazcam rover frame); NaN where it does not project."""
    return case.haz.left_model.project(np.asarray(X_haz, float).reshape(1, 3))[0]


def track(case: HandoffCase, template, start_uv, radius_px, min_score, template_center_uv=None):
    """NCC-track ``template`` (h, w) in the hazcam-left image within ``radius_px`` of ``start_uv`` (2,)
    (:func:`~scipctl.core.tracking.track`)."""
    from ..tracking import track as _track

    return _track(template, case.haz.left_img, start_uv, radius_px, template_center_uv=template_center_uv,
                  min_score=min_score)


def search_reaches_image(start_uv, radius_px: float, width: int, height: int) -> bool:
    """Whether the square search region of half-width ``radius_px`` around ``start_uv`` (2,) (as
    :func:`~scipctl.core.tracking.track` searches) meets the ``width`` x ``height`` image at all."""
    u, v = (float(x) for x in np.asarray(start_uv, float).reshape(2))
    r = float(radius_px)
    return bool(-r <= u <= width - 1 + r and -r <= v <= height - 1 + r)


def local_ifov_rad(model: CameraModel, uv) -> float:
    """Angle subtended by one pixel at ``uv`` (geometric mean of the u and v directions), rad.

    At the image centre this is ``~1/hs``; off-centre in a fish-eye it differs,
    which matters when a window is scaled from one camera to another.
    """
    uv = np.asarray(uv, float).reshape(2)
    pts = np.array([uv - [0.5, 0], uv + [0.5, 0], uv - [0, 0.5], uv + [0, 0.5]])
    _, d = model.unproject(pts)
    a_u = np.arccos(np.clip(np.dot(d[0], d[1]), -1, 1))
    a_v = np.arccos(np.clip(np.dot(d[2], d[3]), -1, 1))
    return float(np.sqrt(a_u * a_v))


def interp_xyz(xyz: np.ndarray, uv) -> Optional[np.ndarray]:
    """Bilinear point ``(3,)`` of a point grid ``xyz`` (h, w, 3) at grid pixel ``uv`` (2,); None if not finite."""
    out = np.array([bilinear_sample(xyz[..., k], np.asarray(uv, float)[None])[0] for k in range(3)])
    return out if np.all(np.isfinite(out)) else None
