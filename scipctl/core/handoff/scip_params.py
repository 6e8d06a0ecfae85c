"""Parameters of ``scip``, the recommended handoff (one home, checked): its evidence and its GO rule."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Optional

from .trust_model import TrustModel


@dataclass
class ScipParams:
    """``scip``'s parameters. Pixel figures are hazcam-left pixels unless named otherwise.

    ``model``: the fitted trust model (:class:`~scipctl.core.handoff.trust_model.TrustModel`; the core reads no
    file: ``scipctl.io.trust_model.load_trust_model`` loads the packaged one and the pipeline passes it in);
    None: ``scip`` answers with ``p_success`` unknown and NO-GO. ``success_px``: the success radius the
    probability is for (the model must have been fitted for it, or for two radii around it: see
    :meth:`TrustModel.probability`). ``go_min_p``: GO when ``p_success >= go_min_p``; None takes the model's
    recommended threshold for ``success_px`` (chosen when it was fitted: docs/handoff.md, "Trust: scip").
    """

    model: Optional[TrustModel] = None
    success_px: float = 4.0
    go_min_p: Optional[float] = None
    agree_px: float = 3.0  # candidates this close count as agreeing (support, near/far agreement)
    appearance_radius_px: float = 8.0  # the expected window is tracked this far around each candidate
    backtrack_radius_px: float = 30.0  # forward-backward: the hazcam window's search in the navcam (hazcam px)
    dedup_px: float = 0.25  # candidates closer than this are one candidate (evidence computed once)
    geometry_sigma_floor_m: float = 0.005  # 3-D agreement: sigma = hypot(stereo sigmas, this floor)
    # occlusion evidence: the hazcam's dense stereo over the disk of this radius around a candidate, against the
    # predicted target's range (the success radius: a surface in front over that disk hides the target there)
    occlusion_disk_px: float = 4.0
    # geometry veto: NO-GO, whatever p_success, when the answer's hazcam point lands farther than this (hazcam px)
    # from the navcam target in every view (Evidence.geo_best_nav_res_px; unknown: no veto). None: no veto.
    # 40 px: 1.5x the largest of any candidate within 4 px in tests/data/trust/evidence-24dl.jsonl.gz (27.3 px;
    # median 48.6 px for those > 20 px off); it vetoes none of the 321 held-out GO answers there and catches
    # look-alike answers to hidden targets (tests/pipeline/test_handoff_broken.py, docs/handoff.md)
    geometry_veto_px: Optional[float] = 40.0

    def check(self) -> "ScipParams":
        """Raise ``ValueError`` naming the first parameter out of its range; return ``self``."""
        def bad(name, why):
            raise ValueError(f"ScipParams.{name} = {getattr(self, name)!r}: {why}")

        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, (int, float)) and not isinstance(v, bool) and not math.isfinite(v):
                bad(f.name, "must be finite")
        for name in ("success_px", "agree_px", "appearance_radius_px", "backtrack_radius_px", "dedup_px",
                     "geometry_sigma_floor_m", "occlusion_disk_px"):
            if not getattr(self, name) > 0:
                bad(name, "must be > 0")
        if self.geometry_veto_px is not None and not self.geometry_veto_px > 0:
            bad("geometry_veto_px", "must be > 0 (or None: no veto)")
        if self.go_min_p is not None and not 0 <= self.go_min_p <= 1:
            bad("go_min_p", "is a probability: must be in [0, 1]")
        if self.model is not None and not isinstance(self.model, TrustModel):
            bad("model", "must be a TrustModel or None")
        return self
