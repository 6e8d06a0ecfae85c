"""Linearisation of CAHVOR/CAHVORE models to CAHV and stereo-pair rectification.

In the spirit of JPL cmod's "warp models": both rectified models are CAHV,
share ``A``, ``H``, ``V`` (one image plane), keep their own ``C``; the
rectified ``A`` is perpendicular to the baseline and rows run along it, so a
3-D point falls on the same row in both rectified images, and its disparity
``d = u_left - u_right`` is ``>= 0`` in front of the cameras. The scale and
centre are chosen so the common field of view fits the output image, at no
more than the original centre resolution.

Non-central (CAHVORE) models are warped for points at ``ref_range_m`` from
the camera (as JPL's warp routines take an approximate distance).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .camera import CameraModel


def _unit(x):
    return x / np.linalg.norm(x)


def _border_pixels(width: int, height: int, n: int = 64) -> dict:
    us = np.linspace(-0.5, width - 0.5, n)
    vs = np.linspace(-0.5, height - 0.5, n)
    return {
        "left": np.stack([np.full(n, -0.5), vs], -1),
        "right": np.stack([np.full(n, width - 0.5), vs], -1),
        "top": np.stack([us, np.full(n, -0.5)], -1),
        "bottom": np.stack([us, np.full(n, height - 0.5)], -1),
    }


def _inner_box(model: CameraModel, width, height, A, h, v, max_tan):
    """Inner box (x0, x1, y0, y1) in normalised rectified coordinates of the model's image."""
    out = {}
    for side, uv in _border_pixels(width, height).items():
        _, d = model.unproject(uv)
        z = d @ A
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(z > 1e-6, (d @ h) / z, np.nan)
            y = np.where(z > 1e-6, (d @ v) / z, np.nan)
        out[side] = (x, y)
    x0 = np.nanmax(out["left"][0]) if np.any(np.isfinite(out["left"][0])) else -max_tan
    x1 = np.nanmin(out["right"][0]) if np.any(np.isfinite(out["right"][0])) else max_tan
    y0 = np.nanmax(out["top"][1]) if np.any(np.isfinite(out["top"][1])) else -max_tan
    y1 = np.nanmin(out["bottom"][1]) if np.any(np.isfinite(out["bottom"][1])) else max_tan
    return (max(x0, -max_tan), min(x1, max_tan), max(y0, -max_tan), min(y1, max_tan))


def linearize(model: CameraModel, width: int, height: int, out_width: Optional[int] = None,
              out_height: Optional[int] = None, max_half_fov_rad: float = np.radians(60)) -> CameraModel:
    """A CAHV model with the same ``C`` and axis ``A`` whose image covers the model's field of view (inner box).

    Pixels are square, at no more than the original centre resolution.
    """
    ow = out_width or width
    oh = out_height or height
    A = model.A
    h = _unit(model.h_axis - np.dot(model.h_axis, A) * A)
    v = np.cross(A, h)
    max_tan = np.tan(max_half_fov_rad)
    x0, x1, y0, y1 = _inner_box(model, width, height, A, h, v, max_tan)
    f = 0.5 * (model.hs + model.vs)
    f = min(f, (ow - 1) / (x1 - x0), (oh - 1) / (y1 - y0))
    hc = (ow - 1) / 2 - f * (x0 + x1) / 2
    vc = (oh - 1) / 2 - f * (y0 + y1) / 2
    return CameraModel("CAHV", C=model.C, A=A, H=f * h + hc * A, V=f * v + vc * A)


def _cubic_weights(n_out: int, step: int, n_nodes: int) -> np.ndarray:
    """(n_out, n_nodes) Catmull-Rom interpolation matrix from nodes at ``(k - 1) * step`` to pixels ``0..n_out-1``."""
    x = np.arange(n_out, dtype=float) / step + 1.0  # node coordinate (node 0 is one step before pixel 0)
    i = np.floor(x).astype(int)
    t = x - i
    w = np.stack([
        ((-t + 2) * t - 1) * t / 2,
        ((3 * t - 5) * t * t + 2) / 2,
        ((-3 * t + 4) * t + 1) * t / 2,
        (t - 1) * t * t / 2,
    ], -1)
    W = np.zeros((n_out, n_nodes))
    for k in range(4):
        np.add.at(W, (np.arange(n_out), np.clip(i - 1 + k, 0, n_nodes - 1)), w[:, k])
    return W


