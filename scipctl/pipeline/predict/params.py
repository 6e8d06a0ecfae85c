"""Parameters of the pre-uplink prediction: the arm workspace and rover footprint models, the approach
planning, the pose-error model and the prediction as a whole (each with ``check()``), and the fixed criteria
a tracked pixel is judged by."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

FOV_MARGIN_PX = {"pancam": 24, "navcam": 20, "hazcam": 20}
# a tracked pixel is accurate when it lies this close to the target on the surface (the paper's goal is 1 cm
# at the hazcams), or within MIN_SUCCESS_PX; farther than LOST_M the chain has lost the target
SUCCESS_M = {"pancam": 0.02, "navcam": 0.02, "hazcam": 0.01}
MIN_SUCCESS_PX = 1.0
LOST_M = 0.05


@dataclass(frozen=True)
class ArmWorkspace:
    """Where the arm can place its instrument, in the rover frame at the final pose (a simple documented model).

    The target's horizontal position ``(x forward, y right)`` must satisfy
    ``r_min_m <= hypot(x, y) <= r_max_m``, ``x > 0`` and ``|y| <= half_width_m``
    (an annulus sector ahead of the rover origin).
    """

    r_min_m: float = 0.6
    r_max_m: float = 1.0
    half_width_m: float = 0.4

    @property
    def centre_m(self) -> float:
        return 0.5 * (self.r_min_m + self.r_max_m)

    def contains(self, xy_rover) -> np.ndarray:
        """``xy_rover`` (..., 2) horizontal rover-frame positions -> (...,) bool."""
        p = np.asarray(xy_rover, float)
        if p.shape[-1] != 2:
            raise ValueError(f"xy_rover: expected (..., 2), got {p.shape}")
        r = np.hypot(p[..., 0], p[..., 1])
        return (r >= self.r_min_m) & (r <= self.r_max_m) & (p[..., 0] > 0) & (np.abs(p[..., 1]) <= self.half_width_m)


@dataclass(frozen=True)
class RoverBody:
    """The rover's footprint in its own frame: the rectangle ``rear_m <= x <= front_m``, ``|y| <= half_width_m``."""

    front_m: float = 0.5
    rear_m: float = -0.5
    half_width_m: float = 0.4

    def distance(self, xy_rover) -> np.ndarray:
        """Horizontal distance (m) of rover-frame points ``(..., 2)`` from the footprint (0 inside)."""
        p = np.asarray(xy_rover, float)
        if p.shape[-1] != 2:
            raise ValueError(f"xy_rover: expected (..., 2), got {p.shape}")
        dx = np.maximum(np.maximum(self.rear_m - p[..., 0], p[..., 0] - self.front_m), 0.0)
        dy = np.maximum(np.abs(p[..., 1]) - self.half_width_m, 0.0)
        return np.hypot(dx, dy)

    def corners(self) -> np.ndarray:
        """(4, 2) footprint corners, rover frame."""
        return np.array([[self.front_m, -self.half_width_m], [self.front_m, self.half_width_m],
                         [self.rear_m, self.half_width_m], [self.rear_m, -self.half_width_m]])


@dataclass(frozen=True)
class ApproachParams:
    """How the approach is planned (distances are horizontal, rover origin to target)."""

    stop_fraction: float = 0.15  # a stop after every ~15 % of the remaining distance
    min_leg_m: float = 0.3
    merge_m: float = 0.25  # regular stops this close to a special stop are dropped
    pancam_handoff_m: float = 4.5
    hazcam_handoff_m: float = 2.0
    hazcam_stops_m: tuple = (1.4,)
    standoff_m: Optional[float] = None  # final distance; None: the arm workspace centre
    detour_bearings_rad: tuple = tuple(np.deg2rad([0.0, 15.0, -15.0, 30.0, -30.0, 45.0, -45.0]).tolist())
    path_step_m: float = 0.05
    turn_step_rad: float = math.radians(10.0)
    rock_height_m: float = 0.15  # rocks at least this tall (above the local ground) are obstacles
    rock_cell_m: float = 0.05
    ground_window_m: float = 1.0
    rock_keep_out_m: float = 0.15
    target_keep_out_m: float = 0.25
    arm: ArmWorkspace = field(default_factory=ArmWorkspace)
    body: RoverBody = field(default_factory=RoverBody)

    @property
    def final_distance_m(self) -> float:
        return self.arm.centre_m if self.standoff_m is None else float(self.standoff_m)


@dataclass(frozen=True)
class UncertaintyParams:
    """Pose-estimate error model for the Monte Carlo (1-sigma, per stop, relative to the previous stop).

    ``sigma_position_m`` / ``sigma_yaw_rad``: ``None`` takes them from the
    downlink pose of today's image (``sigma_position_m``, ``sigma_yaw_rad``),
    else the defaults. Each leg adds ``drive_error_frac`` x leg length (m)
    and ``yaw_error_rad_per_m`` x leg length in quadrature. The target's 3-D
    re-estimate at each stop has range noise ``r^2 sigma_d / (f b)``.
    """

    sigma_position_m: Optional[float] = None
    sigma_yaw_rad: Optional[float] = None
    default_sigma_position_m: float = 0.01
    default_sigma_yaw_rad: float = math.radians(0.5)
    drive_error_frac: float = 0.05  # wheel odometry: a few % of the distance driven
    yaw_error_rad_per_m: float = math.radians(1.0)  # heading drift per metre
    disparity_sigma_px: float = 0.25
    n_samples: int = 1000
    n_track_samples: int = 8
    seed: int = 0


@dataclass(frozen=True)
class PredictParams:
    approach: ApproachParams = field(default_factory=ApproachParams)
    uncertainty: UncertaintyParams = field(default_factory=UncertaintyParams)
    render_width_px: int = 256  # nominal expected views (for reports)
    stereo_downsample: int = 2
    max_edge_ratio: float = 20.0  # grid-mesh edge longer than this x its angular footprint: a depth discontinuity
    min_edge_m: float = 0.03
    smooth_sigma_px: float = 1.5  # stereo grids are smoothed along their rays before meshing (smooth_grid)
    occlusion_tol_m: float = 0.04
    low_texture_std: float = 0.015  # std of the expected window (0..1 units) below which texture is "low"
    min_coverage: float = 0.6  # fraction of the expected window the terrain covers
    max_incidence_rad: float = math.radians(85.0)  # grazing view of the target surface
    max_foreshortening_change: float = 2.0  # cos(incidence) ratio between consecutive images of the chain
    risk_probability: float = 0.9  # a stop/handoff whose probability is below this is at risk
    run_chain: bool = True
    search_margin_px: float = 40.0  # chain sim: rendered search region = true offset + this (see docs)
