"""Issue #14 item 6: deliberately broken downlinks get no confident wrong answer from ``scip``.

Each case breaks the bundled sample sol (``paper`` seed 1, ``s1-straight``, default errors, 3 marked targets)
in memory (``tests/pipeline/broken_downlinks.py``) and runs ``scip`` through the command's own path
(``build_setup`` / ``run_targets``, the packaged trust model, ``--success-px 4``). What each test asserts is
what an operator needs from that break, decided per case (the issue's point: no confident wrong answer):

* **washed-out far navcams** (both eyes exposed 4x too long, the simulator's ``washed_out`` error; and fully
  saturated): the near navcams are intact, so a right answer is possible: a GO must be right (within
  ``SUCCESS_PX``), for ``scip`` and for every far-based candidate;
* **3 deg mast tilt error** (the near, then the far navcam pair's downlinked tilt off by 3 deg): the mast
  prediction is wrong by tens of px (checked), but the registrations and the other navcam can still find the
  target: a GO must be right;
* **a target occluded in the hazcam** (a textured disk on the left hazcam's line of sight to each target, ~40 cm
  or ~5 cm in front of it, hiding it from both hazcam eyes): the target cannot be seen, so no hazcam pixel is a
  right answer (the mark's pixel shows the occluder): every target must be NO-GO, and so must every candidate
  (for the 5 cm occluder this holds only since the session-7 refit: the comment above OCCLUDERS);
* **textureless sand** (no texture on the ground within 10 cm of the flat target, in every navcam and hazcam
  image): appearance cannot place the target inside the patch, geometry alone might: a GO must be right.

The no-error case (GO within 1 px) is in ``test_handoff.py`` (its no-error downlink is computed there once).

Cost: one module-scoped load; every broken copy shares with the others the stereo views (dense stereo) and
the whole cases (registrations) it does not break (``setup_reusing``), so each case pays only for its break.
The bounds do not depend on one fitted model's digits: the GO threshold is the model's own
(``diagnostics["go_min_p"]``) and the success radius the issue's 4 px.
"""

from pathlib import Path

import numpy as np
import pytest

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.handoff import build_setup, marked_targets, run_targets
from tests.pipeline import broken_downlinks as B

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
SUCCESS_PX = 4.0  # the success radius (1 cm at 1 m); p_success is P(error <= this)


@pytest.fixture(scope="module")
def sol():
    """The sample sol and its handoff setup (nothing computed yet: the first case computes what it shares)."""
    dl = read_downlink(SAMPLE)
    return dl, build_setup(dl)


def run_scip(broken, sol) -> tuple:
    """(target id -> ``scip``'s record, the setup) on the broken copy ``broken`` of the sample sol."""
    dl, base = sol
    setup = B.setup_reusing(broken, dl, base)
    recs = run_targets(broken, setup, marked_targets(broken, setup), methods=("scip",), success_px=SUCCESS_PX,
                       downlink_name=SAMPLE.name)
    out = {r.target: r for r in recs}
    assert all(r.method == "scip" and r.truth_uv is not None and r.p_success is not None for r in out.values())
    return out, setup


def candidates(rec) -> list:
    """(sources, error px, p_success, GO) of every candidate answer ``scip`` weighed for ``rec``'s target."""
    go_min = rec.diagnostics["go_min_p"]
    t = np.asarray(rec.truth_uv, float)
    return [(c["sources"], float(np.linalg.norm(np.asarray(c["uv"], float) - t)), c["p_success"],
             c["p_success"] >= go_min) for c in rec.diagnostics["candidates"]]


def describe(rec) -> str:
    cs = sorted(candidates(rec), key=lambda c: -c[2])[:4]
    return (f"{rec.target}: p={rec.p_success:.3f} go={rec.go} err={rec.error_px:.1f} px; top candidates "
            + "; ".join(f"{'+'.join(s)} p={p:.3f} err={e:.1f}" for s, e, p, _ in cs))