def _sampling_map(src: CameraModel, dst: CameraModel, width: int, height: int, ref_range_m: float, step: int = 8):
    """For each pixel of ``dst`` (height, width), the ``src`` pixel seeing the same ray (float32 maps).

    Computed exactly on a grid every ``step`` pixels and interpolated with
    Catmull-Rom cubics (the maps are smooth; the tests bound the error).
    """
    nu = int(np.ceil((width - 1) / step)) + 4
    nv = int(np.ceil((height - 1) / step)) + 4
    gu = (np.arange(nu) - 1.0) * step
    gv = (np.arange(nv) - 1.0) * step
    u, v = np.meshgrid(gu, gv)
    o, d = dst.unproject(np.stack([u, v], -1).reshape(-1, 2))
    src_uv = src.project(o + ref_range_m * d).reshape(nv, nu, 2)
    invalid = ~np.all(np.isfinite(src_uv), axis=-1)
    src_uv = np.where(invalid[..., None], 0.0, src_uv)
    Wu = _cubic_weights(width, step, nu)
    Wv = _cubic_weights(height, step, nv)
    mu = Wv @ src_uv[..., 0] @ Wu.T
    mv = Wv @ src_uv[..., 1] @ Wu.T
    if invalid.any():  # output pixels that any invalid node contributes to
        bad = (np.abs(Wv) @ invalid.astype(float) @ np.abs(Wu).T) > 1e-9
        mu[bad] = -1e6
        mv[bad] = -1e6
    return mu.astype(np.float32), mv.astype(np.float32)


