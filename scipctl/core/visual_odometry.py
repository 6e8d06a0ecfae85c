"""A camera's pose error from many points at once (pure numerics): visual odometry for the chain's tracking steps.

The rover's pose estimate at a new stop is off by its drive's odometry error (and a mast camera's by its pointing
error); every pixel of the new image moves with that one error. Given points whose 3-D positions are known in the
new rover frame *as the pose estimate puts them* (e.g. keypoints of the previous image with its stereo) and the
pixels where the new camera really saw them, the camera's true pose relative to its estimate follows from
perspective-n-point with RANSAC (OpenCV's ``solvePnPRansac``, EPnP, then Levenberg-Marquardt on the inliers).

Frames: ``X_rover`` are in the new image's rover frame (pose estimate); the camera model is in that frame too. The
correction is solved in a camera frame ``cam`` (origin at the model's ``C``, z along ``A``, x along the horizontal
image axis): ``x_camtrue = R_camtrue_camest @ x_camest + t_camtrue_camest_m``. :meth:`CameraCorrection.apply`
returns, for points of the estimated rover frame, the rover-frame coordinates at which the camera model (as
calibrated) sees them, so that ``camera_model.project(correction.apply(X_rover))`` is where they really appear.
Pixels go through the model's own rays (CAHV/CAHVOR/CAHVORE: :meth:`~scipctl.core.camera.CameraModel.unproject`),
turned into normalised coordinates, so the distortion is the model's and PnP sees a pinhole of unit focal length
(a non-central CAHVORE ray is taken from ``C`` to its point at the point's estimated range).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class CameraCorrection:
    """A camera's pose relative to its estimate (see the module docstring).

    ``R_camtrue_camest`` (3, 3), ``t_camtrue_camest_m`` (3,): the correction in the camera frame;
    ``R_cam_rover`` (3, 3): rows are the camera frame's axes in the rover frame; ``C_rover_m`` (3,): the camera
    centre in the rover frame. ``n_points``: the 2-D/3-D pairs tried; ``n_inliers``; ``inlier_uv`` (K, 2): the
    inliers' observed pixels.
    """

    R_camtrue_camest: np.ndarray
    t_camtrue_camest_m: np.ndarray
    R_cam_rover: np.ndarray
    C_rover_m: np.ndarray
    n_points: int
    n_inliers: int
    inlier_uv: np.ndarray

    def apply(self, X_rover) -> np.ndarray:
        """Points ``(N, 3)`` of the estimated rover frame -> where the calibrated camera model sees them ``(N, 3)``
        (rover frame)."""
        X = np.asarray(X_rover, float)
        if X.ndim != 2 or X.shape[1] != 3:
            raise ValueError(f"X_rover: expected (N, 3), got {X.shape}")
        x_camest = (X - self.C_rover_m) @ self.R_cam_rover.T
        x_camtrue = x_camest @ self.R_camtrue_camest.T + self.t_camtrue_camest_m
        return x_camtrue @ self.R_cam_rover + self.C_rover_m

    @property
    def rotation_rad(self) -> float:
        """The correction's rotation angle (rad)."""
        c = (np.trace(self.R_camtrue_camest) - 1.0) / 2.0
        return float(np.arccos(np.clip(c, -1.0, 1.0)))


def camera_axes(camera_model) -> np.ndarray:
    """Rows: the camera frame's x (the horizontal image axis, orthogonalised), y = z cross x, z (``A``), in the
    rover frame ``(3, 3)``."""
    A = np.asarray(camera_model.A, float)
    z = A / np.linalg.norm(A)
    H = np.asarray(camera_model.H, float)
    x = H - (H @ z) * z
    x = x / np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


def camera_correction(X_rover, uv, camera_model, threshold_px: float = 2.0, min_inliers: int = 20,
                      iterations: int = 2000, seed: int = 0):
    """The :class:`CameraCorrection` that best explains pixels ``uv`` ``(N, 2)`` of points ``X_rover`` ``(N, 3)``
    (estimated rover frame), or None when fewer than ``min_inliers`` pairs agree within ``threshold_px`` pixels
    (measured in the model's horizontal pixel scale ``hs``). Deterministic: OpenCV's RNG is seeded with ``seed``."""
    import cv2

    X = np.asarray(X_rover, float)
    p = np.asarray(uv, float)
    if X.ndim != 2 or X.shape[1] != 3 or p.ndim != 2 or p.shape[1] != 2 or len(X) != len(p):
        raise ValueError(f"X_rover (N, 3) and uv (N, 2) expected, got {X.shape} and {p.shape}")
    if not (threshold_px > 0 and min_inliers >= 4 and iterations >= 1):
        raise ValueError("threshold_px > 0, min_inliers >= 4 and iterations >= 1 expected")
    R_cam_rover = camera_axes(camera_model)
    C = np.asarray(camera_model.C, float)
    obj = (X - C) @ R_cam_rover.T
    # each pixel's ray (origin o, direction d); for a non-central model (CAHVORE) o moves with the pixel, so the
    # observed direction from C is taken to the ray's point at the point's estimated range (exact for central
    # models; for CAHVORE off only by the pose error's share of the range, a second-order term)
    o, d = camera_model.unproject(p)
    rng = np.linalg.norm(X - C, axis=1)
    dc = (o + rng[:, None] * d - C) @ R_cam_rover.T
    keep = np.all(np.isfinite(obj), 1) & np.all(np.isfinite(dc), 1) & (obj[:, 2] > 0) & (dc[:, 2] > 1e-6)
    obj, dc, p = obj[keep], dc[keep], p[keep]
    n = len(obj)
    if n < max(min_inliers, 6):
        return None
    img = dc[:, :2] / dc[:, 2:3]
    cv2.setRNGSeed(int(seed))
    ok, rvec, tvec, inl = cv2.solvePnPRansac(obj, img, np.eye(3), None,
                                             reprojectionError=threshold_px / camera_model.hs,
                                             iterationsCount=int(iterations), confidence=0.999,
                                             flags=cv2.SOLVEPNP_EPNP)
    if not ok or inl is None or len(inl) < min_inliers:
        return None
    inl = inl.ravel()
    rvec, tvec = cv2.solvePnPRefineLM(obj[inl], img[inl], np.eye(3), None, rvec, tvec)
    R, _ = cv2.Rodrigues(rvec)
    return CameraCorrection(R, tvec.ravel().astype(float), R_cam_rover, C, n, int(len(inl)), p[inl].copy())
