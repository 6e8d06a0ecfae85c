"""JPL CAHV / CAHVOR / CAHVORE camera models (pure numerics).

Definitions follow JPL ``cmod`` (Yakimovsky & Cunningham 1978; Gennery 2001, 2006):

* CAHV: for a point ``P`` (model frame, metres) and ``d = P - C``::

      u = (d . H) / (d . A),   v = (d . V) / (d . A)

* CAHVOR adds radial distortion about the optical axis ``O``::

      zeta = d . O,  lam = d - zeta O,  tau = |lam|^2 / zeta^2
      mu = r0 + r1 tau + r2 tau^2,     d' = d + mu lam,   then CAHV on d'

* CAHVORE adds a moving entrance pupil (non-central) and a fish-eye
  "linearity" ``L`` (type 1: L = 1 perspective, type 2: L = 0 fish-eye,
  type 3: general L). The incoming ray makes angle ``theta`` with ``O`` and
  starts at ``C + s(theta) O`` where
  ``s(theta) = (theta / sin(theta) - 1) (e0 + e1 theta^2 + e2 theta^4)``.
  ``theta`` maps to ``chi = tan(L theta)/L`` (L > 0), ``sin(L theta)/L``
  (L < 0) or ``theta`` (L = 0); the CAHVOR radial term uses ``tau = chi^2``.

Pixels are ``(u, v)`` = (column, row), 0-based, ``(0, 0)`` the centre of the
top-left pixel. Arrays: points ``(..., 3)``, pixels ``(..., 2)``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from .transforms import RigidTransform

KINDS = ("CAHV", "CAHVOR", "CAHVORE")
_NEWTON_MAX = 100
_EPS = 1e-15


def _v3(x, name):
    a = np.asarray(x, dtype=float).reshape(-1)
    if a.shape != (3,):
        raise ValueError(f"{name}: expected 3 numbers, got shape {np.asarray(x).shape}")
    return a


def _cross3(a, b) -> np.ndarray:
    """``np.cross`` of two ``(3,)`` vectors, bit for bit (the same products and differences, each rounded once;
    numpy's general version costs ~20x more per call, and models are built thousands of times per sequence)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def _columns(cols, lead: tuple) -> np.ndarray:
    """A C-ordered ``lead + (3,)`` array from its three components ``(M,)`` (``M = prod(lead)``).

    The per-point arithmetic of this module is written per component (``x_k = a_k - b * c_k``): the same
    operations on the same numbers as on ``(..., 3)`` arrays, but numpy's broadcasting of ``(N, 1)`` or ``(3,)``
    against ``(N, 3)`` costs 4-10x more (an inner loop of 3 per point). The arrays are packed back in the
    layout the ``(..., 3)`` expressions gave, so that :func:`_dot` sums exactly as before."""
    out = np.empty((len(cols[0]), 3))
    for k in range(3):
        out[:, k] = cols[k]
    return out.reshape(lead + (3,))


def _dot(a, b):
    """Row-wise dot product over the last axis (einsum: no temporary product array)."""
    a, b = np.broadcast_arrays(a, b)
    return np.einsum("...i,...i->...", a, b)


class CameraModelError(ValueError):
    """A camera model that is malformed or degenerate; ``field`` names the culprit."""

    def __init__(self, field: str, message: str):
        super().__init__(f"{field}: {message}")
        self.field = field


@dataclass(frozen=True)
class CameraModel:
    """A JPL camera model in some 3-D frame (the frame is the caller's to track).

    ``kind`` is ``"CAHV"``, ``"CAHVOR"`` or ``"CAHVORE"``. ``C``, ``A``, ``H``,
    ``V``, ``O`` are ``(3,)``; ``R`` = ``(r0, r1, r2)``; ``E`` = ``(e0, e1, e2)``.
    ``cahvore_type`` is 1 (perspective), 2 (fish-eye) or 3 (general, with
    ``linearity``).
    """

    kind: str
    C: np.ndarray
    A: np.ndarray
    H: np.ndarray
    V: np.ndarray
    O: Optional[np.ndarray] = None
    R: Optional[np.ndarray] = None
    E: Optional[np.ndarray] = None
    cahvore_type: Optional[int] = None
    linearity: Optional[float] = None

    def __post_init__(self):
        kind = str(self.kind).upper()
        if kind not in KINDS:
            raise CameraModelError("type", f"unknown camera model type {self.kind!r} (want CAHV, CAHVOR or CAHVORE)")
        object.__setattr__(self, "kind", kind)
        for name in "CAHV":
            object.__setattr__(self, name, _v3(getattr(self, name), name))
        if kind in ("CAHVOR", "CAHVORE"):
            for name in "OR":
                if getattr(self, name) is None:
                    raise CameraModelError(name, f"required for {kind}")
                object.__setattr__(self, name, _v3(getattr(self, name), name))
        else:
            object.__setattr__(self, "O", None)
            object.__setattr__(self, "R", None)
        if kind == "CAHVORE":
            if self.E is None:
                raise CameraModelError("E", "required for CAHVORE")
            object.__setattr__(self, "E", _v3(self.E, "E"))
            t = self.cahvore_type
            if t is None:
                t = 3 if self.linearity is not None else 1
            try:
                t = int(t)
            except (TypeError, ValueError):
                raise CameraModelError("cahvore_type", f"not an integer: {t!r}") from None
            if t not in (1, 2, 3):
                raise CameraModelError("cahvore_type", f"must be 1, 2 or 3, got {t}")
            if t == 1:
                lin = 1.0
            elif t == 2:
                lin = 0.0
            else:
                if self.linearity is None:
                    raise CameraModelError("linearity", "required for CAHVORE type 3")
                lin = float(self.linearity)
            object.__setattr__(self, "cahvore_type", t)
            object.__setattr__(self, "linearity", lin)
        else:
            object.__setattr__(self, "E", None)
            object.__setattr__(self, "cahvore_type", None)
            object.__setattr__(self, "linearity", None)
        self.validate()

    # ------------------------------------------------------------------ checks
    def validate(self) -> None:
        """Raise :class:`CameraModelError` for NaN/inf or degenerate geometry."""
        for name in ("C", "A", "H", "V", "O", "R", "E"):
            val = getattr(self, name)
            if val is not None and not np.all(np.isfinite(val)):
                raise CameraModelError(name, "contains NaN or infinity")
        if self.linearity is not None and not np.isfinite(self.linearity):
            raise CameraModelError("linearity", "NaN or infinity")
        # Finite but huge numbers (1e300) overflow below: no warnings, and every test is written so that
        # NaN/inf fail it (``not ok``) rather than slip past a ``bad`` comparison.
        with np.errstate(over="ignore", invalid="ignore"):
            na = np.linalg.norm(self.A)
            if not abs(na - 1.0) <= 1e-3:
                raise CameraModelError("A", f"must be a unit vector (|A| = {na:.6g})")
            if self.O is not None:
                no = np.linalg.norm(self.O)
                if not abs(no - 1.0) <= 1e-3:
                    raise CameraModelError("O", f"must be a unit vector (|O| = {no:.6g})")
                if not np.dot(self.O, self.A) >= 0.5:
                    raise CameraModelError("O", "optical axis is more than 60 deg from A")
            hp = _cross3(self.A, self.H)
            vp = _cross3(self.A, self.V)
            nh, nv = np.linalg.norm(hp), np.linalg.norm(vp)
            for name, n in (("H", nh), ("V", nv)):
                if not np.isfinite(n):
                    raise CameraModelError(name, f"too large (|A x {name}| overflows)")
            if not nh >= 1e-9:
                raise CameraModelError("H", "parallel to A (no horizontal scale)")
            if not nv >= 1e-9:
                raise CameraModelError("V", "parallel to A (no vertical scale)")
            s = np.linalg.norm(_cross3(hp / nh, vp / nv))
            if not s >= 1e-3:
                raise CameraModelError("V", "H and V are parallel (degenerate image plane)")

    # ------------------------------------------------------------ derived terms
    @property
    def hs(self) -> float:
        return float(np.linalg.norm(_cross3(self.A, self.H)))

    @property
    def hc(self) -> float:
        return float(np.dot(self.A, self.H))

    @property
    def vs(self) -> float:
        return float(np.linalg.norm(_cross3(self.A, self.V)))

    @property
    def vc(self) -> float:
        return float(np.dot(self.A, self.V))

    @property
    def h_axis(self) -> np.ndarray:
        """Unit image-plane direction of increasing ``u`` (``(3,)``)."""
        return (self.H - self.hc * self.A) / self.hs

    @property
    def v_axis(self) -> np.ndarray:
        """Unit image-plane direction of increasing ``v`` (``(3,)``)."""
        return (self.V - self.vc * self.A) / self.vs

    @property
    def theta_rad(self) -> float:
        """Angle between the image axes as JPL reports it (``-pi/2`` for an orthogonal, right-handed model)."""
        hp, vp = self.h_axis, self.v_axis
        cr = _cross3(vp, hp)
        sn = np.linalg.norm(cr) * (1.0 if np.dot(cr, self.A) >= 0 else -1.0)
        return float(np.arctan2(sn, np.dot(vp, hp)))

    def ifov_rad(self) -> tuple[float, float]:
        """Instantaneous field of view at the optical centre, ``(horizontal, vertical)`` rad/px."""
        return 1.0 / self.hs, 1.0 / self.vs

    def field_of_view_rad(self, width: int, height: int) -> tuple[float, float]:
        """Full horizontal and vertical field of view through the image centre lines (rad)."""
        cu, cv = (width - 1) / 2.0, (height - 1) / 2.0
        uv = np.array([[-0.5, cv], [width - 0.5, cv], [cu, -0.5], [cu, height - 0.5]])
        _, d = self.unproject(uv)
        h = np.arccos(np.clip(np.dot(d[0], d[1]), -1, 1))
        v = np.arccos(np.clip(np.dot(d[2], d[3]), -1, 1))
        return float(h), float(v)

    @property
    def is_central(self) -> bool:
        return self.kind != "CAHVORE" or not np.any(self.E != 0)

    # ---------------------------------------------------------------- motion
    def transformed(self, T_new_old: RigidTransform) -> "CameraModel":
        """This model moved rigidly: ``T_new_old`` maps the model's frame into the new frame.

        ``C`` moves as a point; ``A``, ``H``, ``V``, ``O`` rotate.
        """
        Rm = T_new_old.R
        kw = dict(C=T_new_old.apply(self.C), A=Rm @ self.A, H=Rm @ self.H, V=Rm @ self.V)
        if self.O is not None:
            kw["O"] = Rm @ self.O
        return replace(self, **kw)

    # ------------------------------------------------------------ projection
    def project(self, P, jacobian: bool = False):
        """Project points ``P`` ``(..., 3)`` (model frame) to pixels ``(..., 2)``.

        With ``jacobian=True`` also returns ``d(uv)/dP`` of shape ``(..., 2, 3)``.
        Points behind the camera (``(P - C) . A <= 0``) give NaN.
        """
        P = np.asarray(P, dtype=float)
        if P.shape[-1] != 3:
            raise ValueError(f"P: expected shape (..., 3), got {P.shape}")
        lead = P.shape[:-1]
        Pf = P.reshape(-1, 3)
        d = _columns([Pf[:, k] - self.C[k] for k in range(3)], lead)  # P - C
        if self.kind == "CAHV":
            w, J_w = d, None
        elif self.kind == "CAHVOR":
            w, J_w = self._distort_cahvor(d, jacobian)
        else:
            w, J_w = self._distort_cahvore(d, jacobian)
        if self.kind == "CAHVORE":  # wide-angle: valid beyond 90 deg from A, judged on the ray angle
            bad = ~np.isfinite(_dot(w, w))
        else:
            bad = ~(_dot(d, self.A) > 0)
        a = _dot(w, self.A)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = _dot(w, self.H) / a
            v = _dot(w, self.V) / a
        uv = np.stack([u, v], axis=-1)
        bad = bad | ~(a > 0)
        uv[bad] = np.nan
        if not jacobian:
            return uv
        with np.errstate(divide="ignore", invalid="ignore"):
            Ju = (self.H - u[..., None] * self.A) / a[..., None]
            Jv = (self.V - v[..., None] * self.A) / a[..., None]
        J = np.stack([Ju, Jv], axis=-2)  # d(uv)/dw  (..., 2, 3)
        if J_w is not None:
            J = J @ J_w
        J[bad] = np.nan
        return uv, J

    def _distort_cahvor(self, d, jacobian):
        O = self.O
        r0, r1, r2 = self.R
        zeta = _dot(d, O)
        lead, df, zf = d.shape[:-1], d.reshape(-1, 3), zeta.reshape(-1)
        lam = _columns([df[:, k] - zf * O[k] for k in range(3)], lead)  # d - zeta O
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = _dot(lam, lam) / (zeta * zeta)
        mu = r0 + (r1 + r2 * tau) * tau
        lf, mf = lam.reshape(-1, 3), mu.reshape(-1)
        w = _columns([df[:, k] + mf * lf[:, k] for k in range(3)], lead)  # d + mu lam
        if not jacobian:
            return w, None
        I = np.eye(3)
        P_perp = I - np.outer(O, O)
        with np.errstate(divide="ignore", invalid="ignore"):
            dtau = 2 * lam / (zeta * zeta)[..., None] - 2 * (tau / zeta)[..., None] * O
        dmu = (r1 + 2 * r2 * tau)[..., None] * dtau  # (..., 3)
        J = I + mu[..., None, None] * P_perp + lam[..., :, None] * dmu[..., None, :]
        return w, J

    def _chi_of_theta(self, theta):
        L = self.linearity
        if L > 1e-15:
            return np.tan(L * theta) / L, 1.0 / np.cos(L * theta) ** 2
        if L < -1e-15:
            return np.sin(L * theta) / L, np.cos(L * theta)
        return theta, np.ones_like(theta)

    def _theta_of_chi(self, chi):
        L = self.linearity
        if L > 1e-15:
            return np.arctan(L * chi) / L
        if L < -1e-15:
            return np.arcsin(np.clip(L * chi, -1, 1)) / L
        return chi

    def _solve_theta(self, zeta, lam):
        """Solve ``zeta sin(t) - lam cos(t) - (t - sin t)(e0 + e1 t^2 + e2 t^4) = 0`` for ``t``."""
        e0, e1, e2 = self.E
        theta = np.arctan2(lam, zeta)
        if not np.any(self.E != 0):
            return theta, None
        g_t = None
        active = np.ones(theta.shape, dtype=bool)
        for _ in range(_NEWTON_MAX):
            t = theta
            t2 = t * t
            st, ct = np.sin(t), np.cos(t)
            S = e0 + (e1 + e2 * t2) * t2
            dS = (2 * e1 + 4 * e2 * t2) * t
            g = zeta * st - lam * ct - (t - st) * S
            g_t = zeta * ct + lam * st - (1 - ct) * S - (t - st) * dS
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(active, g / g_t, 0.0)
            theta = t - step
            active = np.abs(step) > 1e-15
            if not np.any(active):
                break
        return theta, None

    def _distort_cahvore(self, d, jacobian):
        O = self.O
        r0, r1, r2 = self.R
        e0, e1, e2 = self.E
        zeta = _dot(d, O)
        lam_v = d - zeta[..., None] * O
        lam = np.sqrt(_dot(lam_v, lam_v))
        theta, _ = self._solve_theta(zeta, lam)
        chi, dchi_dtheta = self._chi_of_theta(theta)
        L = self.linearity
        if L != 0:  # outside the linearity mapping's domain
            chi = np.where(np.abs(L * theta) < np.pi / 2, chi, np.nan)
        chi2 = chi * chi
        mu = r0 + (r1 + r2 * chi2) * chi2
        k = (1 + mu) * chi  # distorted tan-like radius
        small = lam < 1e-12 * np.maximum(np.abs(zeta), 1e-300)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam_hat = np.where(small[..., None], 0.0, lam_v / lam[..., None])
        w = O + k[..., None] * lam_hat
        if not jacobian:
            return w, None
        # implicit derivative of theta(zeta, lam)
        t = theta
        t2 = t * t
        st, ct = np.sin(t), np.cos(t)
        S = e0 + (e1 + e2 * t2) * t2
        dS = (2 * e1 + 4 * e2 * t2) * t
        g_t = zeta * ct + lam * st - (1 - ct) * S - (t - st) * dS
        dk_dchi = 1 + mu + chi * (2 * r1 * chi + 4 * r2 * chi2 * chi)
        I = np.eye(3)
        P_perp = I - np.outer(O, O)
        with np.errstate(divide="ignore", invalid="ignore"):
            dtheta = (-st[..., None] * O + ct[..., None] * lam_hat) / g_t[..., None]  # (..., 3)
            dk = (dk_dchi * dchi_dtheta)[..., None] * dtheta
            lhl = lam_hat[..., :, None] * lam_hat[..., None, :]
            J = lam_hat[..., :, None] * dk[..., None, :] + (k / lam)[..., None, None] * ((I - lhl) @ P_perp)
            # on the optical axis: w ~ O + c lam_v with c = (1 + r0) dchi/dtheta dtheta/dlam
            c0 = (1 + r0) * dchi_dtheta / g_t
        if np.any(small):
            J = np.where(small[..., None, None], c0[..., None, None] * P_perp, J)
        return w, J

    # ---------------------------------------------------------- unprojection
    def unproject(self, uv):
        """Pixels ``(..., 2)`` -> ray origins ``(..., 3)`` and unit directions ``(..., 3)``.

        For CAHV and CAHVOR the origin is ``C``; for CAHVORE it slides along ``O``
        with the ray angle (non-central model).
        """
        uv = np.asarray(uv, dtype=float)
        if uv.shape[-1] != 2:
            raise ValueError(f"uv: expected shape (..., 2), got {uv.shape}")
        lead = uv.shape[:-1]
        flat = uv.reshape(-1, 2)
        x, y = flat[:, 0], flat[:, 1]
        # (V - y A) x (H - x A) = V x H - x (V x A) - y (A x H): linear in (u, v); per component (_columns)
        c_vh, c_va, c_ah = _cross3(self.V, self.H), _cross3(self.V, self.A), _cross3(self.A, self.H)
        rr = _columns([(c_vh[k] - x * c_va[k]) - y * c_ah[k] for k in range(3)], lead)
        n = np.sqrt(_dot(rr, rr)).reshape(-1)
        rf = rr.reshape(-1, 3)
        rr = _columns([rf[:, k] / n for k in range(3)], lead)  # rr / |rr|
        sgn = np.sign(_dot(rr, self.A)).reshape(-1)
        sgn = np.where(sgn == 0, 1.0, sgn)
        rf = rr.reshape(-1, 3)
        rr = _columns([rf[:, k] * sgn for k in range(3)], lead)
        origin = np.broadcast_to(self.C, rr.shape).copy()
        if self.kind == "CAHV":
            return origin, rr
        O = self.O
        r0, r1, r2 = self.R
        omega = _dot(rr, O)
        om, rf = omega.reshape(-1), rr.reshape(-1, 3)
        lam_v = _columns([rf[:, k] - om * O[k] for k in range(3)], lead)  # rr - omega O
        tau = _dot(lam_v, lam_v) / (omega * omega)  # distorted chi^2
        # solve s (1 + r0 + r1 s^2 tau + r2 s^4 tau^2) = 1 for the undistortion factor s
        k1 = 1 + r0
        k3 = r1 * tau
        k5 = r2 * tau * tau
        s = np.ones_like(tau)
        for _ in range(_NEWTON_MAX):
            s2 = s * s
            poly = ((k5 * s2 + k3) * s2 + k1) * s - 1
            deriv = (5 * k5 * s2 + 3 * k3) * s2 + k1
            step = poly / deriv
            s = s - step
            if np.all(np.abs(step) < 1e-15):
                break
        lf = lam_v.reshape(-1, 3)
        if self.kind == "CAHVOR":
            sf = s.reshape(-1)
            d = _columns([om * O[k] + sf * lf[:, k] for k in range(3)], lead)  # omega O + s lam_v
            nf, df = np.linalg.norm(d, axis=-1, keepdims=True).reshape(-1), d.reshape(-1, 3)
            return origin, _columns([df[:, k] / nf for k in range(3)], lead)
        # CAHVORE: ideal chi -> theta -> ray and entrance-pupil shift
        lam_d = np.sqrt(_dot(lam_v, lam_v))
        chi = s * lam_d / omega
        theta = self._theta_of_chi(chi)
        ldf = lam_d.reshape(-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam_hat = _columns([np.where(ldf > 1e-15, lf[:, k] / ldf, 0.0) for k in range(3)], lead)
        st, ct = np.sin(theta), np.cos(theta)
        stf, ctf, lhf = st.reshape(-1), ct.reshape(-1), lam_hat.reshape(-1, 3)
        d = _columns([ctf * O[k] + stf * lhf[:, k] for k in range(3)], lead)  # cos O + sin lam_hat
        e0, e1, e2 = self.E
        t2 = theta * theta
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(np.abs(theta) > 1e-4, theta / st - 1.0, t2 / 6.0 + 7.0 * t2 * t2 / 360.0)
        shift = ratio * (e0 + (e1 + e2 * t2) * t2)
        shf = shift.reshape(-1)
        origin = _columns([self.C[k] + shf * O[k] for k in range(3)], lead)  # C + shift O
        return origin, d

    # -------------------------------------------------------------- helpers
    def epipolar_curve(self, origin, direction, ranges_m) -> np.ndarray:
        """Project points ``origin + r * direction`` for each range in ``ranges_m`` (N,) -> ``(N, 2)``."""
        r = np.asarray(ranges_m, dtype=float)[:, None]
        return self.project(np.asarray(origin)[None, :] + r * np.asarray(direction)[None, :])

    def to_dict(self) -> dict:
        """Plain-data form with the downlink-format keys (lists of floats)."""
        out = {"type": self.kind, "C": self.C.tolist(), "A": self.A.tolist(), "H": self.H.tolist(), "V": self.V.tolist()}
        if self.kind in ("CAHVOR", "CAHVORE"):
            out["O"] = self.O.tolist()
            out["R"] = self.R.tolist()
        if self.kind == "CAHVORE":
            out["E"] = self.E.tolist()
            out["cahvore_type"] = int(self.cahvore_type)
            out["linearity"] = float(self.linearity)
        return out

    @staticmethod
    def from_dict(d: dict) -> "CameraModel":
        """Inverse of :meth:`to_dict`; raises :class:`CameraModelError` naming the bad field."""
        if not isinstance(d, dict):
            raise CameraModelError("camera_model", "must be a mapping")
        if "type" not in d:
            raise CameraModelError("type", "missing")
        kind = str(d["type"]).upper()
        if kind not in KINDS:
            raise CameraModelError("type", f"unknown camera model type {d['type']!r}")
        kw = {}
        needed = {"CAHV": "CAHV", "CAHVOR": "CAHVOR", "CAHVORE": "CAHVORE"}[kind]
        for name in needed:
            if name not in d or d[name] is None:
                raise CameraModelError(name, f"missing (required for {kind})")
            try:
                kw[name] = _v3(d[name], name)
            except (TypeError, ValueError) as e:
                raise CameraModelError(name, f"not 3 numbers ({e})") from None
        if kind == "CAHVORE":
            kw["cahvore_type"] = d.get("cahvore_type")
            kw["linearity"] = d.get("linearity")
            if kw["cahvore_type"] is None:
                raise CameraModelError("cahvore_type", "missing (required for CAHVORE)")
        return CameraModel(kind=kind, **kw)

    def almost_equal(self, other: "CameraModel", tol: float = 1e-12) -> bool:
        if self.kind != other.kind:
            return False
        for name in ("C", "A", "H", "V", "O", "R", "E"):
            a, b = getattr(self, name), getattr(other, name)
            if (a is None) != (b is None):
                return False
            if a is not None and not np.allclose(a, b, atol=tol, rtol=0):
                return False
        if self.kind == "CAHVORE":
            return self.cahvore_type == other.cahvore_type and abs(self.linearity - other.linearity) <= tol
        return True


def cahv_from_intrinsics(
    fx_px: float,
    fy_px: float,
    cx_px: float,
    cy_px: float,
    T_frame_cam: RigidTransform,
) -> CameraModel:
    """A CAHV model from pinhole intrinsics and a camera pose.

    The camera frame is x right (u), y down (v), z forward (boresight), as in
    OpenCV; ``T_frame_cam`` maps camera-frame points into the model's frame.
    """
    R = T_frame_cam.R
    x_ax, y_ax, z_ax = R[:, 0], R[:, 1], R[:, 2]
    A = z_ax
    H = fx_px * x_ax + cx_px * A
    V = fy_px * y_ax + cy_px * A
    return CameraModel("CAHV", C=T_frame_cam.t, A=A, H=H, V=V)


def T_model_cam(model: CameraModel) -> RigidTransform:
    """``T_model_cam``: the orthonormal (OpenCV-style) camera frame ``cam`` (x ~ h axis, y ~ v axis, z = A, origin
    ``C``) in the frame ``model`` is expressed in (e.g. ``T_rover_cam`` for a rover-frame model)."""
    z = model.A
    x = model.h_axis - np.dot(model.h_axis, z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RigidTransform(np.stack([x, y, z], axis=1), model.C)


def with_distortion(model: CameraModel, **kw) -> CameraModel:
    """Convenience: a copy with some fields replaced (e.g. ``kind``, ``O``, ``R``, ``E``)."""
    return replace(model, **kw)



def check_camera_model(model, name: str) -> None:
    """Raise ``ValueError`` naming argument ``name`` unless ``model`` is a :class:`CameraModel`."""
    if not isinstance(model, CameraModel):
        raise ValueError(f"{name}: expected a CameraModel, got {type(model).__name__}")
