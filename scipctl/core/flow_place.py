"""Placing a tracked point by dense optical flow between its rendered template and the image.

NCC of a rendered template finds the translation that best aligns the whole window; where the template was drawn
through a plane and the ground has relief, each template pixel is off along the line of sight by its own height
above that plane, and the window's best translation is a weighted mean of those offsets, not the offset at the
tracked point. The flow between the template (placed at the NCC peak) and the image measures the residual offset
pixel by pixel, with a smoothness the window-wide translation lacks; its value at the tracked point places it
(docs/stereo-and-tracking.md, "Optical flow places the first pancam track").

OpenCV's DIS optical flow (Kroeger et al. 2016, ``cv2.DISOpticalFlow``) on 8-bit views of the two windows, the
image's window first matched to the template's mean and spread over the pixels the template covers.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

# the image's window is the template's grown by this many pixels on each side (room for the residual flow)
FLOW_MARGIN_PX = 6
# the flow at the tracked point: the mean over the (2 h + 1)^2 pixels around it
FLOW_AVERAGE_HALF_PX = 2
# the DIS preset: "ultrafast", "fast" or "medium" (cv2.DISOPTICAL_FLOW_PRESET_*)
FLOW_PRESET = "medium"
# ... with its finest pyramid level set to this (0: full resolution). The presets stop at level 1 (the flow at half
# resolution, upsampled), which smooths an offset that varies over the template's centre: on a synthetic bump of
# 2-3 px along v (sigma 6-14 px) DIS recovers 38-73 % of it at level 1 and 76-92 % at level 0 (session 51)
FLOW_FINEST_SCALE = 0


def _to_uint8(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return np.clip((a - lo) / max(hi - lo, 1e-6) * 255.0, 0, 255).astype(np.uint8)


def flow_place(template, image, found_uv, centre_in_template_uv, margin_px: int = FLOW_MARGIN_PX,
               average_half_px: int = FLOW_AVERAGE_HALF_PX, preset: str = FLOW_PRESET,
               finest_scale: int = FLOW_FINEST_SCALE) -> Optional[np.ndarray]:
    """The tracked point placed by the optical flow from ``template`` to ``image`` at its NCC position.

    Parameters
    ----------
    template : (h, w) real array, finite
        The rendered window (the NCC's template).
    image : (H, W) real array
        The image it was found in.
    found_uv : (2,)
        Where NCC put the template's point ``centre_in_template_uv`` in ``image`` (pixels, ``(u, v)``).
    centre_in_template_uv : (2,)
        The tracked point in template pixels (may be fractional).

    Returns
    -------
    (2,) float array: ``found_uv`` plus the flow at the tracked point (mean over ``average_half_px`` around it);
    None when the window around ``found_uv`` does not lie inside the image, ``found_uv`` is not finite, the
    template is flat, or the flow is not finite there.
    """
    import cv2

    from .image import as_float_image

    tpl = as_float_image(template, "flow_place: template")
    img = as_float_image(image, "flow_place: image")
    presets = {"ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
               "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}
    if preset not in presets:
        raise ValueError(f"flow_place: preset must be one of {', '.join(presets)}, got {preset!r}")
    found = np.asarray(found_uv, float).reshape(2)
    tc = np.asarray(centre_in_template_uv, float).reshape(2)
    if not (np.all(np.isfinite(found)) and np.all(np.isfinite(tc)) and np.all(np.isfinite(tpl))):
        return None
    th, tw = tpl.shape
    hh, hw = th // 2 + margin_px, tw // 2 + margin_px
    c = np.round(found).astype(int)
    if c[0] - hw < 0 or c[1] - hh < 0 or c[0] + hw >= img.shape[1] or c[1] + hh >= img.shape[0]:
        return None
    patch = img[c[1] - hh:c[1] + hh + 1, c[0] - hw:c[0] + hw + 1].copy()
    size = (2 * hw + 1, 2 * hh + 1)
    at = found - (c - np.array([hw, hh]))  # the tracked point in the patch
    shift = np.float32([[1, 0, at[0] - tc[0]], [0, 1, at[1] - tc[1]]])
    placed = cv2.warpAffine(tpl, shift, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    covered = cv2.warpAffine(np.ones_like(tpl), shift, size, flags=cv2.INTER_LINEAR, borderValue=0) > 0.99
    a, b = placed[covered], patch[covered]
    if a.size < 9 or a.std() <= 0 or b.std() <= 0:
        return None
    # the image's window in the template's units (mean and spread over the pixels the template covers)
    patch = (patch - b.mean()) / b.std() * a.std() + a.mean()
    lo, hi = np.percentile(a, [0.5, 99.5])
    dis = cv2.DISOpticalFlow_create(presets[preset])
    dis.setFinestScale(int(finest_scale))
    flow = dis.calc(_to_uint8(placed, lo, hi), _to_uint8(patch, lo, hi), None)
    x, y = int(round(at[0])), int(round(at[1]))
    k = average_half_px
    d = flow[max(y - k, 0):y + k + 1, max(x - k, 0):x + k + 1].reshape(-1, 2).mean(0).astype(float)
    if not np.all(np.isfinite(d)):
        return None
    return found + d
