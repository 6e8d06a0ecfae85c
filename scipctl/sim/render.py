"""Ray-cast rendering through exact JPL camera models, and the camera's radiometry (pure numerics).

Every sub-pixel sample ``(u, v)`` is unprojected through the **true** camera
model (``CameraModel.unproject``: per-sample ray origin and direction; CAHVORE
is non-central) and cast into the scene with Open3D's ``RaycastingScene``.
``supersample`` x ``supersample`` samples per pixel on a regular grid inside
the pixel (centre ``(u, v)``, extent +-0.5 px) are box-filtered, so a pixel
value is the mean radiance over the pixel's footprint: sub-pixel truth is
meaningful. Shading: Lambertian albedo (a function of the 3-D point, see
``appearance.Appearance``) x (ambient + direct sun with shadow rays).

Octaves of the albedo finer than the pixel footprint are faded out
(anti-aliasing; the footprint is ``range x pixel angle / sqrt(|cos incidence|)``).

Radiometry (:func:`expose`): electrons = radiance x exposure x responsivity
x full well; Gaussian shot noise (variance = electrons) and read noise;
saturation at the full well; quantisation to 8 bits, or to 12 bits stored in
a 16-bit PNG by bit replication (``v16 = v12 << 4 | v12 >> 8``, the PNG
convention for fewer significant bits), so 1.0 is full scale in both.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..core.camera import CameraModel


def subpixel_offsets(supersample: int) -> np.ndarray:
    """``(s,)`` offsets in pixels of a regular ``s``-point grid over ``[-0.5, 0.5]`` (cell centres)."""
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample: must be >= 1, got {supersample}")
    return (np.arange(s) + 0.5) / s - 0.5


def crop_model(model: CameraModel, u0_px: float, v0_px: float) -> CameraModel:
    """The model of a window whose pixel (0, 0) is the original's ``(u0_px, v0_px)``: ``u' = u - u0``.

    ``H' = H - u0 A``, ``V' = V - v0 A``; rendering a crop through it gives exactly the original's pixels there.
    """
    from dataclasses import replace

    return replace(model, H=model.H - float(u0_px) * model.A, V=model.V - float(v0_px) * model.A)


def _block(scene, model_site: CameraModel, width: int, v0: int, v1: int, ss: int, shadows: bool, lod: bool):
    off = subpixel_offsets(ss)
    us = (np.arange(width)[:, None] + off[None, :]).ravel()  # (W*ss,)
    vs = (np.arange(v0, v1)[:, None] + off[None, :]).ravel()  # (R*ss,)
    U, V = np.meshgrid(us, vs)
    uv = np.stack([U, V], axis=-1).reshape(-1, 2)
    o, d = model_site.unproject(uv)
    hits = scene.cast(o, d)
    fp = None
    if lod:
        g = d.reshape(len(vs), len(us), 3)
        e = np.diff(g, axis=1)
        dh = np.sqrt(np.einsum("ijk,ijk->ij", e, e))
        dh = np.concatenate([dh, dh[:, -1:]], axis=1)
        if len(vs) > 1:
            e = np.diff(g, axis=0)
            dv = np.sqrt(np.einsum("ijk,ijk->ij", e, e))
            dv = np.concatenate([dv, dv[-1:]], axis=0)
        else:
            dv = dh
        ang = (ss * np.sqrt(dh * dv)).reshape(-1)  # rad per pixel
        cosi = np.abs(np.einsum("ij,ij->i", hits.normal, d))
        with np.errstate(invalid="ignore"):
            fp = np.where(hits.hit, hits.t_m * ang / np.sqrt(np.maximum(cosi, 0.05)), np.inf).astype(np.float32)
    rad = scene.radiance(hits, d, fp, shadows=shadows)
    return rad.reshape(v1 - v0, ss, width, ss).mean(axis=(1, 3), dtype=np.float64).astype(np.float32)


def render_radiance(scene, model_site: CameraModel, width: int, height: int, supersample: int = 2,
                    shadows: bool = True, lod: bool = True, rows_per_block: int = 32, threads: int = 2) -> np.ndarray:
    """Render ``(height, width)`` float32 radiance seen by ``model_site`` (a camera model in the SITE frame).

    Deterministic: blocks of rows are computed independently and assembled in order.
    """
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    scene.raycaster()  # build once before threading
    starts = list(range(0, height, rows_per_block))
    out = np.empty((height, width), np.float32)

    def job(v0):
        v1 = min(v0 + rows_per_block, height)
        out[v0:v1] = _block(scene, model_site, width, v0, v1, supersample, shadows, lod)

    if threads > 1 and len(starts) > 1:
        with ThreadPoolExecutor(max_workers=threads) as ex:
            list(ex.map(job, starts))
    else:
        for v0 in starts:
            job(v0)
    return out


@dataclass(frozen=True)
class Sensor:
    """A camera's radiometry. ``bits`` is 8 or 12 (12-bit data go into a 16-bit PNG)."""

    bits: int = 8
    full_well_e: float = 20000.0
    read_noise_e: float = 12.0
    target_fraction: float = 0.75  # auto-exposure puts the 99.5th percentile here

    def __post_init__(self):
        if self.bits not in (8, 12):
            raise ValueError(f"bits: must be 8 or 12, got {self.bits}")


def auto_exposure(radiance: np.ndarray, sensor: Sensor) -> float:
    """Exposure scale (full-well fractions per unit radiance) that puts the 99.5th percentile at ``target_fraction``."""
    p = float(np.percentile(radiance, 99.5))
    return sensor.target_fraction / max(p, 1e-6)


def bit_replicate_12(v: np.ndarray) -> np.ndarray:
    """12-bit values (uint16 array, 0..4095) -> 16-bit words with the top bits repeated below (``v << 4 | v >> 8``):
    how a 12-bit image is stored in a 16-bit PNG."""
    return (v << 4) | (v >> 8)


def expose(radiance: np.ndarray, exposure: float, responsivity: float, sensor: Sensor,
           rng: np.random.Generator | None) -> np.ndarray:
    """Radiance ``(H, W)`` -> pixels: uint8 (8 bits) or uint16 (12 bits, bit-replicated to 16). ``rng`` None: no noise."""
    fw = sensor.full_well_e
    e = radiance.astype(np.float64) * (exposure * responsivity * fw)
    e = np.clip(e, 0, None)
    if rng is not None:
        e = e + np.sqrt(e) * rng.standard_normal(e.shape) + sensor.read_noise_e * rng.standard_normal(e.shape)
    full = (1 << sensor.bits) - 1
    dn = np.clip(np.rint(e / fw * full), 0, full)
    if sensor.bits == 8:
        return dn.astype(np.uint8)
    return bit_replicate_12(dn.astype(np.uint16))
