import numpy as np
import pytest

from scipctl.core.rectify import linearize, rectify_pair
from tests.models import HEIGHT, WIDTH, pixel_grid, stereo_pair


def _points_in_view(left, n=400, seed=0, rmin=0.8, rmax=20.0):
    rng = np.random.default_rng(seed)
    uv = np.stack([rng.uniform(100, WIDTH - 100, n), rng.uniform(100, HEIGHT - 100, n)], -1)
    o, d = left.unproject(uv)
    return o + rng.uniform(rmin, rmax, n)[:, None] * d


@pytest.mark.parametrize("kind", ["CAHV", "CAHVOR", "CAHVORE"])
def test_rectified_rows_agree(kind):
    left, right = stereo_pair(kind, baseline_m=0.1 if kind == "CAHVORE" else 0.2)
    rp = rectify_pair(left, right, WIDTH, HEIGHT)
    P = _points_in_view(left)
    uvl = rp.left_model.project(P)
    uvr = rp.right_model.project(P)
    # both rectified models are linear CAHV sharing A, H, V, the baseline along H: the rows agree up to float
    # rounding (measured 3.4e-13 to 4.5e-13 px, points within 20 m and |uv| ~ 1e3 px)
    assert np.abs(uvl[:, 1] - uvr[:, 1]).max() < 1e-9
    disp = uvl[:, 0] - uvr[:, 0]
    assert np.all(disp > 0)
    # disparity gives depth along A: f B / d
    depth = (P - left.C) @ rp.left_model.A
    assert np.allclose(rp.disparity_to_depth(disp), depth, rtol=1e-9)
    # shared image plane
    assert np.allclose(rp.left_model.A, rp.right_model.A)
    assert np.allclose(rp.left_model.H, rp.right_model.H)
    assert abs(np.dot(rp.left_model.A, right.C - left.C)) < 1e-12


@pytest.mark.parametrize("kind", ["CAHV", "CAHVOR", "CAHVORE"])
def test_maps_sample_the_right_original_pixels(kind):
    left, right = stereo_pair(kind, baseline_m=0.1 if kind == "CAHVORE" else 0.2)
    rp = rectify_pair(left, right, WIDTH, HEIGHT, ref_range_m=2.0)
    # points at the reference range: the maps are exact there for every model kind
    uv = pixel_grid(15, margin=150)
    o, d = left.unproject(uv)
    P = o + 2.0 * d
    for model_o, model_r, maps in ((left, rp.left_model, rp.map_left), (right, rp.right_model, rp.map_right)):
        uv_rect = model_r.project(P)
        inside = (uv_rect[:, 0] > 1) & (uv_rect[:, 0] < rp.width - 2) & (uv_rect[:, 1] > 1) & (uv_rect[:, 1] < rp.height - 2)
        assert inside.mean() > 0.9
        uvr, uvo = uv_rect[inside], model_o.project(P[inside])
        # bilinear look-up of the maps at the rectified pixel
        iu, iv = np.floor(uvr[:, 0]).astype(int), np.floor(uvr[:, 1]).astype(int)
        fu, fv = uvr[:, 0] - iu, uvr[:, 1] - iv
        got = []
        for m in maps:
            got.append((1 - fu) * (1 - fv) * m[iv, iu] + fu * (1 - fv) * m[iv, iu + 1]
                       + (1 - fu) * fv * m[iv + 1, iu] + fu * fv * m[iv + 1, iu + 1])
        got = np.stack(got, -1)
        assert np.abs(got - uvo).max() < 0.02  # float32 maps + bilinear interpolation of a smooth map


def test_rectified_pair_round_trip_through_pixels():
    left, right = stereo_pair("CAHVOR")
    rp = rectify_pair(left, right, WIDTH, HEIGHT)
    uv = pixel_grid(11, margin=200)
    back = rp.unrectify_left_uv(rp.left_uv_to_rect(uv))
    assert np.abs(back - uv).max() < 1e-6


def test_rectified_image_content_is_row_aligned():
    """Render a textured plane through both original models, rectify, and check rows match."""
    import cv2

    left, right = stereo_pair("CAHVOR", misalign_rad=0.0)
    rp = rectify_pair(left, right, WIDTH, HEIGHT)

    # a plane 3 m in front of the left camera, perpendicular to its axis; texture = smooth function of the 3-D point
    n = left.A
    p0 = left.C + 3.0 * n

    def render(model):
        u, v = np.meshgrid(np.arange(WIDTH, dtype=float), np.arange(HEIGHT, dtype=float))
        o, d = model.unproject(np.stack([u, v], -1).reshape(-1, 2))
        t = ((p0 - o) @ n) / (d @ n)
        X = o + t[:, None] * d
        val = 0.5 + 0.25 * np.sin(X @ np.array([37.0, 11.0, 5.0])) + 0.25 * np.cos(X @ np.array([-7.0, 29.0, 13.0]))
        return (val.reshape(HEIGHT, WIDTH) * 255).astype(np.float32)

    L = rp.rectify_left(render(left))
    R = rp.rectify_right(render(right))
    # at 3 m along A the disparity is constant: f B / 3; shift the right image and compare a central block
    disp = rp.focal_px * rp.baseline_m / ((p0 - left.C) @ rp.left_model.A)
    M = np.float32([[1, 0, disp], [0, 1, 0]])
    R_shift = cv2.warpAffine(R, M, (rp.width, rp.height), flags=cv2.INTER_CUBIC)
    c = slice(300, 700)
    err = np.abs(L[c, c] - R_shift[c, c])
    assert np.median(err) < 1.0  # grey levels out of 255


