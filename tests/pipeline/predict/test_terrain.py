"""scipctl.pipeline.predict.terrain (and geometry): meshing, smoothing, rendering, casting, ground and rocks, on exact truth."""

import math

import numpy as np

from scipctl.core.camera import cahv_from_intrinsics
from scipctl.core.transforms import RigidTransform
from scipctl.pipeline import predict as P
from tests.pipeline import scene as S
from tests.pipeline.predict.helpers import box_fn, heightfield_source


def _pinhole_grid(h, w, ranges):
    m = cahv_from_intrinsics(100.0, 100.0, (w - 1) / 2, (h - 1) / 2, RigidTransform.identity())
    us, vs = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    o, d = m.unproject(np.stack([us, vs], -1).reshape(-1, 2))
    return (o + ranges.reshape(-1, 1) * d).reshape(h, w, 3)


def test_grid_mesh_keeps_a_surface_and_drops_a_depth_step():
    h, w = 12, 16
    smooth = _pinhole_grid(h, w, np.full((h, w), 5.0))
    v, t, used = P.grid_mesh(smooth, np.zeros(3))
    assert len(t) == 2 * (h - 1) * (w - 1) and len(v) == h * w
    step = np.full((h, w), 5.0)
    step[:, w // 2:] = 8.0  # a depth discontinuity between columns w/2 - 1 and w/2
    _, t2, _ = P.grid_mesh(_pinhole_grid(h, w, step), np.zeros(3))
    assert len(t2) == 2 * (h - 1) * (w - 1) - 2 * (h - 1)
    holes = _pinhole_grid(h, w, np.full((h, w), 5.0))
    holes[3, 4] = np.nan  # one invalid vertex removes the 6 triangles that use it
    v3, t3, used3 = P.grid_mesh(holes, np.zeros(3))
    assert len(t3) == 2 * (h - 1) * (w - 1) - 6
    # the kept vertices: each grid vertex some triangle uses, once, in grid order, and nothing else
    assert np.all(np.diff(used3) > 0) and len(used3) == h * w - 1 and 3 * w + 4 not in used3
    assert np.array_equal(np.unique(t3), np.arange(len(used3)))
    assert np.array_equal(v3, holes.reshape(-1, 3)[used3])


def test_smooth_grid_reduces_range_noise_and_keeps_steps():
    rng = np.random.default_rng(1)
    h, w = 40, 40
    r = np.full((h, w), 5.0)
    r[:, 20:] = 8.0
    noisy = r + rng.normal(0, 0.02, r.shape)
    g = _pinhole_grid(h, w, noisy)
    sm = P.smooth_grid(g, np.zeros(3), sigma_px=1.5, max_rel=0.03)
    rs = np.linalg.norm(sm, axis=2)
    inner = np.s_[5:-5, 5:15]
    # a 2-D Gaussian of sigma 1.5 px takes white noise's std down by 1 / (2 sqrt(pi) sigma) = 0.188; measured 0.179
    # (OpenCV 5.0 and 4.14, 1 and 2 threads; numpy only), bound 0.5 (2.7x the model)
    assert np.std(rs[inner] - 5.0) < 0.5 * np.std(noisy[inner] - 5.0)
    # no point is pulled across the 3 m step: measured at most 0.016 m off (the noise left, 0.02 m std before
    # smoothing), the same on all four; bound 0.1 m (6x, and 3 % of the step)
    assert np.all(np.abs(rs - r) < 0.1)
    # points only move along their own rays: the unit directions agree to float rounding (measured 2.2e-16, 1-2
    # ulp, on OpenCV 5.0 and 4.14, 1 and 2 threads); 1e-12 is a float-identity tolerance
    d0 = g / np.linalg.norm(g, axis=2, keepdims=True)
    d1 = sm / np.linalg.norm(sm, axis=2, keepdims=True)
    assert np.max(np.abs(d0 - d1)) < 1e-12


def test_render_through_the_source_camera_gives_the_source_image_back():
    world, dl = S.cached("rock")
    src = [s for s in S.oracle_sources(world, dl, cameras=("pancam",), step=1)]
    ter = P.Terrain(src, smooth_sigma_px=0)
    s = ter.sources[0]
    view = ter.render(s.left_model_site, S.SIZE, S.SIZE)
    ok = np.isfinite(view.image)
    # Through the source's own camera every pixel's ray runs exactly through its grid point, a vertex of the mesh.
    # What comes back is the kept mesh (grid_mesh drops the triangles across depth steps), nothing else: no pixel
    # rendered whose grid point is in no kept triangle (exact; measured none on OpenCV 5.0 and 4.14, 1 and 2 threads).
    # (This replaces "ok.mean() > 0.8", measured 0.8093: a figure of the scene with 1 % to spare, not a rule.)
    V, T, vidx = P.grid_mesh(s.xyz_site, s.centre_site)
    h, w = ok.shape
    incident = np.bincount(vidx[T].ravel(), minlength=h * w).reshape(h, w)  # kept triangles at each grid point
    assert not np.any(ok & (incident == 0))
    # A grid point inside the kept mesh (all 6 of its triangles kept) is hit unless the ray, passing exactly
    # through the shared vertex, slips between its triangles in Open3D's float32 intersection test (not watertight
    # at vertices; a ray of another camera almost never passes through one): measured 523 of 53121 such points
    # missed (0.98 %), the same on OpenCV 5.0 and 4.14, 1 and 2 threads, Open3D 0.20; bound 2 % (2x)
    inner = incident == 6
    assert inner.sum() > 0.5 * h * w  # a precondition, not a bound: the check covers most of the view (81 %)
    assert np.count_nonzero(inner & ~ok) < 0.02 * inner.sum()
    # the source's own pixels come back: measured exactly 0 on all four. The images are float32 in [0, 1] (8-bit
    # levels 3.9e-3 apart): 1e-3 is a quarter of a grey level, not a measured margin
    assert np.max(np.abs(view.image[ok] - s.left_img[ok])) < 1e-3
    # and depth equals the distance to the true surface along each ray
    us, vs = np.meshgrid(np.arange(S.SIZE, dtype=float), np.arange(S.SIZE, dtype=float))
    o, d = s.left_model_site.unproject(np.stack([us, vs], -1).reshape(-1, 2))
    t = world.cast(o, d).reshape(S.SIZE, S.SIZE)
    good = ok & np.isfinite(t) & (t < 30)
    # the depth map is float32: measured median 4.8e-7 m, one float32 ulp at 4-8 m (OpenCV 5.0 and 4.14, 1 and 2
    # threads). Bound 1e-5 m, 5 ulps at the 30 m cut-off (was 0.01 m, 20000x the measurement)
    assert np.median(np.abs(view.depth_m[good] - t[good])) < 1e-5


def test_cast_hits_a_plane_at_the_exact_distance(flat_terrain):
    o = np.array([[1.0, 0.5, -2.0], [3.0, -1.0, -1.5], [7.2, 2.2, -0.3]])
    d = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.6, 0.8]])
    hits = flat_terrain.cast(o, d)
    assert hits.hit.all()
    # the caster works in float32 relative to the mesh's mean vertex ((6, 0, 0) here; these rays run 1-6 m from
    # it, a float32 ulp there is 1.2e-7-4.8e-7 m): measured 1.19e-7 m in both t and z, identical on OpenCV 5.0 and
    # 4.14, 1 and 2 threads. Bound 1e-5 m, ~20 ulps at 4-8 m, as the rendered depth's in
    # test_render_through_the_source_camera_gives_the_source_image_back (was atol 1e-4 + rtol 1e-5, 840x)
    assert np.allclose(hits.t_m, -o[:, 2] / d[:, 2], rtol=0, atol=1e-5)
    assert np.allclose(hits.points[:, 2], 0.0, rtol=0, atol=1e-5)
    # a flat mesh's triangle normals are exactly vertical (measured exactly 1 on all four): a float-identity bound
    assert np.allclose(np.abs(hits.normals[:, 2]), 1.0, atol=1e-6)
    miss = flat_terrain.cast(np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, -1.0]]))
    assert not miss.hit[0] and not np.isfinite(miss.t_m[0])


