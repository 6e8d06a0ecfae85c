"""Expected images and geometric look-ups for the handoff methods (pure numerics).

* :func:`splat_points` — z-buffered splatting of a coloured point cloud into a
  camera (the paper's step 8: each point fills the four pixels it falls
  between; the nearest point wins), with see-through holes removed and small
  holes filled.
* :func:`drape` — intensities of one image sampled at the projections of 3-D
  points (the "draping" of refined geometric handoff).
* :func:`nearest_projection` — the pixel of a per-pixel point map whose point
  projects nearest a given pixel of another camera (pure geometric handoff),
  refined to sub-pixel by a local affine fit.
* :func:`match_projection` — Gauss-Newton on a pixel of one camera so that
  its 3-D point (from any per-pixel range source, e.g. point stereo) projects
  onto a given pixel of another camera (sub-pixel pure geometric handoff that
  does not inherit the dense map's per-pixel range noise).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from .camera import CameraModel


@dataclass
class SplatResult:
    image: np.ndarray  # (H, W) float32, NaN where no data
    depth_m: np.ndarray  # (H, W) float32, distance from the camera centre, NaN where no data
    filled_fraction: float  # fraction of the (ROI) pixels that received a point
    see_through_removed: int  # pixels rejected as seen through a hole
    origin_uv: tuple  # (u0, v0) pixel of image[0, 0] in the camera's full image


def splat_points(
    points: np.ndarray,
    intensities: np.ndarray,
    model: CameraModel,
    width: int,
    height: int,
    roi: Optional[tuple] = None,
    see_through_ratio: float = 0.05,
    fill_holes_px: int = 2,
    soft_depth_ratio: float = 0.01,
    cone_margin_rad: Optional[float] = 0.05,
) -> SplatResult:
    """Render points ``(N, 3)`` (the model's frame) with ``intensities`` ``(N,)`` into ``model``.

    ``roi = (u0, v0, w, h)`` restricts the output to a window of the full
    ``width`` x ``height`` image (pixel ``image[0, 0]`` is ``(u0, v0)``).
    A pixel whose depth exceeds the minimum depth of its 5x5 neighbourhood by
    more than ``see_through_ratio`` (relative) is treated as seen through a hole
    and cleared; holes up to ``fill_holes_px`` wide are filled from neighbours.
    With ``soft_depth_ratio`` > 0, each pixel blends (bilinear weights) the points
    within that relative depth of its nearest point; 0 keeps only the nearest
    point, as the paper describes.
    With a ``roi``, points farther than ``cone_margin_rad`` outside the cone of
    rays through the window's corners are dropped before projection (a speed-up
    that changes nothing while the margin exceeds the parallax of a non-central
    model's moving pupil, mm at tens of cm); None projects every point.
    """
    import cv2

    P = np.asarray(points, dtype=float)
    I = np.asarray(intensities, dtype=np.float32).reshape(-1)
    if P.ndim != 2 or P.shape[1] != 3 or len(I) != len(P):
        raise ValueError(f"points (N,3) and intensities (N,) expected, got {P.shape} and {I.shape}")
    u0, v0, w, h = roi if roi is not None else (0, 0, width, height)
    if roi is not None and cone_margin_rad is not None:
        # only points within a cone around the window can land in it: skip projecting the others
        sel = _roi_cone_mask(P, model, roi, cone_margin_rad)
        if sel is not None:
            P, I = P[sel], I[sel]
    uv = model.project(P)
    depth = np.linalg.norm(P - model.C, axis=-1)
    ok = np.all(np.isfinite(uv), axis=-1) & np.isfinite(I)
    uv, depth, I = uv[ok], depth[ok], I[ok]
    # local pixel coords in the ROI
    x = uv[:, 0] - u0
    y = uv[:, 1] - v0
    keep = (x > -1) & (x < w) & (y > -1) & (y < h)
    x, y, depth, I = x[keep], y[keep], depth[keep], I[keep]
    xf = np.floor(x).astype(np.int64)
    yf = np.floor(y).astype(np.int64)
    fx, fy = x - xf, y - yf
    cand_idx, cand_depth, cand_val, cand_w = [], [], [], []
    for dx in (0, 1):
        for dy in (0, 1):
            xi, yi = xf + dx, yf + dy
            inside = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
            cand_idx.append(yi[inside] * w + xi[inside])
            cand_depth.append(depth[inside])
            cand_val.append(I[inside])
            # bilinear weight of this pixel for the point (how close the point falls to its centre)
            wx = fx if dx else 1.0 - fx
            wy = fy if dy else 1.0 - fy
            cand_w.append((wx * wy)[inside])
    idx = np.concatenate(cand_idx)
    dep = np.concatenate(cand_depth)
    val = np.concatenate(cand_val)
    wgt = np.concatenate(cand_w)
    img = np.full(w * h, np.nan, np.float32)
    zbuf = np.full(w * h, np.nan, np.float32)
    if len(idx):
        order = np.lexsort((dep, idx))  # by pixel, then nearest first
        idx_s = idx[order]
        first = np.ones(len(idx_s), bool)
        first[1:] = idx_s[1:] != idx_s[:-1]
        sel = order[first]
        zbuf[idx[sel]] = dep[sel]
        img[idx[sel]] = val[sel]  # the nearest point (the paper's rule)
        if soft_depth_ratio > 0:
            # soft z-buffer: the points on the nearest surface (depth within soft_depth_ratio of the nearest)
            # are blended with their bilinear weights
            keep = dep <= zbuf[idx] * (1.0 + soft_depth_ratio)
            num = np.bincount(idx[keep], weights=(wgt * val)[keep], minlength=w * h)
            den = np.bincount(idx[keep], weights=wgt[keep], minlength=w * h)
            has = den > 1e-9
            img[has] = (num[has] / den[has]).astype(np.float32)
    img = img.reshape(h, w)
    zbuf = zbuf.reshape(h, w)
    filled = float(np.isfinite(img).mean()) if img.size else 0.0
    # see-through rejection: compare with the nearest depth around
    zb = np.where(np.isfinite(zbuf), zbuf, np.float32(1e9)).astype(np.float32)
    zmin = cv2.erode(zb, np.ones((5, 5), np.uint8))
    through = np.isfinite(zbuf) & (zbuf > zmin * (1 + see_through_ratio))
    img[through] = np.nan
    zbuf[through] = np.nan
    # fill small holes by normalised box filtering of the valid pixels
    if fill_holes_px > 0:
        k = 2 * fill_holes_px + 1
        valid = np.isfinite(img).astype(np.float32)
        num = cv2.boxFilter(np.where(valid > 0, img, 0).astype(np.float32), -1, (k, k), normalize=False)
        den = cv2.boxFilter(valid, -1, (k, k), normalize=False)
        znum = cv2.boxFilter(np.where(valid > 0, zbuf, 0).astype(np.float32), -1, (k, k), normalize=False)
        hole = (valid == 0) & (den >= 0.3 * k * k)
        img[hole] = num[hole] / den[hole]
        zbuf[hole] = znum[hole] / den[hole]
    return SplatResult(img, zbuf, filled, int(through.sum()), (u0, v0))


def _roi_cone_mask(P: np.ndarray, model: CameraModel, roi: tuple, margin_rad: float) -> Optional[np.ndarray]:
    """``(N,)`` bool: points ``(N, 3)`` within ``margin_rad`` of the cone of rays (from the ray origin of the
    window's centre) through the corners of the pixel window ``roi = (u0, v0, w, h)`` widened by one pixel;
    None when the cone is too wide to be worth it (over 60 deg half-angle) or a corner has no ray."""
    u0, v0, w, h = roi
    centre = np.array([u0 + (w - 1) / 2.0, v0 + (h - 1) / 2.0])
    corners = np.array([[u0 - 1.0, v0 - 1.0], [u0 + w, v0 - 1.0], [u0 - 1.0, v0 + h], [u0 + w, v0 + h]])
    o_c, d_c = model.unproject(centre)
    _, d_k = model.unproject(corners)
    cos_k = d_k @ d_c
    if not (np.all(np.isfinite(cos_k)) and np.all(np.isfinite(o_c))):
        return None
    half_rad = float(np.arccos(np.clip(cos_k.min(), -1.0, 1.0))) + float(margin_rad)
    if half_rad > np.radians(60):
        return None
    D = P - o_c
    along = D @ d_c
    # cos(angle) > cos(half)  <=>  along > 0 and along^2 > cos^2(half) |D|^2
    return (along > 0) & (along * along > np.cos(half_rad) ** 2 * np.einsum("ij,ij->i", D, D))


def bilinear_sample(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Sample ``image`` (H, W) at pixels ``uv`` (..., 2); NaN outside the pixel centres' span ``[0, W-1] x [0, H-1]``
    (the outer half pixel has no neighbour to interpolate with). ValueError for other shapes."""
    img = np.asarray(image, dtype=np.float32)  # no copy of a float32 view
    if img.ndim != 2:
        raise ValueError(f"image: expected a single-channel (H, W) image, got shape {img.shape}")
    uv = np.asarray(uv, dtype=float)
    if uv.ndim == 0 or uv.shape[-1] != 2:
        raise ValueError(f"uv: expected pixels of shape (..., 2), got shape {uv.shape}")
    H, W = img.shape
    u, v = uv[..., 0], uv[..., 1]
    ok = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1)
    uc = np.where(ok, u, 0.0)
    vc = np.where(ok, v, 0.0)
    i0 = np.clip(np.floor(uc).astype(int), 0, W - 2)
    j0 = np.clip(np.floor(vc).astype(int), 0, H - 2)
    fu, fv = uc - i0, vc - j0
    out = (
        (1 - fu) * (1 - fv) * img[j0, i0]
        + fu * (1 - fv) * img[j0, i0 + 1]
        + (1 - fu) * fv * img[j0 + 1, i0]
        + fu * fv * img[j0 + 1, i0 + 1]
    )
    return np.where(ok, out, np.nan).astype(np.float32)


def drape(points: np.ndarray, model: CameraModel, image: np.ndarray) -> np.ndarray:
    """Intensity of ``image`` (taken by ``model``) at the projection of each point ``(..., 3)``; NaN where unseen."""
    P = np.asarray(points, dtype=float)
    shape = P.shape[:-1]
    flat = P.reshape(-1, 3)
    out = np.full(len(flat), np.nan, np.float32)
    ok = np.all(np.isfinite(flat), axis=-1)
    if np.any(ok):
        out[ok] = bilinear_sample(image, model.project(flat[ok]))
    return out.reshape(shape)


def project_map(xyz_map: np.ndarray, model: CameraModel) -> np.ndarray:
    """Project a point map ``(h, w, 3)`` (NaN invalid) through ``model`` -> ``(h, w, 2)`` (NaN invalid)."""
    flat = xyz_map.reshape(-1, 3)
    ok = np.all(np.isfinite(flat), axis=-1)
    proj = np.full((len(flat), 2), np.nan)
    proj[ok] = model.project(flat[ok])
    return proj.reshape(xyz_map.shape[:-1] + (2,))


class ProjectionMap:
    """The projections of a point map ``xyz_map`` ``(h, w, 3)`` (NaN invalid) through ``model``, computed on
    demand by region: ``region(rows, cols)`` -> ``(h', w', 2)`` (NaN invalid), ``full()`` -> ``(h, w, 2)``
    (computed once, then every region is cut from it).

    A projection depends only on its own point, so a region equals the same
    slice of :func:`project_map` of the whole map (a test checks it bit for
    bit); projecting only the regions a search visits saves projecting a
    million-point map when a few thousand points decide.
    """

    def __init__(self, xyz_map: np.ndarray, model: CameraModel, full: Optional[np.ndarray] = None):
        if xyz_map.ndim != 3 or xyz_map.shape[-1] != 3:
            raise ValueError(f"xyz_map: expected (h, w, 3), got {xyz_map.shape}")
        if full is not None and full.shape != xyz_map.shape[:-1] + (2,):
            raise ValueError(f"full: expected {xyz_map.shape[:-1] + (2,)}, got {full.shape}")
        self.xyz_map = xyz_map
        self.model = model
        self._full = full

    @property
    def shape(self) -> tuple:
        return self.xyz_map.shape[:-1] + (2,)

    def full(self) -> np.ndarray:
        if self._full is None:
            self._full = project_map(self.xyz_map, self.model)
        return self._full

    def region(self, rows: slice, cols: slice) -> np.ndarray:
        if self._full is not None:
            return self._full[rows, cols]
        return project_map(self.xyz_map[rows, cols], self.model)


@dataclass
class NearestProjection:
    uv: np.ndarray  # (2,) sub-pixel position in the point map's image
    uv_integer: np.ndarray  # (2,) the best whole pixel
    distance_px: float  # distance of its projection from the wanted pixel (other camera's pixels)
    xyz: np.ndarray  # (3,) the point of the best whole pixel


def _squared_distance_map(P: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """``(h, w)`` squared distances of projections ``P`` ``(h, w, 2)`` from ``goal`` ``(2,)``; inf where invalid."""
    d = np.einsum("...i,...i->...", P - goal, P - goal)
    d[~np.isfinite(d)] = np.inf
    return d


def nearest_projection(
    xyz_map: np.ndarray,
    origin_uv: tuple,
    model: CameraModel,
    goal_uv,
    proj=None,
) -> Optional[NearestProjection]:
    """Among the pixels of a point map ``xyz_map`` (h, w, 3) (NaN invalid), find where the projection through
    ``model`` lands nearest ``goal_uv``; ``origin_uv`` is the full-image pixel of ``xyz_map[0, 0]``.

    Sub-pixel: the projection is locally affine in the pixel position, so the
    best pixel is refined by solving ``J dp = goal - uv(p0)`` with ``J`` from
    valid neighbours (kept only if it moves less than one pixel).
    ``proj``: the projections of ``xyz_map`` through ``model``, either all of
    them ``(h, w, 2)`` (see :func:`project_map`; NaN where invalid) or a
    :class:`ProjectionMap` of the same map and model that computes (and
    remembers) what the search needs; by default only the regions the search
    visits are projected.
    """
    goal = np.asarray(goal_uv, dtype=float).reshape(2)
    h, w, _ = xyz_map.shape
    if proj is None:
        proj = ProjectionMap(xyz_map, model)
    elif not isinstance(proj, ProjectionMap):
        proj = ProjectionMap(xyz_map, model, full=np.asarray(proj).reshape(h, w, 2))
    if proj.shape != (h, w, 2):
        raise ValueError(f"proj: expected the projections of a {(h, w)} map, got {proj.shape}")
    # coarse-to-fine: the best node of an 8-pixel lattice, then every pixel within 3 lattice steps of it
    # (exact unless the nearest point sits in a sliver narrower than the lattice, e.g. at a silhouette,
    # so the whole map is searched as well whenever the lattice answer is not already within 1 px)
    step = 8
    ds = _squared_distance_map(proj.region(slice(None, None, step), slice(None, None, step)), goal)
    ks = int(np.argmin(ds))
    if not np.isfinite(ds.flat[ks]):
        # no valid lattice node: the whole map decides (an empty map has no answer)
        d2 = _squared_distance_map(proj.full(), goal)
        k = int(np.argmin(d2))
        if not np.isfinite(d2.flat[k]):
            return None
        j, i = divmod(k, w)
    else:
        js, is_ = divmod(ks, ds.shape[1])
        j0, j1 = max(0, js * step - 3 * step), min(h, js * step + 3 * step + 1)
        i0, i1 = max(0, is_ * step - 3 * step), min(w, is_ * step + 3 * step + 1)
        dw = _squared_distance_map(proj.region(slice(j0, j1), slice(i0, i1)), goal)
        kw = int(np.argmin(dw))
        jw, iw = divmod(kw, dw.shape[1])
        j, i = j0 + jw, i0 + iw
        nb = _neighbourhood(proj, j, i, h, w)
        c = nb[1, 1]
        spacing = max([float(np.linalg.norm(q - c)) for q in (nb[1, 2], nb[1, 0], nb[2, 1], nb[0, 1])
                       if np.all(np.isfinite(q))] or [0.0])
        # the lattice answer is trusted when it is within one local pixel spacing of the goal; otherwise
        # (a silhouette, a hole, the goal outside the map) search the whole map
        if not np.sqrt(dw[jw, iw]) <= max(spacing, 1e-9):
            d2 = _squared_distance_map(proj.full(), goal)
            k = int(np.argmin(d2))
            if not np.isfinite(d2.flat[k]):
                return None
            j, i = divmod(k, w)
    nb = _neighbourhood(proj, j, i, h, w)
    P0 = nb[1, 1]
    d2_best = float(np.sum((P0 - goal) ** 2))
    uv_int = np.array([origin_uv[0] + i, origin_uv[1] + j], float)
    uv = uv_int.copy()
    if 0 < i < w - 1 and 0 < j < h - 1:
        du = (nb[1, 2] - nb[1, 0]) / 2
        dv = (nb[2, 1] - nb[0, 1]) / 2
        J = np.stack([du, dv], axis=1)
        if np.all(np.isfinite(J)) and abs(np.linalg.det(J)) > 1e-9:
            step = np.linalg.solve(J, goal - P0)
            if np.all(np.abs(step) <= 1.0):
                uv = uv_int + step
    return NearestProjection(uv, uv_int, float(np.sqrt(d2_best)), xyz_map[j, i].copy())


def _neighbourhood(proj: ProjectionMap, j: int, i: int, h: int, w: int) -> np.ndarray:
    """Projections ``(3, 3, 2)`` of pixel ``(j, i)`` and its eight neighbours (NaN beyond the map)."""
    out = np.full((3, 3, 2), np.nan)
    j0, j1, i0, i1 = max(0, j - 1), min(h, j + 2), max(0, i - 1), min(w, i + 2)
    out[j0 - j + 1 : j1 - j + 1, i0 - i + 1 : i1 - i + 1] = proj.region(slice(j0, j1), slice(i0, i1))
    return out


@dataclass
class ProjectionMatch:
    uv: np.ndarray  # (2,) pixel of the first camera
    xyz: np.ndarray  # (3,) its 3-D point (the second camera's model frame)
    residual_px: float  # |projection - goal| at ``uv`` (second camera's pixels)
    iterations: int  # Gauss-Newton steps taken
    converged: bool  # the last step was below ``tol_px``


def match_projection(
    xyz_of_pixel: Callable[[np.ndarray], Optional[np.ndarray]],
    model: CameraModel,
    goal_uv,
    uv0,
    jacobian: np.ndarray,
    max_iterations: int = 6,
    tol_px: float = 0.01,
    max_step_px: float = 3.0,
) -> Optional[ProjectionMatch]:
    """The pixel ``uv`` of a first camera whose 3-D point ``xyz_of_pixel(uv)`` projects through ``model`` onto
    ``goal_uv`` (2,), by Gauss-Newton from ``uv0`` (2,).

    ``xyz_of_pixel``: ``(2,)`` pixel -> ``(3,)`` point in ``model``'s frame, or
    None where no range is available. ``jacobian`` ``(2, 2)``: an approximation
    of d(projection)/d(uv) near the answer (e.g. from a dense point map), kept
    fixed: the iteration converges whenever it is within a few tens of percent
    of the true one. Steps are clipped to ``max_step_px``. Returns None when no
    point is available at ``uv0``; otherwise the best pixel visited (smallest
    residual).
    """
    J = np.asarray(jacobian, dtype=float)
    if J.shape != (2, 2) or not np.all(np.isfinite(J)) or abs(np.linalg.det(J)) < 1e-12:
        raise ValueError(f"jacobian: expected a finite, invertible (2, 2) matrix, got {J!r}")
    goal = np.asarray(goal_uv, dtype=float).reshape(2)
    uv = np.asarray(uv0, dtype=float).reshape(2).copy()
    best = None
    converged = False
    it = 0
    for it in range(max_iterations + 1):
        X = xyz_of_pixel(uv)
        if X is None or not np.all(np.isfinite(X)):
            break
        X = np.asarray(X, dtype=float).reshape(3)
        q = model.project(X[None])[0]
        if not np.all(np.isfinite(q)):
            break
        r = goal - q
        res = float(np.hypot(*r))
        if best is None or res < best.residual_px:
            best = ProjectionMatch(uv.copy(), X, res, it, False)
        if converged or it == max_iterations:
            break
        step = np.linalg.solve(J, r)
        n = float(np.hypot(*step))
        if n > max_step_px:
            step *= max_step_px / n
        uv = uv + step
        converged = n < tol_px
    if best is not None:
        best.converged = converged
    return best


def footprint_blur_cov(A: np.ndarray) -> np.ndarray:
    """Extra blur ``(2, 2)`` covariance (source px^2) that turns source pixels into destination pixels.

    ``A`` ``(2, 2)``: d(source pixel)/d(destination pixel). A destination pixel
    (unit box, variance 1/12 per axis) covers ``A A^T / 12`` in the source; the
    source pixel already integrates ``I / 12``; the difference (clipped to
    positive semi-definite) is what the source image must be blurred by before
    it is sampled at destination pixels. Zero where the source is coarser.
    """
    A = np.asarray(A, dtype=float)
    if A.shape != (2, 2) or not np.all(np.isfinite(A)):
        raise ValueError(f"A: expected a finite (2, 2) matrix, got {A!r}")
    w, V = np.linalg.eigh((A @ A.T - np.eye(2)) / 12.0)
    return (V * np.clip(w, 0.0, None)) @ V.T


def map_jacobian(q: np.ndarray) -> Optional[np.ndarray]:
    """Median d(q)/d(pixel) ``(2, 2)`` of a pixel map ``q`` (h, w, 2) (NaN invalid) by neighbour differences:
    column 0 is d(q)/du, column 1 d(q)/dv; None with fewer than 9 interior pixels where both are known."""
    du = (q[:, 2:] - q[:, :-2])[1:-1] / 2
    dv = (q[2:] - q[:-2])[:, 1:-1] / 2
    ok = np.all(np.isfinite(du), axis=-1) & np.all(np.isfinite(dv), axis=-1)
    if ok.sum() < 9:
        return None
    return np.stack([np.median(du[ok], axis=0), np.median(dv[ok], axis=0)], axis=1)


def antialiased_sample(image: np.ndarray, q: np.ndarray, A: np.ndarray) -> np.ndarray:
    """``image`` (H, W) at source pixels ``q`` (..., 2) -> (...) float32 (NaN where ``q`` is not finite), each
    destination pixel integrated over its footprint in the source.

    ``A`` ``(2, 2)``: d(source px)/d(destination px). The part of ``image`` the samples need (with a 3-sigma
    margin) is blurred by :func:`footprint_blur_cov` of ``A`` (nothing where the source is the coarser), then sampled
    bilinearly: a source finer than the destination is averaged as the destination camera's own pixels average
    the scene, instead of point-sampled (aliased).
    """
    q = np.asarray(q, float)
    if q.shape[-1:] != (2,):
        raise ValueError(f"q: expected (..., 2) source pixels, got shape {q.shape}")
    ok = np.all(np.isfinite(q), axis=-1)
    out = np.full(q.shape[:-1], np.nan, np.float32)
    if not ok.any():
        return out
    cov = footprint_blur_cov(A)
    pad = int(np.ceil(3 * np.sqrt(max(cov[0, 0], cov[1, 1])))) + 2
    H, W = image.shape
    u0 = int(max(np.floor(q[ok][:, 0].min()) - pad, 0))
    v0 = int(max(np.floor(q[ok][:, 1].min()) - pad, 0))
    u1 = int(min(np.ceil(q[ok][:, 0].max()) + pad + 1, W))
    v1 = int(min(np.ceil(q[ok][:, 1].max()) + pad + 1, H))
    if u1 - u0 < 2 or v1 - v0 < 2:
        return out
    crop = gaussian_blur_cov(image[v0:v1, u0:u1], cov)
    out[ok] = bilinear_sample(crop, q[ok] - [u0, v0])
    return out


def gaussian_blur_cov(image: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``image`` (H, W) convolved with the Gaussian of covariance ``cov`` ``(2, 2)`` (px^2, (u, v) order).

    Returned as float32; the input itself when the covariance is negligible.
    Borders replicate.
    """
    import cv2

    img = np.asarray(image, dtype=np.float32)
    S = np.asarray(cov, dtype=float)
    if S.shape != (2, 2) or not np.all(np.isfinite(S)):
        raise ValueError(f"cov: expected a finite (2, 2) matrix, got {S!r}")
    if np.max(np.linalg.eigvalsh(S)) < 0.05**2:
        return img
    r = int(np.ceil(3.0 * np.sqrt(max(S[0, 0], S[1, 1])))) + 1
    x, y = np.meshgrid(np.arange(-r, r + 1, dtype=float), np.arange(-r, r + 1, dtype=float))
    # tiny floor keeps a rank-deficient covariance (blur along one direction only) invertible
    Si = np.linalg.inv(S + 1e-4 * np.eye(2))
    k = np.exp(-0.5 * (Si[0, 0] * x * x + 2 * Si[0, 1] * x * y + Si[1, 1] * y * y))
    k /= k.sum()
    return cv2.filter2D(img, -1, k.astype(np.float32), borderType=cv2.BORDER_REPLICATE)


def plane_points(model: CameraModel, uv: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Where the rays of pixels ``uv`` (..., 2) of ``model`` meet the plane through ``point`` (3,) with ``normal``
    (3,) -> (..., 3) in the model's frame; NaN where a ray misses it (parallel or behind the camera)."""
    uv = np.asarray(uv, dtype=float)
    if uv.shape[-1] != 2:
        raise ValueError(f"uv: expected (..., 2), got {uv.shape}")
    X0 = np.asarray(point, dtype=float).reshape(3)
    n = np.asarray(normal, dtype=float).reshape(3)
    o, d = model.unproject(uv.reshape(-1, 2))
    o = np.broadcast_to(o, d.shape)
    den = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((X0 - o) @ n) / den
    P = o + t[:, None] * d
    P[~(np.isfinite(t) & (t > 0))] = np.nan
    return P.reshape(uv.shape[:-1] + (3,))