def test_linearize_keeps_centre_and_axis():
    from tests.models import cahvore

    m = cahvore()
    lin = linearize(m, WIDTH, HEIGHT)
    assert lin.kind == "CAHV"
    assert np.allclose(lin.A, m.A)
    # the linear model covers the field without magnifying beyond the centre resolution
    assert lin.hs <= 0.5 * (m.hs + m.vs) + 1e-9
    P = m.C + 5.0 * m.A
    assert np.allclose(lin.project(P[None])[0], [lin.hc, lin.vc], atol=1e-9)  # the axis is the linear centre
    # which sits off the image centre by the inner box's asymmetry (the model's distortion is not symmetric about
    # A): measured (3.95, 5.05) px for this model (numpy only, no build dependence); bound 2x
    assert np.all(np.abs(np.array([lin.hc, lin.vc]) - np.array([511.5, 511.5])) < 10.0)


@pytest.mark.parametrize("kind", ["CAHVOR", "CAHVORE"])
def test_interpolated_maps_match_exact_maps_everywhere(kind):
    left, right = stereo_pair(kind, baseline_m=0.1)
    rp = rectify_pair(left, right, WIDTH, HEIGHT, ref_range_m=2.0)
    u, v = np.meshgrid(np.arange(rp.width, dtype=float), np.arange(rp.height, dtype=float))
    o, d = rp.left_model.unproject(np.stack([u, v], -1).reshape(-1, 2))
    exact = left.project(o + 2.0 * d)
    got = np.stack([rp.map_left[0].ravel(), rp.map_left[1].ravel()], -1)
    inside = np.all((exact > 0) & (exact < WIDTH - 1), axis=-1) & (got[:, 0] > -1e5)
    assert inside.mean() > 0.95
    assert np.abs(got[inside] - exact[inside]).max() < 1e-3


def test_cached_rectification_is_the_same_and_keyed_on_the_models():
    from scipctl.core.rectify import rectify_pair_cached

    left, right = stereo_pair("CAHVOR")
    a = rectify_pair_cached(left, right, WIDTH, HEIGHT, scale=0.5)
    b = rectify_pair_cached(left, right, WIDTH, HEIGHT, scale=0.5)
    assert a is b
    fresh = rectify_pair(left, right, WIDTH, HEIGHT, scale=0.5)
    assert fresh.left_model.almost_equal(a.left_model) and np.array_equal(fresh.map_left[0], a.map_left[0])
    _, right2 = stereo_pair("CAHVOR", baseline_m=0.25)
    c = rectify_pair_cached(left, right2, WIDTH, HEIGHT, scale=0.5)
    assert c is not a and abs(c.baseline_m - 0.25) < 1e-12


def test_sampling_map_marks_pixels_near_rays_the_source_cannot_see():
    """Where some lattice rays of the destination point behind the source camera, the map is -1e6 for every
    pixel those nodes' cubic weights reach and exact elsewhere; with none, nothing is marked."""
    from scipctl.core.rectify import _sampling_map
    from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix

    left, _ = stereo_pair("CAHV", baseline_m=0.2)
    mu, mv = _sampling_map(left, left, WIDTH, HEIGHT, 2.0)
    u, v = np.meshgrid(np.arange(WIDTH, dtype=np.float32), np.arange(HEIGHT, dtype=np.float32))
    assert np.abs(mu - u).max() < 1e-3 and np.abs(mv - v).max() < 1e-3  # the identity map, nothing marked
    # a source camera rotated 90 degrees about the destination's v axis (its A along the destination's h):
    # the destination's rays on the left-hand side of the image point behind it
    R = axis_angle_to_matrix(left.v_axis, np.radians(90.0))
    src = left.transformed(RigidTransform(R, left.C - R @ left.C))  # turned about its own centre
    mu, mv = _sampling_map(src, left, WIDTH, HEIGHT, 2.0)
    o, d = left.unproject(np.stack([u, v], -1).reshape(-1, 2))
    ahead = (d @ src.A > 0).reshape(HEIGHT, WIDTH)
    marked = mu == -1e6
    assert marked.any() and (~marked).any()
    assert np.array_equal(marked, mv == -1e6)
    assert not np.any(marked & ahead & (np.arange(WIDTH)[None, :] > WIDTH / 2 + 40))  # far from the edge: exact
    assert np.all(marked[~ahead])  # every pixel whose own ray is behind the source is marked