def _same_hits(a, b, normals=True):
    fields = ("hit", "t_m", "source", "points") + (("normals",) if normals else ())
    for f in fields:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f


def test_cast_of_a_batch_equals_the_cast_of_its_finite_rays(flat_terrain):
    """A batch with non-finite rays (the scatter path) gives, ray for ray, the very values the all-finite batch of
    its finite rays gives (the direct path), misses included; ``normals=False`` changes only the normals."""
    o = np.array([[1.0, 0.5, -2.0], [np.nan, 0.0, -1.0], [3.0, -1.0, -1.5], [0.0, 0.0, -1.0], [7.2, 2.2, -0.3]])
    d = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.0, -1.0], [0.0, np.inf, 0.8]])
    d = d / np.linalg.norm(np.where(np.isfinite(d), d, 1.0), axis=1, keepdims=True)
    mixed = flat_terrain.cast(o, d)
    keep = [0, 2, 3]
    finite = flat_terrain.cast(o[keep], d[keep])
    assert finite.hit.tolist() == [True, True, False] and mixed.hit.tolist() == [True, False, True, False, False]
    for f in ("hit", "t_m", "source", "points", "normals"):
        x, y = getattr(mixed, f)[keep], getattr(finite, f)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f
    assert np.all(np.isnan(mixed.points[[1, 3, 4]])) and np.all(mixed.source[[1, 3, 4]] == -1)
    assert np.all(np.isinf(mixed.t_m[[1, 3, 4]]))
    for oo, dd in ((o, d), (o[keep], d[keep])):
        bare = flat_terrain.cast(oo, dd, normals=False)
        _same_hits(bare, flat_terrain.cast(oo, dd), normals=False)
        assert np.all(np.isnan(bare.normals))
    empty = flat_terrain.cast(np.zeros((0, 3)), np.zeros((0, 3)))
    assert empty.hit.shape == (0,) and empty.points.shape == (0, 3)


