"""Track a designated target through the stops of an approach (SCIP steps 3 and 5) and hand it
from pancam to navcam, then to the hazcams.

At each rover position (time order) the target's 3-D estimate (site frame,
through the rover's pose estimates) predicts where it appears in the new left
image. The pose estimates can be degrees off in yaw, so the prediction can be
hundreds of pixels off: the previous stop's image is rendered into the new
view through the local surface plane (which takes out the change of scale and
perspective), SIFT features of the rendering are matched against the whole
new image and a RANSAC model maps the target's place in the rendering into it
(the coarse position); a template rendered through that model is then
NCC-tracked within ``ChainParams.feature_fine_radius_px`` of it. When no feature model is
found, the older NCC path (a large context window over the search region) gives
an answer that is reported as unverified. At the same stop, the pancam window
is shrunk by the IFOV ratio and tracked into the navcam image (the paper's
handoff). Stereo at the tracked pixel updates the 3-D estimate. Every step
records in ``extra`` which path found it, the feature inlier counts and the
coarse position; a weak or unverified step has ``ok=False`` and is not used as
the reference for the next stop.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..core.point_stereo import PointStereoParams, on_left_ray
from ..model import Downlink, ImageProduct, InputError
from .feature_track import feature_track, texture_view, vo_correction
from .plane_warp import local_normals_site, near_dense_stereo, plane_warped_template, render_planes
from ..jsonutil import finite_or_none

def _per_camera(name: str, values: dict, fallback, minimum, integer: bool = False) -> None:
    """Raise ValueError unless every value of ``values`` (camera -> number) and ``fallback`` is >= ``minimum``."""
    if not isinstance(values, dict) or not values:
        raise ValueError(f"ChainParams.{name}: expected a non-empty {{camera: value}} dict, got {values!r}")
    for cam, v in list(values.items()) + [("other cameras", fallback)]:
        ok = isinstance(v, (int, np.integer)) if integer else isinstance(v, (int, float, np.number))
        if not ok or not np.isfinite(v) or v < minimum:
            kind = "an integer" if integer else "a number"
            raise ValueError(f"ChainParams.{name}[{cam!r}]: must be {kind} >= {minimum}, got {v!r}")


CHAIN_ANSWERS = ("handoff", "closure")  # ChainParams.answer
DEFAULT_CHAIN_ANSWER = "closure"


@dataclass(frozen=True)
class ChainParams:
    """Window sizes, search radii and feature-matching settings of the tracking chain (:func:`run_chain`).

    Per-camera values are ``{camera: value}`` dicts; a camera not in a dict
    takes the ``other_*`` fallback. The pre-uplink prediction
    (``scipctl.pipeline.predict``) runs the chain on rendered views with the
    same windows.
    """

    template_half_px: dict = field(default_factory=lambda: {"pancam": 20, "navcam": 15, "hazcam": 15})
    # pointing error from the pose estimate: pancam IFOV is 1/3 of navcam's, so it needs 3x the radius in pixels
    search_radius_px: dict = field(default_factory=lambda: {"pancam": 300.0, "navcam": 100.0, "hazcam": 80.0})
    # fallback when no feature match is found: half-size of the NCC context window that first finds the pose
    # error, and the target search radius after it
    context_half_px: dict = field(default_factory=lambda: {"pancam": 100, "navcam": 60, "hazcam": 60})
    fine_radius_px: float = 20.0
    # feature-guided step (feature_track): the previous view rendered into the new view covers +-view_reach_px
    # new pixels around the prediction
    view_reach_px: int = 300
    # the rendering's pixel = this many previous-image pixels (1: its own resolution); the coarser one is tried
    # when nothing was confirmed at the finer one (smooth 10 m sand against the 4.5 m image's fine speckle)
    feature_step_factors: tuple = (1.0, 1.5)
    # a median filter of this odd size (detection pixels; 0: none) on both images before SIFT: the nearer camera
    # resolves grains and pits the farther one averages away, and their keypoints match nothing there
    # (detect_features; docs/stereo-and-tracking.md, "Grains")
    feature_median_px: int = 3
    # the feature step's NCC refinement (template and new image) median-filtered over this many previous-image pixels
    # (the new image's window: the odd size nearest to it x the zoom, at least 3): grains only the nearer view
    # resolves are impulses the template, rendered from the farther one, lacks. None (the default): unfiltered.
    # Measured: docs/stereo-and-tracking.md, "A median for the feature step's NCC" (session 29)
    ncc_median_prev_px: Optional[float] = None
    # with ncc_median_prev_px: the median-filtered NCC only finds the peak; its position and score are the unfiltered
    # NCC's within feature_track.MEDIAN_FIND_PLACE_PX of it (the filtered one when that fails). False: the filtered
    # NCC's own (docs/stereo-and-tracking.md, "A median for the feature step's NCC")
    ncc_median_find: bool = False
    # the tracking steps' NCC refinement can count only the template pixels the plane places where the new image's
    # dense stereo puts them (core/relief_mask.py): within relief_max_parallax_px new pixels, given the stereo's
    # disparity error bound relief_disparity_error_px (half-resolution pixels; SGBM's measured p99 there is 0.45 px).
    # None (the default): every pixel counts. Measured on 187 held-out chains (docs/stereo-and-tracking.md,
    # "Relief"): with 1.0 px the tracking steps are right a little more often, the final answer is not (122 -> 124
    # within 4 px, its median better on one population and worse on the other), for a dense stereo pair per step
    # (0.15-0.20 CPU s each); the closure check never uses it (it confirmed more wrong closures). Session 53, on
    # today's chain: 78 -> 84 of 98 chains on two populations, but calibration failed its rule; on two fresh ones,
    # with the trust models refitted to it, 65 -> 67 of 97 (won 5, lost 3): not adopted ("The relief mask on
    # today's chain"); ~40 % more chain CPU
    relief_max_parallax_px: Optional[float] = None
    relief_disparity_error_px: float = 0.45
    # ... unless fewer than this part of the template is kept (then every pixel counts)
    relief_min_kept: float = 0.25
    # the tracking steps' NCC templates drawn through the surface the reference image's dense stereo measured
    # (core/surface_raycast.py, plane_warp.render_through_surface), instead of through the plane alone; the feature
    # views, the NCC fallback, the handoffs and the closure keep the plane. False (the default): the plane.
    # template_surface_gate_px: the plane kept where the crossing is within that many (half-resolution) disparity
    # pixels of it (the stereo's error bound, as relief_disparity_error_px); None: every crossing the stereo
    # measured. template_surface_level: the stereo shifted to agree with the plane at the template's centre first.
    # Measured on the first 18 trav38 chains (docs/stereo-and-tracking.md, "A template through the measured surface"
    # and "The surface template without its gate"): navcam tracks within 4 px 116 of 177 with the plane, 109 with
    # gate 0.45 and levelling (these defaults), 105 with neither (better single steps from the true reference)
    template_surface: bool = False
    template_surface_gate_px: Optional[float] = 0.45
    template_surface_level: bool = True
    # two-stage NCC in the feature step (feature_track.place_with_centre): for the cameras in this dict, the whole
    # template finds the peak, scores it and decides with it (confirmation, pooling, the trust evidence), then its
    # central (2 h + 1)-pixel crop (h the value; smaller than the camera's template_half_px) places each pooled
    # candidate's answer, NCC within +-ncc_place_radius_px of its peak; a peak on that border or a failed match keeps
    # the found position. A large window finds the target; the relief around it biases where
    # (docs/stereo-and-tracking.md, "A two-stage NCC for the navcam tracks"). {} (the default): one stage.
    # (Session 41's traverse figures below placed before deciding: a placed peak could move a candidate across
    # feature_confirm_px.)
    # Measured with {"navcam": 7, "hazcam": 7} on two held-out traverse populations (102 chains): final answer within
    # 4 px 71 -> 73, the finals smaller in 66 chains and larger in 30, navcam tracks within 4 px +6 %, no chain GO;
    # on the paper scenario (the navcam handoff across the drive a feature step too; session 42, 139 chains): 90 -> 93,
    # none better on the fresh population (28 -> 27 of 49) and one chain lost beyond 20 px on the dev ones, so off
    ncc_place_half_px: dict = field(default_factory=dict)
    ncc_place_radius_px: float = 2.0
    # optical flow places the feature step's answer for these cameras (core/flow_place.py): each candidate's NCC
    # peak still finds the target and decides (confirmation, pooling, the trust evidence); the dense flow from its
    # template, placed there, to the image, read at the target, moves it by the relief the plane template misses
    # (docs/stereo-and-tracking.md, "Optical flow places the first pancam track" and "... the cross-drive navcam
    # handoff"). () : the NCC peak answers. Measured in session 51: ("pancam",) put more first pancam tracks within
    # 4 mm (+3 net on two populations) but left whole chains at 35 of 50 on a fresh one, so not for the pancam;
    # ("navcam",) put more cross-drive navcam handoffs within 1 px (59 -> 68 of 116) and whole chains 35 -> 37 of 46
    # on a fresh population (asked +3). The default since session 52, judged on two more fresh populations by the
    # rule written before them: 71 -> 76 of 96 chains (won 6, lost 1), no chain GO, every miss NO-GO in time, final
    # Brier 0.085 -> 0.086 and 0.112 -> 0.082; on the two populations rendered after the decision 61 -> 62 of 92
    # (won 4, lost 3), safe the same way
    ncc_place_flow: tuple = ("navcam",)
    # visual odometry (core/visual_odometry.py, feature_track.vo_correction): for tracking steps of these cameras
    # (() : none, the default), the new camera's pose error is also estimated from the whole image (the previous
    # image's keypoints, placed in 3-D by its stereo, matched to the new image's; PnP RANSAC within vo_threshold_px,
    # at least vo_min_inliers; 2-NN ratio vo_ratio) and the target seen through it is one more candidate of the
    # feature step (docs/stereo-and-tracking.md, "Visual odometry for the navcam tracks"). Measured with ("navcam",)
    # on 187 held-out chains: navcam tracks right 162 -> 176 of 340, the final answer 122 -> 124 of 176 (it is mostly
    # the closure's), for +27-34 % chain CPU, so off by default
    vo_cameras: tuple = ()
    # the closure check's feature step (pipeline/chain_closure.py) takes the visual-odometry candidate too: the pose
    # error of the drive from the reference's stop to the final hazcam, fitted to the whole hazcam image. Measured on
    # whole chains (docs/stereo-and-tracking.md, "Visual odometry in the closure, the default"): the chain's final
    # answer within 4 px 169 -> 179 of 260 chains (tuning) and 122 -> 131 of 186 (held out), for +17-19 % of the
    # chain's CPU on the bundled sols; the closure trust model is fitted on such closures (session 18)
    closure_vo: bool = True
    # the feature step of a handoff across a drive (the navcam at the approach's imaging stop found from the ~10 m
    # pancam designation, when the pancam track there is not trusted) takes the visual-odometry candidate too: the
    # 10 m pancam and the 4.5 m navcam see the ground at about the same scale, so the whole images match where the
    # target's surroundings alone do not (docs/stereo-and-tracking.md, "Visual odometry for the cross-drive handoff").
    # The default since session 31: over nine populations (486 chains; pop18 held out for the decision) the final
    # answer within 4 px 309 -> 330 (21 won, none lost), chain GO never wrong, the final p as well calibrated as
    # without it (reliability 0.0064 -> 0.0048); it answers chains that had no answer, at ~50 % right and NO-GO;
    # +2-8 % of the chain's CPU
    vo_handoff: bool = True
    # when the closure would start from the navcam handoff at the imaging stop (its pancam track there not trusted),
    # it first starts from the pancam image of that stop at the navcam handoff's point projected into it
    # (chain_closure.pancam_from_navcam), and keeps that closure when it is confirmed (docs/stereo-and-tracking.md,
    # "The closure's reference")
    closure_pancam_from_navcam: bool = False
    vo_threshold_px: float = 2.0
    vo_min_inliers: int = 20
    vo_ratio: float = 0.8
    # candidates: (keypoints of the rendering within this part of its half-size, RANSAC model, inliers needed);
    # the smallest reach follows a target off the ground (a rock), whose image moves unlike the ground's (parallax)
    feature_candidates: tuple = ((0.15, "similarity", 6), (0.3, "homography", 12), (0.5, "homography", 12),
                                 (1.0, "homography", 12))
    feature_fine_radius_px: float = 20.0  # NCC refinement radius around a feature-guided coarse position
    feature_local_px: float = 75.0  # inliers within this many new pixels of the target are counted as local
    # NCC must land within this of the feature match to confirm it; an unconfirmed match is reported as a weak
    # step, never the next stop's reference
    feature_confirm_px: float = 8.0
    # confirmed candidates whose NCC positions lie within this of the best-scoring one are pooled (weighted by score)
    feature_agree_px: float = 2.0
    # the feature step's NCC compares the template with the new image blurred to the template's resolution (the
    # previous image's pixel footprint through the plane: core/matched_blur.py); False: the sharp image
    ncc_matched_blur: bool = False
    # the previous view rendered into the new one (plane_warp.render_through_plane: the feature step's views and NCC
    # templates, the NCC fallback's templates) is blurred to the new pixels' footprint in it where it is the finer
    # view (the closure's 4.5 m pancam seen from the hazcam, the 10 m pancam from the 4.5 m navcam), as the handoff's
    # windows are (core/expected.antialiased_sample); False: point samples (bilinear)
    render_antialias: bool = False
    # a feature step that confirms nothing is tried once more on both images' texture without their lighting
    # (core/illumination.log_highpass: the log image less its Gaussian blur of this many new-image pixels; the
    # previous image's divided by the zoom where the new view is the finer, at least 1 px); None: not tried
    texture_retry_sigma_px: Optional[float] = None
    # point stereo at each tracked pixel: the designation's band and window per camera
    point_stereo: PointStereoParams = field(default_factory=PointStereoParams)
    other_template_half_px: int = 15
    other_search_radius_px: float = 60.0
    other_context_half_px: int = 100
    # the closure check (pipeline/chain_closure.py): the final hazcam answer re-found straight from the last
    # trusted pancam track, recorded on the final step's extra["closure"]. It always runs with answer="closure" (the
    # default); this flag records it on a chain that answers by handoff too (it costs 12-44 % of a chain's CPU)
    closure: bool = False
    # which pixel is the chain's final hazcam answer: "closure" (runs the closure check and, when it is confirmed,
    # answers with the closure's pixel: a path that skips the navcam tracks; p_success from the closure model) or
    # "handoff" (scip's handoff of the chain's navcam pixel). Measured on 56 chains of 10 held-out families: within
    # 4 px 25 -> 31 with the closure, no family worse (docs/stereo-and-tracking.md, "Closure as the answer")
    answer: str = DEFAULT_CHAIN_ANSWER
    # the closure model's domain: a closure whose reference lies more drives than this from the designation is
    # never GO. The model was fitted on the paper's approaches (its reference at most two drives away: the 4.5 m
    # pancam track, or the navcam at the next stop); its evidence is the reference step's own p, blind to the drift
    # the tracks before it add up. On traverse-shaped approaches (the shape `sequence` plans; reference four drives
    # away) 2 of 10 GO chains were wrong, one 20 px off at p 0.95 (docs/stereo-and-tracking.md, "Traverse-shaped
    # approaches")
    closure_go_max_drives: int = 2

    def check(self) -> "ChainParams":
        """Raise ValueError naming the first bad field; return self."""
        _per_camera("template_half_px", self.template_half_px, self.other_template_half_px, 1, integer=True)
        if isinstance(self.closure_go_max_drives, bool) or not isinstance(self.closure_go_max_drives, int) \
                or self.closure_go_max_drives < 0:
            raise ValueError(f"ChainParams.closure_go_max_drives: must be an integer >= 0, got "
                             f"{self.closure_go_max_drives!r}")
        _per_camera("search_radius_px", self.search_radius_px, self.other_search_radius_px, 0.0)
        _per_camera("context_half_px", self.context_half_px, self.other_context_half_px, 1, integer=True)
        self.point_stereo.check()
        for name in ("fine_radius_px", "feature_fine_radius_px", "feature_local_px", "feature_confirm_px",
                     "feature_agree_px"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ValueError(f"ChainParams.{name}: must be a number > 0, got {v!r}")
        if not (isinstance(self.view_reach_px, int) and self.view_reach_px >= 1):
            raise ValueError(f"ChainParams.view_reach_px: must be an integer >= 1, got {self.view_reach_px!r}")
        if not self.feature_step_factors or not all(
                isinstance(f, (int, float)) and np.isfinite(f) and f >= 1.0 for f in self.feature_step_factors):
            raise ValueError(f"ChainParams.feature_step_factors: must be a non-empty tuple of numbers >= 1, "
                             f"got {self.feature_step_factors!r}")
        for cand in self.feature_candidates:
            ok = (isinstance(cand, tuple) and len(cand) == 3 and isinstance(cand[0], (int, float)) and 0 < cand[0] <= 1
                  and cand[1] in ("similarity", "homography") and isinstance(cand[2], int) and cand[2] >= 2)
            if not ok:
                raise ValueError(f"ChainParams.feature_candidates: each must be (reach in (0, 1], 'similarity' or "
                                 f"'homography', min inliers >= 2), got {cand!r}")
        if not self.feature_candidates:
            raise ValueError("ChainParams.feature_candidates: must not be empty")
        m = self.feature_median_px
        if not (isinstance(m, int) and not isinstance(m, bool) and (m in (0, 1) or (m >= 3 and m % 2 == 1))):
            raise ValueError(f"ChainParams.feature_median_px: must be 0, 1 or an odd integer >= 3, got {m!r}")
        n = self.ncc_median_prev_px
        if n is not None and not (isinstance(n, (int, float)) and not isinstance(n, bool) and np.isfinite(n) and n > 0):
            raise ValueError(f"ChainParams.ncc_median_prev_px: must be a number > 0 or None, got {n!r}")
        if not isinstance(self.ncc_median_find, bool):
            raise ValueError(f"ChainParams.ncc_median_find: must be True or False, got {self.ncc_median_find!r}")
        if self.ncc_median_find and n is None:
            raise ValueError("ChainParams.ncc_median_find: needs ncc_median_prev_px (the median that finds the peak)")
        if not isinstance(self.ncc_matched_blur, bool):
            raise ValueError(f"ChainParams.ncc_matched_blur: must be true or false, got {self.ncc_matched_blur!r}")
        if n is not None and self.ncc_matched_blur:
            raise ValueError("ChainParams.ncc_median_prev_px and ncc_matched_blur: one filter of the NCC's image at a time")
        r = self.relief_max_parallax_px
        if r is not None and not (isinstance(r, (int, float)) and not isinstance(r, bool) and np.isfinite(r) and r > 0):
            raise ValueError(f"ChainParams.relief_max_parallax_px: must be a number > 0 or None, got {r!r}")
        e = self.relief_disparity_error_px
        if not (isinstance(e, (int, float)) and not isinstance(e, bool) and np.isfinite(e) and e >= 0):
            raise ValueError(f"ChainParams.relief_disparity_error_px: must be a number >= 0, got {e!r}")
        k = self.relief_min_kept
        if not (isinstance(k, (int, float)) and not isinstance(k, bool) and 0 <= k <= 1):
            raise ValueError(f"ChainParams.relief_min_kept: must be a number in [0, 1], got {k!r}")
        if not (isinstance(self.vo_cameras, tuple) and all(isinstance(c, str) for c in self.vo_cameras)):
            raise ValueError(f"ChainParams.vo_cameras: must be a tuple of camera names, got {self.vo_cameras!r}")
        t = self.vo_threshold_px
        if not (isinstance(t, (int, float)) and not isinstance(t, bool) and np.isfinite(t) and t > 0):
            raise ValueError(f"ChainParams.vo_threshold_px: must be a number > 0, got {t!r}")
        n = self.vo_min_inliers
        if not (isinstance(n, int) and not isinstance(n, bool) and n >= 6):
            raise ValueError(f"ChainParams.vo_min_inliers: must be an integer >= 6, got {n!r}")
        q = self.vo_ratio
        if not (isinstance(q, (int, float)) and not isinstance(q, bool) and 0 < q <= 1):
            raise ValueError(f"ChainParams.vo_ratio: must be a number in (0, 1], got {q!r}")
        if not isinstance(self.template_surface, bool):
            raise ValueError(f"ChainParams.template_surface: must be true or false, got {self.template_surface!r}")
        gp = self.template_surface_gate_px
        if gp is not None and not (isinstance(gp, (int, float)) and not isinstance(gp, bool) and np.isfinite(gp)
                                   and gp >= 0):
            raise ValueError(f"ChainParams.template_surface_gate_px: must be a number >= 0 or None, got {gp!r}")
        if not isinstance(self.template_surface_level, bool):
            raise ValueError(f"ChainParams.template_surface_level: must be true or false, got "
                             f"{self.template_surface_level!r}")
        if not isinstance(self.ncc_place_half_px, dict):
            raise ValueError(f"ChainParams.ncc_place_half_px: must be a mapping camera -> integer, got "
                             f"{self.ncc_place_half_px!r}")
        for cam, h in self.ncc_place_half_px.items():
            if isinstance(h, bool) or not isinstance(h, (int, np.integer)) or not 1 <= h < self.template_half(cam):
                raise ValueError(f"ChainParams.ncc_place_half_px[{cam!r}]: must be an integer >= 1 and below the "
                                 f"camera's template_half_px ({self.template_half(cam)}), got {h!r}")
        if self.ncc_place_half_px and (self.ncc_median_prev_px is not None or self.ncc_matched_blur):
            raise ValueError("ChainParams.ncc_place_half_px: places on the unfiltered image only, not with "
                             "ncc_median_prev_px or ncc_matched_blur")
        pf = self.ncc_place_flow
        if not (isinstance(pf, (tuple, list)) and all(isinstance(c, str) for c in pf)):
            raise ValueError(f"ChainParams.ncc_place_flow: must be a tuple of camera names, got {pf!r}")
        if pf and (self.ncc_median_prev_px is not None or self.ncc_matched_blur):
            raise ValueError(f"ChainParams.ncc_place_flow: places on the unfiltered image only, not with "
                             f"ncc_median_prev_px or ncc_matched_blur (it is {tuple(pf)!r}; "
                             f"ncc_place_flow=() turns it off)")
        both = sorted(set(pf) & set(self.ncc_place_half_px))
        if both:
            raise ValueError(f"ChainParams.ncc_place_flow and ncc_place_half_px: one placement per camera, both name "
                             f"{', '.join(both)} (ncc_place_flow=() turns the flow off)")
        r = self.ncc_place_radius_px
        if not (isinstance(r, (int, float)) and not isinstance(r, bool) and np.isfinite(r) and r > 0):
            raise ValueError(f"ChainParams.ncc_place_radius_px: must be a number > 0, got {r!r}")
        if not isinstance(self.closure_vo, bool):
            raise ValueError(f"ChainParams.closure_vo: must be true or false, got {self.closure_vo!r}")
        if not isinstance(self.vo_handoff, bool):
            raise ValueError(f"ChainParams.vo_handoff: must be true or false, got {self.vo_handoff!r}")
        if not isinstance(self.closure_pancam_from_navcam, bool):
            raise ValueError(f"ChainParams.closure_pancam_from_navcam: must be true or false, got "
                             f"{self.closure_pancam_from_navcam!r}")
        if not isinstance(self.render_antialias, bool):
            raise ValueError(f"ChainParams.render_antialias: must be true or false, got {self.render_antialias!r}")
        t = self.texture_retry_sigma_px
        if t is not None and not (isinstance(t, (int, float)) and not isinstance(t, bool) and np.isfinite(t) and t > 0):
            raise ValueError(f"ChainParams.texture_retry_sigma_px: must be a number > 0 or None, got {t!r}")
        if not isinstance(self.closure, bool):
            raise ValueError(f"ChainParams.closure: must be true or false, got {self.closure!r}")
        if self.answer not in CHAIN_ANSWERS:
            raise ValueError(f"ChainParams.answer: must be one of {', '.join(CHAIN_ANSWERS)}, got {self.answer!r}")
        return self

    def template_half(self, camera: str) -> int:
        return self.template_half_px.get(camera, self.other_template_half_px)

    def search_radius(self, camera: str) -> float:
        return self.search_radius_px.get(camera, self.other_search_radius_px)

    def context_half(self, camera: str) -> int:
        return self.context_half_px.get(camera, self.other_context_half_px)

    def band(self, camera: str) -> float:
        return self.point_stereo.band(camera)

    def stereo_window(self, camera: str) -> int:
        return self.point_stereo.window(camera)


@dataclass
class ChainStep:
    """One step of the tracking chain: the target's pixel in one left image (``kind``: the designation, a
    track from the previous stop, or a handoff to another camera), against its mark when there is one.

    ``predicted_uv``: where the pose estimates put the target; ``tracked_uv``: where it was found (None: lost);
    ``xyz_site_m``: point stereo at the tracked pixel, site frame through the downlinked pose;
    ``truth_xyz_site_m``: the true target (simulation truth). ``ok`` False: a weak or unverified step
    (``reason``), not used as the next stop's reference. ``extra``: how it was found (docs/stereo-and-tracking.md).
    ``p_success``/``go``/``advice``: the step's trust (:mod:`scipctl.pipeline.chain_trust`).
    """

    position: tuple  # (site, drive)
    camera: str
    product_id: str
    kind: str  # "designate" | "track" | "handoff"
    predicted_uv: Optional[list]
    tracked_uv: Optional[list]
    mark_uv: Optional[list]
    error_px: Optional[float]
    ncc_peak: Optional[float]
    range_m: Optional[float]
    xyz_site_m: Optional[list]
    truth_xyz_site_m: Optional[list]
    error_3d_m: Optional[float]  # stereo point vs the true target, both in the true rover frame
    ok: bool
    reason: str = ""
    extra: dict = field(default_factory=dict)
    # P(within the step's success radius of its mark) and p >= the GO threshold (docs/stereo-and-tracking.md,
    # "Trust along the chain"); None / False: not scored. ``advice``: what the operator should do at a NO-GO step.
    p_success: Optional[float] = None
    go: bool = False
    advice: Optional[str] = None

    def to_dict(self):
        d = dict(self.__dict__)
        d["position"] = list(self.position)
        return d

    @classmethod
    def from_dict(cls, d, product: str = "chain", index: Optional[int] = None) -> "ChainStep":
        """A step as read back from JSON (``to_dict``'s inverse); :class:`InputError` naming ``product`` and the
        field (``steps[index].field``) on a missing or ill-typed value."""
        from ..jsonutil import RecordReader

        r = RecordReader(d, product, "" if index is None else f"steps[{index}].", "chain step")
        pos = d.get("position")
        if not (isinstance(pos, list) and len(pos) == 2):
            r.bad("position", f"expected [site, drive], got {pos!r}")
        ok = r.flag("ok", required=True, nullable=False)
        return cls(
            position=tuple(pos), camera=r.text("camera", required=True, nullable=False),
            product_id=r.text("product_id", required=True, nullable=False),
            kind=r.text("kind", required=True, nullable=False),
            predicted_uv=r.vector("predicted_uv", 2, required=True, kind=list),
            tracked_uv=r.vector("tracked_uv", 2, required=True, kind=list),
            mark_uv=r.vector("mark_uv", 2, required=True, kind=list), error_px=r.number("error_px", required=True),
            ncc_peak=r.number("ncc_peak", required=True), range_m=r.number("range_m", required=True),
            xyz_site_m=r.vector("xyz_site_m", 3, required=True, kind=list),
            truth_xyz_site_m=r.vector("truth_xyz_site_m", 3, required=True, kind=list),
            error_3d_m=r.number("error_3d_m", required=True), ok=ok, reason=r.text("reason") or "",
            extra=r.mapping("extra") or {}, p_success=r.number("p_success"),
            go=bool(r.flag("go")), advice=r.text("advice"))


_f = finite_or_none


def stereo_at(dl: Downlink, left: ImageProduct, uv, params: ChainParams):
    """Point stereo at the left-image pixel ``uv`` (2,) with the chain's band and window for that camera (rover
    frame); None when ``left`` has no right eye."""
    from ..core.point_stereo import point_stereo

    right = dl.stereo_pair(left)
    if right is None:
        return None
    return point_stereo(left.pixels_float(), right.pixels_float(), left.camera_model, right.camera_model,
                        np.asarray(uv, float), band_px=params.band(left.camera),
                        window_px=params.stereo_window(left.camera))


def run_chain(dl: Downlink, start: ImageProduct, start_uv, target_id: Optional[str] = None,
              handoff_method: str = "scip", template_mode: str = "plane", handoff_at: str = "every",
              params: Optional[ChainParams] = None, step_model=None, setups: Optional[dict] = None,
              closure_model=None, feature_cache: Optional[dict] = None, designation_model=...) -> list:
    """Follow the target from ``start`` (a left pancam or navcam image) to the last hazcam image.

    ``template_mode``: ``"plane"`` (default) renders the previous stop's image
    into the new view through the local surface plane (from dense stereo) and
    finds the pose error with features first (:func:`feature_track`), falling
    back to NCC over the search region (reported unverified) when no feature
    model is found; ``"scale"`` scales the previous window uniformly by the
    IFOV and range ratios and NCC-tracks it over the search region (the paper's
    way, no features). The pancam->navcam handoff at the same stop always
    scales the pancam window by the IFOV ratio, as the paper does; a handoff
    from a pancam image at an earlier stop (the 4.5 m pancam track was not
    trusted) goes through the feature path. Returns the list of
    :class:`ChainStep`; the last step is the navcam->hazcam handoff by
    ``handoff_method`` when a hazcam pair exists: ``scip`` (default) from the chain's navcam pixel at that stop
    and its last verified navcam pixel at an earlier stop (:func:`~scipctl.pipeline.chain_handoff.hazcam_handoff`),
    another method from the near navcams alone.
    ``handoff_at``: at which stops with hazcam images the navcam->hazcam
    handoff is made: ``"every"`` (default; the navcam track goes on through
    all stops, each handoff is a step, the last one has ``extra["final"]``
    True: the one the arm would use), ``"last"`` (only the last such stop),
    ``"first"`` (the chain ends at the first such stop). A step with
    ``ok=False`` whose ``reason`` starts ``weak match`` or ``unverified`` has a
    pixel that is reported but not used as the next stop's reference.
    ``params``: window sizes and feature settings (:class:`ChainParams`, checked).
    Every step gets ``p_success``/``go`` (and ``advice`` when NO-GO): the tracking steps from ``step_model``
    (:class:`~scipctl.core.step_trust.StepTrustModel`; None: the packaged one), the hazcam handoff from
    ``scip``'s times its input navcam step's (:func:`~scipctl.pipeline.chain_trust.score_hazcam_handoffs`).
    ``setups``: a dict shared by the chains of one downlink,
    where the hazcam handoffs keep their :class:`~scipctl.pipeline.handoff.HandoffSetup` by product ids (dense
    stereo and registrations do not depend on the target: computed once, the same answers).
    ``closure_model``: the :class:`~scipctl.core.closure_trust.ClosureTrustModel` of an adopted closure answer
    (``params.answer == "closure"``; None: the packaged one). ``feature_cache``: a dict shared by the chains of one
    downlink, where the feature step keeps each image's keypoints by (product id, downsampling): computed once,
    the same keypoints (None: this chain's own). ``designation_model``: the designation trust model
    (:mod:`scipctl.pipeline.designation_trust`) that scores the designation step as ``scipctl designate`` would
    (``extra["designation"]``: its ``p_ok`` at the model's default tolerance, GO, threshold and veto; the step's
    ``p_success``/``go`` are those, :func:`~scipctl.pipeline.chain_trust.score_steps`); left out: the packaged one;
    None: not scored (``p_success`` None, GO, as before the designation had a model).
    """
    params = (params or ChainParams()).check()
    if template_mode not in ("plane", "scale"):
        raise ValueError(f"template_mode must be 'plane' or 'scale', got {template_mode!r}")
    if handoff_at not in ("every", "last", "first"):
        raise ValueError(f"handoff_at must be 'every', 'last' or 'first', got {handoff_at!r}")
    from ..core.tracking import track
    from ..core.windows import extract_window, scale_window, window_scale_for_handoff
    from ..core.handoff.scip import SCIP
    from .chain_handoff import far_reference, hazcam_handoff

    tgt = None
    truth_xyz = None
    if target_id is not None:
        try:
            tgt = dl.target(target_id)
        except InputError:
            tgt = None
        tt = dl.truth_target(target_id)
        truth_xyz = None if tt is None else np.asarray(tt.xyz_site_m, float)

    def mark(prod):
        if tgt is None:
            return None
        m = tgt.mark_in(prod.product_id)
        return None if m is None else [m.u, m.v]

    def step(prod, kind, pred, uv, ps, ncc=None, ok=True, reason="", extra=None):
        mk = mark(prod)
        err = None if (mk is None or uv is None) else float(np.hypot(uv[0] - mk[0], uv[1] - mk[1]))
        xyz_site = None
        e3 = None
        rng = None
        if ps is not None and ps.ok:
            xyz_site = prod.pose.T_site_rover.apply(np.asarray(ps.xyz, float))
            rng = _f(ps.range_m)
            tp = dl.truth_for(prod.product_id)
            if truth_xyz is not None and tp is not None:
                # in the rover frame, where stereo measures it (the site-frame error is mostly pose-estimate error)
                X_true_rover = tp.pose.T_site_rover.inverse().apply(truth_xyz)
                e3 = float(np.linalg.norm(np.asarray(ps.xyz, float) - X_true_rover))
        # the target's footprint of one pixel of this image (its stereo range, else the current estimate's):
        # how the chain's trust compares pixel errors of different cameras and ranges (chain_trust.py)
        est = rng if rng is not None else float(np.linalg.norm(
            prod.pose.T_site_rover.inverse().apply(X_site) - prod.camera_model.C))
        extra = dict(extra or {})
        extra["px_mm"] = None if est is None else _f(1000.0 * est / prod.camera_model.hs)
        return ChainStep(prod.position, prod.camera, prod.product_id, kind,
                         None if pred is None else [float(x) for x in pred],
                         None if uv is None else [float(x) for x in uv], mk, err, _f(ncc), rng,
                         None if xyz_site is None else xyz_site.tolist(),
                         None if truth_xyz is None else truth_xyz.tolist(), e3, ok, reason, extra)

    steps = []
    uv = np.asarray(start_uv, float)
    ps = stereo_at(dl, start, uv, params)
    if ps is None or not ps.ok:
        reason = "no right eye" if ps is None else ps.reason
        raise InputError(start.product_id, "pixel", f"designation has no stereo: {reason}")
    steps.append(step(start, "designate", None, uv, ps))
    # the designation's own evidence, as `scipctl designate` builds it from the same point stereo (scored below)
    from .designate import designation_from_stereo

    designation = designation_from_stereo(start, dl.stereo_pair(start), uv, ps, params.band(start.camera),
                                          params.stereo_window(start.camera), target_id or "target")
    X_site = start.pose.T_site_rover.apply(on_left_ray(start.camera_model, uv, ps.xyz))
    prev, prev_uv, prev_range = start, uv, float(ps.range_m)
    cam = start.camera
    normal, ground, normal_from, prev_stereo = None, None, None, None
    # (product_id, downsampling, median) -> keypoints of the whole image (each new image is searched once); the
    # visual odometry's whole-image matches too (vo_correction)
    feats = {} if feature_cache is None else feature_cache

    positions = [p for p in dl.positions() if p != start.position]
    positions = [p for p in positions if min(im.time_s for im in dl.images_at(p)) > start.time_s]
    haz_positions = [p for p in positions if dl.images_at(p, "hazcam", "left")] or [None]
    for pos in positions:
        lefts = {im.camera: im for im in sorted(dl.images_at(pos, eye="left"), key=lambda i: i.time_s)}
        order = []
        if cam in lefts:
            order.append(cam)
        if cam == "pancam" and "navcam" in lefts:
            order.append("navcam")
        for c in order:
            prod = lefts[c]
            X_rover = prod.pose.T_site_rover.inverse().apply(X_site)
            pred = prod.camera_model.project(X_rover[None])[0]
            rng_new = float(np.linalg.norm(X_rover - prod.camera_model.C))
            if not np.all(np.isfinite(pred)):
                steps.append(step(prod, "track", None, None, None, ok=False, reason="target behind the camera"))
                continue
            scale = window_scale_for_handoff(1.0 / prev.camera_model.hs, prev_range, 1.0 / prod.camera_model.hs, rng_new)
            half = params.template_half(c)
            kind = "handoff" if c != prev.camera else "track"
            tpl, tc, mode = None, None, "scale"
            radius_override, search_uv = None, None
            extra = {}
            tr = None
            # the pose error lies between stops: a track, or a handoff from a camera at an earlier stop
            if template_mode == "plane" and (kind == "track" or prev.position != prod.position):
                if normal_from is not prev:
                    X_prev = prev.pose.T_site_rover.inverse().apply(X_site)
                    prev_stereo = near_dense_stereo(dl, prev, prev_range)  # the normals' and the odometry's
                    (normal, ground), normal_from = local_normals_site(prev, X_prev, prev_range, prev_stereo), prev
                # the surface plane at the target (or the rover's ground plane when dense stereo gave no normal)
                # renders the template; the coarse step also tries the surrounding ground's plane
                planes, n_view = render_planes(prev, normal, ground)
                # the new image's own stereo says which template pixels the plane misplaces (relief_mask)
                new_stereo = None if params.relief_max_parallax_px is None else near_dense_stereo(dl, prod, rng_new)
                vo = None
                if kind == "track" and c in params.vo_cameras:
                    vo = vo_correction(dl, prev, prod, prev_range, feats, params, prev_stereo)
                elif kind == "handoff" and params.vo_handoff:
                    # (a handoff here is across a drive: the block's condition) between two cameras whose pixels
                    # may differ on the ground by a factor of 3 (Mars 2020): keypoints at matched resolutions
                    vo = vo_correction(dl, prev, prod, prev_range, feats, params, prev_stereo, new_range_m=rng_new)
                surface = prev_stereo if (params.template_surface and kind == "track") else None
                tr, finfo = feature_track(prev, prod, X_site, planes, n_view, pred, scale, half, feats, params,
                                          new_stereo, vo=vo, surface=surface)
                sig = params.texture_retry_sigma_px
                if sig is not None and finfo.get("feature_status") != "confirmed":
                    # nothing confirmed: the two views may differ in their lighting (another sun); the same step on
                    # their texture alone. Where the new view is the finer (scale > 1, a track towards the target) the
                    # previous image's blur covers the same ground as the new one's; otherwise both blur by sig px
                    tr2, finfo2 = feature_track(texture_view(prev, max(sig / max(scale, 1.0), 1.0)),
                                                texture_view(prod, sig), X_site, planes, n_view, pred, scale, half,
                                                feats, params, new_stereo, surface=surface)
                    if finfo2.get("feature_status") == "confirmed":
                        tr, finfo = tr2, dict(finfo2, texture_retry=finfo.get("feature_status"))
                    else:
                        finfo["texture_retry"] = finfo2.get("feature_status")
                extra.update(finfo)
                if tr is not None:
                    mode = "plane, feature-guided"
                elif normal is not None:
                    extra["coarse"] = "ncc context (features failed)"
                    # fallback: a large window of the previous view, warped through the local plane, found over
                    # the whole search region by NCC; then the target window near it
                    big_half = params.context_half(c)
                    tpl_big, tc_big = plane_warped_template(prev, prod, X_site, normal, pred, big_half,
                                                            antialias=params.render_antialias)
                    tr_big = None
                    if tpl_big is not None:
                        tr_big = track(tpl_big, prod.pixels_float(), pred, params.search_radius(c),
                                       template_center_uv=tc_big, min_score=0.3)
                    # the template shows the previous view of the plane around the target, built around the
                    # pose-estimate prediction (where the warp puts the target at the template's centre)
                    tpl, tc = plane_warped_template(prev, prod, X_site, normal, pred, half,
                                                    antialias=params.render_antialias)
                    mode = "plane"
                    if tr_big is not None and tr_big.ok and np.all(np.isfinite(tr_big.uv)):
                        search_uv = tr_big.uv  # searched for near the prediction corrected for the pose error
                        radius_override = params.fine_radius_px
                        mode = "plane, context-corrected"
            if tr is None:
                if tpl is None:
                    src_half = max(3, int(np.ceil(half / scale)))
                    win = extract_window(prev.pixels_float(), prev_uv, src_half)
                    tpl = scale_window(win, scale)
                    tc = None
                img = prod.pixels_float()
                radius = radius_override or params.search_radius(c)
                search_uv = search_uv if radius_override else pred
                tr = track(tpl, img, search_uv, radius, template_center_uv=tc, min_score=0.3)
                # a pointed mast camera was aimed at the target by the rover: its image centre is a second guess
                centre = np.array([(prod.width - 1) / 2, (prod.height - 1) / 2])
                if prod.mast is not None and radius_override is None and np.linalg.norm(centre - pred) > radius / 2:
                    tr2 = track(tpl, img, centre, radius, template_center_uv=tc, min_score=0.3)
                    if np.all(np.isfinite(tr2.uv)) and (not np.all(np.isfinite(tr.uv)) or tr2.score > tr.score):
                        tr = tr2
            if not tr.ok or not np.all(np.isfinite(tr.uv)):
                steps.append(step(prod, kind, pred, None, None, tr.score, ok=False, reason=f"track: {tr.reason}"))
                continue
            ps = stereo_at(dl, prod, tr.uv, params)
            ok = ps is not None and ps.ok
            reasons = [] if ok else ["no right eye" if ps is None else f"stereo: {ps.reason}"]
            weak = False
            if extra.get("feature_status") == "unconfirmed":
                # a position from feature matches alone is an extrapolation of a RANSAC model: it moved by pixels
                # with the OpenCV build or one DN of noise (docs/stereo-and-tracking.md, "Reproducibility"), so it
                # is reported but never the next stop's reference (no count threshold to flip across)
                nl = extra.get("feature_local_inliers", 0)
                weak = True
                reasons.append(f"weak match: position from the feature match alone ({nl} keypoint matches near the "
                               f"target); NCC did not confirm it")
            elif extra.get("feature_status") == "failed":
                # measured on the simulated runs: NCC alone over the pose error's search region was wrong
                # every time the features failed, so its answer is reported but not trusted
                weak = True
                reasons.append(f"unverified: no feature match ({extra.get('feature_reason', '')}); "
                               f"NCC-only answer over a {radius:g} px search")
            steps.append(step(prod, kind, pred, tr.uv, ps, tr.score, ok=ok and not weak, reason="; ".join(reasons),
                              extra={"scale": scale, "template": mode, "ncc_ratio": _f(tr.ratio),
                                     "reference": prev.product_id, "unverified": weak, **extra}))
            if weak:  # not a reference for the next stop: the next one is tracked from the last good one
                continue
            if ok:
                X_site = prod.pose.T_site_rover.apply(on_left_ray(prod.camera_model, tr.uv, ps.xyz))
                prev_range = float(ps.range_m)
            else:
                # no stereo: the tracked pixel's ray at the predicted range keeps the estimate consistent with the
                # pixel in this pose (a handoff at the same stop then predicts without the pose error)
                o, d = prod.camera_model.unproject(np.asarray(tr.uv, float)[None])
                X_site = prod.pose.T_site_rover.apply(o[0] + rng_new * d[0])
                prev_range = rng_new
            prev, prev_uv, cam = prod, tr.uv, c
        if "hazcam" in lefts and cam == "navcam" and (handoff_at != "last" or pos == haz_positions[-1]):
            haz = lefts["hazcam"]
            hstereo = (lambda uv, _h=haz: stereo_at(dl, _h, uv, params))
            far = far_reference(steps, pos)
            if prev.position == pos:
                steps.append(hazcam_handoff(dl, prev, prev_uv, haz, handoff_method, step, hstereo,
                                            far=far, target_id=target_id, setups=setups))
            elif handoff_method == SCIP and "navcam" in lefts and far is not None:
                # this stop's navcam track is not verified: scip hands off from the last verified navcam pixel
                # (an earlier stop) alone, as simulate-handoff does with a far mark only
                steps.append(hazcam_handoff(dl, lefts["navcam"], None, haz, handoff_method, step, hstereo,
                                            far=far, target_id=target_id, setups=setups))
            else:
                continue
            if handoff_at == "first":
                break
    handoffs = [s for s in steps if s.camera == "hazcam" and s.kind == "handoff"]
    for s in handoffs:
        s.extra["final"] = s is handoffs[-1]
    _mark_after_unverified(steps)
    if (params.closure or params.answer == "closure") and handoffs and handoffs[-1].tracked_uv is not None:
        from .chain_closure import closure_check

        handoffs[-1].extra["closure"] = closure_check(dl, steps, params, feats).to_dict()
    from .chain_trust import advice_for, score_hazcam_handoffs, score_steps

    if step_model is None:
        from ..io.step_trust_model import load_packaged_step_trust_model

        step_model = load_packaged_step_trust_model()
    if designation_model is ...:
        from ..io.trust_model import PACKAGED_DESIGNATION, load_packaged_trust_model

        designation_model = load_packaged_trust_model(PACKAGED_DESIGNATION)
    if designation_model is not None:
        from .designate import with_window_range_gap
        from .designation_trust import assess, uses_window_gap

        if uses_window_gap(designation_model):  # its dense stereo costs ~0.5 s: only for a model that reads it
            designation = with_window_range_gap(designation, start, dl.stereo_pair(start),
                                                params.stereo_window(start.camera))
        a = assess(designation_model, designation)
        steps[0].extra["designation"] = {"p_ok": a.p_ok, "go": a.go, "tolerance_pct": a.tolerance_pct,
                                         "go_min_p": a.go_min_p, "veto": a.veto}
    score_steps(steps, step_model)
    score_hazcam_handoffs(steps)
    if params.answer == "closure" and handoffs and "closure" in handoffs[-1].extra:
        # after the scoring: the closure's evidence includes its reference step's own p_success
        final = steps.index(handoffs[-1])
        _adopt_closure(dl, steps, final, step, params, closure_model)
        steps[final].advice = None if steps[final].go else advice_for(steps, final)
    return steps


def _adopt_closure(dl: Downlink, steps: list, final: int, make_step, params: ChainParams, model=None) -> None:
    """Make a confirmed closure the chain's final answer, in place: ``steps[final]`` (the final hazcam handoff) is
    replaced by a step at the closure's pixel (point stereo there, the error against the mark), ``extra["answer"]``
    ``"closure"`` and the handoff's own answer kept under ``extra["handoff"]``; its ``p_success`` (and
    ``extra["go_min_p"]``) from the closure trust model (``model``; None: the packaged one; no model: None and
    NO-GO); never GO when its reference is more than ``params.closure_go_max_drives`` drives from the designation
    (:func:`reference_drives`; ``reason`` says so). An unconfirmed or failed closure leaves the handoff's answer
    (``extra["answer"]`` ``"handoff"``)."""
    from .chain_closure import closure_evidence

    H = steps[final]
    cl = H.extra.get("closure") or {}
    if cl.get("status") != "confirmed" or cl.get("uv") is None:
        H.extra["answer"] = "handoff"
        return
    if model is None:
        from ..io.closure_trust_model import load_packaged_closure_trust_model

        model = load_packaged_closure_trust_model()
    haz = dl.product(H.product_id)
    uv = np.asarray(cl["uv"], float)
    ps = stereo_at(dl, haz, uv, params)
    ok = ps is not None and ps.ok
    own = ("scip_p_success", "scip_go", "navcam_p_success")  # the handoff's trust (chain_trust.score_hazcam_handoffs)
    handoff = {"uv": H.tracked_uv, "error_px": H.error_px, "p_success": H.p_success, "go": H.go,
               "go_min_p": H.extra.get("go_min_p"), "ncc_peak": H.ncc_peak, "ok": H.ok, "reason": H.reason,
               **{k: H.extra[k] for k in own if k in H.extra}}
    extra = {k: v for k, v in H.extra.items() if k not in ("px_mm", "go_min_p") + own}
    extra.update({"answer": "closure", "handoff": handoff, "go_min_p": None if model is None else model.go_min_p})
    reason = "" if ok else ("no right eye" if ps is None else f"stereo: {ps.reason}")
    new = make_step(haz, H.kind, H.predicted_uv, uv, ps, cl.get("ncc_peak"), ok=ok, reason=reason, extra=extra)
    if model is None:
        new.p_success, new.go = None, False
    else:
        p = float(model.probability([closure_evidence(steps, cl)])[0])
        new.p_success = p
        new.go, note = closure_go(ok, p, model.go_min_p, steps, cl.get("reference_step"),
                                  params.closure_go_max_drives)
        if note:
            new.reason = f"{new.reason}; {note}" if new.reason else note
    steps[final] = new


def closure_go(stereo_ok: bool, p_success: float, go_min_p: float, steps: list, reference_step,
               max_drives: int) -> tuple[bool, str]:
    """The GO rule of an adopted closure, the one place it is spelled (the chain's ``_adopt_closure`` and the
    measurement scripts that score recorded chains again call it): ``(go, note)``. GO needs point stereo at the
    closure's pixel (``stereo_ok``), ``p_success >= go_min_p`` (the closure model's threshold) and a reference step
    no more than ``max_drives`` drives from the designation (``ChainParams.closure_go_max_drives``,
    :func:`reference_drives`). ``note`` is non-empty only when the drives rule alone turned a GO down, and says so."""
    if not (stereo_ok and p_success >= go_min_p):
        return False, ""
    drives = reference_drives(steps, reference_step)
    if drives is not None and drives <= max_drives:
        return True, ""
    return False, (f"the closure's reference is {drives} drives from the designation, beyond the closure model's "
                   f"{max_drives} (its p does not see the drift of the tracks between)")


def reference_drives(steps: list, reference_step) -> Optional[int]:
    """How many drives separate the designation (``steps[0]``) from ``steps[reference_step]``: the distinct stops
    (``position``) from the first step to it, less one; None when ``reference_step`` is not a step index."""
    if not isinstance(reference_step, int) or not 0 <= reference_step < len(steps):
        return None
    return len({tuple(s.position) for s in steps[: reference_step + 1]}) - 1


def _mark_after_unverified(steps: list) -> None:
    """Steps after an unverified one carry ``extra["follows_unverified"]`` (its product id) and say so.

    The chain skips an unverified step as a reference (the next stop is
    tracked from the last verified image, across a longer drive and a
    larger change of scale), so whatever error that longer step makes is
    magnified by every later zoom. The step itself may be right (s1-straight
    t1: 2.1-3.3 px at the hazcam), but it is not the chain the operator
    expects, and ``reason`` says so.
    """
    first = None
    for s in steps:
        if first is not None and s.kind in ("track", "handoff"):
            s.extra["follows_unverified"] = first
            note = f"warning: follows the unverified step at {first}"
            s.reason = f"{s.reason}; {note}" if s.reason else note
        elif first is None and s.extra.get("unverified"):
            first = s.product_id
