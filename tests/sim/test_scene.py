"""The assembled scene: content, ray casting, shading, ground height (scipctl/sim/scene.py)."""

import numpy as np
import pytest

from scipctl.sim.appearance import MAT_PEBBLE, MAT_ROCK, MAT_SKY, MAT_TERRAIN
from scipctl.sim.scene import GEOM_ROCKS


def test_scene_content(run_exact):
    sc = run_exact.scene
    rock = sc.target_rock
    assert rock.is_target and np.allclose(rock.centre_xy_m, 0)
    assert 0.45 <= rock.size_m[0] <= 0.7 and 0.2 <= rock.size_m[2] <= 0.4
    for r in sc.rocks[1:]:
        assert 0.15 <= max(r.size_m[:2]) <= 0.7
    assert sc.sun_dir_site[2] < -0.5  # sun well above the horizon (z down)
    assert len(sc.pebble_tris) > 0 and len(sc.appearance.sand_patches) >= 1


def test_ray_hits_lie_on_the_surfaces_and_carry_materials(run_exact):
    sc = run_exact.scene
    rng = np.random.default_rng(0)
    xy = rng.uniform(-3.5, 3.5, (3000, 2))
    o = np.concatenate([xy, np.full((len(xy), 1), -5.0)], 1)
    d = np.tile([0.0, 0.0, 1.0], (len(xy), 1))
    h = sc.cast(o, d)
    assert h.hit.all()
    ter = h.material == MAT_TERRAIN
    assert ter.mean() > 0.8 and np.any(h.material == MAT_PEBBLE)
    assert np.abs(-h.points[ter, 2] - sc.ground_height_m(xy[ter])).max() < 1e-5
    assert np.abs(-h.points[ter, 2] - sc.field.height_m(xy[ter])).max() < 2e-3  # mesh vs smooth field, 2 cm grid
    # rays looking up see the sky
    up = sc.cast(o, -d)
    assert not up.hit.any() and np.all(up.material == MAT_SKY)
    # the big rock is hit from above near the origin
    top = sc.cast(np.array([[0.0, 0.0, -5.0]]), np.array([[0.0, 0.0, 1.0]]))
    assert top.geometry_id[0] == GEOM_ROCKS and top.material[0] == MAT_ROCK
    assert -top.points[0, 2] - sc.ground_height_m([[0.0, 0.0]])[0] > 0.15
    # normals face the ray
    assert np.all(np.einsum("ij,ij->i", h.normal_geom, d) < 0)


def test_lambertian_shading_and_shadows(run_exact):
    sc = run_exact.scene
    rng = np.random.default_rng(2)
    xy = rng.uniform(-3, 3, (4000, 2))
    o = np.concatenate([xy, np.full((len(xy), 1), -5.0)], 1)
    d = np.tile([0.0, 0.0, 1.0], (len(xy), 1))
    h = sc.cast(o, d)
    L = sc.radiance(h, d, None, shadows=True)
    alb = sc.appearance.albedo(h.points, h.material, h.obj_scale, None)
    cos_s = np.clip(h.normal @ sc.sun_dir_site, 0, None)
    irr_lit = sc.ambient + (1 - sc.ambient) * cos_s / max(-sc.sun_dir_site[2], 0.3)
    lit = np.isclose(L, alb * irr_lit, rtol=1e-5)
    shadowed = np.isclose(L, alb * sc.ambient, rtol=1e-5)
    assert np.all(lit | shadowed)
    assert shadowed.mean() > 0.0005 and lit.mean() > 0.9
    # a shadowed point facing the sun really has something between it and the sun (the renderer starts shadow
    # rays 0.2 mm off the surface), and mostly at a distance: cast shadows, not self-shadowing "acne"
    i = np.flatnonzero(shadowed & (cos_s > 0.2))
    assert len(i) >= 10
    toward = sc.cast(h.points[i] + 2e-4 * h.normal_geom[i], np.tile(sc.sun_dir_site, (len(i), 1)))
    assert toward.hit.all()
    assert np.mean(toward.t_m > 0.005) > 0.7


