import numpy as np

from scipctl.core.camera import cahv_from_intrinsics
import pytest

from scipctl.core.expected import (
    antialiased_sample,
    bilinear_sample,
    drape,
    footprint_blur_cov,
    gaussian_blur_cov,
    map_jacobian,
    match_projection,
    nearest_projection,
    plane_points,
    splat_points,
)
from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix

W = H = 200
R_FWD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def cam(tilt_down, C, f=180.0):
    R = axis_angle_to_matrix([0, 1, 0], -tilt_down) @ R_FWD
    return cahv_from_intrinsics(f, f, (W - 1) / 2, (H - 1) / 2, RigidTransform(R, np.array(C, float)))


def texture(X):
    return 0.5 + 0.2 * np.sin(40 * X[..., 0]) * np.cos(33 * X[..., 1]) + 0.1 * np.sin(90 * X[..., 0] + 70 * X[..., 1])


def ground_points(step=0.002, extent=((0.6, 2.4), (-1.0, 1.0))):
    xs = np.arange(*extent[0], step)
    ys = np.arange(*extent[1], step)
    X, Y = np.meshgrid(xs, ys)
    return np.stack([X, Y, np.zeros_like(X)], -1).reshape(-1, 3)


def ray_ground(model, uv):
    o, d = model.unproject(uv)
    t = -o[..., 2] / d[..., 2]
    return o + t[..., None] * d


def test_splat_matches_direct_rendering_of_a_plane():
    m = cam(np.radians(45), [0.5, 0.0, -0.5])
    P = ground_points()
    res = splat_points(P, texture(P), m, W, H)
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    truth = texture(ray_ground(m, np.stack([u, v], -1)))
    c = (slice(60, 140), slice(60, 140))
    assert np.isfinite(res.image[c]).all()
    # each pixel takes a point within half a pixel-footprint: error bounded by the texture slope times 1-2 mm
    # (|grad texture| is at most 18.4 /m over the patch, sampled; 22 /m bounds it from the amplitudes and frequencies;
    # times the 1.4 mm half-diagonal of the 2 mm grid: 0.026-0.031, a bound on the worst pixel, so the median's bound
    # needs no margin of its own). Measured median 0.0019 on OpenCV 5.0 and 4.14, 1 and 2 threads (numpy only)
    assert np.nanmedian(np.abs(res.image[c] - truth[c])) < 0.03
    # the patch covers the whole view (the image's corners land at x 0.64-2.24 m, |y| < 0.9 m, inside 0.6-2.4 x
    # +-1 m) at 2 mm, finer than the smallest pixel footprint (2.3 mm, bottom rows): every pixel is filled. Measured
    # 1.0 (OpenCV 5.0 and 4.14, 1 and 2 threads); bound 0.95 leaves 5 % for border rounding (was 0.5, which let half
    # the view go empty)
    assert res.filled_fraction > 0.95


def test_splat_nearest_point_wins_and_see_through_is_removed():
    m = cam(np.radians(45), [0.5, 0.0, -0.5])
    ground = ground_points(step=0.003)
    # a raised square (10 cm above ground) in front, with a hole in the middle
    xs, ys = np.meshgrid(np.arange(1.0, 1.3, 0.002), np.arange(-0.15, 0.15, 0.002))
    top = np.stack([xs, ys, np.full_like(xs, -0.1)], -1).reshape(-1, 3)
    hole = (np.abs(top[:, 0] - 1.15) < 0.006) & (np.abs(top[:, 1]) < 0.006)
    top = top[~hole]
    P = np.concatenate([ground, top])
    I = np.concatenate([np.zeros(len(ground)), np.ones(len(top))])
    res = splat_points(P, I, m, W, H, fill_holes_px=0)
    uv_centre = m.project(np.array([[1.15, 0.0, -0.1]]))[0]
    i, j = np.round(uv_centre).astype(int)
    # the ground seen through the small hole is rejected, never shown as ground (0)
    patch = res.image[j - 1:j + 2, i - 1:i + 2]
    assert not np.any(patch == 0.0)
    assert res.see_through_removed > 0
    # with hole filling, the hole takes the surrounding top intensity
    res2 = splat_points(P, I, m, W, H, fill_holes_px=2)
    assert np.allclose(res2.image[j - 1:j + 2, i - 1:i + 2], 1.0)


