import warnings

import numpy as np
import pytest

from scipctl.core.camera import CameraModel, CameraModelError
from scipctl.core.transforms import RigidTransform, rotvec_to_matrix
from tests.models import all_models, pixel_grid

MODELS = all_models()


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("range_m", [0.3, 1.0, 4.0, 50.0])
def test_unproject_project_round_trip(name, range_m):
    m = MODELS[name]
    uv = pixel_grid(41)
    o, d = m.unproject(uv)
    assert np.allclose(np.linalg.norm(d, axis=-1), 1.0)
    uv2 = m.project(o + range_m * d)
    err = np.abs(uv2 - uv).max()
    assert err < 1e-6, f"{name}: round trip error {err:.3g} px"


@pytest.mark.parametrize("name", sorted(MODELS))
def test_project_unproject_round_trip(name):
    m = MODELS[name]
    rng = np.random.default_rng(1)
    uv = pixel_grid(25)
    o, d = m.unproject(uv)
    r = rng.uniform(0.5, 20.0, size=len(uv))
    P = o + r[:, None] * d
    uv2 = m.project(P)
    o2, d2 = m.unproject(uv2)
    # the recovered ray passes through P
    off = P - o2
    perp = off - np.sum(off * d2, axis=-1)[:, None] * d2
    assert np.linalg.norm(perp, axis=-1).max() < 1e-9 * r.max()


@pytest.mark.parametrize("name", sorted(MODELS))
def test_jacobian_matches_finite_differences(name):
    m = MODELS[name]
    uv = pixel_grid(9, margin=5)
    o, d = m.unproject(uv)
    P = o + 2.0 * d
    _, J = m.project(P, jacobian=True)
    h = 1e-6
    Jfd = np.zeros_like(J)
    for k in range(3):
        dp = np.zeros(3)
        dp[k] = h
        Jfd[..., k] = (m.project(P + dp) - m.project(P - dp)) / (2 * h)
    rel = np.abs(J - Jfd).max() / np.abs(Jfd).max()
    assert rel < 1e-6, f"{name}: Jacobian relative error {rel:.3g}"


def test_jacobian_on_optical_axis():
    m = MODELS["CAHVORE3"]
    P = m.C + 1.5 * m.O
    uv, J = m.project(P[None], jacobian=True)
    h = 1e-6
    Jfd = np.stack([(m.project(P + e * h) - m.project(P - e * h)) / (2 * h) for e in np.eye(3)], axis=-1)
    assert np.abs(J[0] - Jfd).max() < 1e-4 * np.abs(Jfd).max()


@pytest.mark.parametrize("name", sorted(MODELS))
def test_rigid_motion_invariance(name):
    m = MODELS[name]
    T = RigidTransform(rotvec_to_matrix([0.3, -0.2, 1.1]), [1.0, -2.0, 0.5])
    m2 = m.transformed(T)
    uv = pixel_grid(11)
    o, d = m.unproject(uv)
    P = o + 3.0 * d
    assert np.abs(m2.project(T.apply(P)) - uv).max() < 1e-6
    # T then T^-1 gives the model back
    assert m2.transformed(T.inverse()).almost_equal(m, tol=1e-12)


def test_behind_camera_is_nan():
    m = MODELS["CAHVOR"]
    P = m.C - 2.0 * m.A
    assert np.all(np.isnan(m.project(P[None])))


def test_cahvore_is_non_central_and_types_imply_linearity():
    m = MODELS["CAHVORE3"]
    axis_uv = m.project(m.C + m.O)
    o, _ = m.unproject(np.array([[0.0, 0.0], axis_uv]))
    assert np.linalg.norm(o[0] - m.C) > 1e-5  # edge ray starts off C
    assert np.linalg.norm(o[1] - m.C) < 1e-12  # the ray along O starts at C
    assert MODELS["CAHVORE1"].linearity == 1.0
    assert MODELS["CAHVORE2"].linearity == 0.0


def test_derived_quantities():
    m = MODELS["CAHV"]
    assert m.hs == pytest.approx(1220.0)
    assert m.vs == pytest.approx(1220.0 * 1.003)
    assert m.hc == pytest.approx(511.3)
    assert m.vc == pytest.approx(514.8)
    assert m.theta_rad == pytest.approx(-np.pi / 2)
    h, v = m.field_of_view_rad(1024, 1024)
    assert h == pytest.approx(2 * np.arctan(512 / 1220.0), rel=2e-3)


@pytest.mark.parametrize(
    "field,mutate",
    [
        ("A", lambda d: d.update(A=[0.0, 0.0, 2.0])),
        ("C", lambda d: d.update(C=[float("nan"), 0.0, 0.0])),
        ("V", lambda d: d.update(V=d["H"])),
        ("H", lambda d: d.update(H=d["A"])),
        ("R", lambda d: d.pop("R")),
        ("type", lambda d: d.update(type="PINHOLE")),
    ],
)
def test_degenerate_models_name_the_field(field, mutate):
    d = MODELS["CAHVOR"].to_dict()
    mutate(d)
    with pytest.raises(CameraModelError) as ei:
        CameraModel.from_dict(d)
    assert ei.value.field == field


@pytest.mark.parametrize(
    "field,mutate",
    [
        ("A", lambda d: d.update(A=[1e308, 0.0, 0.0])),
        ("O", lambda d: d.update(O=[0.0, 1e200, 0.0])),
        ("H", lambda d: d.update(H=[1e308, -1e308, 1e308])),  # A x H overflowed to NaN and passed every check
        ("V", lambda d: d.update(V=[1e200, 1e200, 0.0])),
    ],
)
def test_huge_finite_vectors_name_the_field_without_warnings(field, mutate):
    d = MODELS["CAHVOR"].to_dict()
    mutate(d)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's overflow warnings were extra lines on the CLI's stderr
        with pytest.raises(CameraModelError) as ei:
            CameraModel.from_dict(d)
    assert ei.value.field == field


