"""Navcam -> hazcam handoff methods (pure numerics).

The paper's twelve methods are six methods, each run from "near" navcams (the
pair taken at the hazcam's rover position) or "far" navcams (a pair taken
earlier, a few metres back, which brings the rover's pose estimate into the
chain). A :class:`HandoffCase` holds one navcam pair, the hazcam pair and the
transform between their rover frames; its shared products (dense stereo,
clouds, registrations) are computed once and reused by every method and
target.

Paper methods (names used on the command line and in JSON):

``pure-kinematic``      point stereo on the navcams -> 3-D -> hazcam model.
``alt-pure-kinematic``  the same with the dense ("JPL", rectified) stereo range.
``refined-kinematic``   near: expected hazcam window splatted from the navcam
                        dense cloud, centred on the alt-pure-kinematic point,
                        NCC-tracked into the hazcam image; far: the far navcam
                        window brought into the hazcam view, tracked around the
                        near pure-kinematic point (as in the paper). Beyond the
                        paper, the window is warped through the local plane (fitted
                        to the far navcam's dense points around the target) instead
                        of scaled uniformly by the IFOV and range ratios — the
                        "affine warping" the paper left unexplored; the uniform
                        scale (``far_window_warp="scale"``) misses by ~4 px off the
                        fish-eye hazcam's axis even with no error.
``pure-geometric``      hazcam dense cloud -> navcam image; the hazcam point whose
                        projection lands nearest the navcam target. Beyond the
                        paper, refined by Gauss-Newton on the hazcam pixel with
                        hazcam point stereo for the range (the dense range's
                        few-mm error at one pixel is ~1 px of handoff error).
``refined-geometric``   the navcam image draped over the hazcam stereo surface as
                        the expected hazcam window (anti-aliased to the hazcam
                        pixel footprint), centred on the pure-geometric point,
                        NCC-tracked.
``mesh-registration``   ICP between the navcam and hazcam clouds (seeded with the
                        mast kinematics for near, the pose estimate for far), then
                        kinematic handoff through the recovered transform.

Methods beyond the paper (see docs/handoff.md):

``coarse-fine-geometric`` the paper's suggestion for refinement failures: track a
                        large draped window (more context) first, then the
                        small one within a few pixels of that answer.
``consensus``           of coarse-fine-geometric, refined-geometric and
                        refined-kinematic, those with NCC peak above
                        ``consensus_min_score`` that agree within
                        ``consensus_agree_px`` (two or more): their mean, flagged
                        confident; otherwise the pure-geometric answer, flagged
                        not confident. Failure detection from expected images
                        built in different ways.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .camera import CameraModel
from .expected import (
    bilinear_sample,
    drape,
    footprint_blur_cov,
    gaussian_blur_cov,
    match_projection,
    nearest_projection,
    plane_points,
    ProjectionMap,
    project_map,
    splat_points,
)
from ..jsonutil import finite_or_none
from .transforms import RigidTransform
from .registration import select_rows, squared_distances

PAPER_METHODS = (
    "pure-kinematic",
    "alt-pure-kinematic",
    "refined-kinematic",
    "pure-geometric",
    "refined-geometric",
    "mesh-registration",
)
EXTRA_METHODS = ("coarse-fine-geometric", "consensus")
ALL_METHODS = PAPER_METHODS + EXTRA_METHODS


@dataclass
class HandoffParams:
    template_half_px: int = 15  # expected hazcam window: 31 x 31 px
    search_radius_px: float = 60.0  # NCC search around the method's starting point (hazcam px)
    refined_min_score: float = 0.0  # the paper's refined methods always answer; the score is reported
    point_stereo_band_px: float = 3.0
    point_stereo_window_px: int = 21
    nav_cloud_radius_m: float = 0.6  # navcam points used for the expected window (around the target)
    registration_max_range_m: float = 5.0  # whole-cloud ICP uses points within this range of the hazcam
    # ... and at each ICP scale only the hazcam points whose stereo range uncertainty (this disparity uncertainty,
    # the same a priori figure as point stereo's) is within the scale's correspondence distance
    registration_disparity_sigma_px: float = 0.25
    dense_downsample: int = 1  # shared dense stereo: 1 full resolution (accurate), 2 half (fast)
    coarse_template_half_px: int = 40
    fine_search_px: float = 4.0
    consensus_agree_px: float = 3.0
    consensus_min_score: float = 0.5
    haz_point_stereo_window_px: int = 11  # pure geometric refinement (0: the paper's dense-only answer)
    haz_point_stereo_range_frac: float = 0.15  # its range search: +-15 % around the dense range
    geometric_iterations: int = 6
    geometric_max_residual_px: float = 0.5  # navcam px; a refinement that does not converge is not used
    far_window_warp: str = "plane"  # refined-kinematic far: "plane" (local plane warp) or "scale" (the paper's)
    drape_antialias: bool = True  # draped windows: navcam blurred to the hazcam pixel footprint
    far_plane_radius_m: float = 0.05  # its plane fit: navcam dense points within this distance of the target


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
            from .dense_stereo import dense_stereo, dense_stereo_coarse

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


@dataclass
class MethodResult:
    method: str
    navcam: str  # "near" | "far"
    ok: bool
    uv: Optional[np.ndarray]  # (2,) predicted hazcam-left pixel, None when the method gave no answer
    reason: str = ""
    diagnostics: dict = field(default_factory=dict)
    seconds: float = 0.0


@dataclass
class HandoffCase:
    """Handoff from one navcam pair to the hazcam pair.

    ``T_haz_nav`` maps points in the rover frame at the navcam acquisition into
    the rover frame at the hazcam acquisition (identity for near navcams; from
    the pose estimates for far navcams).
    """

    label: str  # "near" | "far"
    nav: StereoView
    haz: StereoView
    T_haz_nav: RigidTransform
    params: HandoffParams = field(default_factory=HandoffParams)
    _cache: dict = field(default_factory=dict, repr=False)
    registration_seconds: Optional[float] = field(default=None, repr=False)  # wall time of whole_registration

    # ----------------------------------------------------------- shared
    def point_stereo(self, nav_uv) -> object:
        key = ("ps", tuple(np.round(np.asarray(nav_uv, float), 6)))
        if key not in self._cache:
            from .point_stereo import point_stereo

            self._cache[key] = point_stereo(
                self.nav.left_img, self.nav.right_img, self.nav.left_model, self.nav.right_model,
                np.asarray(nav_uv, float), band_px=self.params.point_stereo_band_px,
                window_px=self.params.point_stereo_window_px,
            )
        return self._cache[key]

    def nav_cloud_in_haz(self) -> tuple[np.ndarray, np.ndarray]:
        if "nav_cloud" not in self._cache:
            pts, val = self.nav.cloud()
            self._cache["nav_cloud"] = (self.T_haz_nav.apply(pts), val)
        return self._cache["nav_cloud"]

    def haz_cloud(self) -> np.ndarray:
        if "haz_cloud" not in self._cache:
            pts, _ = self.haz.cloud()
            self._cache["haz_cloud"] = pts
        return self._cache["haz_cloud"]

    def haz_model(self) -> CameraModel:
        return self.haz.left_model

    def nav_model_in_haz(self) -> CameraModel:
        return self.nav.left_model.transformed(self.T_haz_nav)

    def whole_registration(self):
        """ICP of the whole navcam cloud onto the hazcam cloud, seeded with ``T_haz_nav`` (cached): a
        :class:`~scipctl.core.registration.RegistrationResult`, or the ``ValueError`` saying why there is none.
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
        from .registration import register_clouds

        t0 = time.perf_counter()
        nav_pts, _ = self.nav.cloud()
        haz_pts = self.haz_cloud()
        C = self.haz.left_model.C
        r = self.params.registration_max_range_m
        haz_pts = select_rows(haz_pts, squared_distances(haz_pts, C) < r**2)
        # the navcam cloud where it can overlap the hazcam's, i.e. within r + 1 m of the hazcam seeded into the
        # navcam frame (distances are the same in both frames: no need to move the whole cloud)
        nav_pts = select_rows(nav_pts, squared_distances(nav_pts, self.T_haz_nav.inverse().apply(C)) < (r + 1.0) ** 2)
        try:
            reg = register_clouds(
                nav_pts, haz_pts, self.T_haz_nav,
                # far seeds carry the pose-estimate error (decimetres): start coarser
                scales_m=(0.08, 0.04, 0.02) if self.label == "near" else (0.32, 0.16, 0.08, 0.04, 0.02),
                # hazcam stereo's range uncertainty grows as r^2 (0.25 px: 3 cm at 1.9 m, 21 cm at 5 m)
                target_noise=(C, self.params.registration_disparity_sigma_px / self.haz.dense.focal_baseline_px_m))
        except ValueError as e:
            return e
        self.registration_seconds = time.perf_counter() - t0
        return reg

    # ----------------------------------------------------------- helpers
    def _project_haz(self, X_haz) -> np.ndarray:
        return self.haz.left_model.project(np.asarray(X_haz, float).reshape(1, 3))[0]

    def _track(self, template, start_uv, radius_px, min_score, template_center_uv=None):
        from .tracking import track

        return track(
            template, self.haz.left_img, start_uv, radius_px, template_center_uv=template_center_uv,
            min_score=min_score,
        )

    def _draped_window(self, centre_uv, T_haz_nav: RigidTransform, half: int):
        """Expected hazcam window (2 half + 1)^2 around ``centre_uv``: navcam image draped over hazcam stereo.

        Beyond the paper: the navcam image is low-pass filtered before it is
        sampled (:func:`~scipctl.core.expected.footprint_blur_cov` of the local
        navcam-per-hazcam pixel Jacobian at the window centre), so that a
        navcam finer than the hazcam at the target (near navcams, ~1.5 navcam px
        per hazcam px) is integrated over the hazcam pixel's footprint as the
        hazcam itself does, instead of point-sampled (aliased).
        """
        k = half
        c = np.round(np.asarray(centre_uv, float))
        us, vs = np.meshgrid(np.arange(c[0] - k, c[0] + k + 1), np.arange(c[1] - k, c[1] + k + 1))
        uv = np.stack([us, vs], -1).reshape(-1, 2)
        X_haz = self.haz.xyz_at(uv)
        X_nav = T_haz_nav.inverse().apply(np.where(np.isfinite(X_haz), X_haz, 0.0))
        X_nav[~np.all(np.isfinite(X_haz), axis=1)] = np.nan
        if self.params.drape_antialias:
            q = project_map(X_nav.reshape(2 * k + 1, 2 * k + 1, 3), self.nav.left_model)
            A = _map_jacobian(q)
            vals = self._sample_nav(q, A) if A is not None else drape(X_nav, self.nav.left_model, self.nav.left_img)
        else:
            vals = drape(X_nav, self.nav.left_model, self.nav.left_img)
        vals = np.asarray(vals, np.float32).reshape(2 * k + 1, 2 * k + 1)
        frac = float(np.isfinite(vals).mean())
        return _fill_nan(vals), frac, c

    def _nav_plane_normal(self, nav_uv, X_nav, half_px: Optional[int] = None) -> Optional[np.ndarray]:
        """Unit normal ``(3,)`` (navcam rover frame) of a plane fitted to the navcam dense points around the target.

        Points on a ``(2 h + 1)^2`` pixel grid around ``nav_uv`` (``h``: the
        hazcam template's size in navcam pixels, from ``far_plane_radius_m``),
        within ``far_plane_radius_m`` of the target ``X_nav``; least squares
        (SVD), refitted once without the points beyond 3x the median residual.
        None with fewer than 30 points.
        """
        p = self.params
        r = p.far_plane_radius_m
        if half_px is None:
            rng = float(np.linalg.norm(X_nav - self.nav.left_model.C))
            half_px = int(np.clip(np.ceil(r / (rng * local_ifov_rad(self.nav.left_model, nav_uv))), 3, 60))
        c = np.asarray(nav_uv, float)
        us, vs = np.meshgrid(np.arange(-half_px, half_px + 1), np.arange(-half_px, half_px + 1))
        uv = c + np.stack([us, vs], -1).reshape(-1, 2)
        P = self.nav.xyz_at(uv)
        P = P[np.all(np.isfinite(P), axis=1)]
        P = P[np.linalg.norm(P - X_nav, axis=1) < r]
        for _ in range(2):
            if len(P) < 30:
                return None
            m = P.mean(axis=0)
            _, _, Vt = np.linalg.svd(P - m, full_matrices=False)
            n = Vt[2]
            res = np.abs((P - m) @ n)
            P = P[res <= max(3.0 * float(np.median(res)), 1e-4)]
        return n / np.linalg.norm(n)

    def _plane_window(self, X_haz, n_haz, half: int):
        """Expected hazcam window from the navcam image through the local plane (beyond the paper).

        The ``(2 half + 1)^2`` hazcam pixels around the projection of the target
        ``X_haz`` (3,) are cast onto the plane through it with normal ``n_haz``
        (both in the hazcam rover frame), the plane points projected into the
        navcam (through ``T_haz_nav``), and the navcam image sampled there after
        the anti-alias blur of :func:`~scipctl.core.expected.footprint_blur_cov`.
        Returns ``(template, template centre uv (2,), A (2, 2) navcam px per hazcam px)``
        or ``(None, None, None)``.
        """
        centre = self._project_haz(X_haz)
        if not np.all(np.isfinite(centre)):
            return None, None, None
        k = half
        c = np.round(centre)
        us, vs = np.meshgrid(np.arange(c[0] - k, c[0] + k + 1), np.arange(c[1] - k, c[1] + k + 1))
        grid = np.stack([us, vs], -1)
        P = plane_points(self.haz.left_model, grid, X_haz, n_haz)
        q = self.nav.left_model.project(self.T_haz_nav.inverse().apply(P.reshape(-1, 3))).reshape(grid.shape)
        A = np.stack([(q[k, k + 1] - q[k, k - 1]) / 2, (q[k + 1, k] - q[k - 1, k]) / 2], axis=1)
        if not (np.all(np.isfinite(A)) and np.isfinite(q).mean() > 0.9):
            return None, None, None
        vals = self._sample_nav(q, A)
        tpl = _fill_nan(vals)
        if tpl is None:
            return None, None, None
        return tpl, centre - (c - k), A

    def _sample_nav(self, q: np.ndarray, A: np.ndarray) -> np.ndarray:
        """The navcam-left image at navcam pixels ``q`` (h, w, 2), anti-aliased for ``A`` = d(navcam px)/d(hazcam px)."""
        ok = np.all(np.isfinite(q), axis=-1)
        out = np.full(q.shape[:-1], np.nan, np.float32)
        if not ok.any():
            return out
        cov = footprint_blur_cov(A)
        pad = int(np.ceil(3 * np.sqrt(max(cov[0, 0], cov[1, 1])))) + 2
        H, W = self.nav.left_img.shape
        u0 = int(max(np.floor(q[ok][:, 0].min()) - pad, 0))
        v0 = int(max(np.floor(q[ok][:, 1].min()) - pad, 0))
        u1 = int(min(np.ceil(q[ok][:, 0].max()) + pad + 1, W))
        v1 = int(min(np.ceil(q[ok][:, 1].max()) + pad + 1, H))
        if u1 - u0 < 2 or v1 - v0 < 2:
            return out
        crop = gaussian_blur_cov(self.nav.left_img[v0:v1, u0:u1], cov)
        out[ok] = bilinear_sample(crop, q[ok] - [u0, v0])
        return out

    # ----------------------------------------------------------- methods
    def run(self, method: str, nav_uv, near_hint: Optional[MethodResult] = None) -> MethodResult:
        """Run one method for the navcam-left pixel ``nav_uv`` (2,).

        ``near_hint``: the near-navcam pure-kinematic result for the same
        target; far refined-kinematic centres its search there, as the paper does.
        """
        self._near_hint = near_hint
        fn = {
            "pure-kinematic": self._pure_kinematic,
            "alt-pure-kinematic": self._alt_pure_kinematic,
            "refined-kinematic": self._refined_kinematic,
            "pure-geometric": self._pure_geometric,
            "refined-geometric": self._refined_geometric,
            "mesh-registration": self._mesh_registration,
            "coarse-fine-geometric": self._coarse_fine_geometric,
            "consensus": self._consensus,
        }.get(method)
        if fn is None:
            raise ValueError(f"unknown handoff method {method!r} (known: {', '.join(ALL_METHODS)})")
        t0 = time.perf_counter()
        try:
            res = fn(np.asarray(nav_uv, float).reshape(2))
        except _NoAnswer as e:
            res = MethodResult(method, self.label, False, None, str(e), e.diagnostics)
        res.method = method
        res.navcam = self.label
        res.seconds = time.perf_counter() - t0
        return res

    def _nav_point(self, nav_uv):
        ps = self.point_stereo(nav_uv)
        if not ps.ok:
            raise _NoAnswer(f"navcam point stereo: {ps.reason}", {"stereo_score": _f(getattr(ps, "score", np.nan))})
        return ps

    def _pure_kinematic(self, nav_uv):
        ps = self._nav_point(nav_uv)
        X = self.T_haz_nav.apply(ps.xyz)
        uv = self._project_haz(X)
        if not np.all(np.isfinite(uv)):
            raise _NoAnswer("target does not project into the hazcam")
        return MethodResult("", "", True, uv, diagnostics={
            "stereo_score": _f(ps.score), "range_m": _f(ps.range_m), "epipolar_offset_px": _f(ps.epipolar_offset_px),
            "xyz_haz_rover_m": X.tolist(),
        })

    def _dense_point(self, nav_uv):
        X = self.nav.xyz_at(np.asarray(nav_uv, float)[None])[0]
        if not np.all(np.isfinite(X)):
            raise _NoAnswer("no dense-stereo range at the navcam target")
        return X

    def _alt_pure_kinematic(self, nav_uv):
        X = self.T_haz_nav.apply(self._dense_point(nav_uv))
        uv = self._project_haz(X)
        if not np.all(np.isfinite(uv)):
            raise _NoAnswer("target does not project into the hazcam")
        return MethodResult("", "", True, uv, diagnostics={"xyz_haz_rover_m": X.tolist()})

    def _refined_kinematic(self, nav_uv):
        p = self.params
        k = p.template_half_px
        if self.label == "near":
            X = self.T_haz_nav.apply(self._dense_point(nav_uv))
            centre = self._project_haz(X)
            if not np.all(np.isfinite(centre)):
                raise _NoAnswer("target does not project into the hazcam")
            pts, vals = self.nav_cloud_in_haz()
            near = squared_distances(pts, X) < p.nav_cloud_radius_m**2
            c = np.round(centre).astype(int)
            roi = (int(c[0] - k), int(c[1] - k), 2 * k + 1, 2 * k + 1)
            sp = splat_points(pts[near], vals[near], self.haz.left_model, self.haz.width, self.haz.height, roi=roi)
            tpl = _fill_nan(sp.image)
            if tpl is None:
                raise _NoAnswer("expected hazcam window is empty (no navcam stereo around the target)")
            tc = centre - np.array([roi[0], roi[1]], float)
            tr = self._track(tpl, centre, p.search_radius_px, p.refined_min_score, template_center_uv=tc)
            diag = {"expected_filled": sp.filled_fraction, "start_uv": centre.tolist()}
        else:
            ps = self._nav_point(nav_uv)
            near_pk = getattr(self, "_near_hint", None)
            X_far = self.T_haz_nav.apply(ps.xyz)
            if near_pk is None or not near_pk.ok:
                # fall back to the far kinematic point when the near one is not available
                start = self._project_haz(X_far)
                X_haz = X_far
            else:
                start = near_pk.uv
                X_haz = np.asarray(near_pk.diagnostics["xyz_haz_rover_m"])
            tpl = None
            if p.far_window_warp == "plane":
                n_nav = self._nav_plane_normal(nav_uv, ps.xyz)
                if n_nav is not None:
                    tpl, tc, A = self._plane_window(X_far, self.T_haz_nav.rotate(n_nav), k)
                    if tpl is not None:
                        tr = self._track(tpl, start, p.search_radius_px, p.refined_min_score, template_center_uv=tc)
                        diag = {"warp": "local plane", "nav_px_per_haz_px": A.tolist(),
                                "start_uv": np.asarray(start).tolist()}
            if tpl is None:  # the paper's uniformly scaled window
                from .windows import extract_window, scale_window, window_scale_for_handoff

                ifov_nav = local_ifov_rad(self.nav.left_model, nav_uv)
                ifov_haz = local_ifov_rad(self.haz.left_model, start)
                range_haz = float(np.linalg.norm(X_haz - self.haz.left_model.C))
                scale = window_scale_for_handoff(ifov_nav, ps.range_m, ifov_haz, range_haz)
                src_half = int(np.ceil(k / scale))
                win = extract_window(self.nav.left_img, nav_uv, src_half)
                tpl = scale_window(win, scale)
                tr = self._track(tpl, start, p.search_radius_px, p.refined_min_score)
                diag = {"warp": "uniform scale", "scale": scale, "start_uv": np.asarray(start).tolist()}
        if not np.all(np.isfinite(tr.uv)):
            raise _NoAnswer(f"NCC track failed: {tr.reason}", diag)
        diag.update(_track_diag(tr))
        return MethodResult("", "", True, tr.uv, diagnostics=diag)

    def haz_point(self, haz_uv, range_hint_m: Optional[float] = None):
        """Point stereo on the hazcam pair at the left-hazcam pixel ``haz_uv`` (2,) (cached).

        The small correlation window (``haz_point_stereo_window_px``) with the
        affine-refined NCC keeps sharp relief (corners) that the dense
        stereo's smoothing rounds; ``range_hint_m`` bounds the search to
        +-``haz_point_stereo_range_frac`` of it. Returns the 3-D point ``(3,)``
        (hazcam rover frame) or None.
        """
        p = self.params
        uv = np.asarray(haz_uv, float).reshape(2)
        key = ("hps", tuple(np.round(uv, 4)))
        if key not in self._cache:
            from .point_stereo import point_stereo

            lo, hi = self.haz.min_range_m, self.haz.max_range_m
            if range_hint_m is not None and np.isfinite(range_hint_m):
                f = p.haz_point_stereo_range_frac
                lo, hi = max(lo, (1 - f) * range_hint_m), min(hi, (1 + f) * range_hint_m)
            ps = point_stereo(
                self.haz.left_img, self.haz.right_img, self.haz.left_model, self.haz.right_model, uv,
                band_px=p.point_stereo_band_px, window_px=p.haz_point_stereo_window_px,
                min_range_m=lo, max_range_m=hi,
            )
            self._cache[key] = ps.xyz.copy() if ps.ok else None
        return self._cache[key]

    def _haz_to_nav_jacobian(self, haz_uv, nav_in_haz: CameraModel, step_px: float = 2.0) -> Optional[np.ndarray]:
        """d(navcam pixel)/d(hazcam pixel) ``(2, 2)`` at ``haz_uv`` by central differences of the dense surface."""
        uv = np.asarray(haz_uv, float).reshape(2)
        offs = np.array([[step_px, 0], [-step_px, 0], [0, step_px], [0, -step_px]])
        X = self.haz.xyz_at(uv + offs)
        if not np.all(np.isfinite(X)):
            return None
        q = nav_in_haz.project(X)
        J = np.stack([(q[0] - q[1]), (q[2] - q[3])], axis=1) / (2 * step_px)
        if not np.all(np.isfinite(J)) or abs(np.linalg.det(J)) < 1e-6:
            return None
        return J

    def _pure_geometric(self, nav_uv):
        """The paper's pure geometric handoff, then (beyond the paper) a sub-pixel refinement.

        Paper: the hazcam dense point whose navcam projection lands nearest the
        navcam target (here refined to sub-pixel by the local affine fit of the
        projection). Its error is the dense range error at that one pixel times
        the hazcam-navcam parallax (~0.2 hazcam px per mm of range at 1 m from
        near navcams: SGBM's few-mm noise and corner rounding is ~1 px).
        Refinement: Gauss-Newton on the hazcam pixel, with each pixel's 3-D
        point from hazcam point stereo (small window, affine NCC) and the
        Jacobian from the dense surface, until that point projects onto the
        navcam target. The dense answer is kept when point stereo fails.
        """
        key = ("pg", tuple(np.round(np.asarray(nav_uv, float), 6)))
        if key in self._cache:
            r = self._cache[key]
            if isinstance(r, _NoAnswer):
                raise r
            return MethodResult(r.method, r.navcam, r.ok, r.uv.copy(), r.reason, dict(r.diagnostics))
        try:
            r = self._pure_geometric_uncached(nav_uv)
        except _NoAnswer as e:
            self._cache[key] = e
            raise
        self._cache[key] = r
        return MethodResult(r.method, r.navcam, r.ok, r.uv.copy(), r.reason, dict(r.diagnostics))

    def _pure_geometric_uncached(self, nav_uv):
        d = self.haz.dense
        xyz = d.xyz  # rectified-left grid of the hazcam, hazcam rover frame
        nav_in_haz = self.nav_model_in_haz()
        if "haz_in_nav" not in self._cache:  # hazcam points through the navcam, projected as needed, once per case
            self._cache["haz_in_nav"] = ProjectionMap(xyz, nav_in_haz)
        res = nearest_projection(xyz, (0, 0), nav_in_haz, nav_uv, proj=self._cache["haz_in_nav"])
        if res is None:
            raise _NoAnswer("no hazcam stereo projects into the navcam")
        # sub-pixel point on the rectified grid -> 3-D -> original hazcam pixel
        X = _interp_xyz(xyz, res.uv)
        if X is None:
            X = res.xyz
        uv = self._project_haz(X)
        diag = {"nearest_distance_navcam_px": res.distance_px, "dense_uv": uv.tolist()}
        refined = None
        if self.params.haz_point_stereo_window_px > 0 and np.all(np.isfinite(uv)):
            J = self._haz_to_nav_jacobian(uv, nav_in_haz)
            C = self.haz.left_model.C
            r_hint = float(np.linalg.norm(X - C))
            if J is not None:
                refined = match_projection(lambda p: self.haz_point(p, r_hint), nav_in_haz, nav_uv, uv, J,
                                           max_iterations=self.params.geometric_iterations)
        if refined is not None and refined.residual_px <= self.params.geometric_max_residual_px:
            diag.update({"refined_by": "hazcam point stereo", "refinement_px": float(np.hypot(*(refined.uv - uv))),
                         "refinement_residual_navcam_px": refined.residual_px,
                         "refinement_iterations": refined.iterations})
            uv, X = refined.uv, refined.xyz
        else:
            diag["refined_by"] = None
        diag["xyz_haz_rover_m"] = X.tolist()
        return MethodResult("", "", True, uv, diagnostics=diag)

    def _refined_geometric(self, nav_uv):
        p = self.params
        pg = self._pure_geometric(nav_uv)
        tpl, frac, c = self._draped_window(pg.uv, self.T_haz_nav, p.template_half_px)
        if tpl is None:
            raise _NoAnswer("expected hazcam window is empty (no hazcam stereo around the target)")
        tc = np.asarray(pg.uv) - (c - p.template_half_px)
        tr = self._track(tpl, pg.uv, p.search_radius_px, p.refined_min_score, template_center_uv=tc)
        if not np.all(np.isfinite(tr.uv)):
            raise _NoAnswer(f"NCC track failed: {tr.reason}")
        diag = {"draped_fraction": frac, "start_uv": pg.uv.tolist()}
        diag.update(_track_diag(tr))
        return MethodResult("", "", True, tr.uv, diagnostics=diag)

    def _mesh_registration(self, nav_uv):
        ps = self._nav_point(nav_uv)
        reg = self.whole_registration()
        if isinstance(reg, Exception):
            raise _NoAnswer(f"registration failed: {reg}")
        X = reg.T_target_source.apply(ps.xyz)
        uv = self._project_haz(X)
        diag = _reg_diag(reg)
        diag["registration_seconds"] = _f(self.registration_seconds)  # shared by the targets; maybe run meanwhile
        return MethodResult("", "", bool(np.all(np.isfinite(uv))), uv, diagnostics=diag)

    def _coarse_fine_geometric(self, nav_uv):
        p = self.params
        pg = self._pure_geometric(nav_uv)
        big, frac_big, cb = self._draped_window(pg.uv, self.T_haz_nav, p.coarse_template_half_px)
        small, frac, cs = self._draped_window(pg.uv, self.T_haz_nav, p.template_half_px)
        if big is None or small is None:
            raise _NoAnswer("expected hazcam window is empty (no hazcam stereo around the target)")
        tr1 = self._track(big, pg.uv, p.search_radius_px, p.refined_min_score,
                          template_center_uv=np.asarray(pg.uv) - (cb - p.coarse_template_half_px))
        if not np.all(np.isfinite(tr1.uv)):
            raise _NoAnswer(f"coarse NCC track failed: {tr1.reason}")
        tr2 = self._track(small, tr1.uv, p.fine_search_px, p.refined_min_score,
                          template_center_uv=np.asarray(pg.uv) - (cs - p.template_half_px))
        diag = {"draped_fraction": frac_big, "start_uv": pg.uv.tolist(), "coarse_uv": tr1.uv.tolist(),
                "coarse_ncc_peak": _f(tr1.score), "coarse_ncc_ratio": _f(tr1.ratio)}
        if not np.all(np.isfinite(tr2.uv)):
            diag["fallback"] = f"fine track failed: {tr2.reason}"
            return MethodResult("", "", True, tr1.uv, diagnostics=diag)
        diag.update(_track_diag(tr2))
        return MethodResult("", "", True, tr2.uv, diagnostics=diag)

    def _consensus(self, nav_uv):
        p = self.params
        hint = getattr(self, "_near_hint", None)
        cands = {}
        for m in ("coarse-fine-geometric", "refined-geometric", "refined-kinematic"):
            r = self.run(m, nav_uv, near_hint=hint)
            if r.ok and r.uv is not None and np.all(np.isfinite(r.uv)):
                score = r.diagnostics.get("ncc_peak") or r.diagnostics.get("coarse_ncc_peak") or 0.0
                if score >= p.consensus_min_score:
                    cands[m] = np.asarray(r.uv, float)
        self._near_hint = hint
        diag = {"candidates": {k: v.tolist() for k, v in cands.items()}}
        best = None
        names = list(cands)
        for i in range(len(names)):
            group = [n for n in names if np.linalg.norm(cands[n] - cands[names[i]]) <= p.consensus_agree_px]
            if len(group) >= 2 and (best is None or len(group) > len(best)):
                best = group
        if best:
            diag["agreeing"] = best
            diag["confident"] = True
            return MethodResult("", "", True, np.mean([cands[n] for n in best], axis=0), diagnostics=diag)
        pg = self._pure_geometric(nav_uv)
        diag["confident"] = False
        diag["fallback"] = "refined answers disagree or are weak: pure-geometric"
        return MethodResult("", "", True, pg.uv, diagnostics=diag)


