import numpy as np
import pytest

from scipctl.core.registration import register_clouds
from scipctl.core.transforms import RigidTransform, rotvec_to_matrix


def _terrain(seed=0, n=60000):
    """Rolling ground with a few rocks: structure in all three axes, so registration is well posed."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([0.5, -1.5], [3.5, 1.5], size=(n, 2))
    z = 0.05 * np.sin(2.1 * xy[:, 0]) * np.cos(1.7 * xy[:, 1]) + 0.02 * np.sin(7 * xy[:, 0] + 3 * xy[:, 1])
    for cx, cy, r in ((1.5, 0.3, 0.25), (2.4, -0.6, 0.35), (1.1, -0.9, 0.2), (3.0, 0.8, 0.3)):
        d2 = (xy[:, 0] - cx) ** 2 + (xy[:, 1] - cy) ** 2
        z = z - np.where(d2 < r * r, np.sqrt(np.maximum(r * r - d2, 0)) * 0.8, 0)
    return np.column_stack([xy, z])


@pytest.mark.parametrize("method", ["point-to-plane", "generalized"])
def test_icp_recovers_a_small_transform(method):
    tgt = _terrain(0)
    T_true = RigidTransform(rotvec_to_matrix([0.01, -0.015, 0.02]), [0.03, -0.02, 0.015])  # T_target_source
    src = T_true.inverse().apply(_terrain(1))  # a different sampling of the same surface
    res = register_clouds(src, tgt, RigidTransform.identity(), method=method)
    P = np.array([[1.5, 0.3, -0.2], [2.0, 0.0, 0.0]])
    err = np.linalg.norm(res.T_target_source.apply(P) - T_true.apply(P), axis=1).max()
    assert err < 0.003, f"{method}: residual {err * 1000:.2f} mm"
    assert res.fitness > 0.8
    assert res.correction_rad > 0.01


def test_icp_uses_the_seed_and_crop():
    tgt = _terrain(0)
    T_true = RigidTransform(rotvec_to_matrix([0.0, 0.0, 0.3]), [0.5, 0.2, 0.0])
    src = T_true.inverse().apply(_terrain(1))
    seed = RigidTransform(rotvec_to_matrix([0.0, 0.0, 0.29]), [0.49, 0.21, 0.0])
    res = register_clouds(src, tgt, seed, crop_center_m=[2.0, 0.0, 0.0], crop_radius_m=1.2)
    P = np.array([[2.0, 0.0, 0.0]])
    assert np.linalg.norm(res.T_target_source.apply(P) - T_true.apply(P)) < 0.003
    with pytest.raises(ValueError):
        register_clouds(src[:10], tgt, seed)


def test_a_perfect_seed_is_kept():
    """ICP on two samplings of one surface, seeded with the truth: it must not walk away (it cannot fit better)."""
    tgt = _terrain(0)
    T_true = RigidTransform(rotvec_to_matrix([0.01, -0.015, 0.02]), [0.03, -0.02, 0.015])
    src = T_true.inverse().apply(_terrain(1))
    res = register_clouds(src, tgt, T_true, scales_m=(0.32, 0.16, 0.08, 0.04, 0.02))
    P = np.array([[1.5, 0.3, -0.2], [2.0, 0.0, 0.0]])
    assert np.linalg.norm(res.T_target_source.apply(P) - T_true.apply(P), axis=1).max() < 0.002
    if res.kept_seed:
        assert res.correction_m == 0.0