def test_splat_roi_is_a_window_of_the_full_image():
    m = cam(np.radians(45), [0.5, 0.0, -0.5])
    P = ground_points()
    full = splat_points(P, texture(P), m, W, H)
    win = splat_points(P, texture(P), m, W, H, roi=(70, 80, 40, 30))
    assert np.allclose(win.image, full.image[80:110, 70:110], equal_nan=True)


def test_drape_and_bilinear_sample():
    m = cam(np.radians(45), [0.5, 0.0, -0.5])
    img = np.add.outer(np.arange(H, dtype=np.float32), 2 * np.arange(W, dtype=np.float32))  # value = v + 2u
    uv = np.array([[10.25, 20.5], [150.0, 3.75], [-3.0, 5.0]])
    vals = bilinear_sample(img, uv)
    assert np.allclose(vals[:2], uv[:2, 1] + 2 * uv[:2, 0])
    assert np.isnan(vals[2])
    X = ray_ground(m, uv[:2])
    # float64 ray-plane-projection round trip (~1e-12 px, times the image's slope 2.2 per px) sampled from a float32
    # image whose values reach 600 (ulp 6e-5): 1e-3 is ~16 float32 ulps there. Measured 0.0 (OpenCV 5.0 and 4.14, 1
    # and 2 threads)
    assert np.allclose(drape(X, m, img), uv[:2, 1] + 2 * uv[:2, 0], atol=1e-3)


def test_bilinear_sample_checks_its_shapes():
    img = np.zeros((H, W), np.float32)
    # (N, 3) points for (N, 2) pixels were sampled at their first two columns, silently
    with pytest.raises(ValueError, match=r"uv: expected pixels of shape \(\.\.\., 2\)"):
        bilinear_sample(img, np.zeros((4, 3)))
    with pytest.raises(ValueError, match="single-channel"):
        bilinear_sample(np.zeros((H, W, 3)), np.zeros((4, 2)))
    assert bilinear_sample(img, np.zeros((2, 5, 2))).shape == (2, 5)


def test_nearest_projection_is_subpixel_exact_on_a_plane():
    haz = cam(np.radians(45), [0.5, 0.0, -0.5])
    nav = cam(np.radians(60), [0.3, 0.1, -1.5], f=250.0)
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    xyz = ray_ground(haz, np.stack([u, v], -1))
    rng = np.random.default_rng(0)
    for _ in range(10):
        uv_h = rng.uniform(40, 160, 2)
        X = ray_ground(haz, uv_h[None])[0]
        goal = nav.project(X[None])[0]
        res = nearest_projection(xyz, (0, 0), nav, goal)
        # exact on a plane up to the sub-pixel solver's convergence: measured 0.0009 px (numpy only, session 36)
        assert np.linalg.norm(res.uv - uv_h) < 0.01
        # the best grid pixel is within half a pixel's diagonal (0.71 px) of the point, plus 0.2 px for the
        # nav-distance ordering of neighbours not being the hazcam-distance ordering; measured 0.62 px
        assert np.linalg.norm(res.uv_integer - uv_h) <= np.sqrt(2) * 0.5 + 0.2
    # a window of the map gives the same answer in full-image pixels
    X = ray_ground(haz, np.array([[100.3, 90.7]]))[0]
    res = nearest_projection(xyz[60:130, 50:150], (50, 60), nav, nav.project(X[None])[0])
    assert np.linalg.norm(res.uv - [100.3, 90.7]) < 0.01


