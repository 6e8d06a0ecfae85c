"""Choosing a run's targets on and around the big rock (pure numerics).

Kinds: ``flat`` (pebble-free level ground), ``point`` (a sharp corner of the big rock), ``edge``
(the rock's occluding edge as the hazcams see it), ``sand`` (inside a drift-sand patch),
``contrast`` (a high-contrast spot). Every target is visible in both eyes of every key image pair
of the plan. Points ``(K, 3)`` site frame metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import DEG
from .marks import project_visible
from .scenarios import KINDS, RunPlan
from .scene import GEOM_ROCKS, GEOM_TERRAIN, MAT_ROCK, MAT_TERRAIN, Scene


@dataclass
class Target:
    id: str
    kind: str
    description: str
    xyz_site_m: np.ndarray


_DESCRIPTIONS = {
    "flat": "flat, pebble-free ground near the big rock",
    "point": "sharp corner of the big rock",
    "edge": "point on the big rock's occluding edge as the hazcams see it",
    "sand": "inside a drift-sand patch (low texture)",
    "contrast": "high-contrast spot",
}


def _tangent_rings(P, n, radius_m, k=8):
    """Points on circles of ``radius_m`` around ``P`` ``(K, 3)`` in the planes normal to ``n`` ``(K, 3)`` -> ``(K * k, 3)``."""
    P = np.asarray(P, float).reshape(-1, 3)
    n = np.broadcast_to(np.asarray(n, float), P.shape)
    a = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0, 0], [0, 1.0, 0])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    ang = np.arange(k) * 2 * np.pi / k
    ring = P[:, None, :] + radius_m * (np.cos(ang)[None, :, None] * t1[:, None, :] + np.sin(ang)[None, :, None] * t2[:, None, :])
    return ring.reshape(-1, 3)


def choose_targets(scene: Scene, plan: RunPlan, products: list, rng: np.random.Generator):
    """Pick ``len(plan.kinds)`` targets visible in both eyes of every ``plan.key_images`` pair.

    Returns ``(targets, record)``; a kind with no valid candidate is replaced by the next kind that has one.
    """
    by = {(p.stop, p.camera, p.eye): p for p in products}
    keys = [(s, c, e) for s, c in plan.key_images for e in ("left", "right")]
    keys = [k for k in keys if k in by]
    haz = by.get((plan.key_images[0][0], "hazcam", "left"))
    ref = haz if haz is not None else by[keys[0]]
    m_ref = ref.model_true_site
    W, H = ref.width, ref.height
    n = 90
    us = np.linspace(0.06 * W, 0.94 * W, n)
    vs = np.linspace(0.06 * H, 0.94 * H, n)
    U, V = np.meshgrid(us, vs)
    uv = np.stack([U.ravel(), V.ravel()], 1)
    o, d = m_ref.unproject(uv)
    hits = scene.cast(o, d)
    rock = scene.target_rock
    n_rock_tris = len(rock.triangles)
    r_xy = np.hypot(hits.points[:, 0], hits.points[:, 1])
    cand = hits.hit & (r_xy < 1.3)
    on_rock = cand & (hits.geometry_id == GEOM_ROCKS) & (hits.primitive_id < n_rock_tris)
    on_ter = cand & (hits.geometry_id == GEOM_TERRAIN) & (r_xy > rock.radius_m + 0.12)

    def visible_everywhere(X):
        X = np.asarray(X, float).reshape(-1, 3)
        ok = np.ones(len(X), bool)
        for k in keys:
            p = by[k]
            w, h = p.width, p.height
            uvk, vis = project_visible(scene, p.model_true_site, w, h, X)
            inner = (uvk[:, 0] > 0.04 * w) & (uvk[:, 0] < 0.96 * w) & (uvk[:, 1] > 0.04 * h) & (uvk[:, 1] < 0.96 * h)
            ok &= vis & inner
        return ok

    # per-kind candidate pools: (points (K, 3), scores (K,)) -- higher score is better
    pools = {}
    P = hits.points
    nrm = hits.normal
    # flat / sand: terrain; check the ground around with vertical rays
    ter_idx = np.flatnonzero(on_ter)
    if len(ter_idx):
        ws = scene.appearance.sand_weight(P[ter_idx, :2])
        slope = np.arccos(np.clip(-nrm[ter_idx, 2], -1, 1))
        k_ring = 8
        rings = _tangent_rings(P[ter_idx], np.array([0, 0, -1.0]), 0.04, k_ring)
        hr = scene.cast(rings - np.array([0, 0, 1.0]), np.tile([0, 0, 1.0], (len(rings), 1)))
        clean = (np.all((hr.geometry_id == GEOM_TERRAIN).reshape(-1, k_ring), axis=1)
                 & (np.ptp(np.nan_to_num(hr.points[:, 2], nan=1e9).reshape(-1, k_ring), axis=1) < 0.008)
                 & (slope <= 10 * DEG))
        wr = scene.appearance.sand_weight(rings[:, :2]).reshape(-1, k_ring)
        flat_ok = clean & (ws == 0) & np.all(wr == 0, axis=1)
        sand_ok = clean & (ws >= 1) & np.all(wr >= 1, axis=1)
        pools["flat"] = (P[ter_idx[flat_ok]], -slope[flat_ok])
        pools["sand"] = (P[ter_idx[sand_ok]], np.zeros(int(sand_ok.sum())))
    # edge: the big rock seen at grazing incidence by the reference camera, next to its silhouette
    rk_idx = np.flatnonzero(on_rock)
    if len(rk_idx):
        cosi = np.abs(np.einsum("ij,ij->i", nrm[rk_idx], d[rk_idx]))
        sel = rk_idx[(cosi > 0.12) & (cosi < 0.45)]
        edge_pts, edge_scores = [], []
        step = 0.012 * W
        for i in sel:
            nb = uv[i][None, :] + step * np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [-1, -1], [1, -1], [-1, 1]])
            on, dn = m_ref.unproject(nb)
            hn = scene.cast(on, dn)
            if np.any(hn.t_m > hits.t_m[i] + 0.08):
                edge_pts.append(P[i])
                edge_scores.append(-abs(np.einsum("j,j->", nrm[i], d[i])))
        pools["edge"] = (np.array(edge_pts).reshape(-1, 3), np.array(edge_scores))
    # point: next to the hull corners of the big rock (3 mm in, on an adjacent facet), sharpest first
    from .mesh import vertex_normals

    cv = rock.vertices[rock.corner_idx]
    g = scene.ground_height_m(cv[:, :2])
    above = (-cv[:, 2]) - g > 0.03
    vn = vertex_normals(rock.vertices, rock.triangles)[rock.corner_idx]
    inward = np.array([rock.centre_xy_m[0], rock.centre_xy_m[1], rock.aim_point_site()[2]])[None, :] - cv
    inward -= np.einsum("ij,ij->i", inward, vn)[:, None] * vn
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    hc = scene.cast(cv + 0.05 * vn + 0.003 * inward, -vn)
    ok = above & hc.hit & (hc.geometry_id == GEOM_ROCKS) & (hc.primitive_id < n_rock_tris)
    ok &= np.linalg.norm(np.nan_to_num(hc.points - cv, nan=1.0), axis=1) < 0.008
    pools["point"] = (hc.points[ok], rock.corner_sharpness_rad[ok])
    # contrast: local albedo range within 4 mm, over rock and ground candidates
    cc = np.flatnonzero(cand & ((hits.material == MAT_TERRAIN) | (hits.material == MAT_ROCK)))
    if len(cc):
        pick = cc if len(cc) <= 1500 else rng.choice(cc, 1500, replace=False)
        pick = np.sort(pick)
        rings = _tangent_rings(P[pick], nrm[pick], 0.004)
        mats = np.repeat(hits.material[pick], 8)
        sc = np.repeat(hits.obj_scale[pick], 8)
        alb = scene.appearance.albedo(rings, mats, sc, None).reshape(len(pick), 8)
        pools["contrast"] = (P[pick], np.ptp(alb, axis=1))

    chosen: list[Target] = []
    rec = {"wanted": list(plan.kinds), "pool_sizes": {k: int(len(v[0])) for k, v in sorted(pools.items())}, "substituted": []}

    def try_kind(kind):
        pts, scores = pools.get(kind, (np.zeros((0, 3)), np.zeros(0)))
        if len(pts) == 0:
            return None
        # best-scoring quarter first (in random order), then the rest by score
        order_i = np.argsort(-scores, kind="stable")
        q = max(8, len(order_i) // 4)
        top = order_i[:q][rng.permutation(min(q, len(order_i)))]
        for i in list(top) + list(order_i[q:q + 200]):
            X = pts[i]
            if any(np.linalg.norm(X - t.xyz_site_m) < 0.05 for t in chosen):
                continue
            if visible_everywhere(X)[0]:
                return Target(f"t{len(chosen) + 1}", kind, _DESCRIPTIONS[kind], np.array(X, float))
        return None

    for kind in plan.kinds:
        t = try_kind(kind)
        if t is not None:
            chosen.append(t)
    for kind in [k for k in KINDS if k not in plan.kinds] + list(KINDS):
        if len(chosen) >= len(plan.kinds):
            break
        t = try_kind(kind)
        if t is not None:
            chosen.append(t)
            rec["substituted"].append(kind)
    return chosen, rec
