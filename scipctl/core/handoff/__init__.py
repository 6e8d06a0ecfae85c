"""Navcam -> hazcam handoff methods (pure numerics).

The paper's twelve methods are six methods, each run from "near" navcams (the
pair taken at the hazcam's rover position) or "far" navcams (a pair taken
earlier, a few metres back, which brings the rover's pose estimate into the
chain). A :class:`HandoffCase` (``case.py``) holds one navcam pair, the hazcam
pair and the transform between their rover frames; its shared products (dense
stereo, clouds, registrations) are computed once and reused by every method
and target.

Each method is a function ``method(case, nav_uv, params, *, near_hint=None) ->
MethodResult`` in a family module, registered by name in ``registry.py``
(:data:`METHODS`, :class:`Method`); :func:`run_method` runs one by name.

Paper methods (names used on the command line and in JSON):

``pure-kinematic``      (kinematic) point stereo on the navcams -> 3-D -> hazcam model.
``alt-pure-kinematic``  (kinematic) the same with the dense ("JPL", rectified) stereo range.
``refined-kinematic``   (kinematic) near: expected hazcam window splatted from the navcam
                        dense cloud, centred on the alt-pure-kinematic point,
                        NCC-tracked into the hazcam image; far: the far navcam
                        window brought into the hazcam view, tracked around the
                        near pure-kinematic point (``near_hint``, as in the paper).
                        Beyond the paper, the window is warped through the local plane
                        (fitted to the far navcam's dense points around the target)
                        instead of scaled uniformly by the IFOV and range ratios — the
                        "affine warping" the paper left unexplored; the uniform
                        scale (``far_window_warp="scale"``) misses by ~4 px off the
                        fish-eye hazcam's axis even with no error.
``pure-geometric``      (geometric) hazcam dense cloud -> navcam image; the hazcam point
                        whose projection lands nearest the navcam target. Beyond the
                        paper, refined by Gauss-Newton on the hazcam pixel with
                        hazcam point stereo for the range (the dense range's
                        few-mm error at one pixel is ~1 px of handoff error).
``refined-geometric``   (geometric) the navcam image draped over the hazcam stereo surface
                        as the expected hazcam window (anti-aliased to the hazcam
                        pixel footprint), centred on the pure-geometric point,
                        NCC-tracked.
``mesh-registration``   (registration) ICP between the navcam and hazcam clouds (seeded
                        with the mast kinematics for near, the pose estimate for far),
                        then kinematic handoff through the recovered transform.

Methods beyond the paper (see docs/handoff.md):

``coarse-fine-geometric`` (geometric) the paper's suggestion for refinement failures:
                        track a large draped window (more context) first, then the
                        small one within a few pixels of that answer.
``consensus``           (combined) of coarse-fine-geometric, refined-geometric and
                        refined-kinematic, those with NCC peak above
                        ``consensus_min_score`` that agree within
                        ``consensus_agree_px`` (two or more): their mean, flagged
                        confident; otherwise the pure-geometric answer, flagged
                        not confident. Failure detection from expected images
                        built in different ways.
"""

from .case import HandoffCase
from .params import HandoffParams
from .registry import ALL_METHODS, EXTRA_METHODS, METHODS, PAPER_METHODS, Method, run_method
from .result import MethodResult, NoAnswer
from .run import MethodFn, call_method
from .steps import local_ifov_rad
from .view import StereoView

__all__ = [
    "ALL_METHODS", "EXTRA_METHODS", "HandoffCase", "HandoffParams", "METHODS", "Method", "MethodFn",
    "MethodResult", "NoAnswer", "PAPER_METHODS", "StereoView", "call_method", "local_ifov_rad", "run_method",
]
