"""Frame graph (label coordinate systems) and models of subframed/downsampled images."""

import numpy as np
import pytest

from scipctl.core.camera_subimage import fullframe_model, subimage_model
from scipctl.core.frames import FrameGraph, FrameRef
from scipctl.core.transforms import RigidTransform, euler_zyx_to_matrix
from tests.models import all_models


def _T(yaw, pitch, roll, t):
    return RigidTransform(euler_zyx_to_matrix(yaw, pitch, roll), np.array(t, float))


def test_frame_graph_chains_edges_both_ways_and_matches_index_prefixes():
    site13, site14 = FrameRef("SITE_FRAME", (13,)), FrameRef("SITE_FRAME", (14,))
    rover = FrameRef("ROVER_NAV_FRAME", (14, 1262, 6, 188))
    head = FrameRef("RSM_HEAD_FRAME", (14, 1262, 6, 188))
    T_13_14, T_14_rover, T_rover_head = _T(0.1, 0, 0, [5, 6, 0]), _T(2.0, 0.02, -0.01, [-176, -129, -0.2]), _T(
        0.7, -0.4, 0.0, [0.8, 0.56, -1.9])
    g = FrameGraph()
    g.add(T_13_14, site14, site13)
    g.add(T_14_rover, rover, site14)
    g.add(T_rover_head, head, rover)
    p = np.array([0.3, -0.2, 0.1])
    # head -> site 13 through two edges, and back (inverse edges)
    T = g.transform(site13, FrameRef("RSM_HEAD_FRAME", (14, 1262, 6)))  # a shorter index matches its prefix
    np.testing.assert_allclose(T.apply(p), T_13_14.apply(T_14_rover.apply(T_rover_head.apply(p))), atol=1e-12)
    back = g.transform(head, site13)
    np.testing.assert_allclose(back.apply(T.apply(p)), p, atol=1e-12)
    assert g.transform(FrameRef("ARM_TURRET_FRAME", (14, 1262)), rover) is None
    assert g.transform(FrameRef("ROVER_NAV_FRAME", (14, 1260)), rover) is None  # another drive: another frame


@pytest.mark.parametrize("name", ["CAHV", "CAHVOR", "CAHVORE1", "CAHVORE3"])
@pytest.mark.parametrize("x0,y0,s", [(0, 0, 1), (2544, 0, 2), (100, 37, 4), (1272, 952, 1)])
def test_subimage_model_maps_window_pixels_to_full_frame_pixels(name, x0, y0, s):
    full = all_models()[name]
    sub = subimage_model(full, x0, y0, s)
    rng = np.random.default_rng(0)
    pts = full.C + full.A * rng.uniform(2, 8, (40, 1)) + rng.normal(0, 0.5, (40, 3))
    uv_full = full.project(pts)
    uv_sub = sub.project(pts)
    ok = np.all(np.isfinite(uv_full), axis=1)
    assert ok.sum() > 30
    # independent statement of the window geometry: full = x0 + s*u + (s-1)/2
    np.testing.assert_allclose(uv_full[ok], np.array([x0, y0]) + s * uv_sub[ok] + (s - 1) / 2, atol=1e-8)
    back = fullframe_model(sub, x0, y0, s)
    np.testing.assert_allclose(back.H, full.H, rtol=0, atol=1e-9 * np.abs(full.H).max())
    np.testing.assert_allclose(back.V, full.V, rtol=0, atol=1e-9 * np.abs(full.V).max())