def test_soft_zbuffer_blends_the_nearest_surface_and_beats_nearest_only():
    m = cam(np.radians(45), [0.5, 0.0, -0.5])
    P = ground_points(step=0.003)
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    truth = texture(ray_ground(m, np.stack([u, v], -1)))
    c = (slice(60, 140), slice(60, 140))
    errs = {}
    for soft in (0.0, 0.01):
        res = splat_points(P, texture(P), m, W, H, soft_depth_ratio=soft)
        errs[soft] = float(np.nanmedian(np.abs(res.image[c] - truth[c])))
    # measured ratio 0.082 (OpenCV 5.0 and 4.14, 1 and 2 threads; numpy only, seed-free): bound 0.7 (8.5x margin),
    # the claim being only that the soft z-buffer is clearly better
    assert errs[0.01] < 0.7 * errs[0.0], errs
    # a far surface behind the near one does not leak into the blend
    back = P + np.array([0.0, 0.0, 0.3])  # 30 cm below the ground, hidden
    both = np.concatenate([P, back])
    vals = np.concatenate([texture(P), np.full(len(back), 5.0)])
    res = splat_points(both, vals, m, W, H, soft_depth_ratio=0.01)
    # the texture is at most 0.5 + 0.2 + 0.1 = 0.8 by construction; the hidden surface's 5.0 blended in with weight w
    # lifts a pixel by 4.2 w, so 0.801 catches any w > 2.4e-4 (float32 image: 0.8 is stored as 0.80000001).
    # Measured 0.795 on OpenCV 5.0 and 4.14, 1 and 2 threads (was < 1.5, which let w reach 0.17)
    assert np.nanmax(res.image[c]) < 0.801


def _fd_jacobian(haz, nav, uv, h=1.0):
    cols = []
    for d in (np.array([h, 0.0]), np.array([0.0, h])):
        a = nav.project(ray_ground(haz, (uv + d)[None]))[0]
        b = nav.project(ray_ground(haz, (uv - d)[None]))[0]
        cols.append((a - b) / (2 * h))
    return np.stack(cols, axis=1)


def test_match_projection_converges_to_the_exact_pixel_with_an_approximate_jacobian():
    haz = cam(np.radians(45), [0.5, 0.0, -0.5])
    nav = cam(np.radians(60), [0.3, 0.1, -1.5], f=250.0)
    rng = np.random.default_rng(1)
    for _ in range(5):
        uv_true = rng.uniform(50, 150, 2)
        goal = nav.project(ray_ground(haz, uv_true[None]))[0]
        J = _fd_jacobian(haz, nav, uv_true)
        J_approx = J @ np.array([[1.2, 0.1], [-0.1, 0.85]])  # 10-20 % wrong, as a noisy dense map gives
        uv0 = uv_true + rng.uniform(-2.5, 2.5, 2)
        m = match_projection(lambda p: ray_ground(haz, p[None])[0], nav, goal, uv0, J_approx, max_iterations=12,
                             tol_px=1e-4)
        assert m is not None and m.converged
        # converged: the last step was under tol_px (1e-4 px), and with J 10-20 % off each step contracts the error
        # by ~0.3 or better, so what is left is under tol_px; the residual is J (norm ~1 here) times it. Measured at
        # most 2.0e-5 px (pixel) and 1.1e-5 px (residual) over the 5 draws, OpenCV 5.0 and 4.14, 1 and 2 threads
        # (numpy only): bound tol_px, 5x and 9x margins (was 1e-3)
        assert np.linalg.norm(m.uv - uv_true) < 1e-4
        assert m.residual_px < 1e-4
        # the returned point is the map's point at the returned pixel
        assert np.allclose(m.xyz, ray_ground(haz, m.uv[None])[0])


def test_match_projection_without_a_point_and_bad_jacobian():
    haz = cam(np.radians(45), [0.5, 0.0, -0.5])
    nav = cam(np.radians(60), [0.3, 0.1, -1.5], f=250.0)
    assert match_projection(lambda p: None, nav, [100.0, 100.0], [100.0, 100.0], np.eye(2)) is None
    with pytest.raises(ValueError):
        match_projection(lambda p: ray_ground(haz, p[None])[0], nav, [100.0, 100.0], [100.0, 100.0],
                         np.zeros((2, 2)))


def test_footprint_blur_cov():
    # source twice as fine as the destination: (4 - 1) / 12 px^2 per axis
    assert np.allclose(footprint_blur_cov(2 * np.eye(2)), 0.25 * np.eye(2))
    # source coarser: nothing to blur
    assert np.allclose(footprint_blur_cov(0.5 * np.eye(2)), 0.0)
    # one axis finer, one coarser, rotated: blur only along the finer axis, rotated with it
    a = np.radians(30)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    cov = footprint_blur_cov(R @ np.diag([2.0, 0.5]))
    assert np.allclose(cov, R @ np.diag([0.25, 0.0]) @ R.T)


