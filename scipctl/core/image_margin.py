"""How far points sit inside both images of a body-fixed stereo pair (pure numerics): the hazcam field-of-view
margin that the planner searches on, the ``hazcam-fov-final`` flight rule checks and the Mars 2020 rules
derivation maps (one function for the three)."""

from __future__ import annotations

import numpy as np


def pair_margin_px(rover_config, camera: str, xyz_rover) -> np.ndarray:
    """``(N,)`` the smaller distance (px) of rover-frame points ``xyz_rover`` ``(N, 3)`` from the edges of
    ``camera``'s left and right images (models at zero mast angles: a body-fixed pair): negative outside an image,
    ``-inf`` where a point does not project into an eye (behind it) or the rover has no such camera."""
    P = np.asarray(xyz_rover, float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"pair_margin_px: xyz_rover must be (N, 3), got {P.shape}")
    if camera not in rover_config.cameras:
        return np.full(len(P), -np.inf)
    out = np.full(len(P), np.inf)
    for eye in ("left", "right"):
        spec = rover_config.spec(camera, eye)
        uv = rover_config.camera_model(camera, eye, 0.0, 0.0).project(P)
        m = np.minimum.reduce([uv[:, 0], uv[:, 1], spec.width - 1 - uv[:, 0], spec.height - 1 - uv[:, 1]])
        out = np.minimum(out, np.where(np.all(np.isfinite(uv), axis=1), m, -np.inf))
    return out
