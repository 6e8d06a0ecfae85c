"""Speed of rendering one 1024 x 1024 image (2 x 2 samples per pixel, shadows, anti-aliased albedo).

Measure with ``pytest tests/sim/test_bench_render.py --benchmark-enable``; without
it the navcam case runs once as a plain test and the others are skipped. Target:
a few seconds per image on the 2-core build machine; the measured figures are in
docs/simulator.md.
"""

import numpy as np
import pytest

from scipctl.sim.render import render_radiance


@pytest.mark.parametrize("stop,camera", [("near", "navcam"), ("near", "hazcam"), ("pan10", "pancam")])
def test_bench_render_1024(benchmark, run_full_exact, stop, camera):
    if benchmark.disabled and camera != "navcam":
        pytest.skip("measured with --benchmark-enable only")
    sim = run_full_exact
    p = next(q for q in sim.products if q.stop == stop and q.camera == camera and q.eye == "left")
    model = p.model_true_site
    sim.scene.raycaster()  # the BVH is built once per scene, not per image
    img = benchmark.pedantic(render_radiance, args=(sim.scene, model, 1024, 1024, 2), rounds=3 if not benchmark.disabled else 1,
                             iterations=1)
    assert img.shape == (1024, 1024) and np.isfinite(img).all()
    assert img.std() > 0.01  # a textured scene, not a blank frame