def test_gaussian_blur_cov_has_the_requested_moments():
    img = np.zeros((61, 61), np.float32)
    img[30, 30] = 1.0
    cov = np.array([[4.0, 1.5], [1.5, 2.0]])
    out = gaussian_blur_cov(img, cov)
    # the kernel is normalised; float32 sums over 61 x 61 pixels: ~1e-6 relative. Measured exactly 1.0 (OpenCV 5.0 and
    # 4.14, 1 and 2 threads)
    assert out.sum() == pytest.approx(1.0, rel=1e-4)
    v, u = np.mgrid[0:61, 0:61] - 30.0
    m = np.array([[np.sum(out * u * u), np.sum(out * u * v)], [np.sum(out * u * v), np.sum(out * v * v)]])
    # the kernel's discretisation and its 1e-4 px^2 floor: measured at most 0.0093 px^2 off (OpenCV 5.0 and 4.14, 1
    # and 2 threads); bound 0.05 px^2 (5x margin), 1-2.5 % of the requested moments
    assert np.allclose(m, cov, atol=0.05)
    assert gaussian_blur_cov(img, np.zeros((2, 2))) is not None
    assert np.array_equal(gaussian_blur_cov(img, np.zeros((2, 2))), img)


def test_plane_points_lie_on_the_plane_and_project_back():
    haz = cam(np.radians(45), [0.5, 0.0, -0.5])
    X0 = np.array([1.2, 0.1, -0.05])
    n = np.array([0.2, -0.1, 1.0])
    n /= np.linalg.norm(n)
    uv = np.array([[100.0, 100.0], [30.5, 170.25], [150.0, 60.0]])
    P = plane_points(haz, uv, X0, n)
    # float64 round-off: measured 7e-17 m off the plane and 5.7e-14 px in the round trip (OpenCV 5.0 and 4.14, 1 and
    # 2 threads; numpy only). Bounds 1e-9 m and 1e-9 px: round-off on 1 m and 200 px scales (2e-16 relative) with a
    # conditioning margin of ~1e4 (the pixel bound was 1e-6)
    assert np.allclose((P - X0) @ n, 0.0, atol=1e-9)
    assert np.allclose(haz.project(P), uv, atol=1e-9)
    # a plane behind the camera is never hit
    assert np.all(np.isnan(plane_points(haz, uv, haz.C - 5 * haz.A, haz.A)))


@pytest.mark.parametrize("name", ["CAHV", "CAHVOR", "CAHVORE1", "CAHVORE3", "CAHVORE3-neg"])
def test_splat_roi_cone_prefilter_changes_nothing(name):
    """Dropping the points outside the window's cone before projecting gives the same window, for every model
    kind (non-central CAHVORE included), points from 0.2 m to 5 m, some behind the camera."""
    from tests.models import HEIGHT as MH, WIDTH as MW, all_models

    m = all_models()[name]
    rng = np.random.default_rng(3)
    for roi in [(500, 500, 31, 31), (3, 990, 31, 31), (700, 100, 61, 41)]:
        # dense around the window (40 px beyond it), sparse over the whole image, a few anywhere around the camera
        uv = np.concatenate([rng.uniform([roi[0] - 40, roi[1] - 40], [roi[0] + roi[2] + 40, roi[1] + roi[3] + 40],
                                         size=(40000, 2)), rng.uniform(0, [MW, MH], size=(20000, 2))])
        o, d = m.unproject(uv)
        r = rng.uniform(0.2, 5.0, size=len(d))
        P = np.concatenate([o + r[:, None] * d, m.C + rng.normal(scale=2.0, size=(2000, 3))])
        I = rng.uniform(0, 1, size=len(P))
        a = splat_points(P, I, m, MW, MH, roi=roi)
        b = splat_points(P, I, m, MW, MH, roi=roi, cone_margin_rad=None)
        assert np.isfinite(a.image).sum() > 100
        assert np.array_equal(a.image, b.image, equal_nan=True) and np.array_equal(a.depth_m, b.depth_m, equal_nan=True)
        assert a.filled_fraction == b.filled_fraction and a.see_through_removed == b.see_through_removed


