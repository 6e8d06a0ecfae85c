"""The terrain's height field and graded grid (scipctl/sim/terrain.py)."""

import numpy as np

from scipctl.sim.terrain import graded_axis, grid_mesh, random_height_field


def test_height_field_gradient_graded_axis_and_grid_mesh():
    f = random_height_field(np.random.default_rng(5))
    g = random_height_field(np.random.default_rng(5))
    assert np.array_equal(f.wavevectors, g.wavevectors)
    xy = np.random.default_rng(0).uniform(-3, 3, (200, 2))
    h, grad = f.height_and_gradient(xy)
    eps = 1e-6
    fd = np.stack([(f.height_m(xy + [eps, 0]) - f.height_m(xy - [eps, 0])) / (2 * eps),
                   (f.height_m(xy + [0, eps]) - f.height_m(xy - [0, eps])) / (2 * eps)], 1)
    # central differences' rounding: x + eps off by up to 2.2e-16 (|x| <= 3) over 2 eps = 1e-6 is 2.2e-10 of |grad|
    # <= 0.2, and a few ulps of |h| <= 0.36 m over 1e-6; measured max 1.3e-10 (numpy only; the same on OpenCV 5.0 and
    # 4.14, 1 and 2 threads). Bound 5e-10 absolute (3.9x the worst; was atol 1e-7 plus allclose's default rtol 1e-5,
    # 2e-6 at |grad| 0.2: 16000x)
    assert np.allclose(grad, fd, rtol=0, atol=5e-10)
    ax = graded_axis()
    # measured at most 4.3e-16 off 0.02 (half an ulp at 4 m) on all four; allclose's default 2e-7 m, unchanged: the
    # spacing's check, not an error bound
    assert np.allclose(np.diff(ax[np.abs(ax) <= 4.0]), 0.02)
    assert np.all(np.diff(ax) > 0) and ax[-1] == 150.0 and ax[0] == -150.0
    xyg, tris, sp = grid_mesh(ax[:5], ax[:4])
    assert len(xyg) == 20 and len(tris) == 2 * 4 * 3


def test_terrain_kinds_share_one_signature_and_draw_reproducibly():
    from scipctl.sim.terrain import TERRAIN_KINDS

    xy = np.random.default_rng(1).uniform(-4, 4, (500, 2))
    for name, make in TERRAIN_KINDS.items():
        a, b = make(np.random.default_rng(9)), make(np.random.default_rng(9))
        assert a.params.check() == b.params
        h, g = a.field.height_and_gradient(xy)
        assert h.shape == (500,) and g.shape == (500, 2) and np.array_equal(h, b.field.height_m(xy)), name
        # centimetre-to-decimetre relief near the rock, not cliffs: measured 0.43 m (rolling, pebble-field,
        # rock-strewn), 0.23 m (sand-sheet), 0.11 m (bedrock-slabs), the same on OpenCV 5.0 and 4.14, 1 and 2 threads
        # (numpy only, seeded); bound 0.5 m unchanged (the terrain's design, not an error bound)
        assert np.abs(h).max() < 0.5, name


def test_slab_field_is_continuous_with_steps_and_cracks_and_its_gradient_is_the_slope():
    from scipctl.sim.terrain import bedrock_slabs

    f = bedrock_slabs(np.random.default_rng(2)).field
    # a dense transect crosses several plate borders: the height is continuous (no jump over 0.5 mm steps of
    # 0.5 mm: the steepest part of a blended 3 cm step over 5 cm, or of a 2 cm crack over 3 cm, is < 1.2 slope)
    t = np.arange(0.0, 8.0, 0.0005)
    line = np.stack([t - 4.0, 0.3 * t - 1.0], 1)
    h = f.height_m(line)
    # measured max 0.32 mm per 0.5 mm step (slope 0.64) on all four (numpy only); bound 0.75 mm unchanged (the
    # slope-1.2 model above, 0.6 mm, plus 25 %)
    assert np.abs(np.diff(h)).max() < 0.0005 * 1.5
    # cracks are there: an 8.4 m transect over ~1.6 m plates crosses at least 3 (exposure < 1: dust; a crack's
    # strength is the product of two U(0.15, 1) draws, so some are faint), and most of it is bare plate
    e = f.exposure(line)
    crossings = np.count_nonzero(np.diff((e < 0.999).astype(int)) == 1)
    # measured 7 crossings and 88 % bare on all four (seeded, numpy only); bounds unchanged (the design's counts)
    assert crossings >= 3 and np.mean(e == 1.0) > 0.5
    # the gradient agrees with finite differences of the height (1 mm central differences inside; 0.1 mm here)
    xy = np.random.default_rng(0).uniform(-3, 3, (300, 2))
    g = f.gradient(xy)
    eps = 1e-4
    fd = np.stack([(f.height_m(xy + [eps, 0]) - f.height_m(xy - [eps, 0])) / (2 * eps),
                   (f.height_m(xy + [0, eps]) - f.height_m(xy - [0, eps])) / (2 * eps)], 1)
    # the smoothstep's curvature over 1 mm: measured max 0.0041 on OpenCV 5.0 and 4.14, 1 and 2 threads (numpy only;
    # this comment said 0.01 before); bound 0.012 (2.9x the worst; was 0.02)
    assert np.abs(g - fd).max() < 0.012


def test_grid_values_interpolate_as_the_mesh_triangles():
    from scipctl.sim.terrain import GridValues

    ax = graded_axis(1.0, 0.1, 5.0, 1.3, 1.0)
    xy, _, _ = grid_mesh(ax, ax)
    lin = 0.3 + 2.0 * xy[:, 0] - 0.7 * xy[:, 1]  # linear: reproduced exactly on every triangle
    gv = GridValues(ax, lin)
    q = np.random.default_rng(1).uniform(-5, 5, (1000, 2))
    # float32 output, values up to 14 in magnitude: half an ulp at 8-16 is 4.8e-7; measured max 4.7e-7 on all four
    # (numpy only). Bound 2e-6 absolute, two float32 ulps there (4.2x; was atol 1e-5 plus allclose's rtol 1e-5,
    # 1.5e-4 at 14)
    assert np.allclose(gv(q), 0.3 + 2.0 * q[:, 0] - 0.7 * q[:, 1], rtol=0, atol=2e-6)
    assert np.array_equal(gv(xy), lin.astype(np.float32))
