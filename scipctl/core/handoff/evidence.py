"""Evidence for one candidate answer of a handoff: is this hazcam pixel the navcam target? (pure numerics)

A candidate is a hazcam-left pixel ``c`` (2,) some method answered for a target. Its :class:`Evidence` comes from
three sources whose errors are as independent as this problem allows (one NCC tracker fails the same way on every
window built from one image, so agreement between trackers alone is weak evidence):

* **appearance**, per navcam view (near / far): the *expected window* -- the navcam image around the navcam target
  warped into the hazcam view through the target's local plane (``windows.plane_window``; its centre is the navcam
  target by construction) -- compared with the hazcam image at ``c``: the NCC with its centre exactly at ``c``,
  and a track within ``appearance_radius_px`` of ``c`` (peak score, the peak's distance from ``c``, uniqueness
  = ratio to the second peak, sharpness);
* **geometry**, per view: hazcam point stereo at ``c`` (a 3-D point, hazcam rover frame) against the target's 3-D
  point from navcam point stereo moved by the registered navcam -> hazcam transform (whole-cloud ICP; the seed
  when it failed), in units of the expected sigma (both stereo range sigmas, 0.25 px of disparity, and a floor),
  and the same point projected back into the navcam: its distance from the navcam target, in hazcam px;
  occlusion: the hazcam's own dense stereo over the disk of ``occlusion_disk_px`` around ``c`` against the
  predicted target's range (the median of how much nearer the surface there is, in units of the same sigma: a
  stone standing in front of the target puts the answer on the stone); the registration's own checks (ICP fitness
  and RMS, and the registration-check keys of :data:`REGISTRATION_CHECK_KEYS` when the mesh-registration
  diagnostics carry them);
* **consistency**: forward-backward (the hazcam window at ``c`` warped into the navcam view and tracked back
  there: the return error, in hazcam px), and agreement between candidates (how many method groups --
  kinematic / geometric / registration, near / far -- answered within ``agree_px`` of ``c``; how many *other*
  families did; the distance to the nearest candidate of the other navcam).

Features are NaN (``None`` in JSON) when they cannot be computed; the trust model imputes them
(:mod:`.trust_model`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..expected import bilinear_sample, footprint_blur_cov, gaussian_blur_cov
from ..transforms import RigidTransform
from .case import HandoffCase
from .params import HandoffParams
from .result import MethodResult, NoAnswer
from .trust_model import evidence_from_dict, evidence_to_dict
from .steps import track
from .windows import nav_plane_normal, plane_window

# the methods whose answers are scip's candidates, and their families (methods of one family share failures)
METHOD_FAMILY = {
    "pure-kinematic": "kinematic", "alt-pure-kinematic": "kinematic", "refined-kinematic": "kinematic",
    "pure-geometric": "geometric", "refined-geometric": "geometric", "coarse-fine-geometric": "geometric",
    "mesh-registration": "registration",
}
CANDIDATE_METHODS = tuple(METHOD_FAMILY)
VIEWS = ("near", "far")

# registration-check evidence in mesh-registration's diagnostics (issue #14 item 2), when present:
# Evidence field suffix -> (where, key, absolute value): "diag" a key of the diagnostics (the ICP of the chosen
# answer), "check" a key of diagnostics["registration_check"] (core.registration_check.RegistrationEvidence)
REGISTRATION_CHECK_KEYS = {
    "fitness": ("diag", "icp_fitness", False),
    "rmse_m": ("diag", "icp_rmse_m", False),
    "global_agree_px": ("check", "global_px", False),  # global-seeded basin's answer against the chosen, at the target
    "seed_spread_px": ("check", "spread_px", False),  # largest distance to another basin's answer at the target
    "target_residual_m": ("check", "range_residual_m", True),  # |range - hazcam point stereo's range| at the answer
}

NAN = float("nan")


def _nanmin(*vals: float) -> float:
    known = [v for v in vals if math.isfinite(v)]
    return min(known) if known else NAN


@dataclass
class Evidence:
    """The evidence for one candidate answer (see the module docstring). Floats are NaN when unknown.

    ``method`` / ``navcam``: whose answer the candidate is (the first of the methods that gave it, when several
    gave the same pixel). Pixel distances are hazcam-left px, NCC scores in [-1, 1].
    """

    method: str
    navcam: str
    # appearance, near view
    app_near_score_at: float = NAN
    app_near_peak: float = NAN
    app_near_offset_px: float = NAN
    app_near_ratio: float = NAN
    app_near_sharpness: float = NAN
    # appearance, far view
    app_far_score_at: float = NAN
    app_far_peak: float = NAN
    app_far_offset_px: float = NAN
    app_far_ratio: float = NAN
    app_far_sharpness: float = NAN
    # forward-backward return error
    fb_near_error_px: float = NAN
    fb_far_error_px: float = NAN
    # geometry
    geo_near_sigma: float = NAN
    geo_far_sigma: float = NAN
    geo_near_nav_res_px: float = NAN
    geo_far_nav_res_px: float = NAN
    geo_haz_point: float = NAN  # 1: hazcam point stereo at c, 0.5: dense stereo only, 0: no hazcam range at c
    # occlusion: median over the disk around c of (predicted target range - hazcam dense range) / sigma, per view
    occ_near_front_sigma: float = NAN
    occ_far_front_sigma: float = NAN
    # the registrations (of the near / far navcam cloud onto the hazcam cloud)
    reg_near_fitness: float = NAN
    reg_near_rmse_m: float = NAN
    reg_near_global_agree_px: float = NAN
    reg_near_seed_spread_px: float = NAN
    reg_near_target_residual_m: float = NAN
    reg_far_fitness: float = NAN
    reg_far_rmse_m: float = NAN
    reg_far_global_agree_px: float = NAN
    reg_far_seed_spread_px: float = NAN
    reg_far_target_residual_m: float = NAN
    # consistency between candidates
    support_groups: float = NAN  # (family, navcam) groups other than the candidate's own answer within agree_px
    support_other_families: float = NAN  # families other than the candidate's own with an answer within agree_px
    other_navcam_px: float = NAN  # distance to the nearest candidate of the other navcam
    n_candidates: float = NAN

    # derived (not stored: computed from the per-view fields, so evidence tables written before them have them)
    @property
    def geo_best_nav_res_px(self) -> float:
        """The smaller of ``geo_near_nav_res_px`` / ``geo_far_nav_res_px`` (NaN when neither is known): how far
        (hazcam px) the hazcam point at the candidate lands from the navcam target in the view whose registered
        geometry agrees with it best (``scip``'s geometry veto, :class:`~.scip_params.ScipParams`)."""
        return _nanmin(self.geo_near_nav_res_px, self.geo_far_nav_res_px)

    def to_dict(self) -> dict:
        return evidence_to_dict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "Evidence":
        """From :meth:`to_dict`'s output; unknown keys are ignored, missing or null features are NaN."""
        return evidence_from_dict(cls, d)

    def feature(self, name: str) -> float:
        return float(getattr(self, name))


@dataclass
class TargetView:
    """What one navcam view knows of one target, computed once per target (see :func:`target_view`).

    Frames: ``X_pred_haz`` hazcam rover frame; ``A`` (2, 2) d(navcam px)/d(hazcam px) at the target.
    """

    label: str
    case: HandoffCase
    nav_uv: np.ndarray  # (2,)
    X_pred_haz: Optional[np.ndarray]  # (3,) target point (navcam point stereo) moved by the registered transform
    T_haz_nav_reg: RigidTransform  # registered (or seed) navcam -> hazcam rover transform
    sigma_m: float  # expected 3-D discrepancy sigma (hazcam and navcam stereo, floor)
    template: Optional[np.ndarray] = None  # expected hazcam window
    template_centre: Optional[np.ndarray] = None  # (2,) the navcam target in template pixels
    A: Optional[np.ndarray] = None
    reg: dict = field(default_factory=dict)  # registration-check evidence (Evidence suffix -> value)


def _range_sigma_m(r_m: float, focal_baseline_px_m: float, disparity_sigma_px: float) -> float:
    return disparity_sigma_px * r_m * r_m / focal_baseline_px_m


def target_view(case: HandoffCase, nav_uv, hparams: HandoffParams, sigma_floor_m: float,
                registration: Optional[MethodResult] = None) -> TargetView:
    """The :class:`TargetView` of ``case`` for the navcam-left pixel ``nav_uv`` (2,).

    ``registration``: the case's mesh-registration result for this target (its diagnostics carry the
    registration checks), if it ran.
    """
    nav_uv = np.asarray(nav_uv, float).reshape(2)
    T_haz_nav_seed = case.T_haz_nav
    reg = case.whole_registration()
    T_haz_nav_reg = T_haz_nav_seed if isinstance(reg, Exception) else reg.T_target_source
    regd = {}
    if registration is not None:
        check = registration.diagnostics.get("registration_check") or {}
        for suffix, (where, key, absolute) in REGISTRATION_CHECK_KEYS.items():
            v = (registration.diagnostics if where == "diag" else check).get(key)
            if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
                regd[suffix] = abs(float(v)) if absolute else float(v)
    elif not isinstance(reg, Exception):
        regd = {"fitness": float(reg.fitness), "rmse_m": float(reg.inlier_rmse_m)}
    ps = case.point_stereo(nav_uv)
    if not ps.ok:
        return TargetView(case.label, case, nav_uv, None, T_haz_nav_reg, NAN, reg=regd)
    X_nav = np.asarray(ps.xyz, float)
    X_pred = T_haz_nav_reg.apply(X_nav)
    r_nav = float(np.linalg.norm(X_nav - case.nav.left_model.C))
    r_haz = float(np.linalg.norm(X_pred - case.haz.left_model.C))
    ds = hparams.registration_disparity_sigma_px
    sigma = math.sqrt(_range_sigma_m(r_nav, case.nav.dense.focal_baseline_px_m, ds) ** 2
                      + _range_sigma_m(r_haz, case.haz.dense.focal_baseline_px_m, ds) ** 2 + sigma_floor_m**2)
    view = TargetView(case.label, case, nav_uv, X_pred, T_haz_nav_reg, sigma, reg=regd)
    n_nav = nav_plane_normal(case, hparams, nav_uv, X_nav)
    if n_nav is not None:
        tpl, tc, A = plane_window(case, T_haz_nav_seed.apply(X_nav), T_haz_nav_seed.rotate(n_nav),
                                  hparams.template_half_px)
        if tpl is not None and np.all(np.isfinite(A)) and abs(np.linalg.det(A)) > 1e-6:
            view.template, view.template_centre, view.A = tpl, np.asarray(tc, float), np.asarray(A, float)
    return view


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.mean() < 0.9:
        return NAN
    x = a[ok] - a[ok].mean()
    y = b[ok] - b[ok].mean()
    d = math.sqrt(float(x @ x) * float(y @ y))
    return float(x @ y) / d if d > 1e-9 else NAN


def appearance(view: TargetView, c: np.ndarray, radius_px: float) -> dict:
    """Appearance evidence of the hazcam pixel ``c`` (2,) against ``view``'s expected window (suffix -> value)."""
    if view.template is None:
        return {}
    tpl = view.template
    h, w = tpl.shape
    jj, ii = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    uv = np.stack([c[0] + jj - view.template_centre[0], c[1] + ii - view.template_centre[1]], -1)
    win = bilinear_sample(view.case.haz.left_img, uv)
    out = {"score_at": _ncc(tpl.astype(float).ravel(), win.astype(float).ravel())}
    tr = track(view.case, tpl, c, radius_px, -1.0, template_center_uv=view.template_centre)
    if np.all(np.isfinite(tr.uv)):
        out.update(peak=float(tr.score), offset_px=float(np.linalg.norm(tr.uv - c)),
                   ratio=NAN if math.isnan(tr.ratio) else float(min(tr.ratio, 10.0)),
                   sharpness=float(tr.sharpness))
    return out


def forward_backward(view: TargetView, c: np.ndarray, radius_px: float, half_px: int) -> float:
    """Return error (hazcam px) of the hazcam window at ``c`` (2,) tracked back into ``view``'s navcam.

    The window: hazcam pixels ``c + A^-1 d`` for navcam offsets ``d`` on a grid of about the expected window's
    ground size (anti-aliased when the navcam is coarser), tracked within ``radius_px`` hazcam px (as navcam px
    through ``A``) of the navcam target. ``radius_px`` when the track finds nothing.
    """
    if view.A is None:
        return NAN
    A = view.A
    Ai = np.linalg.inv(A)
    scale = math.sqrt(abs(np.linalg.det(A)))
    K = int(np.clip(round(half_px * scale), 7, 45))
    dj, di = np.meshgrid(np.arange(-K, K + 1, dtype=float), np.arange(-K, K + 1, dtype=float))
    d = np.stack([dj, di], -1)
    uv = c + d @ Ai.T
    haz = view.case.haz.left_img
    cov = footprint_blur_cov(Ai)
    pad = int(np.ceil(3 * math.sqrt(max(cov[0, 0], cov[1, 1])))) + 3
    H, W = haz.shape
    u0, v0 = int(max(np.floor(uv[..., 0].min()) - pad, 0)), int(max(np.floor(uv[..., 1].min()) - pad, 0))
    u1, v1 = int(min(np.ceil(uv[..., 0].max()) + pad + 1, W)), int(min(np.ceil(uv[..., 1].max()) + pad + 1, H))
    if u1 - u0 < 4 or v1 - v0 < 4:
        return NAN
    crop = gaussian_blur_cov(haz[v0:v1, u0:u1], cov)
    tpl = bilinear_sample(crop, uv - [u0, v0])
    if np.isfinite(tpl).mean() < 0.9:
        return NAN
    tpl = np.where(np.isfinite(tpl), tpl, np.nanmean(tpl)).astype(np.float32)
    from ..tracking import track as _track

    r_nav = radius_px * float(np.linalg.norm(A, 2))
    tr = _track(tpl, view.case.nav.left_img, view.nav_uv, r_nav, min_score=-1.0)
    if not np.all(np.isfinite(tr.uv)):
        return float(radius_px)
    return float(min(np.linalg.norm(Ai @ (tr.uv - view.nav_uv)), radius_px))


def haz_point_at(case: HandoffCase, c: np.ndarray, range_hint_m: Optional[float]) -> tuple[Optional[np.ndarray], float]:
    """The hazcam 3-D point at ``c`` (2,) (hazcam rover frame): point stereo (quality 1), else dense (0.5), else
    (None, 0)."""
    X = case.haz_point(c, range_hint_m)
    if X is not None:
        return np.asarray(X, float), 1.0
    Xd = case.haz.xyz_at(np.asarray(c, float)[None])[0]
    if np.all(np.isfinite(Xd)):
        return Xd, 0.5
    return None, 0.0


def geometry(view: TargetView, X_c: Optional[np.ndarray]) -> dict:
    """Geometric evidence of the hazcam point ``X_c`` (3,) against ``view`` (suffix -> value)."""
    if X_c is None or view.X_pred_haz is None:
        return {}
    out = {"sigma": float(np.linalg.norm(X_c - view.X_pred_haz) / view.sigma_m)}
    q = view.case.nav.left_model.project(view.T_haz_nav_reg.inverse().apply(X_c[None]))[0]
    if np.all(np.isfinite(q)):
        Ai = np.linalg.inv(view.A) if view.A is not None else None
        dq = q - view.nav_uv
        out["nav_res_px"] = float(np.linalg.norm(Ai @ dq) if Ai is not None else np.linalg.norm(dq))
    return out


def disk_offsets(radius_px: float) -> np.ndarray:
    """Integer pixel offsets ``(K, 2)`` within ``radius_px`` of the origin (row-major order)."""
    r = int(math.floor(radius_px))
    dv, du = np.mgrid[-r:r + 1, -r:r + 1]
    m = du**2 + dv**2 <= radius_px**2
    return np.stack([du[m], dv[m]], -1).astype(float)


def occlusion(view: TargetView, c: np.ndarray, disk_px: float) -> dict:
    """Occlusion evidence of the hazcam pixel ``c`` (2,) against ``view`` (suffix -> value): ``front_sigma``, the
    median over the hazcam-left pixels within ``disk_px`` of ``c`` of (range of the predicted target - range of
    the hazcam's dense stereo there), both from the hazcam-left centre, in units of ``view.sigma_m``. Positive:
    the surface the hazcam sees at ``c`` is nearer than the target (something stands in front of it, or ``c`` is
    on a nearer surface); empty when fewer than half of the disk's pixels have a dense range."""
    if view.X_pred_haz is None or not (view.sigma_m > 0):
        return {}
    C = view.case.haz.left_model.C
    offsets = disk_offsets(disk_px)
    X = view.case.haz.xyz_at(np.asarray(c, float).reshape(1, 2) + offsets)
    ok = np.all(np.isfinite(X), axis=1)
    if 2 * int(ok.sum()) < len(offsets):
        return {}
    r_target_m = float(np.linalg.norm(view.X_pred_haz - C))
    front_m = r_target_m - np.linalg.norm(X[ok] - C, axis=1)
    return {"front_sigma": float(np.median(front_m)) / view.sigma_m}


@dataclass
class Candidate:
    """One candidate answer: hazcam-left pixel ``uv`` (2,), the methods (``"method/navcam"``) that gave it."""

    uv: np.ndarray
    sources: list  # [(method, navcam), ...]


def candidates_of(results: list[MethodResult], dedup_px: float) -> list[Candidate]:
    """The distinct answers of ``results`` (methods of :data:`CANDIDATE_METHODS` that answered), in order;
    answers within ``dedup_px`` of an earlier one join it."""
    out: list[Candidate] = []
    for r in results:
        if r.method not in METHOD_FAMILY or r.uv is None or not r.ok or not np.all(np.isfinite(r.uv)):
            continue
        uv = np.asarray(r.uv, float).reshape(2)
        for c in out:
            if np.linalg.norm(c.uv - uv) <= dedup_px:
                c.sources.append((r.method, r.navcam))
                break
        else:
            out.append(Candidate(uv, [(r.method, r.navcam)]))
    return out


def consistency(cands: list[Candidate], i: int, agree_px: float) -> dict:
    """Agreement of candidate ``i`` with the others (Evidence field -> value)."""
    c = cands[i]
    own = set(c.sources)
    own_fam = {METHOD_FAMILY[m] for m, _ in c.sources}
    own_nc = {nc for _, nc in c.sources}
    groups, fams, other_nc = set(), set(), math.inf
    for j, o in enumerate(cands):
        d = float(np.linalg.norm(o.uv - c.uv))
        for m, nc in o.sources:
            if (m, nc) in own and j == i:
                continue
            if nc not in own_nc:
                other_nc = min(other_nc, d)
            if d <= agree_px:
                groups.add((METHOD_FAMILY[m], nc))
                if METHOD_FAMILY[m] not in own_fam:
                    fams.add(METHOD_FAMILY[m])
    # the candidate's own groups count when a sibling method of the same group gave the same pixel
    for m, nc in c.sources[1:]:
        groups.add((METHOD_FAMILY[m], nc))
    groups.discard((METHOD_FAMILY[c.sources[0][0]], c.sources[0][1]))
    return {"support_groups": float(len(groups)), "support_other_families": float(len(fams)),
            "other_navcam_px": other_nc if math.isfinite(other_nc) else NAN, "n_candidates": float(len(cands))}


def candidate_evidence(views: dict[str, TargetView], cands: list[Candidate], i: int, sp) -> Evidence:
    """The :class:`Evidence` of candidate ``i`` of ``cands`` given the target's ``views`` (``"near"``/``"far"``
    -> :class:`TargetView`) and :class:`~scipctl.core.handoff.scip_params.ScipParams` ``sp``."""
    c = cands[i]
    uv = c.uv
    method, navcam = c.sources[0]
    kw: dict = {}
    any_view = next(iter(views.values()))
    hint = next((float(np.linalg.norm(v.X_pred_haz - v.case.haz.left_model.C)) for v in views.values()
                 if v.X_pred_haz is not None), None)
    X_c, quality = haz_point_at(any_view.case, uv, hint)
    kw["geo_haz_point"] = quality
    for label, v in views.items():
        for k, val in appearance(v, uv, sp.appearance_radius_px).items():
            kw[f"app_{label}_{k}"] = val
        kw[f"fb_{label}_error_px"] = forward_backward(v, uv, sp.backtrack_radius_px,
                                                      v.case.params.template_half_px)
        for k, val in geometry(v, X_c).items():
            kw[f"geo_{label}_{k}"] = val
        for k, val in occlusion(v, uv, sp.occlusion_disk_px).items():
            kw[f"occ_{label}_{k}"] = val
        for k, val in v.reg.items():
            kw[f"reg_{label}_{k}"] = val
    kw.update(consistency(cands, i, sp.agree_px))
    return Evidence(method, navcam, **kw)


def target_views(cases: dict[str, HandoffCase], nav_uvs: dict, hparams: HandoffParams, sp,
                 registrations: Optional[dict] = None) -> dict[str, TargetView]:
    """:func:`target_view` of each navcam (``"near"``/``"far"``) with a pixel; ``registrations``: navcam ->
    its mesh-registration :class:`MethodResult` for the target, where it ran."""
    out = {}
    for label in VIEWS:
        if label in cases and nav_uvs.get(label) is not None:
            try:
                out[label] = target_view(cases[label], nav_uvs[label], hparams, sp.geometry_sigma_floor_m,
                                         (registrations or {}).get(label))
            except NoAnswer:
                continue
    return out
