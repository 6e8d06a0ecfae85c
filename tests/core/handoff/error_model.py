"""The error model of the handoff methods on the tiny synthetic case (tests/core/handoff/synthetic.py), shared by
the tests of scipctl/core/handoff/ (test_registry.py, test_registration.py).

Models and poses are exact, so a method's error is its own: the
range error of the stereo it uses, carried into the hazcam, plus for the
tracked methods the NCC peak's offset. Stereo's a priori disparity
uncertainty is sigma_d = 0.25 px for point stereo (the figure of
``HandoffParams.registration_disparity_sigma_px``) and, here, 0.5 px for
dense (SGBM) stereo, i.e. sigma_r = r^2 sigma_d / (f b). With 3 sigma:

* kinematic (navcam range): the truth moved along the navcam-left ray by
  3 sigma_r, projected into the hazcam -> ``kin`` px;
* geometric (hazcam range): the truth moved along the hazcam-left ray by
  3 sigma_r moves its navcam projection by dq; the hazcam pixel that
  projects back onto the target moves by J^-1 dq (J: navcam px per hazcam
  px) -> ``geo`` px;
* every answer: + 0.5 px, the rendering (2 x 2 supersampled pixels vs the
  marks' point projection);
* mesh registration: kin + 1 px for ICP started at the exact seed;
* tracked methods (an expected window NCC-tracked): the bound of the
  geometry the window was built from + 1 px (NCC peak and window resampling);
  consensus: the largest of its candidates' bounds.
"""

from __future__ import annotations

import numpy as np

from scipctl.core.handoff import HandoffCase, Method
from scipctl.core.handoff.geometric import haz_to_nav_jacobian

POINT_SIGMA_D_PX = 0.25
DENSE_SIGMA_D_PX = 0.5
RENDER_PX = 0.5
ICP_PX = 1.0
TRACK_PX = 1.0


def _kin_px(case: HandoffCase, X_haz, sigma_d_px: float) -> float:
    """Hazcam px moved by the truth ``X_haz`` (3,) displaced 3 sigma_r along the navcam-left ray."""
    nav = case.nav.left_model
    Xn = case.T_haz_nav.inverse().apply(X_haz[None])[0]
    r = float(np.linalg.norm(Xn - nav.C))
    s = 3 * r * r * sigma_d_px / case.nav.dense.focal_baseline_px_m
    X2 = case.T_haz_nav.apply((Xn + s * (Xn - nav.C) / r)[None])[0]
    haz = case.haz.left_model
    return float(np.linalg.norm(haz.project(X2[None])[0] - haz.project(X_haz[None])[0]))


def _geo_px(case: HandoffCase, X_haz, sigma_d_px: float) -> float:
    """Hazcam px moved by the hazcam range error: J^-1 of the navcam px moved by a 3 sigma_r shift along the
    hazcam-left ray."""
    haz = case.haz.left_model
    r = float(np.linalg.norm(X_haz - haz.C))
    s = 3 * r * r * sigma_d_px / case.haz.dense.focal_baseline_px_m
    nav_in_haz = case.nav_model_in_haz()
    dq = nav_in_haz.project((X_haz + s * (X_haz - haz.C) / r)[None])[0] - nav_in_haz.project(X_haz[None])[0]
    J = haz_to_nav_jacobian(case, haz.project(X_haz[None])[0], nav_in_haz)
    assert J is not None
    return float(np.linalg.norm(np.linalg.solve(J, dq)))


def bound_px(method: str, case: HandoffCase, X_haz) -> float:
    """The error model above, for ``method`` on ``case`` at the true point ``X_haz`` (3,) (hazcam rover frame)."""
    kin = _kin_px(case, X_haz, POINT_SIGMA_D_PX) + RENDER_PX
    kin_dense = _kin_px(case, X_haz, DENSE_SIGMA_D_PX) + RENDER_PX
    geo = _geo_px(case, X_haz, POINT_SIGMA_D_PX) + RENDER_PX
    far_window = max(kin, geo)  # far refined-kinematic: the far navcam window, placed by both stereos
    bounds = {
        Method.PURE_KINEMATIC: kin,
        Method.ALT_PURE_KINEMATIC: kin_dense,
        Method.REFINED_KINEMATIC: (kin_dense if case.label == "near" else far_window) + TRACK_PX,
        Method.PURE_GEOMETRIC: geo,
        Method.REFINED_GEOMETRIC: geo + TRACK_PX,
        Method.MESH_REGISTRATION: kin + ICP_PX,
        Method.COARSE_FINE_GEOMETRIC: geo + TRACK_PX,
    }
    bounds[Method.CONSENSUS] = max(bounds[Method.COARSE_FINE_GEOMETRIC], bounds[Method.REFINED_GEOMETRIC],
                                   bounds[Method.REFINED_KINEMATIC], bounds[Method.PURE_GEOMETRIC])
    bounds[Method.SCIP] = max(bounds.values())  # scip answers one of the candidate methods' answers
    return bounds[Method(method)]
