"""Shared check of simulated downlinks: every mark is the exact projection of its true target (test helper)."""

import numpy as np


def count_exact_marks(dl, scene) -> int:
    """Assert each mark of ``dl`` is its true target projected through the true pose and model (1e-6 px) and that
    the true ray through it hits ``scene`` at the target (1 mm); returns how many marks were checked."""
    n = 0
    for tm in dl.targets:
        X = dl.truth_target(tm.id).xyz_site_m
        for m in tm.marks:
            tr = dl.truth_for(m.product_id)
            uv = tr.camera_model.project(tr.pose.T_site_rover.inverse().apply(X[None]))[0]
            assert np.hypot(uv[0] - m.u, uv[1] - m.v) < 1e-6, (tm.id, m.product_id)
            o, d = tr.camera_model.transformed(tr.pose.T_site_rover).unproject(np.array([[m.u, m.v]]))
            assert np.linalg.norm(scene.cast(o, d).points[0] - X) < 1e-3, (tm.id, m.product_id)
            n += 1
    return n
