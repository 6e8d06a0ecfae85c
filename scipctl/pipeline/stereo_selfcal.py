"""Every stereo pair of a downlink re-aligned from its own matches before any stereo runs on it.

:func:`self_calibrate_downlink` fits each pair's right-eye misalignment (:mod:`scipctl.core.stereo_selfcal`) and
returns a copy of the downlink whose right-eye products carry the turned models; point stereo, dense stereo, visual
odometry and the handoffs then read the corrected models through the products as before. A pair whose fit has too
little support keeps its downlinked model (its :class:`PairSelfCal` says why). The downlink given is not changed.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Optional

from ..core.stereo_selfcal import StereoRotationFit, StereoSelfCalParams, fit_right_rotation, rotated_model, stereo_matches
from ..model import Downlink

__all__ = ["HANDOFF_CAMERAS", "PairSelfCal", "handoff_pairs", "self_calibrate_downlink"]

HANDOFF_CAMERAS = ("navcam", "hazcam")  # the navcam -> hazcam handoff reads these cameras' pairs and no others


def handoff_pairs(left) -> bool:
    """``only`` for :func:`self_calibrate_downlink`: the pairs the navcam -> hazcam handoff reads."""
    return left.camera in HANDOFF_CAMERAS


@dataclass(frozen=True)
class PairSelfCal:
    """One pair's outcome: its products, camera, the fit, and whether the right model was replaced."""

    left_product_id: str
    right_product_id: str
    camera: str
    fit: StereoRotationFit
    applied: bool

    def to_dict(self) -> dict:
        return {"left": self.left_product_id, "right": self.right_product_id, "camera": self.camera,
                "applied": self.applied, **self.fit.to_dict()}


def self_calibrate_downlink(dl: Downlink, params: StereoSelfCalParams = StereoSelfCalParams(),
                            only: Optional[Callable] = None) -> tuple[Downlink, list[PairSelfCal]]:
    """``(downlink with re-aligned right models, one PairSelfCal per stereo pair fitted)``; pairs in product order.

    ``only``: a predicate on a left product (:class:`scipctl.model.ImageProduct`); the pairs whose left product it rejects
    are neither fitted nor changed (a command fits the pairs it reads: each pair's fit depends on that pair alone,
    so a pair's answer is the same whichever others are fitted). None: every pair.
    A right product paired with several left ones (it should not be) is fitted once, with the first.
    """
    params.check()
    out: list[PairSelfCal] = []
    new_models: dict = {}
    fitted: set = set()  # right product ids
    for left in dl.images:
        if left.eye != "left" or (only is not None and not only(left)):
            continue
        right = dl.stereo_pair(left)
        if right is None or right.product_id in fitted:
            continue
        fitted.add(right.product_id)
        uv_l, uv_r = stereo_matches(left.pixels_float(), right.pixels_float(), params)
        fit = fit_right_rotation(left.camera_model, right.camera_model, uv_l, uv_r, params)
        if fit.ok:
            new_models[right.product_id] = rotated_model(right.camera_model, fit.rotvec_rad)
        out.append(PairSelfCal(left.product_id, right.product_id, left.camera, fit, fit.ok))
    images = [replace(im, camera_model=new_models[im.product_id]) if im.product_id in new_models else im
              for im in dl.images]
    return replace(dl, images=images), out
