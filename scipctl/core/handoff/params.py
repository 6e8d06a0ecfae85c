"""Parameters of the navcam -> hazcam handoff methods (one home, checked)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from ..registration_check import RegistrationCheckParams
from .scip_params import ScipParams

FAR_WINDOW_WARPS = ("plane", "scale")


@dataclass
class HandoffParams:
    """Every handoff method's parameters, and those of the shared products a :class:`HandoffCase` caches.

    Pixel figures are hazcam-left pixels unless named otherwise.
    """

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
    # ICP's voxel sizes, coarse to fine, seeded with the mast kinematics (near) or the pose estimate (far: decimetres
    # off, so it starts coarser). Near ends at 1 cm (1.5 cm correspondences): the handoff needs ~1 cm at the target,
    # and a 2 cm finish left the Mars 2020 rig's near registration 5-15 px off; both clouds' stereo noise is within
    # reach there (near navcams <= 2.5 m away). Far ends at 2 cm: its navcam points, 4-6 m away, are noisier than
    # 1.5 cm, and only the hazcam cloud is gated (docs/handoff.md, "A 1 cm ICP scale for the near registration")
    registration_near_scales_m: tuple = (0.08, 0.04, 0.02, 0.01)
    registration_far_scales_m: tuple = (0.32, 0.16, 0.08, 0.04, 0.02)
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
    # mesh registration's seeds, global registration and per-target verdict (core/registration_check.py)
    registration_check: RegistrationCheckParams = field(default_factory=RegistrationCheckParams)
    scip: ScipParams = field(default_factory=ScipParams)  # the recommended handoff's evidence, model and GO rule

    def check(self) -> "HandoffParams":
        """Raise ``ValueError`` naming the first parameter out of its range; return ``self``."""
        def bad(name, why):
            raise ValueError(f"HandoffParams.{name} = {getattr(self, name)!r}: {why}")

        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, (int, float)) and not isinstance(v, bool) and not math.isfinite(v):
                bad(f.name, "must be finite")
        for name in ("template_half_px", "coarse_template_half_px", "point_stereo_window_px", "dense_downsample",
                     "geometric_iterations"):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= 1):
                bad(name, "must be a whole number >= 1")
        if not (isinstance(self.haz_point_stereo_window_px, int) and self.haz_point_stereo_window_px >= 0):
            bad("haz_point_stereo_window_px", "must be a whole number >= 0 (0: no refinement)")
        for name in ("search_radius_px", "fine_search_px", "point_stereo_band_px", "nav_cloud_radius_m",
                     "registration_max_range_m", "registration_disparity_sigma_px", "consensus_agree_px",
                     "geometric_max_residual_px", "far_plane_radius_m"):
            if not getattr(self, name) > 0:
                bad(name, "must be > 0")
        for name in ("registration_near_scales_m", "registration_far_scales_m"):
            v = getattr(self, name)
            if not (isinstance(v, tuple) and v and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                        and math.isfinite(x) and x > 0 for x in v)
                    and all(a > b for a, b in zip(v, v[1:]))):
                bad(name, "must be a non-empty tuple of voxel sizes > 0, coarse to fine (strictly decreasing)")
        if not 0 < self.haz_point_stereo_range_frac < 1:
            bad("haz_point_stereo_range_frac", "must be in (0, 1)")
        if not -1 <= self.refined_min_score <= 1:
            bad("refined_min_score", "is an NCC score: must be in [-1, 1]")
        if not -1 <= self.consensus_min_score <= 1:
            bad("consensus_min_score", "is an NCC score: must be in [-1, 1]")
        try:
            self.registration_check.check()
        except ValueError as e:
            raise ValueError(f"HandoffParams.registration_check: {e}") from None
        if self.far_window_warp not in FAR_WINDOW_WARPS:
            bad("far_window_warp", f"must be one of {', '.join(FAR_WINDOW_WARPS)}")
        self.scip.check()
        return self
