"""One real rover product as read (:mod:`.pds_products`, :mod:`.m2020_json`), before it becomes an
:class:`~scipctl.model.ImageProduct`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .pds_label import ProductGeometry


@dataclass
class ProductRead:
    """One product as read: its geometry, pixels ``(H, W)`` uint8/uint16, and the files it used."""

    geometry: ProductGeometry
    pixels: np.ndarray
    files: list = field(default_factory=list)
    pose_source: str = ""
    sigma_yaw_rad: Optional[float] = None