def test_rock_cells_find_the_tall_box_and_not_the_low_one():
    tall = (2.0, 0.0, 2.5, 0.5, 0.30)
    low = (4.0, 1.0, 4.3, 1.3, 0.08)
    ter = P.Terrain([heightfield_source(box_fn([tall, low]))], smooth_sigma_px=0)
    cells = ter.rock_cells(cell_m=0.05, ground_window_m=1.0, min_height_m=0.15)
    assert len(cells) > 0
    x0, y0, x1, y1, _ = tall
    # design: a 0.05 m cell whose centre is within one cell of the box may count; the centres found measured at
    # least 0.025 m (half a cell) inside it on OpenCV 5.0 and 4.14, 1 and 2 threads
    inside = (cells[:, 0] > x0 - 0.06) & (cells[:, 0] < x1 + 0.06) & (cells[:, 1] > y0 - 0.06) & (cells[:, 1] < y1 + 0.06)
    assert inside.all()
    # the whole top is found (all cells whose centre is inside the box): 10 x 10 cells, a count, not a tolerance
    # (measured exactly 100, the bound itself, on all four: deterministic)
    assert len(cells) >= int(round((x1 - x0) / 0.05)) * int(round((y1 - y0) / 0.05))
    assert not np.any((cells[:, 0] > 3.9) & (cells[:, 0] < 4.4) & (cells[:, 1] > 0.9) & (cells[:, 1] < 1.4))


