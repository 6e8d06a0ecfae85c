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