@pytest.mark.parametrize("name", ["CAHV", "CAHVOR", "CAHVORE1", "CAHVORE3"])
def test_projection_map_regions_equal_the_whole_map(name):
    """A region projected on its own equals the same slice of the whole map's projection, bit for bit (every
    model kind, holes included), and the nearest-projection answer does not depend on whether the whole map
    was projected first."""
    from tests.models import HEIGHT as MH, WIDTH as MW, all_models

    from scipctl.core.expected import ProjectionMap, project_map

    m = all_models()[name]
    rng = np.random.default_rng(5)
    # a 300 x 400 point map: a tilted, bumpy surface 0.8-3 m away seen through the model, 10 % holes
    u, v = np.meshgrid(np.linspace(50, MW - 50, 400), np.linspace(50, MH - 50, 300))
    o, d = m.unproject(np.stack([u, v], -1).reshape(-1, 2))
    r = 0.8 + 2.2 * (v.ravel() / MH) + 0.05 * np.sin(u.ravel() / 17.0)
    xyz = (o + r[:, None] * d).reshape(300, 400, 3)
    xyz[rng.uniform(size=(300, 400)) < 0.1] = np.nan
    full = project_map(xyz, m)
    lazy = ProjectionMap(xyz, m)
    for rows, cols in [(slice(None, None, 8), slice(None, None, 8)), (slice(17, 66), slice(300, 400)),
                       (slice(0, 3), slice(398, 400)), (slice(150, 151), slice(7, 8))]:
        assert np.array_equal(lazy.region(rows, cols), full[rows, cols], equal_nan=True)
    for goal in rng.uniform([60, 60], [MW - 60, MH - 60], size=(8, 2)):
        a = nearest_projection(xyz, (0, 0), m, goal)
        b = nearest_projection(xyz, (0, 0), m, goal, proj=full)
        c = nearest_projection(xyz, (0, 0), m, goal, proj=lazy)
        # the 10 % holes leave the goal's nearest map point up to a few pixels away: measured 0.15-2.66 px over the 32
        # goals (OpenCV 5.0 and 4.14, 1 and 2 threads; numpy only); bound 10 px (3.75x margin)
        assert a is not None and a.distance_px < 10.0
        for x in (b, c):
            assert np.array_equal(a.uv, x.uv) and a.distance_px == x.distance_px
            assert np.array_equal(a.xyz, x.xyz)


def test_nearest_projection_finds_points_off_the_search_lattice():
    """A sparse map whose valid pixels all miss the 8-pixel search lattice still gives the nearest point."""
    haz = cam(np.radians(45), [0.5, 0.0, -0.5])
    nav = cam(np.radians(60), [0.3, 0.1, -1.5], f=250.0)
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    xyz = ray_ground(haz, np.stack([u, v], -1))
    sparse = np.full_like(xyz, np.nan)
    sparse[3::8, 5::8] = xyz[3::8, 5::8]  # never on rows/columns that are multiples of 8
    res = nearest_projection(sparse, (0, 0), nav, nav.project(xyz[99, 101][None])[0])
    assert res is not None and np.array_equal(res.uv_integer, [101.0, 99.0]) and res.distance_px < 1e-9
    assert nearest_projection(np.full_like(xyz, np.nan), (0, 0), nav, [100.0, 100.0]) is None


def test_map_jacobian_of_an_affine_map_is_exact_and_needs_nine_known_pixels():
    """d(q)/d(pixel) of q = A (u, v) + b is A (column 0: d/du) whatever the holes; None when fewer than 9 interior
    pixels have both differences."""
    A = np.array([[1.7, -0.4], [0.3, 2.6]])
    us, vs = np.meshgrid(np.arange(12.0), np.arange(9.0))
    q = np.stack([us, vs], -1) @ A.T + [5.0, -3.0]
    assert np.allclose(map_jacobian(q), A, atol=1e-12)
    q[2:5, 3:7] = np.nan
    assert np.allclose(map_jacobian(q), A, atol=1e-12)
    q[:, 3:] = np.nan
    assert map_jacobian(q) is None


