"""Camera models of subframed and downsampled images (pure numerics).

A flight camera reads a window of its detector and may average ``s x s``
pixel blocks. With 0-based full-frame pixel coordinates (pixel centres at
integers, docs/conventions.md), the window whose first detector pixel is
``(x0, y0)`` (0-based column, row) and whose pixels average ``s x s``
detector pixels maps image pixel ``(u, v)`` to the full-frame point::

    u_full = x0 + s * u + (s - 1) / 2        v_full = y0 + s * v + (s - 1) / 2

Since every CAHV* model ends in ``u = (w . H) / (w . A)`` (the distortion acts
before it), the window's model keeps ``C, A, O, R, E`` and replaces
``H -> (H - (x0 + (s-1)/2) A) / s`` and ``V -> (V - (y0 + (s-1)/2) A) / s``.
This is exact for CAHV, CAHVOR and CAHVORE.
"""

from __future__ import annotations

from dataclasses import replace

from .camera import CameraModel


def subimage_model(model_full: CameraModel, x0_px: float, y0_px: float, scale: float = 1.0) -> CameraModel:
    """The model of the ``scale``-downsampled window starting at full-frame pixel ``(x0_px, y0_px)`` (0-based).

    ``model_full`` and the result are in the same 3-D frame; only the image
    coordinates change (see the module docstring).
    """
    s = float(scale)
    if not s > 0:
        raise ValueError(f"scale must be positive, got {scale!r}")
    du = float(x0_px) + (s - 1.0) / 2.0
    dv = float(y0_px) + (s - 1.0) / 2.0
    A = model_full.A
    return replace(model_full, H=(model_full.H - du * A) / s, V=(model_full.V - dv * A) / s)


def fullframe_model(model_sub: CameraModel, x0_px: float, y0_px: float, scale: float = 1.0) -> CameraModel:
    """Inverse of :func:`subimage_model`: the full-frame model from a window's model."""
    s = float(scale)
    if not s > 0:
        raise ValueError(f"scale must be positive, got {scale!r}")
    du = float(x0_px) + (s - 1.0) / 2.0
    dv = float(y0_px) + (s - 1.0) / 2.0
    A = model_sub.A
    return replace(model_sub, H=model_sub.H * s + du * A, V=model_sub.V * s + dv * A)