def assert_no_wrong_go(rec, sources_like: str = ""):
    """``scip``'s answer, and every candidate whose sources contain ``sources_like``, is NO-GO or right."""
    assert not (rec.go and rec.error_px > SUCCESS_PX), "GO and wrong: " + describe(rec)
    for srcs, err, p, go in candidates(rec):
        if any(sources_like in s for s in srcs):
            assert not (go and err > SUCCESS_PX), (f"candidate {srcs} GO (p={p:.3f}) and {err:.1f} px off; "
                                                   + describe(rec))


# ------------------------------------------------------------------ washed-out far navcams
@pytest.mark.parametrize("factor", [4.0, 1e3], ids=["exposure-x4", "saturated"])
def test_washed_out_far_navcams_give_no_wrong_go(sol, factor):
    """Far navcams washed out (both eyes; x4: the simulator's ``washed_out`` error, ~97 % of the pixels at full
    scale; x1000: every lit pixel at full scale). Asserted: no GO that is wrong, from ``scip`` or from a
    far-based candidate (the near navcams are intact: a right GO is possible, and acceptable)."""
    dl, base = sol
    far = B.pair_of(dl, base.far)
    broken = B.washed_out_copy(dl, far, factor)
    for p in far:
        assert B.saturated_fraction(broken.product(p.product_id)) >= 0.9  # the break is real
    for rec in run_scip(broken, sol)[0].values():
        assert_no_wrong_go(rec, "/far")


# ------------------------------------------------------------------ 3 deg mast error
@pytest.mark.parametrize("navcam", ["near", "far"])
def test_3deg_mast_tilt_error_gives_no_wrong_go(sol, navcam):
    """The ``navcam`` pair's downlinked mast tilt is 3 deg off (its camera models are the head at the wrong
    angle). The mast prediction of that pair is then tens of px off (asserted: the break is real); the
    registrations and the other navcam can still find the target, so a GO is acceptable when right. Asserted:
    no GO that is wrong, from ``scip`` or from any candidate."""
    dl, base = sol
    p = base.near if navcam == "near" else base.far
    broken = B.mast_error_copy(dl, B.pair_of(dl, p), dtilt_rad=3.0 * B.DEG)
    recs, _ = run_scip(broken, sol)
    for rec in recs.values():
        kin = [e for srcs, e, _, _ in candidates(rec) if f"pure-kinematic/{navcam}" in srcs]
        # 3 deg is ~52 mrad: ~10 cm at the targets' 2-3 m from the mast, tens of hazcam px (measured 20-130 px)
        assert kin and kin[0] > 4 * SUCCESS_PX, (navcam, describe(rec))
        assert_no_wrong_go(rec)


# ------------------------------------------------------------------ occluded in the hazcam
# (range fraction of the occluder's centre along the left hazcam's line of sight to the target, its radius m)
FAR_OCCLUDER = (0.6, 0.06)  # ~40 cm in front of targets ~1 m from the hazcams
NEAR_OCCLUDER = (0.95, 0.03)  # ~5 cm in front: hazcam stereo still ranges it close to the target
# With the model fitted on evidence-24dl (before the registration check) this case failed: mesh-registration/far
# answered the mark's pixel (0.5 px, which shows the occluder 5 cm in front of the hidden target) with p 0.905 (GO
# at 0.90), refined-kinematic/far a look-alike 54 px away with p 0.964 (the geometry veto is for scip's own
# answer). With the refit on evidence-20dl-11fam the highest candidate p was 0.834 (t1 mesh-registration/far),
# 0.733 (t2), 0.042 (t3): NO-GO, but with 0.07 of margin. Refits on more tables without shallow occluders moved t1
# back to GO (0.920 / 0.929 on OpenCV 5.0 / 4.14, docs/handoff.md, session 22). The packaged model since session 23
# (four tables, the fourth with pebbles 5-10 cm in front of hidden targets) gives 0.698 / 0.717 (t1), 0.181 / 0.182
# (t2), 0.046 / 0.047 (t3) on the two builds (docs/scripts/broken_occluder_evidence.py): 0.18 of margin. Since
# session 24 (the occlusion evidence: the hazcam's dense stereo in front of the predicted target, the four tables made
# again with it): 0.474 / 0.501 (t1), 0.253 / 0.254 (t2), 0.018 / 0.019 (t3): 0.40 of margin.
OCCLUDERS = [pytest.param(FAR_OCCLUDER, id="occluder-40cm-in-front"),
             pytest.param(NEAR_OCCLUDER, id="occluder-5cm-in-front")]


