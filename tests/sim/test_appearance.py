"""Procedural albedo (scipctl/sim/appearance.py)."""

import numpy as np

from scipctl.sim.appearance import MAT_ROCK, MAT_TERRAIN


def test_albedo_is_a_function_of_the_point_only(run_exact):
    sc = run_exact.scene
    rng = np.random.default_rng(1)
    P = np.concatenate([rng.uniform(-2, 2, (500, 2)), rng.uniform(-0.1, 0.1, (500, 1))], 1)
    mat = np.where(rng.random(500) < 0.5, MAT_TERRAIN, MAT_ROCK).astype(np.int8)
    sc_ = np.ones(500, np.float32)
    a = sc.appearance.albedo(P, mat, sc_, None)
    perm = rng.permutation(500)
    b = sc.appearance.albedo(P[perm], mat[perm], sc_[perm], None)
    assert np.array_equal(a[perm], b)  # independent of batch order / composition
    assert np.array_equal(sc.appearance.albedo(P[:7], mat[:7], sc_[:7], None), a[:7])
    assert 0.02 <= a.min() and a.max() <= 0.98 and a.std() > 0.03
    # rock and soil have different statistics
    assert abs(a[mat == MAT_ROCK].mean() - a[mat == MAT_TERRAIN].mean()) > 0.03