@pytest.mark.parametrize("name", sorted(MODELS))
def test_dict_round_trip(name):
    m = MODELS[name]
    assert CameraModel.from_dict(m.to_dict()).almost_equal(m, tol=0)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_single_pixel_and_point_shapes(name):
    m = MODELS[name]
    o, d = m.unproject(np.array([300.0, 400.0]))
    assert o.shape == (3,) and d.shape == (3,)
    uv = m.project(o + 2.0 * d)
    assert uv.shape == (2,)
    assert np.allclose(uv, [300.0, 400.0], atol=1e-6)


def test_the_small_cross_product_is_numpys_bit_for_bit():
    """camera._cross3 (the models' 3-vector cross products, on the hot path of building and unprojecting
    models) gives np.cross's very numbers, overflow included."""
    from scipctl.core.camera import _cross3

    rng = np.random.default_rng(5)
    for scale in (1e-9, 1.0, 1e9, 1e160):
        a, b = rng.normal(size=(2000, 3)) * scale, rng.normal(size=(2000, 3)) * scale  # 1e160: products overflow
        with np.errstate(over="ignore", invalid="ignore"):
            want = np.cross(a, b)
        with np.errstate(over="ignore", invalid="ignore"):
            got = np.array([_cross3(x, y) for x, y in zip(a, b)])
        assert np.array_equal(got, want, equal_nan=True)


def _reference_unproject(m, uv):
    """camera.unproject as it was written on (..., 3) arrays (before the per-component rewrite), for exactness."""
    from scipctl.core.camera import _NEWTON_MAX, _dot

    x, y = uv[..., 0:1], uv[..., 1:2]
    rr = np.cross(m.V, m.H) - x * np.cross(m.V, m.A) - y * np.cross(m.A, m.H)
    rr = rr / np.sqrt(_dot(rr, rr))[..., None]
    sgn = np.sign(_dot(rr, m.A))
    rr = rr * np.where(sgn == 0, 1.0, sgn)[..., None]
    origin = np.broadcast_to(m.C, rr.shape).copy()
    if m.kind == "CAHV":
        return origin, rr
    O, (r0, r1, r2) = m.O, m.R
    omega = _dot(rr, O)
    lam_v = rr - omega[..., None] * O
    tau = _dot(lam_v, lam_v) / (omega * omega)
    k1, k3, k5 = 1 + r0, r1 * tau, r2 * tau * tau
    s = np.ones_like(tau)
    for _ in range(_NEWTON_MAX):
        s2 = s * s
        step = (((k5 * s2 + k3) * s2 + k1) * s - 1) / ((5 * k5 * s2 + 3 * k3) * s2 + k1)
        s = s - step
        if np.all(np.abs(step) < 1e-15):
            break
    if m.kind == "CAHVOR":
        d = omega[..., None] * O + s[..., None] * lam_v
        return origin, d / np.linalg.norm(d, axis=-1, keepdims=True)
    lam_d = np.sqrt(_dot(lam_v, lam_v))
    theta = m._theta_of_chi(s * lam_d / omega)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam_hat = np.where((lam_d > 1e-15)[..., None], lam_v / lam_d[..., None], 0.0)
    st, ct = np.sin(theta), np.cos(theta)
    d = ct[..., None] * O + st[..., None] * lam_hat
    e0, e1, e2 = m.E
    t2 = theta * theta
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(np.abs(theta) > 1e-4, theta / st - 1.0, t2 / 6.0 + 7.0 * t2 * t2 / 360.0)
    return origin + (ratio * (e0 + (e1 + e2 * t2) * t2))[..., None] * O, d


def _reference_project_cahvor(m, P):
    from scipctl.core.camera import _dot

    d = P - m.C
    zeta = _dot(d, m.O)
    lam = d - zeta[..., None] * m.O
    tau = _dot(lam, lam) / (zeta * zeta)
    w = d + (m.R[0] + (m.R[1] + m.R[2] * tau) * tau)[..., None] * lam
    a = _dot(w, m.A)
    uv = np.stack([_dot(w, m.H) / a, _dot(w, m.V) / a], axis=-1)
    uv[~(_dot(d, m.A) > 0) | ~(a > 0)] = np.nan
    return uv


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("lead", [(), (7,), (5, 9)])
def test_per_component_arithmetic_is_bit_for_bit_the_array_expressions(name, lead):
    """unproject and project compute per component (camera._columns, for speed): exactly the numbers the
    (..., 3) array expressions gave, in every shape (docs/sequence.md, "Speed")."""
    m = MODELS[name]
    rng = np.random.default_rng(11)
    uv = rng.uniform(-50, 1100, size=lead + (2,))
    o, d = m.unproject(uv)
    ro, rd = _reference_unproject(m, uv)
    assert o.shape == ro.shape == d.shape == rd.shape == lead + (3,)
    assert np.array_equal(o, ro, equal_nan=True) and np.array_equal(d, rd, equal_nan=True)
    if m.kind == "CAHVOR":
        P = m.C + rng.normal(size=lead + (3,)) + 3.0 * m.A
        with np.errstate(divide="ignore", invalid="ignore"):
            want = _reference_project_cahvor(m, P)
        assert np.array_equal(m.project(P), want, equal_nan=True)
