"""Where rays meet the surface a dense stereo pair measured, for templates drawn through the terrain's relief.

The chain draws the previous stop's image into the new view through the target's local plane
(pipeline/plane_warp.py). What stands off that plane is drawn where the plane would put it, not where the new
camera sees it, and the NCC peak is pulled by it, step after step in the same direction as the rover closes in
(docs/stereo-and-tracking.md, "A template through the measured surface"). The previous image's own dense stereo
measures that relief. For each ray of the new camera:

- the stereo's disparities are first shifted by their median disagreement with the plane at ``reference`` rays
  (the template's centre: the target's own surface, whose level the point stereo set; the dense stereo is a
  coarser measurement of the same surface and may sit a fraction of a pixel off);
- the ray is marched from ``(1 - span)`` to ``(1 + span)`` times the distance to the plane's point in ``samples``
  steps and the first crossing from in front of the measured surface to behind it (the surface the new camera
  sees first) is found, linearly between the two samples;
- where there is no crossing (nothing measured, or the surface outside the span), the plane's point is kept; with
  a gate ``disparity_error_px`` (the stereo's error bound) also where the crossing lies within it of the plane's
  point, as the reference camera sees them (the plane as the noiseless model of a surface the stereo cannot tell
  from it).

Both the levelling and the gate are optional (``reference`` all False, ``disparity_error_px`` None: the surface as
measured). Measured on 471 single navcam steps from the true reference (docs/stereo-and-tracking.md, "The surface
template without its gate"), they take back most of what the surface gives there; in the chain, without them, the
stereo's own offset from the point stereo moves every step's answer the same way, and the tracks drift more.

Everything here is in the stereo models' frame (the previous image's rover frame).
"""

from __future__ import annotations

import numpy as np

# the march along each ray: +-span of the distance to the plane's point (relief up to 30 cm along a ray 1 m long),
# in this many samples (0.6 % of the range a step; the crossing is interpolated within the step)
MARCH_SPAN = 0.3
MARCH_SAMPLES = 96


def surface_points(origins_m, directions, t_plane_m, stereo, reference, disparity_error_px: float,
                   span: float = MARCH_SPAN, samples: int = MARCH_SAMPLES) -> np.ndarray:
    """``(N, 3)``: where each ray meets the surface ``stereo`` measured (see the module's text).

    ``origins_m`` ``(N, 3)`` and unit ``directions`` ``(N, 3)``: the rays, in the frame of ``stereo``'s camera
    models (a :class:`~scipctl.core.dense_stereo.DenseStereo`); ``t_plane_m`` ``(N,)``: the distance along each ray
    to the plane's point (NaN or <= 0: the ray misses the plane; its row is NaN); ``reference`` ``(N,)`` bool: the
    rays whose median disagreement with the plane offsets the stereo (none finite: no offset);
    ``disparity_error_px`` (>= 0, or None: no gate): the stereo's disparity error bound, in its own (rectified
    grid) pixels;
    ``span`` in (0, 1), ``samples`` >= 2.
    """
    o = np.asarray(origins_m, float)
    d = np.asarray(directions, float)
    t0 = np.asarray(t_plane_m, float)
    ref = np.asarray(reference)
    n = len(o)
    if o.ndim != 2 or o.shape[1:] != (3,) or d.shape != (n, 3) or t0.shape != (n,) or ref.shape != (n,) \
            or ref.dtype != bool:
        raise ValueError(f"origins_m (N, 3), directions (N, 3), t_plane_m (N,) and reference (N,) bool expected, got "
                         f"{o.shape}, {d.shape}, {t0.shape} and {ref.dtype} {ref.shape}")
    if disparity_error_px is not None and not (np.isfinite(disparity_error_px) and disparity_error_px >= 0):
        raise ValueError(f"disparity_error_px: must be >= 0 or None, got {disparity_error_px!r}")
    if not (0 < span < 1):
        raise ValueError(f"span: must be in (0, 1), got {span!r}")
    if not (isinstance(samples, (int, np.integer)) and samples >= 2):
        raise ValueError(f"samples: must be an integer >= 2, got {samples!r}")
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(t0) & (t0 > 0) & np.all(np.isfinite(o), axis=1) & np.all(np.isfinite(d), axis=1)
    out = np.full((n, 3), np.nan)
    if not hit.any():
        return out
    rect = stereo.rectified.left_model
    fb = stereo.focal_baseline_px_m

    def own(P):
        """Each point's (P, 3) own disparity, fB / depth (NaN behind the camera)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = (P - rect.C) @ rect.A
            return np.where(depth > 0, fb / depth, np.nan)

    def disparities(P):
        """Measured disparity at the rectified pixel of each point (P, 3) and the point's own."""
        q = rect.project(P)
        meas = np.full(len(P), np.nan)
        ok = np.all(np.isfinite(q), axis=1)
        if ok.any():
            meas[ok] = stereo.disparity_at_rect_uv(q[ok])
        return meas, own(P)

    P_plane = o[hit] + t0[hit, None] * d[hit]
    meas, own_plane = disparities(P_plane)
    gap = meas - own_plane
    ref_gap = gap[ref[hit] & np.isfinite(gap)]
    offset = float(np.median(ref_gap)) if len(ref_gap) else 0.0
    oo, dd, tt = o[hit], d[hit], t0[hit]
    ts = tt[:, None] * np.linspace(1.0 - span, 1.0 + span, int(samples))[None, :]
    P = (oo[:, None, :] + ts[..., None] * dd[:, None, :]).reshape(-1, 3)
    m, w = disparities(P)
    g = (m - offset - w).reshape(ts.shape)  # < 0: in front of the measured surface, >= 0: at or behind it
    with np.errstate(invalid="ignore"):
        cross = (g[:, :-1] < 0) & (g[:, 1:] >= 0)
    rows = np.nonzero(cross.any(axis=1))[0]
    result = P_plane.copy()
    if len(rows):
        k = cross.argmax(axis=1)[rows]
        g0, g1 = g[rows, k], g[rows, k + 1]
        t = ts[rows, k] + g0 / (g0 - g1) * (ts[rows, k + 1] - ts[rows, k])
        P_hit = oo[rows] + t[:, None] * dd[rows]
        if disparity_error_px is None:
            result[rows] = P_hit
        else:
            # the first surface met is the plane, as far as the stereo can tell: the plane's (noiseless) point
            off_plane = ~(np.abs(own(P_hit) - own_plane[rows]) <= disparity_error_px)
            result[rows[off_plane]] = P_hit[off_plane]
    out[hit] = result
    return out