def test_antialiased_sample_is_a_gaussian_blur_then_bilinear_sample():
    """Against scipy: for A = 2 I (a source twice as fine) the footprint blur is 0.25 px^2 per axis; the same blur by
    scipy.ndimage.gaussian_filter (sigma 0.5, the same 3 px radius, borders 'nearest' as cv2's replicate) then
    linear interpolation (map_coordinates, order 1). Bound 1e-3 on values in [0, 1]: gaussian_blur_cov keeps the
    kernel invertible with a 1e-4 px^2 floor (sigma^2 0.2501 instead of 0.25: < 1e-4 relative on each weight) and
    works in float32 (~1e-7)."""
    from scipy.ndimage import gaussian_filter, map_coordinates

    rng = np.random.default_rng(7)
    img = rng.random((60, 70)).astype(np.float32)
    q = np.stack(np.meshgrid(np.linspace(4.3, 62.9, 9), np.linspace(3.1, 55.7, 7)), -1)
    A = 2.0 * np.eye(2)
    got = antialiased_sample(img, q, A)
    ref = map_coordinates(gaussian_filter(img.astype(float), 0.5, mode="nearest", truncate=6.0),
                          [q[..., 1].ravel(), q[..., 0].ravel()], order=1).reshape(q.shape[:-1])
    assert got.shape == q.shape[:-1] and got.dtype == np.float32
    assert np.max(np.abs(got - ref)) < 1e-3


def test_antialiased_sample_of_a_coarser_source_is_the_bilinear_sample_and_keeps_holes():
    """No blur where the source is the coarser (footprint_blur_cov is 0): the bilinear samples bit for bit; a sample
    at a non-finite pixel is NaN; a q that is not (..., 2) is refused."""
    rng = np.random.default_rng(8)
    img = rng.random((40, 50)).astype(np.float32)
    q = rng.uniform([2, 2], [47, 37], (5, 6, 2))
    q[1, 2] = np.nan
    got = antialiased_sample(img, q, 0.6 * np.eye(2))
    ok = np.all(np.isfinite(q), axis=-1)
    assert np.isnan(got[1, 2]) and np.isfinite(got[ok]).all()
    assert np.array_equal(got[ok], np.asarray(bilinear_sample(img, q[ok]), np.float32))
    with pytest.raises(ValueError, match="q"):
        antialiased_sample(img, q[..., :1], np.eye(2))


def test_antialiased_sample_renders_a_coarser_camera_closer_than_point_samples():
    """An exact scene: a destination camera whose pixel covers 2.5 x 2.5 source pixels sees their box average
    (cv2.resize INTER_AREA of a white-noise source by 2.5 exactly: 5 x 5 source pixels per 2 x 2 destination
    pixels). At the destination pixels' centres the anti-aliased samples are nearer that image than bilinear point
    samples are. Measured RMS 0.040 against 0.129 (the source's own spread is 0.289, seed 9): bound half the point
    samples' RMS (the measured ratio is 0.31)."""
    import cv2

    rng = np.random.default_rng(9)
    src = rng.random((250, 250)).astype(np.float32)
    dst = cv2.resize(src, (100, 100), interpolation=cv2.INTER_AREA)
    j, i = np.meshgrid(np.arange(100.0), np.arange(100.0))
    q = np.stack([(j + 0.5) * 2.5 - 0.5, (i + 0.5) * 2.5 - 0.5], -1)  # destination centres in source pixels
    A = 2.5 * np.eye(2)
    inner = (slice(3, -3), slice(3, -3))
    aa = antialiased_sample(src, q, A)[inner]
    point = np.asarray(bilinear_sample(src, q.reshape(-1, 2)), np.float32).reshape(100, 100)[inner]
    rms_aa = float(np.sqrt(np.mean((aa - dst[inner]) ** 2)))
    rms_point = float(np.sqrt(np.mean((point - dst[inner]) ** 2)))
    assert rms_aa < 0.5 * rms_point
