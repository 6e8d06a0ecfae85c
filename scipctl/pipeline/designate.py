"""Designate a 3-D target from a pixel in a left stereo image (SCIP step 1).

The designation record (:class:`Designation`) is written to ``targets.json`` by ``scipctl designate``
(:meth:`Designation.to_dict`) and read back by the other commands (:func:`designations_from_doc`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from ..core.point_stereo import PointStereoParams
from ..jsonutil import RecordReader, finite_or_none
from ..model import Downlink, ImageProduct, InputError, unit_float
from .designation_trust import (FITTED_CAMERAS, LOW_TEXTURE_WARNING, OTHER_CAMERA_WARNING, SATURATED_WARNING,
                                VETO_WARNING_PREFIX, assess)

EDGE_MARGIN_PX = 20  # a designation closer than this to the image edge is warned about
# a pose with no heading (Mars 2020 raw JSON: position only, sigma_yaw pi) puts the site point on a placeholder heading
UNKNOWN_HEADING_WARNING = "the rover's heading is unknown (a position-only pose): xyz_site_m assumes a placeholder heading"

#: the keys of a designation record in targets.json (Designation.to_dict writes them in this order; the
#: optional ones only when present: the stereo result when the match is good, the surface normal when computed)
_KNOWN_KEYS = ("id", "product_id", "right_product_id", "camera", "position", "pixel_uv", "band_px", "ok", "reason",
               "match_score", "match_ratio", "uv_right", "epipolar_offset_px", "warnings",
               "xyz_rover_m", "xyz_site_m", "range_m", "range_sigma_m", "ray_miss_m", "pose", "window_range_gap_pct",
               "surface_normal_rover", "normal_points", "incidence_deg", "p_ok", "ok_tolerance_pct", "go",
               "designated_from", "provenance")


@dataclass(frozen=True)
class Designation:
    """A designated target: the pixel of a left image and the 3-D point stereo found there.

    Frames: ``xyz_rover_m`` in the rover frame of the left image's acquisition (``pose``: that rover pose,
    ``p_site = R p_rover + t``), ``xyz_site_m`` in the site frame, ``surface_normal_rover`` (unit, up: -z) in
    the rover frame. Pixels ``(u, v)`` as docs/conventions.md. ``band_px``: the epipolar band half-width used.
    ``ok`` False: no reliable stereo match (``reason``), and no 3-D point.
    ``p_ok``: P(the point is within ``ok_tolerance_pct`` % of the range of ideal point stereo on the same
    models) from the designation trust model, ``go`` = ``p_ok`` at or above its GO threshold
    (:mod:`scipctl.pipeline.designation_trust`; None when no model was given).
    ``designated_from``: ``"mark"`` when designated on the fly from a target's mark (None: from targets.json);
    ``provenance``: how ``scipctl designate`` made it (None until saved).
    """

    id: str
    product_id: str
    camera: str
    pixel_uv: tuple  # (u, v) px
    ok: bool = True
    right_product_id: Optional[str] = None
    position: Optional[tuple] = None  # (site, drive) of the left image
    band_px: Optional[float] = None
    reason: str = ""
    match_score: Optional[float] = None
    match_ratio: Optional[float] = None
    uv_right: Optional[tuple] = None
    epipolar_offset_px: Optional[float] = None
    warnings: tuple = ()
    # the stereo result (written when xyz_site_m is set)
    xyz_rover_m: Optional[tuple] = None
    xyz_site_m: Optional[tuple] = None
    range_m: Optional[float] = None
    range_sigma_m: Optional[float] = None
    ray_miss_m: Optional[float] = None
    pose: Optional[dict] = None  # {position_m, orientation_wxyz, source}
    # point stereo's range against dense stereo's over the window, % of the range (core/window_ranges.py; None: none)
    window_range_gap_pct: Optional[float] = None
    # the surface normal (written when normal_points is set; incidence_deg only when there is a normal)
    surface_normal_rover: Optional[tuple] = None
    normal_points: Optional[int] = None
    incidence_deg: Optional[float] = None
    p_ok: Optional[float] = None
    ok_tolerance_pct: Optional[float] = None
    go: Optional[bool] = None
    designated_from: Optional[str] = None
    provenance: Optional[dict] = None
    extra: dict = field(default_factory=dict)  # keys of a read record this version does not know (kept as read)

    @property
    def has_position(self) -> bool:
        """True when the designation has a reliable 3-D point."""
        return bool(self.ok) and self.xyz_site_m is not None

    def to_dict(self) -> dict:
        """The targets.json record (keys in the order ``scipctl designate`` has always written them)."""
        d = {"id": self.id, "product_id": self.product_id, "right_product_id": self.right_product_id,
             "camera": self.camera,
             "position": None if self.position is None else {"site": self.position[0], "drive": self.position[1]},
             "pixel_uv": list(self.pixel_uv), "band_px": self.band_px, "ok": self.ok, "reason": self.reason,
             "match_score": self.match_score, "match_ratio": self.match_ratio,
             "uv_right": None if self.uv_right is None else list(self.uv_right),
             "epipolar_offset_px": self.epipolar_offset_px, "warnings": list(self.warnings)}
        if self.xyz_site_m is not None:
            d.update({"xyz_rover_m": _list(self.xyz_rover_m), "xyz_site_m": list(self.xyz_site_m),
                      "range_m": self.range_m, "range_sigma_m": self.range_sigma_m, "ray_miss_m": self.ray_miss_m,
                      "pose": self.pose})
            if self.window_range_gap_pct is not None:
                d["window_range_gap_pct"] = self.window_range_gap_pct
        if self.normal_points is not None:
            d["surface_normal_rover"] = _list(self.surface_normal_rover)
            d["normal_points"] = self.normal_points
            if self.incidence_deg is not None:
                d["incidence_deg"] = self.incidence_deg
        if self.go is not None:
            d.update({"p_ok": self.p_ok, "ok_tolerance_pct": self.ok_tolerance_pct, "go": self.go})
        if self.designated_from is not None:
            d["designated_from"] = self.designated_from
        if self.provenance is not None:
            d["provenance"] = self.provenance
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, d, product: str = "targets.json", index: Optional[int] = None) -> "Designation":
        """The record as read from ``targets.json`` (``to_dict``'s inverse); :class:`InputError` naming
        ``product`` and the field (``targets[index].field``) when a value is missing or of the wrong kind.
        Required: ``id``, ``product_id``, ``camera``, ``pixel_uv``; ``ok`` defaults to true."""
        r = RecordReader(d, product, "" if index is None else f"targets[{index}].", "designation record")
        tid = r.text("id", required=True, nullable=False)
        if not tid:
            r.bad("id", "must not be empty")
        r.about = f"target {tid!r}: "
        pos = r.mapping("position")
        if pos is not None:
            if not ("site" in pos and "drive" in pos):
                r.bad("position", "expected {site, drive}")
            pos = (pos["site"], pos["drive"])
        warnings = r.strings("warnings")
        return cls(
            id=tid, product_id=r.text("product_id", required=True, nullable=False),
            camera=r.text("camera", required=True, nullable=False),
            pixel_uv=r.vector("pixel_uv", 2, required=True, nullable=False), ok=r.flag("ok", default=True),
            right_product_id=r.text("right_product_id"), position=pos, band_px=r.number("band_px"),
            reason=r.text("reason") or "", match_score=r.number("match_score"), match_ratio=r.number("match_ratio"),
            uv_right=r.vector("uv_right", 2), epipolar_offset_px=r.number("epipolar_offset_px"),
            warnings=tuple(warnings or ()),
            xyz_rover_m=r.vector("xyz_rover_m", 3), xyz_site_m=r.vector("xyz_site_m", 3), range_m=r.number("range_m"),
            range_sigma_m=r.number("range_sigma_m"), ray_miss_m=r.number("ray_miss_m"), pose=r.mapping("pose"),
            window_range_gap_pct=r.number("window_range_gap_pct"),
            surface_normal_rover=r.vector("surface_normal_rover", 3), normal_points=r.integer("normal_points"),
            incidence_deg=r.number("incidence_deg"), p_ok=r.number("p_ok"),
            ok_tolerance_pct=r.number("ok_tolerance_pct"), go=r.flag("go"), designated_from=r.text("designated_from"),
            provenance=r.mapping("provenance"), extra={k: v for k, v in d.items() if k not in _KNOWN_KEYS})


def _list(v):
    return None if v is None else list(v)


def designations_from_doc(doc, product: str = "targets.json") -> list:
    """The :class:`Designation` records of a ``targets.json`` document (None: none yet); :class:`InputError`
    naming ``product`` and the field for a malformed document or record."""
    if doc is None:
        return []
    if not isinstance(doc, dict) or not isinstance(doc.get("targets", []), (list, type(None))):
        raise InputError(product, "targets", "expected a JSON object with a 'targets' list")
    return [Designation.from_dict(r, product, i) for i, r in enumerate(doc.get("targets") or [])]


#: what a target id may be: it names files' records, sequence headers and command options, so one word of
#: letters, digits, '_', '.' and '-' (starting with a letter or digit), at most 64 characters
TARGET_ID_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


def check_target_id(text: str) -> str:
    """``text`` when it is a valid target id (:data:`TARGET_ID_RE`), else :class:`InputError` naming ``--id``."""
    if not isinstance(text, str) or not TARGET_ID_RE.fullmatch(text):
        raise InputError("--id", "id", "expected 1-64 letters, digits, '_', '.' or '-', starting with a letter or "
                         f"digit, got {text!r}")
    return text


def pick_left_product(dl: Downlink, product_id: Optional[str], camera: Optional[str]) -> ImageProduct:
    if product_id is not None and camera is not None:
        raise InputError("designate", "--product", "give --product PRODUCT_ID or --camera NAME, not both")
    if product_id is not None:  # "" too: no product has that id (the CLI refuses empty values before this)
        p = dl.product(product_id)
    elif camera is not None:
        cands = [im for im in dl.images if im.camera == camera and im.eye == "left"]
        if not cands:
            raise InputError(dl.source or "downlink", "camera", f"no left {camera} image in the downlink")
        p = max(cands, key=lambda im: im.time_s)
    else:
        raise InputError("designate", "--product", "give --product PRODUCT_ID or --camera NAME")
    if p.eye != "left":
        raise InputError(p.product_id, "eye", "designate from a left-eye image (the right eye is matched by stereo)")
    return p


def parse_pixel(text: str) -> np.ndarray:
    try:
        parts = [float(x) for x in str(text).replace(" ", "").split(",")]
    except ValueError:
        raise InputError("--pixel", "pixel", f"expected U,V numbers, got {text!r}") from None
    if len(parts) != 2 or not all(np.isfinite(parts)):
        raise InputError("--pixel", "pixel", f"expected two finite numbers U,V, got {text!r}")
    return np.array(parts)


def surface_normal(xyz: np.ndarray, centre: np.ndarray, radius_m: float) -> tuple[Optional[np.ndarray], int]:
    """Plane-fit normal ``(3,)`` of points ``(N, 3)`` within ``radius_m`` of ``centre``; oriented up (-z, rover frame)."""
    pts = xyz[np.all(np.isfinite(xyz), axis=1)]
    pts = pts[np.linalg.norm(pts - centre, axis=1) < radius_m]
    if len(pts) < 10:
        return None, len(pts)
    c = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
    n = vt[-1]
    if n[2] > 0:
        n = -n
    return n, len(pts)


def designation_from_stereo(left: ImageProduct, right: ImageProduct, uv, ps, band_px: float, window_px: int,
                            target_id: str) -> Designation:
    """The :class:`Designation` of the point stereo result ``ps`` (:func:`~scipctl.core.point_stereo.point_stereo`
    at ``uv`` (2,) of ``left`` against ``right`` with band ``band_px`` and window ``window_px``): the match, the
    warnings its left window earns (saturated, low texture, near the edge: the trust model's evidence) and, when the
    match is good, the 3-D point in the rover and site frames. No surface normal and no trust (:func:`designate`
    adds them); the chain's designation step (pipeline/chain.py) builds its own from its point stereo with this."""
    uv = np.asarray(uv, float)
    warnings = []
    k = window_px // 2 + 1
    # the window's pixels as pixels_float() has them, without converting the whole image again
    rows, cols = slice(max(0, int(uv[1]) - k), int(uv[1]) + k + 1), slice(max(0, int(uv[0]) - k), int(uv[0]) + k + 1)
    patch = unit_float(left.pixels[rows, cols], left.full_scale)
    if patch.size and float((patch >= 0.999).mean()) > 0.05:
        warnings.append(SATURATED_WARNING)
    if patch.size and float(patch.std()) < 0.01:
        warnings.append(LOW_TEXTURE_WARNING)
    if min(uv[0], uv[1], left.width - 1 - uv[0], left.height - 1 - uv[1]) < EDGE_MARGIN_PX:
        warnings.append("near the image edge")
    rec = Designation(
        id=target_id, product_id=left.product_id, right_product_id=right.product_id, camera=left.camera,
        position=(left.site, left.drive), pixel_uv=tuple(uv.tolist()), band_px=float(band_px), ok=bool(ps.ok),
        reason=ps.reason, match_score=_f(ps.score), match_ratio=_f(getattr(ps, "ratio", None)),
        uv_right=None if ps.uv_right is None else tuple(float(x) for x in ps.uv_right),
        epipolar_offset_px=_f(ps.epipolar_offset_px), warnings=tuple(warnings))
    if not ps.ok:
        return rec
    X_rover = np.asarray(ps.xyz, float)
    X_site = left.pose.T_site_rover.apply(X_rover)
    return replace(rec, xyz_rover_m=tuple(X_rover.tolist()), xyz_site_m=tuple(X_site.tolist()),
                   range_m=_f(ps.range_m), range_sigma_m=_f(ps.range_sigma_m),
                   ray_miss_m=_f(getattr(ps, "miss_distance_m", None)),
                   pose={"position_m": left.pose.position_m.tolist(),
                         "orientation_wxyz": left.pose.orientation_wxyz.tolist(), "source": left.pose.source})


#: a match this far or farther from its epipolar curve, whose window the pair as downlinked gives no dense ranges:
#: dense stereo on the pair re-aligned at it (measure_window_range_gap)
ALIGN_MIN_PX = 0.5


def _range_interval(range_m: float) -> tuple:
    return max(0.3, 0.5 * range_m), 2.0 * range_m + 1.0


def match_offset_px(left: ImageProduct, right: ImageProduct, uv, uv_right, range_m: float) -> Optional[np.ndarray]:
    """``(2,)`` px from the nearest point of left pixel ``uv``'s epipolar curve (ranges as
    :func:`designation_dense_stereo`'s) to its match ``uv_right`` in ``right``; None when there is no match."""
    from ..core.epipolar import epipolar_curve, polyline_foot

    if uv_right is None or not np.all(np.isfinite(np.asarray(uv_right, float))):
        return None
    uv_right = np.asarray(uv_right, float)
    curve, _ = epipolar_curve(left.camera_model, right.camera_model, np.asarray(uv, float), *_range_interval(range_m))
    return uv_right - polyline_foot(curve, uv_right)[0]


def designation_dense_stereo(L, R, left: ImageProduct, right: ImageProduct, range_m: float, shift_uv=None):
    """Full-resolution dense stereo of the pair ``L``, ``R`` (float images of ``left``, ``right``) over the ranges
    around a designation at ``range_m`` (0.5x to 2x + 1 m, at least 0.3 m): the surface normal's points and the
    window range gap's (:func:`window_range_gap_pct`) come from it; ``shift_uv`` ``(2,)``: the right image is
    first translated by minus that (:func:`~scipctl.core.resample.shifted_image`). Raises what dense stereo raises."""
    from ..core.dense_stereo import dense_stereo

    if shift_uv is not None:
        from ..core.resample import shifted_image

        R = shifted_image(R, shift_uv)
    lo, hi = _range_interval(range_m)
    return dense_stereo(L, R, left.camera_model, right.camera_model, min_range_m=lo, max_range_m=hi)


def window_range_gap_pct(ds, left: ImageProduct, uv, window_px: int, range_m: float) -> Optional[float]:
    """The designation's window range gap in percent of ``range_m`` (:func:`~scipctl.core.window_ranges.
    window_range_gap`): point stereo's range against the median of dense stereo ``ds``'s ranges (from the left
    camera's ``C``) over the ``window_px`` window around ``uv`` in ``left``; None when too few window pixels have a
    dense range."""
    from ..core.window_ranges import window_pixels, window_range_gap

    pix = window_pixels(uv, window_px)
    inside = (pix[:, 0] >= 0) & (pix[:, 1] >= 0) & (pix[:, 0] <= left.width - 1) & (pix[:, 1] <= left.height - 1)
    if not inside.any():
        return None
    xyz = ds.xyz_at_left_uv(pix[inside])
    gap, _ = window_range_gap(np.linalg.norm(xyz - left.camera_model.C, axis=1), float(range_m))
    return None if not math.isfinite(gap) else round(100.0 * gap, 4)


def measure_window_range_gap(L, R, left: ImageProduct, right: ImageProduct, uv, uv_right, range_m: float,
                             window_px: int) -> tuple:
    """``(dense stereo, window range gap %)`` of a designation at ``uv`` matched at ``uv_right`` with ``range_m``.

    Dense stereo of the pair as downlinked first. A pair whose downlinked models are off (the paper saw pancam
    matches up to ~4 px from their epipolar curves) leaves rectified rows that do not meet, and SGBM, which searches
    along a row, then finds almost nothing (measured: 2 % of a pancam pair valid at a 2.5 px offset, 64 % once
    re-aligned). So when the window has too few dense ranges and the match sits ``ALIGN_MIN_PX`` or more off its
    curve (:func:`match_offset_px`), dense stereo runs again on the pair re-aligned as the match says (the right
    image shifted so that the match lands on its curve). Only then: the alignment comes from the match the gap is to
    judge, and a wrong match's offset re-aligns the pair to agree with it (seen once on the fitting rows: 27 % off,
    gap 27 % as downlinked, 0.2 % re-aligned). The dense stereo returned is the one the gap came from (the normal's
    points; the first when neither gave a gap). Raises what dense stereo raises."""
    ds = designation_dense_stereo(L, R, left, right, range_m)
    gap = window_range_gap_pct(ds, left, uv, window_px, range_m)
    if gap is None:
        off = match_offset_px(left, right, uv, uv_right, range_m)
        if off is not None and float(np.linalg.norm(off)) >= ALIGN_MIN_PX:
            ds_aligned = designation_dense_stereo(L, R, left, right, range_m, shift_uv=off)
            gap = window_range_gap_pct(ds_aligned, left, uv, window_px, range_m)
            if gap is not None:
                ds = ds_aligned
    return ds, gap


def with_window_range_gap(rec: Designation, left: ImageProduct, right: ImageProduct, window_px: int) -> Designation:
    """``rec`` (a designation with a 3-D point, made in ``left`` against ``right`` with window ``window_px``) with its
    ``window_range_gap_pct`` from :func:`measure_window_range_gap`, as :func:`designate` measures it (unchanged when
    ``rec`` has no point; None when dense stereo fails): the chain's designation step, scored as ``designate``'s."""
    if not rec.has_position or rec.range_m is None:
        return rec
    try:
        _, gap = measure_window_range_gap(left.pixels_float(), right.pixels_float(), left, right, rec.pixel_uv,
                                          rec.uv_right, float(rec.range_m), window_px)
    except Exception:  # evidence only: without it the trust model takes its training mean
        gap = None
    return replace(rec, window_range_gap_pct=gap)


def check_designation_input(dl: Downlink, left: ImageProduct, uv) -> ImageProduct:
    """The right product :func:`designate` pairs ``left`` with; InputError when ``uv`` ``(2,)`` is outside the
    image or ``left`` has no stereo pair (what a command checks before any work)."""
    uv = np.asarray(uv, float)
    if not (-0.5 <= uv[0] <= left.width - 0.5 and -0.5 <= uv[1] <= left.height - 0.5):
        raise InputError(left.product_id, "pixel", f"({uv[0]:g}, {uv[1]:g}) is outside the {left.width}x{left.height} image")
    right = dl.stereo_pair(left)
    if right is None:
        raise InputError(left.product_id, "eye", f"no right-eye {left.camera} image taken with it: cannot do stereo")
    return right


def designate(dl: Downlink, left: ImageProduct, uv, target_id: str = "t1", with_normal: bool = True,
              params: Optional[PointStereoParams] = None, trust=None) -> Designation:
    """Point stereo at ``uv`` in ``left``; returns the :class:`Designation` (raises InputError).

    When the match is good, dense stereo of the pair around its range (:func:`designation_dense_stereo`) gives the
    window range gap (``window_range_gap_pct``, evidence for the trust model) and, ``with_normal``, the surface
    normal.

    ``params``: the per-camera band and window (default :class:`PointStereoParams`, checked; an operator's
    ``--band-px`` is :meth:`PointStereoParams.with_band`). ``trust``: the designation trust model
    (:mod:`scipctl.pipeline.designation_trust`; None: ``p_ok``/``go`` stay None).
    """
    from ..core.point_stereo import point_stereo

    params = (params or PointStereoParams()).check()
    uv = np.asarray(uv, float)
    right = check_designation_input(dl, left, uv)
    band = float(params.band(left.camera))
    win = params.window(left.camera)
    L = left.pixels_float()
    R = right.pixels_float()
    ps = point_stereo(L, R, left.camera_model, right.camera_model, uv, band_px=band, window_px=win)
    rec = designation_from_stereo(left, right, uv, ps, band, win, target_id)
    if not ps.ok:
        return rec
    warnings = list(rec.warnings)
    sigma_yaw = left.pose.sigma_yaw_rad
    if sigma_yaw is not None and sigma_yaw >= math.pi:
        warnings.append(UNKNOWN_HEADING_WARNING)
    X_rover = np.asarray(ps.xyz, float)
    ds, ds_error, gap = None, None, None
    try:  # dense stereo is evidence and a diagnostic here; the designation stands without it
        ds, gap = measure_window_range_gap(L, R, left, right, uv, ps.uv_right, float(ps.range_m), win)
    except Exception as e:
        ds_error = str(e)
    rec = replace(rec, window_range_gap_pct=gap)
    if with_normal:
        if ds is not None:
            n, npts = surface_normal(ds.xyz.reshape(-1, 3), X_rover, radius_m=max(0.05, 0.02 * ps.range_m))
        else:
            n, npts = None, 0
            warnings.append(f"no surface normal (dense stereo failed: {ds_error})")
        incidence = None
        if n is None and npts < 10:
            warnings.append("no surface normal (too few dense-stereo points around the target)")
        else:
            ray = X_rover - left.camera_model.C
            ray /= np.linalg.norm(ray)
            incidence = float(np.degrees(np.arccos(abs(float(np.dot(ray, n))))))
        rec = replace(rec, surface_normal_rover=None if n is None else tuple(n.tolist()), normal_points=npts,
                      incidence_deg=incidence)
    rec = replace(rec, warnings=tuple(warnings))
    return rec if trust is None else with_trust(rec, trust)


def with_trust(rec: Designation, trust) -> Designation:
    """``rec`` with ``p_ok``/``ok_tolerance_pct``/``go`` from the designation trust model ``trust``
    (:func:`~scipctl.pipeline.designation_trust.assess` at its default tolerance) and, when the model's veto makes
    it NO-GO whatever ``p_ok``, the warning that says why; for a camera the model was not fitted on (a hazcam), a
    warning that ``p_ok`` is outside its data."""
    a = assess(trust, rec)
    rec = replace(rec, p_ok=a.p_ok, ok_tolerance_pct=a.tolerance_pct, go=a.go)
    if a.veto:
        rec = replace(rec, warnings=rec.warnings + (VETO_WARNING_PREFIX + a.veto,))
    if a.p_ok is not None and rec.camera not in FITTED_CAMERAS:  # a hazcam's, scored as if it were a pancam's
        rec = replace(rec, warnings=rec.warnings + (OTHER_CAMERA_WARNING.format(camera=rec.camera),))
    return rec


_f = finite_or_none
