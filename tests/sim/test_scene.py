"""Scene geometry, procedural appearance and ray casting."""

import numpy as np
import pytest

from scipctl.sim.noise import FractalNoise, LatticeNoise, lod_weight
from scipctl.sim.scene import (
    GEOM_ROCKS, MAT_PEBBLE, MAT_ROCK, MAT_SKY, MAT_TERRAIN, graded_axis, grid_mesh, hull_mesh, random_height_field,
)


def test_lattice_noise_is_periodic_continuous_and_seeded():
    a = LatticeNoise(np.random.default_rng(4), 32)
    b = LatticeNoise(np.random.default_rng(4), 32)
    q = np.random.default_rng(0).uniform(-100, 100, (5000, 3))
    va = a(q)
    assert np.array_equal(va, b(q))
    assert va.min() >= 0 and va.max() <= 1 and va.std() > 0.1
    assert np.allclose(a(q + np.array([32.0, -64.0, 96.0])), va, atol=2e-3)  # period n (float32 rounding only)
    step = a(q + 1e-3) - va
    assert np.abs(step).max() < 0.02  # continuous: 1/1000 of a cell changes the value a little
    # lattice points carry the lattice values (bilinear/quintic interpolation is exact there)
    c = LatticeNoise(np.random.default_rng(9), 16)
    assert not np.allclose(c(q[:50]), a(q[:50]))


def test_fractal_noise_fades_octaves_finer_than_the_footprint():
    lat = LatticeNoise(np.random.default_rng(1), 32)
    f = FractalNoise(lat, np.random.default_rng(2), [0.002, 0.2], [1.0, 1.0])
    P = np.random.default_rng(3).uniform(-1, 1, (4000, 3))
    full = f(P)
    coarse_only = f(P, np.full(len(P), 0.05))  # 5 cm footprint: the 2 mm octave is gone
    fine = FractalNoise(lat, np.random.default_rng(2), [0.002, 0.2], [1.0, 0.0])(P)
    assert np.allclose(full - fine, coarse_only, atol=1e-6)
    assert lod_weight(0.01, np.array([0.001, 0.01, 0.02, 0.1])).tolist() == [1.0, 0.5, 0.0, 0.0]


def test_height_field_grid_and_hull_meshes():
    f = random_height_field(np.random.default_rng(5))
    g = random_height_field(np.random.default_rng(5))
    assert np.array_equal(f.wavevectors, g.wavevectors)
    xy = np.random.default_rng(0).uniform(-3, 3, (200, 2))
    h, grad = f.height_and_gradient(xy)
    eps = 1e-6
    fd = np.stack([(f.height_m(xy + [eps, 0]) - f.height_m(xy - [eps, 0])) / (2 * eps),
                   (f.height_m(xy + [0, eps]) - f.height_m(xy - [0, eps])) / (2 * eps)], 1)
    assert np.allclose(grad, fd, atol=1e-7)
    ax = graded_axis()
    assert np.allclose(np.diff(ax[np.abs(ax) <= 4.0]), 0.02)
    assert np.all(np.diff(ax) > 0) and ax[-1] == 150.0 and ax[0] == -150.0
    xyg, tris, sp = grid_mesh(ax[:5], ax[:4])
    assert len(xyg) == 20 and len(tris) == 2 * 4 * 3
    V, F, corners, sharp = hull_mesh(np.random.default_rng(6), 20, 2)
    # closed, outward-oriented: positive volume, every edge used twice (once per direction)
    vol = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6
    assert vol > 0
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    assert len({tuple(x) for x in e.tolist()}) == len(e)
    assert len({tuple(sorted(x)) for x in e.tolist()}) == len(e) // 2
    assert np.all(sharp > 0) and len(corners) == len(sharp)


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
