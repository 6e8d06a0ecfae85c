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


def _patch(n=40000, seed=2):
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.uniform(2.0, 2.5, (n, 2)), rng.uniform(-0.01, 0.0, (n, 1))], 1)


def test_filtered_specks_equal_todays_where_the_specks_are_resolved():
    """Appearance.specks = 'filtered' changes nothing where the footprint resolves the specks (at most 2/3 of the
    finest speck octave's cell: lod_weight 1 for every speck octave, before or after the threshold): bit for bit."""
    from dataclasses import replace

    from scipctl.sim.appearance import make_appearance

    app = make_appearance(np.random.default_rng(7), np.zeros((0, 3)))
    filt = replace(app, specks="filtered")
    P = _patch()
    for mat, cell in ((MAT_TERRAIN, app.spots.octaves[0].cell_m), (MAT_ROCK, app.rock_spots.octaves[0].cell_m)):
        m = np.full(len(P), mat, np.int8)
        fp = np.full(len(P), cell / 2, np.float32)  # lod_weight clamps to exactly 1 (2/3 would round either way)
        assert np.array_equal(app.albedo(P, m, np.ones(len(P), np.float32), fp),
                              filt.albedo(P, m, np.ones(len(P), np.float32), fp))


def test_filtered_specks_keep_their_cover_at_any_range_where_todays_vanish():
    """Today's specks are thresholded from the footprint-faded noise: from a footprint of ~2 speck cells on (7 mm
    for the soil: a 10 m pancam pixel on the ground) none is left, and the ground is brighter than near by.
    Filtered, they fade to their mean cover: the mean speck cover is the same at every footprint."""
    from dataclasses import replace

    from scipctl.sim.appearance import SOIL_SPECKS, make_appearance

    app = make_appearance(np.random.default_rng(7), np.zeros((0, 3)))
    filt = replace(app, specks="filtered")
    PT = np.ascontiguousarray(_patch().T, np.float32)
    near = np.full(PT.shape[1], 0.002, np.float32)  # 2 mm: resolved
    far = np.full(PT.shape[1], 0.02, np.float32)  # 2 cm: beyond 2 cells of the finest (6 mm) octave
    d_near, _ = app._specks(app.spots, SOIL_SPECKS, PT, near)
    d_far_lod, _ = app._specks(app.spots, SOIL_SPECKS, PT, far)
    d_far, b_far = filt._specks(filt.spots, SOIL_SPECKS, PT, far)
    mean_dark, mean_bright = filt._speck_cover(filt.spots, SOIL_SPECKS)
    assert d_near.mean() > 0.01 and d_far_lod.max() == 0.0  # today's: specks near by, none far away
    assert np.all(d_far == np.float32(mean_dark)) and np.all(b_far == np.float32(mean_bright))  # w = 0: the mean
    # the seeded estimate of the cover and this patch's cover agree to sampling error (2^16 and 4e4 points,
    # correlated within a 6 mm cell: the bound is ~5 standard errors of a 4 % cover over ~7000 cells)
    assert abs(d_near.mean() - mean_dark) < 0.012
