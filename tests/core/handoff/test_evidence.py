"""scipctl/core/handoff/evidence.py: the occlusion evidence (the hazcam's dense stereo over the disk at a candidate
against the predicted target's range). The other evidence is tested in test_scip.py."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from scipctl.core.handoff.evidence import Candidate, candidate_evidence, disk_offsets, occlusion, target_views


def test_disk_offsets():
    d = disk_offsets(4.0)
    assert d.shape == (49, 2)  # the 4 px disk: 49 whole pixels (Gauss circle problem, r = 4)
    assert np.all(np.hypot(d[:, 0], d[:, 1]) <= 4.0)
    assert {tuple(x) for x in d} == {tuple(-x) for x in d}  # symmetric
    assert disk_offsets(0.5).tolist() == [[0.0, 0.0]]


def _stub_view(range_of_uv, x_pred=(0.0, 0.0, 1.5), sigma_m=0.01):
    """A TargetView-like stub: hazcam-left centre at the origin, its dense stereo giving the point at
    ``range_of_uv(uv)`` m on the optical axis (the test needs ranges only), the target predicted at ``x_pred``."""
    def xyz_at(uv):
        uv = np.asarray(uv, float).reshape(-1, 2)
        r = np.array([range_of_uv(u) for u in uv], float)
        return np.stack([np.zeros_like(r), np.zeros_like(r), r], -1)

    haz = SimpleNamespace(left_model=SimpleNamespace(C=np.zeros(3)), xyz_at=xyz_at)
    return SimpleNamespace(X_pred_haz=None if x_pred is None else np.asarray(x_pred, float), sigma_m=sigma_m,
                           case=SimpleNamespace(haz=haz))


def test_occlusion_of_a_surface_in_front():
    c = np.array([100.0, 200.0])
    # the surface at the target's range: nothing in front
    assert occlusion(_stub_view(lambda uv: 1.5), c, 4.0) == {"front_sigma": 0.0}
    # a stone 8 cm in front over the disk, the ground elsewhere: 8 sigma (median over the disk's 49 pixels)
    stone = lambda uv: 1.42 if np.hypot(*(uv - c)) <= 4.0 else 1.5  # noqa: E731
    assert occlusion(_stub_view(stone), c, 4.0)["front_sigma"] == pytest.approx(8.0, abs=1e-9)
    # the stone over a quarter of the disk only: the median is the ground's
    corner = lambda uv: 1.42 if (uv[0] > c[0] + 1.5 and uv[1] > c[1] + 1.5) else 1.5  # noqa: E731
    assert occlusion(_stub_view(corner), c, 4.0)["front_sigma"] == pytest.approx(0.0, abs=1e-9)
    # a surface behind the target: negative
    assert occlusion(_stub_view(lambda uv: 1.6), c, 4.0)["front_sigma"] == pytest.approx(-10.0, abs=1e-9)


def test_occlusion_unknown():
    c = np.array([10.0, 10.0])
    # fewer than half of the disk's pixels with a dense range: unknown
    holes = lambda uv: 1.5 if uv[0] < c[0] - 0.5 else math.nan  # noqa: E731  (21 of 49 pixels known)
    assert occlusion(_stub_view(holes), c, 4.0) == {}
    half = lambda uv: 1.45 if uv[0] < c[0] + 0.5 else math.nan  # noqa: E731  (28 of 49 known: the known ones count)
    assert occlusion(_stub_view(half), c, 4.0)["front_sigma"] == pytest.approx(5.0, abs=1e-9)
    assert occlusion(_stub_view(lambda uv: 1.5, x_pred=None), c, 4.0) == {}  # no navcam point: no prediction
    assert occlusion(_stub_view(lambda uv: 1.5, sigma_m=math.nan), c, 4.0) == {}


def test_occlusion_on_the_synthetic_scene(handoff_scene):
    """Exact models and poses: at the true pixel the hazcam's dense range agrees with the predicted target's
    within 2 sigma (sigma: the expected discrepancy of the two stereo ranges, TargetView.sigma_m; measured
    0.09-1.19 on OpenCV 5.0 and 0.12-1.19 on 4.14); 20 px lower in the image, on nearer ground, the surface is in
    front (measured 2.27-4.34 and 2.28-4.31 sigma; the bound: > 1)."""
    cases = handoff_scene.cases
    hp = cases["near"].params
    for t in handoff_scene.targets:
        views = target_views(cases, t.nav_uv, hp, hp.scip)
        uv = np.asarray(t.haz_uv, float)
        cands = [Candidate(uv, [("refined-geometric", "near")]),
                 Candidate(uv + [0.0, 20.0], [("pure-kinematic", "far")])]
        good, nearer = (candidate_evidence(views, cands, i, hp.scip) for i in range(2))
        for v in ("near", "far"):
            assert abs(getattr(good, f"occ_{v}_front_sigma")) < 2.0, (t.id, v)
            assert getattr(nearer, f"occ_{v}_front_sigma") > 1.0, (t.id, v)