class _NoAnswer(Exception):
    def __init__(self, msg, diagnostics=None):
        super().__init__(msg)
        self.diagnostics = diagnostics or {}


_f = finite_or_none


def _track_diag(tr) -> dict:
    return {"ncc_peak": _f(tr.score), "ncc_ratio": _f(tr.ratio), "ncc_sharpness": _f(tr.sharpness),
            "track_ok": bool(tr.ok), "track_reason": tr.reason}


def _reg_diag(reg) -> dict:
    return {"icp_fitness": reg.fitness, "icp_rmse_m": reg.inlier_rmse_m, "icp_points": reg.n_source,
            "icp_correction_deg": float(np.degrees(reg.correction_rad)), "icp_correction_m": reg.correction_m,
            "icp_kept_seed": reg.kept_seed}


def _fill_nan(img: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """Fill NaN pixels with the nearest valid values (repeated 3x3 means); None if nothing is valid."""
    import cv2

    a = np.asarray(img, np.float32).copy()
    valid = np.isfinite(a)
    if not valid.any():
        return None
    if valid.mean() < 0.3:
        return None
    for _ in range(64):
        if valid.all():
            break
        num = cv2.boxFilter(np.where(valid, a, 0).astype(np.float32), -1, (3, 3), normalize=False,
                            borderType=cv2.BORDER_CONSTANT)
        den = cv2.boxFilter(valid.astype(np.float32), -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
        grow = ~valid & (den > 0)
        a[grow] = num[grow] / den[grow]
        valid = valid | grow
    return a


def local_ifov_rad(model: CameraModel, uv) -> float:
    """Angle subtended by one pixel at ``uv`` (geometric mean of the u and v directions), rad.

    At the image centre this is ``~1/hs``; off-centre in a fish-eye it differs,
    which matters when a window is scaled from one camera to another.
    """
    uv = np.asarray(uv, float).reshape(2)
    pts = np.array([uv - [0.5, 0], uv + [0.5, 0], uv - [0, 0.5], uv + [0, 0.5]])
    _, d = model.unproject(pts)
    a_u = np.arccos(np.clip(np.dot(d[0], d[1]), -1, 1))
    a_v = np.arccos(np.clip(np.dot(d[2], d[3]), -1, 1))
    return float(np.sqrt(a_u * a_v))


def _interp_xyz(xyz: np.ndarray, uv) -> Optional[np.ndarray]:
    out = np.array([bilinear_sample(xyz[..., k], np.asarray(uv, float)[None])[0] for k in range(3)])
    return out if np.all(np.isfinite(out)) else None


def _map_jacobian(q: np.ndarray) -> Optional[np.ndarray]:
    """Median d(q)/d(pixel) ``(2, 2)`` of a pixel map ``q`` (h, w, 2) (NaN invalid) by neighbour differences."""
    du = (q[:, 2:] - q[:, :-2])[1:-1] / 2
    dv = (q[2:] - q[:-2])[:, 1:-1] / 2
    ok = np.all(np.isfinite(du), axis=-1) & np.all(np.isfinite(dv), axis=-1)
    if ok.sum() < 9:
        return None
    return np.stack([np.median(du[ok], axis=0), np.median(dv[ok], axis=0)], axis=1)
