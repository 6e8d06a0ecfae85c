"""Lattice and fractal 3-D value noise (scipctl/sim/noise.py)."""

import numpy as np

from scipctl.sim.noise import FractalNoise, LatticeNoise, lod_weight


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
