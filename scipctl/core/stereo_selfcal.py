"""A stereo pair's right eye re-aligned to its left eye from the pair's own feature matches (pure numerics).

A calibrated pair's two models put every scene point's two pixels on one epipolar plane: the plane through both
camera centres and the point. When the right camera has turned a little since calibration (vibration, thermal
flexure of the bar), its rows no longer lie on the left eye's epipolar curves, and every search along those curves
(point stereo's band, dense stereo's rectified rows) looks in the wrong place. The pair itself measures the turn: of
matched features ``(uv_left, uv_right)``, the right ray ``r_R`` of ``uv_right`` should be orthogonal to the epipolar
plane's normal ``n = unit(b x r_L)`` (``b`` the baseline, ``r_L`` the left ray). The small rotation ``w`` (rotation
vector, rover frame, about the right camera's centre) that makes ``n . (R(w) r_R)`` vanish is the right eye's
misalignment, and the right model turned by ``w`` (:func:`rotated_model`) is the pair's calibration again.

Only two of the rotation's three components are observable this way (the residual is the perpendicular distance
from the epipolar plane, in right-camera pixels):

- about the right camera's image-horizontal axis ``h_axis`` (nearly the baseline): every row shifts up or down;
- about its boresight ``A``: the rows tilt (a shift proportional to the column);
- about its image-vertical axis ``v_axis``: every point slides *along* its epipolar curve (a disparity offset, i.e.
  a range bias). For a narrow pinhole eye it leaves the residual unchanged; a wide one shows it weakly (points off
  both image axes shift across their curves by ~``yaw * u * v / f``). It is fitted as a nuisance, with a weak prior,
  so that its signature is not read as roll, and it is not applied: the correction keeps the model's own value
  (where it is weakly seen, a wrong estimate would bias every range).

``fit_right_rotation`` fits the three by robust least squares (soft L1 at ``loss_scale_px``) over matches whose
nominal residual is within ``prior_px`` (larger residuals are mismatches, not misalignment). It is a check as much as
a fit: its ``residual_px_before`` / ``residual_px_after`` are the pair's median epipolar residuals under the
downlinked and the corrected models.

Pixel convention (docs/conventions.md): ``(u, v)`` = (column, row), 0-based, the centre of the top-left pixel at
``(0, 0)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..jsonutil import RecordReader
from .camera import CameraModel, check_camera_model
from .features import detect_features, mutual_knn_matches
from .transforms import RigidTransform, rotvec_to_matrix

__all__ = ["StereoSelfCalParams", "StereoRotationFit", "stereo_matches", "epipolar_residual_px", "fit_right_rotation",
           "rotated_model"]


@dataclass(frozen=True)
class StereoSelfCalParams:
    """``ratio``: Lowe's ratio test of the SIFT matches (both directions; only mutual best matches are kept);
    ``max_features``: the strongest keypoints kept per image (0: all); ``prior_px``: the largest epipolar residual
    (right-camera pixels) a true match can have under the downlinked models, i.e. the largest misalignment corrected
    (matches farther off are left out of the fit); ``loss_scale_px``: the soft-L1 scale (the matched features'
    position noise, ~1 px); ``inlier_px``: a match within this of the corrected epipolar curve counts as an inlier;
    ``min_inliers``: fewer inliers and the pair is left as it was (``ok`` false)."""

    ratio: float = 0.8
    max_features: int = 6000
    prior_px: float = 15.0
    loss_scale_px: float = 1.0
    inlier_px: float = 3.0
    min_inliers: int = 40

    def check(self) -> "StereoSelfCalParams":
        if not 0.0 < self.ratio <= 1.0:
            raise ValueError(f"ratio: must be in (0, 1], got {self.ratio}")
        for name in ("prior_px", "loss_scale_px", "inlier_px"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a positive finite number, got {v}")
        if self.min_inliers < 3 or self.max_features < 0:
            raise ValueError("min_inliers must be >= 3 and max_features >= 0")
        return self


@dataclass(frozen=True)
class StereoRotationFit:
    """The right eye's fitted misalignment.

    ``rotvec_rad`` ``(3,)``: rotation vector in the models' (rover) frame, about the right camera's centre, that
    turns the downlinked right model onto the pair (zero when not ``ok``); ``rows_px`` / ``roll_px``: its components
    about the right camera's ``h_axis`` and ``A`` in right-camera pixels (``angle * hs``: a row shift, and the row
    shift at ~``hs`` columns from the centre); ``sigma_px`` ``(2,)``: their standard errors from the inliers' scatter;
    ``n_matches``: mutual ratio-test matches; ``n_used``: those within ``prior_px``; ``n_inliers``: within
    ``inlier_px`` after the fit; ``residual_px_before`` / ``residual_px_after``: median |epipolar residual| of the
    used matches before and after; ``ok`` false with ``reason`` when too few inliers support a fit."""

    ok: bool
    reason: str
    rotvec_rad: np.ndarray
    rows_px: float
    roll_px: float
    sigma_px: np.ndarray
    n_matches: int
    n_used: int
    n_inliers: int
    residual_px_before: float
    residual_px_after: float

    def to_dict(self) -> dict:
        """JSON-ready (a value that is not finite, as when too few matches left nothing to measure, is None)."""
        def num(x):
            x = float(x)
            return x if np.isfinite(x) else None

        return {"ok": self.ok, "reason": self.reason, "rotvec_rad": [float(x) for x in self.rotvec_rad],
                "rows_px": float(self.rows_px), "roll_px": float(self.roll_px),
                "sigma_px": [num(x) for x in self.sigma_px], "n_matches": self.n_matches, "n_used": self.n_used,
                "n_inliers": self.n_inliers, "residual_px_before": num(self.residual_px_before),
                "residual_px_after": num(self.residual_px_after)}

    @staticmethod
    def from_dict(d: dict, product: str = "stereo self-calibration", where: str = "") -> "StereoRotationFit":
        """Inverse of :meth:`to_dict`: every float back exactly as written (JSON keeps a float's shortest round-trip
        digits), None back to NaN. InputError naming ``product`` and the field (``where`` + key) on a missing or
        ill-typed value."""
        r = RecordReader(d, product, where, "stereo rotation fit")

        def nan_if_none(v):
            return float("nan") if v is None else float(v)

        sigma = d.get("sigma_px")
        if not (isinstance(sigma, list) and len(sigma) == 2 and all(
                x is None or (isinstance(x, (int, float)) and not isinstance(x, bool)) for x in sigma)):
            r.bad("sigma_px", f"expected 2 numbers or nulls, got {sigma!r}")
        return StereoRotationFit(
            r.flag("ok", required=True, nullable=False), r.text("reason", required=True, nullable=False),
            np.array(r.vector("rotvec_rad", 3, required=True, nullable=False), float),
            float(r.number("rows_px", required=True, nullable=False)),
            float(r.number("roll_px", required=True, nullable=False)),
            np.array([nan_if_none(x) for x in sigma], float),
            r.integer("n_matches", required=True, nullable=False), r.integer("n_used", required=True, nullable=False),
            r.integer("n_inliers", required=True, nullable=False),
            nan_if_none(r.number("residual_px_before", required=True)),
            nan_if_none(r.number("residual_px_after", required=True)))


def stereo_matches(left_px: np.ndarray, right_px: np.ndarray, params: StereoSelfCalParams = StereoSelfCalParams()):
    """Mutual SIFT matches of a stereo pair: ``(uv_left (N, 2), uv_right (N, 2))`` pixels.

    ``left_px``, ``right_px``: ``(H, W)`` images (any real dtype; NaN = no data). A match is kept when each keypoint
    is the other's nearest descriptor and passes Lowe's ratio test (``params.ratio``) in both directions.
    """
    params.check()
    fl = detect_features(left_px, max_features=params.max_features)
    fr = detect_features(right_px, max_features=params.max_features)
    if len(fl) < 2 or len(fr) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    lr, rl = mutual_knn_matches(fl, fr)
    i = np.arange(len(fl))
    j = lr.best
    good_lr = lr.best_d < params.ratio * lr.second_d
    good_rl = rl.best_d[j] < params.ratio * rl.second_d[j]
    keep = good_lr & good_rl & (rl.best[j] == i)
    return fl.uv[keep].copy(), fr.uv[j[keep]].copy()


def _planes(left: CameraModel, right: CameraModel, uv_left: np.ndarray, uv_right: np.ndarray):
    """Unit epipolar-plane normals ``(N, 3)`` through both ray origins and the left ray, the right rays ``(N, 3)``,
    and the rays' scale (pixels per radian at the right camera's centre)."""
    oL, rL = left.unproject(uv_left)
    oR, rR = right.unproject(uv_right)
    n = np.cross(oR - oL, rL)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    n = n / np.where(norm > 0, norm, 1.0)
    return n, rR, float(right.hs)


def _turn_residual_px(n: np.ndarray, rR: np.ndarray, hs: float, axes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``n . (R(w) r_R) * hs`` ``(N,)`` for ``w = x @ axes``: ``n``, ``rR`` ``(N, 3)`` (plane normals, right rays),
    ``axes`` ``(K, 3)`` unit axes, ``x`` ``(K,)`` angles (rad)."""
    R = rotvec_to_matrix(x @ axes)
    return np.einsum("ij,ij->i", n, rR @ R.T) * hs


