"""In-memory form of a downlink (format version 1, see docs/downlink-format.md).

Plain data shared by the readers/writers (``scipctl.io``), the simulator and
the commands. No file access here: images are kept as the PNG bytes that
arrived (so MCAP -> directory -> MCAP is lossless) and decoded on demand
(:func:`scipctl.io.images.decode_png`, which imports nothing from here).
:class:`InputError` lives in :mod:`scipctl.errors`; it is re-exported here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .core.camera import CameraModel
from .core.kinematics import RoverConfig, RoverPose
from .errors import InputError, one_line  # noqa: F401  (re-exported: many modules import them from here)

FORMAT_VERSION = "1"
# Mast angles of two products at one (site, drive) this close (each joint) are one pointing: a stereo pair's two
# eyes. The contract gives every product its own joint angles at acquisition, so a producer's readings for the two
# eyes may differ by encoder noise; a mosaic's next pointing is tenths of a radian away.
SAME_POINTING_RAD = 1e-3


def same_pointing(a, b) -> bool:
    """Two products' mast angles (``ImageProduct.mast``, not None) are one pointing: each joint within
    :data:`SAME_POINTING_RAD`."""
    return abs(a.pan_rad - b.pan_rad) <= SAME_POINTING_RAD and abs(a.tilt_rad - b.tilt_rad) <= SAME_POINTING_RAD


@dataclass(frozen=True)
class MastAngles:
    pan_rad: float
    tilt_rad: float


def unit_float(px: np.ndarray, full_scale: float) -> np.ndarray:
    """Pixels ``px`` (any shape) as float32 in [0, 1]: divided by ``full_scale``, the whole image's
    (:attr:`ImageProduct.full_scale`), so that a window of an image converted alone gets the values
    :meth:`ImageProduct.pixels_float` gives it."""
    return px.astype(np.float32) / float(full_scale)


@dataclass
class ImageProduct:
    product_id: str
    camera: str
    eye: str  # "left" | "right"
    time_s: float
    site: int
    drive: int
    pose: RoverPose  # estimated T_site_rover at acquisition
    camera_model: CameraModel  # rover frame at acquisition
    width: int
    height: int
    png: bytes  # the image as PNG bytes (8- or 16-bit, single channel)
    mast: Optional[MastAngles] = None
    exposure_ms: Optional[float] = None
    gain: Optional[float] = None
    _pixels: Optional[np.ndarray] = field(default=None, repr=False, compare=False)

    @property
    def position(self) -> tuple[int, int]:
        return (self.site, self.drive)

    @property
    def pixels(self) -> np.ndarray:
        """Decoded image ``(height, width)`` uint8 or uint16 (cached). Raises :class:`InputError` if corrupt."""
        if self._pixels is None:
            from .io.images import decode_png

            self._pixels = decode_png(self.png, self.product_id)
        return self._pixels

    @property
    def full_scale(self) -> float:
        """The value that is 1.0 in :meth:`pixels_float`: for 16-bit words 4095 when no sample exceeds it (12-bit
        data, as real MER/MSL EDRs store it), else 65535 (16-bit data, or 12-bit data bit-replicated to 16 bits as
        the simulator writes it), :func:`scipctl.core.image.full_scale`; 255 for 8-bit images and for the float
        pixels of :func:`~scipctl.pipeline.feature_track.texture_view` (NCC and SIFT's stretch see no scale).
        Not cached: a copy made with other pixels (``dataclasses.replace``) must not keep the original's."""
        px = self.pixels
        if px.dtype != np.uint16:
            return 255.0
        from .core.image import full_scale

        return full_scale(px)[0]

    def pixels_float(self) -> np.ndarray:
        """Image as float32 in [0, 1]: the pixels over :attr:`full_scale`."""
        return unit_float(self.pixels, self.full_scale)


@dataclass(frozen=True)
class Mark:
    product_id: str
    u: float
    v: float
    sigma_px: float = 0.0


@dataclass
class TargetMarks:
    id: str
    kind: str = ""
    description: str = ""
    marks: list = field(default_factory=list)  # list[Mark]

    def mark_in(self, product_id: str) -> Optional[Mark]:
        for m in self.marks:
            if m.product_id == product_id:
                return m
        return None


@dataclass
class ImageTruth:
    product_id: str
    pose: RoverPose  # true T_site_rover
    camera_model: CameraModel  # true model in the true rover frame


@dataclass
class TargetTruth:
    id: str
    xyz_site_m: np.ndarray  # (3,)


@dataclass
class Downlink:
    mission: str
    sol: int
    rover_config: RoverConfig
    images: list = field(default_factory=list)  # list[ImageProduct]
    targets: list = field(default_factory=list)  # list[TargetMarks]
    truth_images: list = field(default_factory=list)  # list[ImageTruth]
    truth_targets: list = field(default_factory=list)  # list[TargetTruth]
    format_version: str = FORMAT_VERSION
    source: str = ""  # where it was read from (path), for provenance
    source_sha256: str = ""
    unread_files: list = field(default_factory=list)  # a folder of real products: files in it that were not read

    # ------------------------------------------------------------ look-ups
    def product(self, product_id: str) -> ImageProduct:
        for im in self.images:
            if im.product_id == product_id:
                return im
        raise InputError(product_id, "product_id", "no such image product in the downlink")

    def positions(self) -> list[tuple[int, int]]:
        """Rover positions (site, drive) in time order."""
        seen: dict = {}
        for im in sorted(self.images, key=lambda i: i.time_s):
            seen.setdefault(im.position, im.time_s)
        return list(seen)

    def images_at(self, position: tuple[int, int], camera: Optional[str] = None, eye: Optional[str] = None) -> list:
        return [
            im
            for im in self.images
            if im.position == tuple(position) and (camera is None or im.camera == camera) and (eye is None or im.eye == eye)
        ]

    def stereo_pair(self, left: ImageProduct) -> Optional[ImageProduct]:
        """The right-eye product taken with ``left`` (same camera, position and mast angles; nearest in time)."""
        cands = [
            im
            for im in self.images
            if im.camera == left.camera and im.eye == "right" and im.position == left.position
            and (left.mast is None or im.mast is None or same_pointing(im.mast, left.mast))
        ]
        if not cands:
            return None
        return min(cands, key=lambda im: abs(im.time_s - left.time_s))

    def target(self, target_id: str) -> TargetMarks:
        for t in self.targets:
            if t.id == target_id:
                return t
        raise InputError(target_id, "id", "no such target in the downlink")

    def truth_for(self, product_id: str) -> Optional[ImageTruth]:
        for t in self.truth_images:
            if t.product_id == product_id:
                return t
        return None

    def truth_target(self, target_id: str) -> Optional[TargetTruth]:
        for t in self.truth_targets:
            if t.id == target_id:
                return t
        return None

    @property
    def has_truth(self) -> bool:
        return bool(self.truth_images or self.truth_targets)
