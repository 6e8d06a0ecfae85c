"""One stereo pair of a handoff (images, models, its dense stereo computed once)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..camera import CameraModel


@dataclass
class StereoView:
    """One stereo pair: images ``(H, W)`` float32 and models in the rover frame at acquisition."""

    left_img: np.ndarray
    right_img: np.ndarray
    left_model: CameraModel
    right_model: CameraModel
    width: int
    height: int
    min_range_m: float = 0.4
    max_range_m: float = 30.0
    dense_downsample: int = 1
    _dense: object = field(default=None, repr=False)
    _cloud: object = field(default=None, repr=False)
    dense_seconds: float = 0.0

    @property
    def dense(self):
        """Dense stereo of the pair (computed once).

        Two passes: dense stereo's coarse pass (twice as coarse, over the whole
        range interval) finds the ranges actually in view (at full resolution:
        2nd-98th percentile, with a margin, bound the final ranges); the final
        pass at ``dense_downsample`` searches per row band only the disparities
        the coarse pass saw there (``dense_stereo(..., coarse=...)``).
        """
        if self._dense is None:
            from ..dense_stereo import dense_stereo, dense_stereo_coarse

            t0 = time.perf_counter()
            lo, hi = self.min_range_m, self.max_range_m
            coarse = None
            if self.dense_downsample <= 2:
                coarse = dense_stereo_coarse(self.left_img, self.right_img, self.left_model, self.right_model,
                                             min_range_m=lo, max_range_m=hi, downsample=self.dense_downsample)
            if coarse is not None and self.dense_downsample < 2:
                r = coarse.range_m[np.isfinite(coarse.range_m)]
                if r.size > 1000:
                    lo = max(lo, 0.85 * float(np.percentile(r, 2)))
                    hi = min(hi, 1.25 * float(np.percentile(r, 98)))
            self._dense = dense_stereo(
                self.left_img, self.right_img, self.left_model, self.right_model,
                min_range_m=lo, max_range_m=hi, downsample=self.dense_downsample, coarse=coarse,
            )
            self.dense_seconds = time.perf_counter() - t0
        return self._dense

    def cloud(self) -> tuple[np.ndarray, np.ndarray]:
        """Valid dense-stereo points ``(N, 3)`` (rover frame at acquisition) and their left intensities ``(N,)``
        (computed once; callers must not modify them)."""
        if self._cloud is None:
            self._cloud = self.dense.point_cloud()
        return self._cloud

    def xyz_at(self, uv) -> np.ndarray:
        """Dense-stereo points at original left pixels ``(N, 2)`` -> ``(N, 3)``, NaN where invalid."""
        return self.dense.xyz_at_left_uv(np.asarray(uv, float).reshape(-1, 2))