@dataclass
class RectifiedPair:
    """A rectified stereo pair. Rectified pixel ``(u, v)`` of the left image samples ``map_left[k][v, u]`` of the original."""

    left_model: CameraModel  # CAHV, rectified (frame of the inputs)
    right_model: CameraModel
    orig_left: CameraModel
    orig_right: CameraModel
    width: int
    height: int
    map_left: tuple  # (map_u, map_v) float32 (height, width)
    map_right: tuple
    baseline_m: float
    ref_range_m: float

    @property
    def focal_px(self) -> float:
        return self.left_model.hs

    def rectify_left(self, img: np.ndarray, interpolation: Optional[int] = None) -> np.ndarray:
        return _remap(img, self.map_left, interpolation)

    def rectify_right(self, img: np.ndarray, interpolation: Optional[int] = None) -> np.ndarray:
        return _remap(img, self.map_right, interpolation)

    def left_uv_to_rect(self, uv, range_m=None) -> np.ndarray:
        """Original left pixels ``(N, 2)`` -> rectified left pixels ``(N, 2)`` (exact for central models)."""
        o, d = self.orig_left.unproject(np.asarray(uv, float))
        r = self.ref_range_m if range_m is None else np.asarray(range_m, float)[..., None]
        return self.left_model.project(o + r * d)

    def unrectify_left_uv(self, uv_rect, range_m=None) -> np.ndarray:
        """Rectified left pixels ``(N, 2)`` -> original left pixels ``(N, 2)``."""
        o, d = self.left_model.unproject(np.asarray(uv_rect, float))
        r = self.ref_range_m if range_m is None else np.asarray(range_m, float)[..., None]
        return self.orig_left.project(o + r * d)

    def disparity_to_depth(self, disparity_px) -> np.ndarray:
        """Depth along ``A`` (not range along the ray) from disparity (``f B / d``), metres; shape of ``disparity_px``."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.focal_px * self.baseline_m / np.asarray(disparity_px, float)


def _remap(img, maps, interpolation):
    import cv2

    interp = cv2.INTER_LINEAR if interpolation is None else interpolation
    return cv2.remap(img, maps[0], maps[1], interp, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


_CACHE: "OrderedDict[tuple, RectifiedPair]" = OrderedDict()
_CACHE_SIZE = 6  # a 1024^2 pair's maps are 16 MB


def _model_key(m: CameraModel) -> tuple:
    return tuple((k, tuple(v) if isinstance(v, list) else v) for k, v in sorted(m.to_dict().items()))


def rectify_pair_cached(left: CameraModel, right: CameraModel, width: int, height: int, **kw) -> RectifiedPair:
    """:func:`rectify_pair`, remembered for the last few model pairs (maps depend only on the models and sizes).

    Callers must not modify the returned maps.
    """
    key = (_model_key(left), _model_key(right), width, height, tuple(sorted(kw.items())))
    rp = _CACHE.get(key)
    if rp is None:
        rp = rectify_pair(left, right, width, height, **kw)
        _CACHE[key] = rp
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return rp


def rectify_pair(
    left: CameraModel,
    right: CameraModel,
    width: int,
    height: int,
    out_width: Optional[int] = None,
    out_height: Optional[int] = None,
    max_half_fov_rad: float = np.radians(60),
    ref_range_m: float = 2.0,
    scale: float = 1.0,
) -> RectifiedPair:
    """Rectify a stereo pair of models (any kind) for images of ``width`` x ``height``.

    ``scale`` < 1 makes a smaller rectified image (e.g. 0.5 for half resolution).
    """
    b = right.C - left.C
    B = float(np.linalg.norm(b))
    if B < 1e-6:
        raise ValueError("stereo pair: the two camera centres coincide (no baseline)")
    bh = b / B
    A0 = _unit(left.A + right.A)
    A = A0 - np.dot(A0, bh) * bh
    if np.linalg.norm(A) < 1e-3:
        raise ValueError("stereo pair: cameras look along the baseline")
    A = _unit(A)
    h = bh if np.dot(bh, left.h_axis) >= 0 else -bh
    v = np.cross(A, h)
    if np.dot(v, left.v_axis) < 0:  # keep the image upright
        h, v = -h, -v
        if np.dot(h, left.h_axis) < 0:
            raise ValueError("stereo pair: cannot make an upright rectified frame")
    max_tan = np.tan(max_half_fov_rad)
    bl = _inner_box(left, width, height, A, h, v, max_tan)
    br = _inner_box(right, width, height, A, h, v, max_tan)
    x0, x1 = max(bl[0], br[0]), min(bl[1], br[1])
    y0, y1 = max(bl[2], br[2]), min(bl[3], br[3])
    if not (x1 > x0 and y1 > y0):
        raise ValueError("stereo pair: the two fields of view do not overlap")
    ow = int(round((out_width or width) * scale)) if out_width is None else out_width
    oh = int(round((out_height or height) * scale)) if out_height is None else out_height
    f = 0.25 * (left.hs + left.vs + right.hs + right.vs) * scale
    f = min(f, (ow - 1) / (x1 - x0), (oh - 1) / (y1 - y0))
    hc = (ow - 1) / 2 - f * (x0 + x1) / 2
    vc = (oh - 1) / 2 - f * (y0 + y1) / 2
    H = f * h + hc * A
    V = f * v + vc * A
    lm = CameraModel("CAHV", C=left.C, A=A, H=H, V=V)
    rm = CameraModel("CAHV", C=right.C, A=A, H=H, V=V)
    return RectifiedPair(
        left_model=lm,
        right_model=rm,
        orig_left=left,
        orig_right=right,
        width=ow,
        height=oh,
        map_left=_sampling_map(left, lm, ow, oh, ref_range_m),
        map_right=_sampling_map(right, rm, ow, oh, ref_range_m),
        baseline_m=B,
        ref_range_m=ref_range_m,
    )