def _turn_jacobian_px(n: np.ndarray, rR: np.ndarray, hs: float, axes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``(N, K)``: d/dx_k of :func:`_turn_residual_px`, as ``n . (a_k x (R r)) * hs`` to first order in a small step
    about the current rotation (exact at ``x = 0``, a Gauss-Newton approximation elsewhere; the step is a few mrad)."""
    Rr = rR @ rotvec_to_matrix(x @ axes).T
    return np.stack([np.einsum("ij,ij->i", n, np.cross(a, Rr)) for a in axes], axis=1) * hs


def _check_uv(uv_left, uv_right):
    uv_left = np.asarray(uv_left, float)
    uv_right = np.asarray(uv_right, float)
    if uv_left.ndim != 2 or uv_left.shape[1] != 2 or uv_left.shape != uv_right.shape:
        raise ValueError(f"uv_left, uv_right: expected two (N, 2) arrays, got {uv_left.shape} and {uv_right.shape}")
    return uv_left, uv_right


def epipolar_residual_px(left: CameraModel, right: CameraModel, uv_left, uv_right, rotvec_rad=None) -> np.ndarray:
    """Signed distance ``(N,)`` of each right ray (turned by ``rotvec_rad`` ``(3,)``, rover frame; default none)
    from its match's epipolar plane, in right-camera pixels (the sine of the ray's angle to the plane times ``hs``,
    the quantity :func:`fit_right_rotation` minimises).

    ``left``, ``right``: the pair's models (one frame); ``uv_left``, ``uv_right``: ``(N, 2)`` matched pixels.
    """
    check_camera_model(left, "left")
    check_camera_model(right, "right")
    uv_left, uv_right = _check_uv(uv_left, uv_right)
    n, rR, hs = _planes(left, right, uv_left, uv_right)
    if rotvec_rad is not None:
        rR = rR @ rotvec_to_matrix(np.asarray(rotvec_rad, float)).T
    return np.einsum("ij,ij->i", n, rR) * hs


def fit_right_rotation(left: CameraModel, right: CameraModel, uv_left, uv_right,
                       params: StereoSelfCalParams = StereoSelfCalParams()) -> StereoRotationFit:
    """The right eye's misalignment from matched pixels ``uv_left``, ``uv_right`` ``(N, 2)``: see the module.

    Applied about the right model's ``h_axis`` and ``A`` only (the third component, fitted as a nuisance, is not
    applied). Deterministic (no random draw): soft-L1 least squares from zero. ``residual_px_after`` is under the
    applied correction.
    """
    from scipy.optimize import least_squares

    params.check()
    check_camera_model(left, "left")
    check_camera_model(right, "right")
    uv_left, uv_right = _check_uv(uv_left, uv_right)
    n_matches = len(uv_left)
    ax_rows = right.h_axis / np.linalg.norm(right.h_axis)
    ax_roll = right.A / np.linalg.norm(right.A)
    ax_yaw = right.v_axis / np.linalg.norm(right.v_axis)
    axes = np.stack([ax_rows, ax_roll, ax_yaw])  # (3, 3): rows, roll, yaw

    def fail(reason, n_used=0, before=float("nan")):
        return StereoRotationFit(False, reason, np.zeros(3), 0.0, 0.0, np.full(2, np.nan), n_matches, n_used, 0,
                                 before, before)

    if n_matches < params.min_inliers:
        return fail(f"{n_matches} matches, fewer than {params.min_inliers}")
    n, rR, hs = _planes(left, right, uv_left, uv_right)
    r0 = np.einsum("ij,ij->i", n, rR) * hs
    use = np.abs(r0) <= params.prior_px
    n_used = int(use.sum())
    before = float(np.median(np.abs(r0[use]))) if n_used else float("nan")
    if n_used < params.min_inliers:
        return fail(f"{n_used} matches within {params.prior_px:g} px of their epipolar curves, fewer than "
                    f"{params.min_inliers}", n_used, before)
    n, rR = n[use], rR[use]
    # the yaw (about v_axis) is a nuisance: a wide-angle eye's epipolar residual shows it weakly (a shift that grows
    # with u * v / f), and left out it would be read as roll; a weak prior (prior_px) keeps it bounded where the
    # pair does not see it at all (a narrow eye). It is fitted, not applied (see the module).
    prior_w = params.loss_scale_px / (params.prior_px / hs)

    def residual(x):
        return np.append(_turn_residual_px(n, rR, hs, axes, x), x[2] * prior_w)

    def jac(x):
        return np.vstack([_turn_jacobian_px(n, rR, hs, axes, x), [0.0, 0.0, prior_w]])

    sol = least_squares(residual, np.zeros(3), jac=jac, loss="soft_l1", f_scale=params.loss_scale_px, method="trf")
    applied = np.array([sol.x[0], sol.x[1], 0.0])
    res = residual(applied)[:-1]
    res_fit = residual(sol.x)[:-1]
    inl = np.abs(res_fit) <= params.inlier_px
    n_inl = int(inl.sum())
    after = float(np.median(np.abs(res)))
    if n_inl < params.min_inliers:
        return fail(f"{n_inl} matches within {params.inlier_px:g} px after the fit, fewer than {params.min_inliers}",
                    n_used, before)
    J = jac(sol.x)[np.append(inl, True)]
    dof = max(n_inl - 3, 1)
    s2 = float(np.sum(res_fit[inl] ** 2)) / dof
    try:
        cov = np.linalg.inv(J.T @ J) * s2
        sigma = np.sqrt(np.clip(np.diag(cov)[:2], 0, None)) * hs
    except np.linalg.LinAlgError:
        sigma = np.full(2, np.inf)
    return StereoRotationFit(True, "", applied @ axes, float(sol.x[0] * hs), float(sol.x[1] * hs), sigma, n_matches,
                             n_used, n_inl, before, after)


def rotated_model(model: CameraModel, rotvec_rad) -> CameraModel:
    """``model`` turned by ``rotvec_rad`` ``(3,)`` (rotation vector in the model's frame) about its own centre ``C``:
    the turned model's ray of every pixel is ``R(rotvec) @`` the original's (origins, for CAHVORE, turn with it)."""
    check_camera_model(model, "model")
    w = np.asarray(rotvec_rad, float)
    if w.shape != (3,) or not np.all(np.isfinite(w)):
        raise ValueError(f"rotvec_rad: expected a finite (3,) rotation vector, got {w!r}")
    R = rotvec_to_matrix(w)
    C = np.asarray(model.C, float)
    return model.transformed(RigidTransform(R, C - R @ C))