def test_ground_plane_and_pose_on_plane_recover_a_tilted_slope():
    a, b, c = 0.1, -0.05, 0.2
    ter = P.Terrain([heightfield_source(lambda X, Y: -(a * X + b * Y + c))], smooth_sigma_px=0)
    guess = P.pose_on_plane([5.0, 0.5], 0.3, (0.0, 0.0, 0.0))
    body = P.RoverBody()
    plane, n, frac = ter.ground_plane(guess, body)
    # the footprint lies on known terrain: measured frac 1.0 (0.9 asks that almost all of it is known)
    assert plane is not None and frac > 0.9
    # a least-squares plane through exact plane points: float rounding only (measured 6.4e-16, identical on OpenCV
    # 5.0 and 4.14, 1 and 2 threads); 1e-6 (+ allclose's rtol 1e-5) is a float-identity tolerance, as are the
    # 1e-9 and 1e-12 below (measured 2.8e-17 normal, 5.6e-16 m height, 0 tilt, 4.4e-16 orthonormality)
    assert np.allclose(plane, (a, b, c), atol=1e-6)
    T = P.pose_on_plane([5.0, 0.5], 0.3, plane)
    normal_down = np.array([-a, -b, 1.0]) / np.linalg.norm([-a, -b, 1.0])
    assert np.allclose(T.R[:, 2], normal_down, atol=1e-9)
    assert abs(T.t[2] - (a * 5.0 + b * 0.5 + c)) < 1e-9
    # heading kept: the body x axis is the heading projected onto the plane, whose horizontal direction turns by
    # a second-order term, at most |grad z|^2 / 2 = 0.00625 rad here; measured 0.0062 rad (the closed form's value
    # at yaw 0.3, identical on all four). 0.01 rad is 1.6x it
    assert abs(math.atan2(T.R[1, 0], T.R[0, 0]) - 0.3) < 0.01
    assert abs(P.tilt_of(T) - math.acos(normal_down[2])) < 1e-12
    assert np.allclose(T.R.T @ T.R, np.eye(3), atol=1e-12) and np.linalg.det(T.R) > 0


def test_the_targets_own_surface_at_grazing_incidence_does_not_occlude_it_and_a_wall_does():
    """Flat ground with a 1 cm bump 10 cm in front of the target, seen from 15 cm above the ground 2 m away
    (incidence ~86 deg): the ray meets the bump first, so without the target's normal the target counts as
    occluded; the bump lies within ``tol_m`` of the target's tangent plane, so with the normal it does not. A
    30 cm mound halfway is an occluder either way (the ray meets it 6 cm or more off the plane)."""
    def bump(X, Y):
        return 0.01 * np.exp(-((X - 4.9) ** 2) / (2 * 0.03 ** 2))

    def bump_and_mound(X, Y):
        return np.maximum(bump(X, Y), 0.3 * np.exp(-((X - 4.1) ** 2) / (2 * 0.1 ** 2)))

    X = np.array([[5.0, 0.0, 0.0]])
    o = np.array([[3.0, 0.0, -0.15]])  # site z is down: 15 cm above the ground
    up = np.array([0.0, 0.0, -1.0])
    ter = P.Terrain([heightfield_source(bump, x=(2.0, 6.0), y=(-1.0, 1.0), step=0.01)], smooth_sigma_px=0)
    assert ter.occluded(o, X, 0.04)[0]
    assert not ter.occluded(o, X, 0.04, target_normal=up)[0]
    assert not ter.occluded(o, X, 0.04, target_normal=-up)[0]  # either sign
    walled = P.Terrain([heightfield_source(bump_and_mound, x=(2.0, 6.0), y=(-1.0, 1.0), step=0.01)], smooth_sigma_px=0)
    assert walled.occluded(o, X, 0.04)[0] and walled.occluded(o, X, 0.04, target_normal=up)[0]
    assert ter.occluded(o, X, 0.04, target_normal=np.full(3, np.nan))[0]  # no normal known: as before
