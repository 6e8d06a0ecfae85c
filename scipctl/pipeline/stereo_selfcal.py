"""Every stereo pair of a downlink re-aligned from its own matches before any stereo runs on it.

:func:`self_calibrate_downlink` fits each pair's right-eye misalignment (:mod:`scipctl.core.stereo_selfcal`) and
returns a copy of the downlink whose right-eye products carry the turned models; point stereo, dense stereo, visual
odometry and the handoffs then read the corrected models through the products as before. A pair whose fit has too
little support keeps its downlinked model (its :class:`PairSelfCal` says why). The downlink given is not changed.

Fits made before can be given back (``known``, keyed by :func:`pair_key`): a pair whose key is known is not fitted
again. The key is a SHA-256 of everything the fit reads (both products' ids, pixels and models, the parameters)
and of the code that computes it (:func:`fit_code_identity`), so a known fit is the fit this code would make.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, replace
from typing import Callable, Mapping, Optional

from ..core.stereo_selfcal import StereoRotationFit, StereoSelfCalParams, fit_right_rotation, rotated_model, stereo_matches
from ..model import Downlink
from .code_identity import code_identity

__all__ = ["HANDOFF_CAMERAS", "PairSelfCal", "fit_code_identity", "handoff_pairs", "pair_key", "self_calibrate_downlink"]

HANDOFF_CAMERAS = ("navcam", "hazcam")  # the navcam -> hazcam handoff reads these cameras' pairs and no others


def handoff_pairs(left) -> bool:
    """``only`` for :func:`self_calibrate_downlink`: the pairs the navcam -> hazcam handoff reads."""
    return left.camera in HANDOFF_CAMERAS


@dataclass(frozen=True)
class PairSelfCal:
    """One pair's outcome: its products, camera, the fit, and whether the right model was replaced; ``key``: its
    :func:`pair_key` when the caller gave ``known`` fits (else ""), ``cached``: the fit was one of them."""

    left_product_id: str
    right_product_id: str
    camera: str
    fit: StereoRotationFit
    applied: bool
    key: str = ""
    cached: bool = False

    def to_dict(self) -> dict:
        """The record: the same for a fit given back as for the fit made (an uplinked sequence hashes these records,
        and the same inputs give the same bytes)."""
        return {"left": self.left_product_id, "right": self.right_product_id, "camera": self.camera,
                "applied": self.applied, **self.fit.to_dict()}


def fit_code_identity() -> str:
    """SHA-256 of the code a fit runs (:func:`~scipctl.pipeline.code_identity.code_identity`): every file of
    ``scipctl/core`` and this module, with the versions of NumPy, SciPy, OpenCV (SIFT) and Open3D. Any change to them
    makes every :func:`pair_key` new."""
    return code_identity(("core", "pipeline/stereo_selfcal.py"))


def pair_key(left, right, params: StereoSelfCalParams) -> str:
    """SHA-256 (hex) of what the fit of the pair ``left``, ``right`` (:class:`scipctl.model.ImageProduct`) reads:
    both ids, decoded pixels (and the value that is full scale) and camera models, ``params``, and the code."""
    h = hashlib.sha256()
    h.update(json.dumps({"code": fit_code_identity(), "params": asdict(params)}, sort_keys=True).encode())
    for im in (left, right):
        px = im.pixels
        h.update(json.dumps({"id": im.product_id, "model": im.camera_model.to_dict(), "dtype": str(px.dtype),
                             "shape": list(px.shape), "full_scale": float(im.full_scale)}, sort_keys=True).encode())
        h.update(px.tobytes(order="C"))
    return h.hexdigest()


def self_calibrate_downlink(dl: Downlink, params: StereoSelfCalParams = StereoSelfCalParams(),
                            only: Optional[Callable] = None,
                            known: Optional[Mapping[str, StereoRotationFit]] = None) -> tuple[Downlink, list[PairSelfCal]]:
    """``(downlink with re-aligned right models, one PairSelfCal per stereo pair fitted)``; pairs in product order.

    ``only``: a predicate on a left product (:class:`scipctl.model.ImageProduct`); the pairs whose left product it rejects
    are neither fitted nor changed (a command fits the pairs it reads: each pair's fit depends on that pair alone,
    so a pair's answer is the same whichever others are fitted). None: every pair.
    A right product paired with several left ones (it should not be) is fitted once, with the first.
    ``known``: fits made before, by :func:`pair_key` (None: every pair is fitted and no key is computed); a pair
    whose key is there takes that fit (``cached``), the others are fitted; every PairSelfCal then has its key.
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
        key = "" if known is None else pair_key(left, right, params)
        fit = known.get(key) if known is not None else None
        cached = fit is not None
        if fit is None:
            uv_l, uv_r = stereo_matches(left.pixels_float(), right.pixels_float(), params)
            fit = fit_right_rotation(left.camera_model, right.camera_model, uv_l, uv_r, params)
        if fit.ok:
            new_models[right.product_id] = rotated_model(right.camera_model, fit.rotvec_rad)
        out.append(PairSelfCal(left.product_id, right.product_id, left.camera, fit, fit.ok, key, cached))
    images = [replace(im, camera_model=new_models[im.product_id]) if im.product_id in new_models else im
              for im in dl.images]
    return replace(dl, images=images), out