@pytest.fixture(scope="module")
def occluded(sol):
    """occluder -> (target id -> scip record), each occluder's downlink run once (lazily) for the tests below."""
    dl, base = sol
    ids = [t.id for t in dl.targets]
    runs = {}

    def get(occluder):
        if occluder not in runs:
            range_frac, radius_m = occluder
            for tid in ids:  # the break is real: the disk covers both eyes' lines of sight to the target
                assert B.occluder_miss_m(dl, base.hazcam, tid, range_frac) < 0.8 * radius_m, tid  # 20 % margin
            broken = B.occluded_copy(dl, base.hazcam, ids, radius_m, range_frac, seed=7)
            recs, setup = run_scip(broken, sol)
            haz = setup.cases["near"].haz
            for tid, rec in recs.items():
                # and hazcam stereo at the target's pixel ranges the occluder (closer than the target)
                r_true = float(np.linalg.norm(B.true_point_rover(dl, base.hazcam, tid)
                                              - dl.truth_for(base.hazcam.product_id).camera_model.C))
                X = haz.xyz_at(np.asarray(rec.truth_uv, float)[None])[0]
                if np.all(np.isfinite(X)):
                    assert np.linalg.norm(X - haz.left_model.C) < (1.0 + range_frac) / 2 * r_true, tid
            runs[occluder] = recs
        return runs[occluder]
    return get


@pytest.mark.parametrize("occluder", OCCLUDERS)
def test_target_occluded_in_the_hazcams_is_no_go(occluded, occluder):
    """A textured disk in front of each target (``occluded_copy``), hiding it from both hazcam eyes: the hazcams
    see the occluder where the target would be. No hazcam pixel is a right answer: every target must be NO-GO.
    (With the occluder 5 cm in front, scip's model alone says GO to a look-alike 42-53 px away, p 0.94-0.97: the
    geometry veto, ``ScipParams.geometry_veto_px``, is what says NO-GO there.)"""
    for rec in occluded(occluder).values():
        assert not rec.go, "occluded target GO: " + describe(rec)


@pytest.mark.parametrize("occluder", [
    pytest.param(FAR_OCCLUDER, id="occluder-40cm-in-front"),
    pytest.param(NEAR_OCCLUDER, id="occluder-5cm-in-front"),
])
def test_target_occluded_in_the_hazcams_has_no_go_candidate(occluded, occluder):
    """The same, for every candidate answer (each candidate method's record carries the model's GO)."""
    for rec in occluded(occluder).values():
        assert not any(go for _, _, _, go in candidates(rec)), describe(rec)


# ------------------------------------------------------------------ textureless sand
SAND_RADIUS_M = 0.10


@pytest.fixture(scope="module")
def scene():
    """The simulator's scene of the sample sol (rebuilt from its ``.sim.json``; checked to be the one rendered)."""
    return B.sim_scene(SAMPLE.with_suffix(".sim.json"))


def test_textureless_sand_gives_no_wrong_go(sol, scene):
    """No texture on the ground within 10 cm of the flat target (``kind == "flat"``), in every navcam and hazcam
    image the handoff reads (the same ground patch in each: ray-cast in the rebuilt scene). Appearance cannot
    place the target inside the patch; geometry (the registrations) might, so a GO is acceptable when right.
    Asserted: no GO that is wrong, from ``scip`` or from any candidate, for the flat target and the others."""
    dl, base = sol
    flat = [t.id for t in dl.targets if t.kind == "flat"]
    assert flat
    prods = B.pair_of(dl, base.hazcam) + B.pair_of(dl, base.near) + B.pair_of(dl, base.far)
    for p in prods:
        for tid in flat:
            B.check_scene_matches(scene, dl, p, tid)  # the patch is around the target the images show
    broken = B.textureless_copy(dl, scene, prods, flat, SAND_RADIUS_M, seed=5)
    for rec in run_scip(broken, sol)[0].values():
        assert_no_wrong_go(rec)
