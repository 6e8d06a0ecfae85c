"""Speed of dense stereo, point stereo and NCC tracking on 1024 x 1024 navcam-like images.

Run the measurements with ``pytest tests/core/test_bench_stereo.py --benchmark-enable``
(without it each benchmark runs once, as a plain test). Target: a 1024 x 1024
dense-stereo pair in under 0.5 s on the 2-core build machine; the measured
figures are in docs/stereo-and-tracking.md.
"""

from functools import lru_cache

import numpy as np
import pytest

from scipctl.core.dense_stereo import dense_stereo
from scipctl.core.point_stereo import point_stereo
from scipctl.core.tracking import track
from tests.core.stereo_scenes import Scene, make_pair

SIZE = 1024
F_NAVCAM_PX = 1220.0  # ~45 deg over 1024 px, baseline 0.2 m (tests/core/stereo_scenes.make_pair)


@lru_cache(maxsize=None)
def navcam_pair():
    scene = Scene(box=((3.0, -0.35, -0.45), (3.5, 0.35, 0.0)), seed=0, n=24)
    left, right = make_pair("CAHVOR", f_px=F_NAVCAM_PX, width=SIZE, height=SIZE)
    L = np.round(scene.render(left, SIZE, SIZE, ss=1)).astype(np.uint8)
    R = np.round(scene.render(right, SIZE, SIZE, ss=1)).astype(np.uint8)
    return scene, left, right, L, R


@pytest.mark.parametrize(
    "min_range_m,downsample,coarse_to_fine",
    [(0.5, 1, True), (0.5, 2, True), (1.5, 1, True), (1.5, 2, True), (0.5, 1, False), (1.5, 1, False)],
    ids=["full-res-0.5m", "half-res-0.5m", "full-res-1.5m", "half-res-1.5m",
         "full-res-0.5m-single-pass", "full-res-1.5m-single-pass"],
)
def test_bench_dense_stereo(benchmark, min_range_m, downsample, coarse_to_fine):
    """Whole dense_stereo call: rectification (cached maps), remap, coarse pass + per-band SGBM + mirrored SGBM
    (left-right check), 3-D. ``single-pass``: one SGBM pass over the whole disparity interval (as before)."""
    scene, left, right, L, R = navcam_pair()
    ds = benchmark(dense_stereo, L, R, left, right, min_range_m=min_range_m, max_range_m=30.0, downsample=downsample,
                   coarse_to_fine=coarse_to_fine)
    assert ds.disparity_px.shape == (SIZE // downsample, SIZE // downsample)
    # the ground fills the lower ~90 % of the view: most of it must be ranged
    assert ds.valid.mean() > 0.7
    r = ds.range_m[ds.valid]
    assert r.min() >= min_range_m and r.max() <= 30.0


def test_bench_point_stereo(benchmark):
    scene, left, right, L, R = navcam_pair()
    uv = (520.3, 700.6)
    res = benchmark(point_stereo, L, R, left, right, uv, band_px=3.0)
    assert res.ok, res.reason
    X = scene.point_at(left, uv)[0]
    assert np.linalg.norm(res.xyz - X) < res.range_sigma_m


def test_bench_track(benchmark):
    scene, left, right, L, R = navcam_pair()
    tpl = L[685:716, 505:536]
    res = benchmark(track, tpl, L, (525.0, 695.0), 60.0)
    assert res.ok and np.abs(res.uv - (520.0, 700.0)).max() < 0.05
