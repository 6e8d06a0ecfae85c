"""One navcam pair -> hazcam pair handoff and its shared, cached products (pure numerics)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable, Optional

import numpy as np

from ..camera import CameraModel
from ..expected import ProjectionMap
from ..registration import select_rows, squared_distances
from ..transforms import RigidTransform
from .params import HandoffParams
from .result import MethodResult, NoAnswer
from .view import StereoView


@dataclass
class HandoffCase:
    """Handoff from one navcam pair to the hazcam pair, and the products every method and target share.

    ``T_haz_nav`` maps points in the rover frame at the navcam acquisition into
    the rover frame at the hazcam acquisition (identity for near navcams; from
    the pose estimates for far navcams). The products (point stereo per target,
    the clouds, the whole-cloud registration, hazcam point stereo, cached method
    steps) are computed once, on first use, with ``params``; the methods
    themselves are functions in the family modules, looked up by name in
    :data:`~scipctl.core.handoff.registry.METHODS`.
    """

    label: str  # "near" | "far"
    nav: StereoView
    haz: StereoView
    T_haz_nav: RigidTransform
    params: HandoffParams = field(default_factory=HandoffParams)
    _cache: dict = field(default_factory=dict, repr=False)
    registration_seconds: Optional[float] = field(default=None, repr=False)  # wall time of whole_registration

    def __post_init__(self):
        if self.label not in ("near", "far"):
            raise ValueError(f"HandoffCase.label must be 'near' or 'far', got {self.label!r}")
        self.params.check()

    def memo(self, key, compute: Callable[[], object]):
        """``compute()`` once per ``key`` (hashable) for this case; its value afterwards, or the
        :class:`~scipctl.core.handoff.result.NoAnswer` it raised, raised again. For method steps that several
        methods share (the pure-geometric point)."""
        if key not in self._cache:
            try:
                self._cache[key] = compute()
            except NoAnswer as e:
                self._cache[key] = e
                raise
        v = self._cache[key]
        if isinstance(v, NoAnswer):
            raise v
        return v

    # ----------------------------------------------------------- navcam side
    def point_stereo(self, nav_uv) -> object:
        """Navcam point stereo at the navcam-left pixel ``nav_uv`` (2,) (cached per pixel):
        a :func:`~scipctl.core.point_stereo.point_stereo` result, point in the navcam rover frame."""
        key = ("ps", tuple(np.round(np.asarray(nav_uv, float), 6)))
        if key not in self._cache:
            from ..point_stereo import point_stereo

            self._cache[key] = point_stereo(
                self.nav.left_img, self.nav.right_img, self.nav.left_model, self.nav.right_model,
                np.asarray(nav_uv, float), band_px=self.params.point_stereo_band_px,
                window_px=self.params.point_stereo_window_px,
            )
        return self._cache[key]

    def nav_cloud_in_haz(self) -> tuple[np.ndarray, np.ndarray]:
        """Navcam dense cloud ``(N, 3)`` moved into the hazcam rover frame, and its intensities ``(N,)``."""
        if "nav_cloud" not in self._cache:
            pts, val = self.nav.cloud()
            self._cache["nav_cloud"] = (self.T_haz_nav.apply(pts), val)
        return self._cache["nav_cloud"]

    def nav_model_in_haz(self) -> CameraModel:
        """The navcam-left model moved into the hazcam rover frame."""
        return self.nav.left_model.transformed(self.T_haz_nav)

    # ----------------------------------------------------------- hazcam side
    def haz_cloud(self) -> np.ndarray:
        """Hazcam dense cloud ``(N, 3)``, hazcam rover frame."""
        if "haz_cloud" not in self._cache:
            pts, _ = self.haz.cloud()
            self._cache["haz_cloud"] = pts
        return self._cache["haz_cloud"]

    def haz_model(self) -> CameraModel:
        return self.haz.left_model

    def haz_in_nav(self) -> ProjectionMap:
        """The hazcam dense grid (rectified left, hazcam rover frame) projected into the navcam as needed
        (a :class:`~scipctl.core.expected.ProjectionMap`, once per case)."""
        if "haz_in_nav" not in self._cache:
            self._cache["haz_in_nav"] = ProjectionMap(self.haz.dense.xyz, self.nav_model_in_haz())
        return self._cache["haz_in_nav"]

    def haz_point(self, haz_uv, range_hint_m: Optional[float] = None):
        """Point stereo on the hazcam pair at the left-hazcam pixel ``haz_uv`` (2,) (cached).

        The small correlation window (``haz_point_stereo_window_px``) with the
        affine-refined NCC keeps sharp relief (corners) that the dense
        stereo's smoothing rounds; ``range_hint_m`` bounds the search to
        +-``haz_point_stereo_range_frac`` of it. Returns the 3-D point ``(3,)``
        (hazcam rover frame) or None (also when that band lies outside the
        hazcam view's own range window: nothing there to find).
        """
        p = self.params
        uv = np.asarray(haz_uv, float).reshape(2)
        key = ("hps", tuple(np.round(uv, 4)))
        if key not in self._cache:
            from ..point_stereo import point_stereo

            lo, hi = self.haz.min_range_m, self.haz.max_range_m
            if range_hint_m is not None and np.isfinite(range_hint_m):
                f = p.haz_point_stereo_range_frac
                lo, hi = max(lo, (1 - f) * range_hint_m), min(hi, (1 + f) * range_hint_m)
            if not lo < hi:  # a hint beyond the window (a candidate from a wrong navcam pixel): no point there
                self._cache[key] = None
                return None
            ps = point_stereo(
                self.haz.left_img, self.haz.right_img, self.haz.left_model, self.haz.right_model, uv,
                band_px=p.point_stereo_band_px, window_px=p.haz_point_stereo_window_px,
                min_range_m=lo, max_range_m=hi,
            )
            self._cache[key] = ps.xyz.copy() if ps.ok else None
        return self._cache[key]

    # ----------------------------------------------------------- registration
    def whole_registration(self):
        """ICP of the whole navcam cloud onto the hazcam cloud from several seeds (``T_haz_nav``, perturbed by its
        error model, and a global registration; cached): a
        :class:`~scipctl.core.registration_check.CheckedRegistration`, or the ``ValueError`` saying why there is
        none.
        Waits for the computation :meth:`start_registration` started, if any."""
        if "whole_reg" not in self._cache:
            fut = self._cache.pop("whole_reg_future", None)
            self._cache["whole_reg"] = fut.result() if fut is not None else self._compute_registration()
        return self._cache["whole_reg"]

    def start_registration(self, executor) -> None:
        """Start :meth:`whole_registration` on ``executor`` (a ``concurrent.futures`` executor) and return.

        ICP runs in Open3D without Python's global lock, so the caller's thread
        can run the other methods meanwhile (on two cores this hides most of
        the registration time). The dense stereo of both views and their clouds
        are computed first, in the caller's thread, so that nothing shared is
        computed by two threads.
        """
        if "whole_reg" in self._cache or "whole_reg_future" in self._cache:
            return
        self.nav.cloud()
        self.haz_cloud()
        self._cache["whole_reg_future"] = executor.submit(self._compute_registration)

    def _compute_registration(self):
        from ..global_registration import global_registration
        from ..registration import prepare_clouds
        from ..registration_check import checked_registration

        t0 = time.perf_counter()
        nav_pts, _ = self.nav.cloud()
        haz_pts = self.haz_cloud()
        C = self.haz.left_model.C
        r = self.params.registration_max_range_m
        haz_pts = select_rows(haz_pts, squared_distances(haz_pts, C) < r**2)
        # the navcam cloud where it can overlap the hazcam's, i.e. within r + 1 m of the hazcam seeded into the
        # navcam frame (distances are the same in both frames: no need to move the whole cloud)
        nav_pts = select_rows(nav_pts, squared_distances(nav_pts, self.T_haz_nav.inverse().apply(C)) < (r + 1.0) ** 2)
        check = self.params.registration_check
        sigma = check.seed_sigma(self.T_haz_nav, self.nav.left_model.C, moved=self.label == "far")
        try:
            prepared = prepare_clouds(
                nav_pts, haz_pts, self.T_haz_nav,
                # far seeds carry the pose-estimate error (decimetres): start coarser
                scales_m=(self.params.registration_near_scales_m if self.label == "near"
                          else self.params.registration_far_scales_m),
                # hazcam stereo's range uncertainty grows as r^2 (0.25 px: 3 cm at 1.9 m, 21 cm at 5 m)
                target_noise=(C, self.params.registration_disparity_sigma_px / self.haz.dense.focal_baseline_px_m))
            glob = None
            if check.run_global:
                # FPFH + RANSAC on the finest grids (the source seeded: identity prior), matches kept within
                # global_prior_sigmas seed sigmas of the seed at the overlap's far end
                src_seeded, tgt = (np.asarray(pc.points) for pc in prepared.grids[min(prepared.scales_m)])
                radius = check.global_prior_sigmas * float(sigma.displacement_sigma_m(tgt).max())
                g = global_registration(src_seeded, sigma.pivot_m, tgt, C, check.global_params,
                                        prior=(RigidTransform.identity(), radius))
                glob = g if g.T_target_source is None else replace(
                    g, T_target_source=g.T_target_source @ self.T_haz_nav)
            reg = checked_registration(prepared, sigma, check, glob)
        except ValueError as e:
            return e
        self.registration_seconds = time.perf_counter() - t0
        return reg
