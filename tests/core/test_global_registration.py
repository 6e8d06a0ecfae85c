"""scipctl/core/global_registration.py: FPFH + seeded RANSAC finds a transform far outside ICP's reach, and gives
the same bits twice and whatever Open3D's thread count."""

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scipctl.core.global_registration import (GlobalRegistrationParams, global_registration, kabsch,
                                              mutual_matches, ransac_rigid)
from scipctl.core.transforms import RigidTransform, rotvec_to_matrix
from tests.core.clouds import CAMERA_M as CAMERA
from tests.core.clouds import far_pair, flat

PROBES = np.array([[1.5, 0.3, -0.2], [2.0, 0.0, 0.0], [3.0, 1.0, 0.0], [0.6, -1.4, 0.0]])
# 40 deg of yaw and 0.7 m: ICP from the identity cannot reach this (its correspondences are a few cm long)
ROTVEC_FAR, T_FAR_M = [0.02, -0.01, 0.7], [0.6, -0.4, 0.05]
T_FAR = RigidTransform(rotvec_to_matrix(ROTVEC_FAR), T_FAR_M)


def _pair(seed_source=1):
    return far_pair(T_FAR, seed_source)


def test_kabsch_is_exact_and_proper():
    rng = np.random.default_rng(0)
    R = rotvec_to_matrix([0.3, -1.2, 2.0])
    P = rng.normal(size=(5, 4, 3))
    Q = P @ R.T + np.array([1.0, -2.0, 0.5])
    R_est, t_est = kabsch(P, Q)
    np.testing.assert_allclose(R_est, np.broadcast_to(R, (5, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(t_est, np.broadcast_to([1.0, -2.0, 0.5], (5, 3)), atol=1e-12)
    mirrored = P * np.array([1.0, 1.0, -1.0])  # a reflection is not a rotation: the best proper one is returned
    R_m, _ = kabsch(P, mirrored)
    np.testing.assert_allclose(np.linalg.det(R_m), 1.0, atol=1e-12)


def test_ransac_finds_the_transform_among_outliers():
    rng = np.random.default_rng(1)
    A = rng.uniform(-1, 1, size=(400, 3))
    T = RigidTransform(rotvec_to_matrix([0.1, 0.5, -0.3]), [0.2, 0.1, -0.4])
    B = T.apply(A)
    bad = rng.permutation(400)[:300]  # 75 % wrong matches
    B[bad] = rng.uniform(-1, 1, size=(300, 3))
    M, inl = ransac_rigid(A, B, GlobalRegistrationParams())
    good = np.setdiff1d(np.arange(400), bad)
    assert inl[good].all() and inl.sum() < 110  # every true match, and few chance ones (0.09 m within 2 m cubes)
    np.testing.assert_allclose(M, T.matrix, atol=1e-9)  # refitted on exact inliers: exact


def test_mutual_matches_are_symmetric():
    rng = np.random.default_rng(2)
    fa = rng.normal(size=(50, 33))
    fb = np.concatenate([fa[::-1] + 1e-3, rng.normal(size=(10, 33))])
    si, ti = mutual_matches(fa, fb)
    np.testing.assert_array_equal(si, np.arange(50))
    np.testing.assert_array_equal(ti, 49 - np.arange(50))


def test_global_registration_recovers_a_transform_icp_cannot_reach():
    tgt, src, cam = _pair()
    g = global_registration(src, cam, tgt, CAMERA)
    err = np.linalg.norm(g.T_target_source.apply(T_FAR.inverse().apply(PROBES)) - PROBES, axis=1)
    # measured 1.2-4.3 mm over four source samplings (seeds 1-4); 1 cm is a third of ICP's finest reach
    assert err.max() < 0.01, err
    assert g.n_inliers >= GlobalRegistrationParams().min_inliers and 0 < g.inlier_fraction <= 1


def test_a_prior_radius_keeps_only_matches_the_seed_can_reach():
    tgt, src, cam = _pair()
    near_seed = RigidTransform(rotvec_to_matrix([0.0, 0.0, 0.05]), [0.05, 0.0, 0.0]) @ T_FAR
    g = global_registration(src, cam, tgt, CAMERA, prior=(near_seed, 0.3))
    free = global_registration(src, cam, tgt, CAMERA)
    assert g.n_matches < free.n_matches
    err = np.linalg.norm(g.T_target_source.apply(T_FAR.inverse().apply(PROBES)) - PROBES, axis=1)
    assert err.max() < 0.01, err
    with pytest.raises(ValueError, match="prior radius"):
        global_registration(src, cam, tgt, CAMERA, prior=(near_seed, 0.0))


def test_no_answer_without_matches():
    """A prior window no match falls in (the seed 50 m off) leaves no matches: no answer, not a guess."""
    g = global_registration(flat(1), CAMERA, flat(0), CAMERA, prior=(RigidTransform(np.eye(3), [50.0, 0, 0]), 0.1))
    assert g.T_target_source is None and g.n_matches == 0 and g.n_inliers == 0 and g.inlier_fraction == 0.0


def test_params_check_names_the_bad_parameter():
    for change, name in (({"voxel_m": 0.0}, "voxel_m"), ({"samples": 0}, "samples"),
                         ({"edge_ratio": 1.0}, "edge_ratio"), ({"min_inliers": 2}, "min_inliers"),
                         ({"seed": -1}, "seed"), ({"inlier_voxels": float("nan")}, "inlier_voxels")):
        with pytest.raises(ValueError, match=rf"GlobalRegistrationParams\.{name} "):
            GlobalRegistrationParams(**change).check()


_SCRIPT = f"""
import hashlib
from scipctl.core.global_registration import global_registration
from scipctl.core.transforms import RigidTransform, rotvec_to_matrix
from tests.core.clouds import CAMERA_M, far_pair
tgt, src, cam = far_pair(RigidTransform(rotvec_to_matrix({ROTVEC_FAR}), {T_FAR_M}))
g = global_registration(src, cam, tgt, CAMERA_M)
print(hashlib.sha256(g.T_target_source.matrix.tobytes()).hexdigest(), g.n_matches, g.n_inliers)
"""


def test_same_bits_twice_and_with_any_thread_count():
    """Open3D computes normals and FPFH in OpenMP threads and its own RANSAC draws from a shared generator in
    parallel; here only per-point work is threaded and the RANSAC is numpy's, seeded: the answer is the same bits
    in one process, and in processes with one and two OpenMP threads."""
    tgt, src, cam = _pair()
    a = global_registration(src, cam, tgt, CAMERA)
    b = global_registration(src, cam, tgt, CAMERA)
    assert a.T_target_source.matrix.tobytes() == b.T_target_source.matrix.tobytes()
    here = hashlib.sha256(a.T_target_source.matrix.tobytes()).hexdigest()
    root = Path(__file__).resolve().parents[2]
    outs = []
    for threads in ("1", "2"):
        env = dict(os.environ, OMP_NUM_THREADS=threads, PYTHONPATH=str(root))
        outs.append(subprocess.run([sys.executable, "-c", _SCRIPT], env=env, cwd=root, capture_output=True,
                                   text=True, check=True).stdout.split())
    assert outs[0] == outs[1] == [here, str(a.n_matches), str(a.n_inliers)]
