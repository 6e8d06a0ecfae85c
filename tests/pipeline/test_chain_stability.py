"""The chain's answer does not hinge on the last bit: the same bits on a repeat and with another thread count, and
small input changes (0.01 px on the designation, one digital number of intensity noise) move each step by less
than its tolerance (docs/stereo-and-tracking.md, "Reproducibility")."""

from pathlib import Path

import numpy as np
import pytest

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import run_chain
from tests.pipeline.chain_expected import EXPECTED_ERROR_PX

cv2 = pytest.importorskip("cv2")

ROOT = Path(__file__).resolve().parents[2]
# s1-arc t1: an unconfirmed feature step (the chain's most fragile path); s1-straight t2: every track confirmed
CASES = [("paper-s1-arc", "t1"), ("paper-s1-straight", "t2")]


def _start(dl):
    return min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)


def _run(dl, target, offset_px=(0.0, 0.0)):
    start = _start(dl)
    mk = dl.target(target).mark_in(start.product_id)
    return run_chain(dl, start, np.array([mk.u, mk.v]) + np.asarray(offset_px), target_id=target)


def _sol(name):
    return ROOT / "sample_sols/mcap" / f"{name}.mcap"


def _uv(steps):
    return [None if s.tracked_uv is None else np.asarray(s.tracked_uv) for s in steps]


@pytest.fixture(scope="module", params=CASES, ids=lambda c: "/".join(c))
def reference(request):
    sol, target = request.param
    dl = read_downlink(_sol(sol))
    return sol, target, dl, _run(dl, target)


def test_repeat_and_thread_count_give_the_same_bits(reference):
    """Every random draw is seeded and no answer depends on the order threads finish in: a second run, and a run
    with OpenCV limited to one thread, give bit-identical pixels at every tracking step, and the hazcam step
    (scip) within 1e-9 px (its registration's floating-point reductions)."""
    _, target, dl, ref = reference
    n = cv2.getNumThreads()
    try:
        cv2.setNumThreads(1)
        one = _run(dl, target)
    finally:
        cv2.setNumThreads(n)
    again = _run(dl, target)
    for s, a, b, c in zip(ref, _uv(ref), _uv(one), _uv(again)):
        assert (a is None) == (b is None) == (c is None)
        if a is None:
            continue
        if s.camera == "hazcam":
            # scip's hazcam answer: its mesh-registration candidate (Open3D ICP, threaded reductions) is not
            # bit-reproducible -- measured on s1-arc t1 (where scip chose it): 5.7e-14 px between runs. Bound:
            # 1e-9 px, four orders of magnitude above it and far below anything a pixel answer resolves
            assert np.abs(a - b).max() <= 1e-9 and np.abs(a - c).max() <= 1e-9, (a, b, c)
        else:
            assert np.array_equal(a, b) and np.array_equal(a, c), (a, b, c)


def _moves_under_tolerance(sol, target, ref, other, label):
    """Each step after the designation moves by less than its error bound in EXPECTED_ERROR_PX. Measured (session
    13, docs/scripts/other_builds.sh for the second build): at most 0.17 of it on OpenCV 5.0.0, the locked build, and
    0.74 on OpenCV 4.14.0, where 1 DN of noise moves s1-arc t1's flagged 4.5 m pancam match (its error 5.3 -> 9.7 px)
    and the navcam handoff after it by 2.1 px (0.53 of its bound), the hazcam by 0.74 of its; x1.25 and rounded up to a
    quarter gives 1.0 (docs/stereo-and-tracking.md, "Reproducibility")."""
    bounds = EXPECTED_ERROR_PX[sol][target]
    checked = 0
    for s0, s1, bound in zip(ref[1:], other[1:], bounds):
        assert (s0.product_id, s0.kind) == (s1.product_id, s1.kind), label
        if bound is None or s0.tracked_uv is None:
            continue
        assert s1.tracked_uv is not None, (label, s0.product_id)
        moved = float(np.linalg.norm(np.subtract(s1.tracked_uv, s0.tracked_uv)))
        assert moved <= 1.0 * bound, (label, s0.product_id, s0.kind, moved, bound)
        checked += 1
    assert checked >= 4


@pytest.mark.parametrize("offset_px", [(0.01, 0.0), (-0.007, 0.007)])
def test_a_hundredth_of_a_pixel_on_the_designation(reference, offset_px):
    sol, target, dl, ref = reference
    _moves_under_tolerance(sol, target, ref, _run(dl, target, offset_px), f"designation + {offset_px}")


def test_one_digital_number_of_intensity_noise(reference):
    """Every image of the downlink gets seeded uniform noise of -1, 0 or +1 DN (a re-quantisation's worth)."""
    sol, target, _, ref = reference
    dl = read_downlink(_sol(sol))
    rng = np.random.default_rng(1)
    for im in dl.images:
        px = im.pixels
        top = np.iinfo(px.dtype).max
        im._pixels = np.clip(px.astype(np.int64) + rng.integers(-1, 2, px.shape), 0, top).astype(px.dtype)
    _moves_under_tolerance(sol, target, ref, _run(dl, target), "1 DN noise")