@pytest.mark.parametrize("seed", [11])
def test_ground_height_is_the_mesh_height(seed, run_exact):
    sc = run_exact.scene
    ax = sc.terrain_axis_m
    n = len(ax)
    i, j = 200, 233
    v = sc.terrain_vertices()
    assert sc.ground_height_m([[ax[i], ax[j]]])[0] == pytest.approx(-v[i * n + j, 2], abs=1e-12)
    mid = [(ax[i] + ax[i + 1]) / 2, (ax[j] + ax[j + 1]) / 2]  # on the shared diagonal of the cell
    assert sc.ground_height_m([mid])[0] == pytest.approx(-(v[i * n + j, 2] + v[(i + 1) * n + j + 1, 2]) / 2, abs=1e-12)
    with pytest.raises(ValueError):
        sc.ground_height_m([[500.0, 0.0]])


def _box_scene(sun_elevation_deg: float, sun_azimuth_rad: float):
    """A synthetic scene with exact truth: level ground z = 0 (site, z down) on a 0.5 m grid and one box
    1 m high over x, y in [-0.5, 0.5], the sun at the given elevation and azimuth; no pebbles."""
    from scipctl.sim.appearance import make_appearance
    from scipctl.sim.rocks import Rock
    from scipctl.sim.scene import Scene
    from scipctl.sim.terrain import HeightField, grid_mesh

    flat = HeightField(np.zeros((1, 2)) + [1.0, 0.0], np.zeros(1), np.zeros(1))
    ax = np.arange(-10.0, 10.0 + 1e-9, 0.5)
    xy, tris, spacing = grid_mesh(ax, ax)
    c = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0.0, -1.0)])
    from scipy.spatial import ConvexHull

    F = ConvexHull(c).simplices.astype(np.int64)
    box = Rock("box", np.zeros(2), np.array([1.0, 1.0, 1.0]), c, F, np.arange(8), np.ones(8), 1.0, True)
    el, az = np.radians(sun_elevation_deg), sun_azimuth_rad
    sun = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    app = make_appearance(np.random.default_rng(0), np.zeros((0, 3)))
    return Scene(0, flat, ax, xy, tris, spacing, [box], np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.float32),
                 app, sun)


@pytest.mark.parametrize("el_deg", [12.0, 45.0, 80.0])
def test_a_point_whose_sun_ray_is_blocked_is_darker_than_the_same_albedo_lit(el_deg):
    # the sun stands towards +x (north): the box's shadow on level ground reaches from x = -0.5 to
    # x = -0.5 - 1 m / tan(elevation) along -x, for |y| < 0.5; points there see the box towards the sun.
    sc = _box_scene(el_deg, 0.0)
    L_shadow = 1.0 / np.tan(np.radians(el_deg))
    x_in = -0.5 - np.array([0.05, 0.5, 0.95]) * L_shadow  # inside the shadow
    x_out = -0.5 - np.array([1.05, 1.5]) * L_shadow  # beyond its tip
    pts = np.concatenate([np.stack([x_in, np.zeros(3)], 1), np.stack([x_out, np.zeros(2)], 1),
                          [[-0.75, 0.8], [2.0, 0.0]]])  # beside the shadow, and on the sunny side
    in_shadow = np.array([True, True, True, False, False, False, False])
    o = np.concatenate([pts, np.full((len(pts), 1), -3.0)], 1)
    d = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    h = sc.cast(o, d)
    assert h.hit.all() and np.abs(h.points[:, 2]).max() < 1e-6  # on the ground
    with_shadows = sc.radiance(h, d, None, shadows=True)
    without = sc.radiance(h, d, None, shadows=False)
    alb = sc.appearance.albedo(h.points, h.material, h.obj_scale, None)
    s = sc.sun_dir_site
    lit = alb * (sc.ambient + (1 - sc.ambient) * (-s[2]) / max(-s[2], 0.3))  # level ground: cos = -s_z
    np.testing.assert_allclose(without, lit, rtol=1e-5)
    np.testing.assert_allclose(with_shadows[in_shadow], alb[in_shadow] * sc.ambient, rtol=1e-5)
    np.testing.assert_allclose(with_shadows[~in_shadow], lit[~in_shadow], rtol=1e-5)
    assert np.all(with_shadows[in_shadow] < without[in_shadow])
