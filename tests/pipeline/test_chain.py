"""Tracking through the stops and the pancam->navcam handoff, on the bundled sample sols (exact marks)."""

from pathlib import Path

import numpy as np
import pytest

from scipctl.core.tracking import track
from scipctl.core.windows import extract_window, scale_window, window_scale_for_handoff
from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import ChainParams, ChainStep, run_chain
from scipctl.pipeline.plane_warp import plane_warped_template
from tests.pipeline.chain_expected import EXPECTED_ERROR_PX  # the measured bounds and how they were measured

ROOT = Path(__file__).resolve().parents[2]
HANDOFF = ChainParams(answer="handoff")  # the chain whose final answer is scip's handoff (the tracking under test)
SAMPLES = [ROOT / "sample_sols/mcap/paper-s1-straight.mcap", ROOT / "sample_sols/mcap/paper-s1-arc.mcap"]


@pytest.fixture(scope="module", params=SAMPLES, ids=lambda p: p.stem)
def dl(request):
    return read_downlink(request.param)


def _handoff_stop(dl):
    pos = [p for p in dl.positions() if dl.images_at(p, "pancam", "left") and dl.images_at(p, "navcam", "left")]
    assert pos, "a stop with both pancam and navcam images"
    return dl.images_at(pos[0], "pancam", "left")[0], dl.images_at(pos[0], "navcam", "left")[0]


def test_pancam_to_navcam_handoff_by_fov_scaling(dl):
    """The paper's handoff: the pancam window shrunk by the IFOV ratio (~1/3) tracks into the navcam image
    to well under a pixel, from a prediction 25 px off."""
    pan, nav = _handoff_stop(dl)
    scale = window_scale_for_handoff(1 / pan.camera_model.hs, 1.0, 1 / nav.camera_model.hs, 1.0)
    # arithmetic on the sols' camera models, no OpenCV in it: measured 0.3414634146341464 (s1-straight) and
    # ...463 (s1-arc), 0.28 / 0.82 mrad to one ulp, the same on OpenCV 5.0 and 4.14, 1 and 2 threads. The range is
    # the docstring's "~1/3" (which cameras, not an error bound): unchanged
    assert 0.3 < scale < 0.37
    n = 0
    for t in dl.targets:
        mp, mn = t.mark_in(pan.product_id), t.mark_in(nav.product_id)
        if mp is None or mn is None:
            continue
        tpl = scale_window(extract_window(pan.pixels_float(), [mp.u, mp.v], int(np.ceil(15 / scale))), scale)
        tr = track(tpl, nav.pixels_float(), [mn.u + 20, mn.v - 15], 60)
        assert tr.ok, (t.id, tr.reason)
        # measured 0.047-0.77 px over the five targets of the two sols, the same on OpenCV 5.0 and 4.14, 1 and 2
        # threads; bound 1 px, the paper's sub-pixel claim (1.3x the worst: s1-arc t1)
        assert np.linalg.norm(tr.uv - [mn.u, mn.v]) < 1.0, (t.id, tr.uv, (mn.u, mn.v))
        n += 1
    assert n >= 2


def test_plane_warped_template_matches_the_next_view(dl):
    """Between two navcam stops, the previous image warped through the local plane at the true target predicts
    the new view: NCC with the real window is high and tracking lands on the mark."""
    navs = sorted((im for im in dl.images if im.camera == "navcam" and im.eye == "left"), key=lambda i: i.time_s)
    a, b = navs[0], navs[1]
    checked = 0
    for t in dl.targets:
        if t.kind not in ("flat", "sand", "contrast"):
            continue
        ma, mb = t.mark_in(a.product_id), t.mark_in(b.product_id)
        tt = dl.truth_target(t.id)
        ta, tb = dl.truth_for(a.product_id), dl.truth_for(b.product_id)
        if None in (ma, mb, tt, ta, tb):
            continue
        # true poses and true models, so that only the warp (a local plane) is under test
        a2 = type(a)(**{**a.__dict__, "pose": ta.pose, "camera_model": ta.camera_model})
        b2 = type(b)(**{**b.__dict__, "pose": tb.pose, "camera_model": tb.camera_model})
        X = np.asarray(tt.xyz_site_m)
        n_site = ta.pose.T_site_rover.rotate([0.0, 0.0, -1.0])  # flat ground: up
        tpl, tc = plane_warped_template(a2, b2, X, n_site, [mb.u, mb.v], 15)
        assert tpl is not None
        tr = track(tpl, b.pixels_float(), [mb.u + 10, mb.v + 10], 30, template_center_uv=tc, min_score=0.5)
        assert tr.ok, (t.id, tr.reason)
        # measured 0.50-0.59 px over the three targets checked, the same on OpenCV 5.0 and 4.14, 1 and 2 threads;
        # bound 1 px (1.7x the worst)
        assert np.linalg.norm(tr.uv - [mb.u, mb.v]) < 1.0, (t.id, tr.uv, (mb.u, mb.v), tr.score)
        checked += 1
    if checked == 0:
        pytest.skip("no flat/sand/contrast target marked in two navcam stops")


@pytest.fixture(scope="module")
def chains(dl):
    """The handoff path's chain (``ChainParams(answer="handoff")``: the final answer is scip's handoff of the chain's
    navcam pixel, as EXPECTED_ERROR_PX was measured) for each target of EXPECTED_ERROR_PX in this sol (computed
    once: a few s each). The default answer (the closure) is tested against it below."""
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    out = {}
    for tid in EXPECTED_ERROR_PX[_stem(dl)]:
        mk = dl.target(tid).mark_in(start.product_id)
        out[tid] = run_chain(dl, start, [mk.u, mk.v], target_id=tid, params=HANDOFF)
    return out


def _stem(dl):
    return Path(dl.source).stem


def test_chain_records_every_stop_against_the_marks(dl, chains):
    tid = next(iter(chains))
    steps = chains[tid]
    assert steps[0].kind == "designate" and steps[0].error_px == pytest.approx(0.0, abs=1e-9)
    assert steps[0].range_m is not None and 5.0 < steps[0].range_m < 15.0
    assert steps[0].error_3d_m is not None
    cams = [s.camera for s in steps]
    assert "pancam" in cams and "navcam" in cams
    assert any(s.kind == "handoff" and s.camera == "navcam" for s in steps)
    for s in steps:
        if s.tracked_uv is not None and s.mark_uv is not None:
            assert s.error_px == pytest.approx(np.hypot(s.tracked_uv[0] - s.mark_uv[0], s.tracked_uv[1] - s.mark_uv[1]))
    # time order of the stops
    times = [dl.product(s.product_id).time_s for s in steps]
    assert times == sorted(times)


def test_a_feature_step_records_which_candidate_won(chains):
    """A feature-guided step's ``feature_reach`` is the winning candidate's reach (one of ChainParams.feature_candidates',
    or 0 for the visual-odometry candidate, then ``feature_vo`` True): what the records say of how it was found."""
    reaches = {c[0] for c in HANDOFF.feature_candidates} | {0.0}
    seen = 0
    for steps in chains.values():
        for s in steps:
            if s.extra.get("feature_status") in ("confirmed", "unconfirmed"):
                assert s.extra["feature_reach"] in reaches, (s.product_id, s.extra["feature_reach"])
                if "feature_vo" in s.extra:
                    assert s.extra["feature_vo"] == (s.extra["feature_reach"] == 0.0)
                seen += 1
    assert seen > 0


def test_chain_steps_read_back_from_json(chains):
    """Every step of a real chain, written as the commands write JSON and read back, is the same record."""
    import json

    from scipctl.io.workspace import dumps

    steps = [s for ss in chains.values() for s in ss]
    text = dumps([s.to_dict() for s in steps])
    back = [ChainStep.from_dict(d, "handoff.json", i) for i, d in enumerate(json.loads(text))]
    assert dumps([b.to_dict() for b in back]) == text
    assert [(b.position, b.product_id, b.tracked_uv, b.error_px, b.p_success, b.go, b.advice) for b in back] == \
        [(tuple(s.position), s.product_id, s.tracked_uv, s.error_px, s.p_success, s.go, s.advice) for s in steps]


def test_every_step_has_p_success_and_go(dl, chains):
    """The designation has what ``scipctl designate`` says of the same pixel (the packaged designation model's p_ok
    and GO, from the same point stereo); every tracking step has the step model's probability
    and GO; the hazcam handoff's is scip's times its input navcam step's (scip's own kept), GO when both are;
    every NO-GO step says what to do."""
    from scipctl.io.trust_model import PACKAGED_DESIGNATION, load_packaged_trust_model
    from scipctl.pipeline.chain_trust import ADVICE, chain_verdict, handoff_input
    from scipctl.pipeline.designate import designate

    model = load_packaged_trust_model(PACKAGED_DESIGNATION)
    for tid, steps in chains.items():
        d = designate(dl, dl.product(steps[0].product_id), steps[0].tracked_uv, tid, with_normal=False, trust=model)
        assert steps[0].kind == "designate" and d.p_ok is not None
        assert (steps[0].p_success, steps[0].go) == (d.p_ok, d.go), tid  # the same evidence, the same model
        assert steps[0].extra["designation"]["tolerance_pct"] == d.ok_tolerance_pct
        assert (steps[0].advice is None) == steps[0].go
        for s in steps[1:]:
            assert isinstance(s.go, bool)
            assert s.p_success is not None and 0.0 <= s.p_success <= 1.0, (tid, s.product_id)
            assert (s.advice is None) == s.go and (s.go or s.advice in ADVICE), (tid, s.product_id, s.advice)
        haz = steps[-1]
        assert haz.camera == "hazcam" and haz.extra["method"] == "scip"
        assert haz.extra["scip_go"] == (haz.extra["scip_p_success"] >= haz.extra["go_min_p"])
        src = handoff_input(steps, len(steps) - 1)
        assert src is not None and src.camera == "navcam" and haz.extra["navcam_p_success"] == src.p_success
        assert haz.p_success == haz.extra["scip_p_success"] * src.p_success
        assert haz.go == (haz.extra["scip_go"] and src.go)
        v = chain_verdict(steps)
        assert v.go == all(s.go for s in steps)


def test_a_blank_navcam_image_makes_its_step_nogo_with_advice():
    """Forced failure (paper-s1-straight t2, every track confirmed as it is): the navcam image at the middle stop
    replaced by a flat grey one (nothing to track). That step is NO-GO and says take a new image at this stop; the
    chain is NO-GO from that step on."""
    import dataclasses

    from scipctl.pipeline.chain_trust import NEW_IMAGE, chain_verdict

    dl = read_downlink(SAMPLES[0])
    navs = sorted((im for im in dl.images if im.camera == "navcam" and im.eye == "left"), key=lambda i: i.time_s)
    mid = navs[1]  # navcams at 4.5 m (the handoff), ~3 m (this one), ~1.7 m
    flat = np.full_like(mid.pixels, int(np.median(mid.pixels)))
    blank = dataclasses.replace(mid, _pixels=flat)
    dl2 = dataclasses.replace(dl, images=[blank if im is mid else im for im in dl.images])
    start = min((im for im in dl2.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    tid = "t2"
    mk = dl2.target(tid).mark_in(start.product_id)
    steps = run_chain(dl2, start, [mk.u, mk.v], target_id=tid, params=HANDOFF)  # the answer through that step
    (i,) = [k for k, s in enumerate(steps) if s.product_id == mid.product_id]
    assert not steps[i].go and steps[i].advice == NEW_IMAGE, (steps[i].p_success, steps[i].reason)
    v = chain_verdict(steps)
    assert not v.go and v.step is not None and v.step <= i


def test_an_unverified_navcam_at_the_hazcam_stop_hands_off_from_the_earlier_navcam():
    """Forced failure (paper-s1-straight t2): the navcam image at the hazcam stop replaced by a flat grey one. Its
    track cannot be verified, so it is not handed off from; scip hands off from the chain's last verified navcam
    pixel (the ~3 m stop) alone: the same answer as scip given that pixel as its far mark and no near one. (It
    hands on that pixel's error: measured 4.1 px from the hazcam mark, the 3 m track being 2.4 navcam px off.)
    The chain stays NO-GO at or before the failed step."""
    import dataclasses

    from scipctl.pipeline.chain_trust import chain_verdict

    dl = read_downlink(SAMPLES[0])
    navs = sorted((im for im in dl.images if im.camera == "navcam" and im.eye == "left"), key=lambda i: i.time_s)
    near = navs[-1]
    flat = np.full_like(near.pixels, int(np.median(near.pixels)))
    blank = dataclasses.replace(near, _pixels=flat)
    dl2 = dataclasses.replace(dl, images=[blank if im is near else im for im in dl.images])
    start = min((im for im in dl2.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl2.target("t2").mark_in(start.product_id)
    steps = run_chain(dl2, start, [mk.u, mk.v], target_id="t2", params=HANDOFF)
    (i,) = [k for k, s in enumerate(steps) if s.product_id == near.product_id]
    assert not steps[i].ok and not steps[i].go
    haz = steps[-1]
    assert haz.camera == "hazcam" and haz.kind == "handoff" and haz.extra["final"]
    assert haz.extra["navcam"] == "far" and haz.extra["reference"] == navs[-2].product_id
    far = steps[[k for k, s in enumerate(steps) if s.product_id == navs[-2].product_id][0]]
    from scipctl.core.handoff.scip import SCIP
    from scipctl.pipeline.handoff import build_setup, run_targets

    setup = build_setup(dl2, hazcam=haz.product_id, far=far.product_id)
    (rec,) = run_targets(dl2, setup, [("t2", {"near": None, "far": far.tracked_uv}, None)], methods=[SCIP],
                         navcams=tuple(setup.cases), only=set())
    # the registration's Open3D ICP differs between runs by ~1e-15 relative (docs/campaign.md): 1e-9 px
    assert np.allclose(haz.tracked_uv, rec.predicted_uv, rtol=0, atol=1e-9)
    assert haz.extra["scip_p_success"] == pytest.approx(rec.p_success, abs=1e-9) and haz.extra["scip_go"] == rec.go
    # the chain's answer carries its input's trust too: the far pixel's step probability
    assert haz.p_success == pytest.approx(rec.p_success * far.p_success, abs=1e-9)
    v = chain_verdict(steps)
    assert not v.go and v.step is not None and v.step <= i


@pytest.mark.parametrize("change, field, why", [
    ({"position": [1]}, "steps[3].position", "expected [site, drive]"),
    ({"tracked_uv": [1.0, None]}, "steps[3].tracked_uv", "expected 2 finite numbers"),
    ({"ok": None}, "steps[3].ok", "missing"),
    ({"error_px": "1.2"}, "steps[3].error_px", "expected a finite number"),
    ({"kind": 3}, "steps[3].kind", "expected a string"),
    ({"go": "yes"}, "steps[3].go", "expected true or false"),
    ({"p_success": "0.9"}, "steps[3].p_success", "expected a finite number"),
    ({"advice": 1}, "steps[3].advice", "expected a string"),
])
def test_a_bad_chain_step_field_is_named(change, field, why):
    from scipctl.model import InputError

    good = ChainStep((1, 2), "navcam", "p", "track", None, [1.0, 2.0], None, None, 0.9, 3.0, None, None, None,
                     True, p_success=0.25, go=False, advice="new image at this stop").to_dict()
    assert ChainStep.from_dict(good).to_dict() == good
    # a record written before steps were scored reads back unscored and NO-GO
    old = {k: v for k, v in good.items() if k not in ("p_success", "go", "advice")}
    back = ChainStep.from_dict(old)
    assert back.p_success is None and back.go is False and back.advice is None
    with pytest.raises(InputError) as e:
        ChainStep.from_dict(dict(good, **change), "chains.json", 3)
    assert str(e.value).startswith(f"chains.json: {field}: ") and why in str(e.value), str(e.value)


def test_chain_lands_on_the_marks_at_every_stop(dl, chains):
    """Tracked pixels within the measured few px of the marks at each stop (pose estimates 4-14 deg off in yaw:
    the predictions are hundreds of pancam pixels away), and each track says which path found it."""
    expected = EXPECTED_ERROR_PX[_stem(dl)]
    for tid, steps in chains.items():
        kinds = [(s.camera, s.kind) for s in steps[1:]]
        assert kinds == [("pancam", "track"), ("navcam", "handoff"), ("navcam", "track"), ("navcam", "track"),
                         ("hazcam", "handoff")], (tid, kinds)
        for s, bound in zip(steps[1:], expected[tid]):
            if bound is None:
                continue
            assert s.error_px is not None and s.error_px <= bound, (tid, s.product_id, s.error_px, bound, s.reason)
        for s, bound in zip(steps[1:5], expected[tid]):
            if bound is None or (s.kind == "handoff" and s.extra.get("template") == "scale"):
                continue  # the flagged step; the paper's IFOV-scaled handoff at the same stop
            assert s.extra["template"] == "plane, feature-guided", (tid, s.product_id, s.extra)
            assert s.extra["feature_status"] in ("confirmed", "unconfirmed")
            assert s.extra["feature_inliers"] >= 6
        # a confirmed track: NCC refined the feature match within the confirmation radius, and the answer pools the
        # confirmed candidates within ChainParams.feature_agree_px of the best one
        for s in steps[1:5]:
            if s.extra.get("feature_status") == "confirmed":
                assert np.linalg.norm(np.subtract(s.extra["ncc_uv"], s.extra["coarse_uv"])) <= ChainParams().feature_confirm_px
                assert np.linalg.norm(np.subtract(s.tracked_uv, s.extra["ncc_uv"])) <= ChainParams().feature_agree_px
                assert s.extra["feature_pooled"] >= 1


def test_chain_flags_a_track_it_cannot_verify(dl, chains):
    """No answer more than 10 px off is handed on as trusted without a word: it is flagged (``ok`` False), or it
    follows an unverified step and says so. In s1-straight t1 (flat sand at 10 m) no feature model is found at the
    4.5 m pancam stop; the NCC-only answer is 21 px off and is reported as unverified, and the navcam at that stop
    is handed off from the 10 m image instead, through the features. In s1-arc t1 the 4.5 m pancam position comes
    from the feature match alone (NCC confirms nothing within 8 px): flagged, not used as the next reference."""
    for tid, steps in chains.items():
        for s in steps[1:]:
            if s.error_px is not None and s.error_px > 10.0:
                assert (not s.ok and s.reason) or s.extra.get("follows_unverified"), (tid, s.product_id, s.error_px)
        first_flag = next((i for i, s in enumerate(steps) if s.extra.get("unverified")), None)
        for i, s in enumerate(steps[1:], 1):
            after = first_flag is not None and i > first_flag
            assert bool(s.extra.get("follows_unverified")) == after, (tid, s.product_id)
            if after:
                assert "follows the unverified step" in s.reason
    if _stem(dl) == "paper-s1-straight":
        steps = chains["t1"]
        pan = steps[1]
        assert pan.camera == "pancam" and not pan.ok
        assert "unverified" in pan.reason and pan.extra["feature_status"] == "failed"
        assert pan.error_px > 10.0  # it was right to distrust it
        hand = steps[2]
        assert hand.camera == "navcam" and hand.kind == "handoff"
        assert hand.extra["template"] == "plane, feature-guided"  # from the 10 m pancam image, across the drive
        assert hand.extra["reference"] == steps[0].product_id
        # the same step as chain_expected.EXPECTED_ERROR_PX["paper-s1-straight"]["t1"][1]: measured 0.12-0.33 px on
        # OpenCV 5.0.0 and 0.08-0.25 px on 4.14.0 over four runs each (a thread count changes no bit:
        # test_chain_stability.py); that table's 0.5 px is the tight bound, this one only says it is on the mark
        assert hand.ok and hand.error_px < 1.0
    else:
        pan = chains["t1"][1]
        assert pan.camera == "pancam" and not pan.ok and pan.extra["feature_status"] == "unconfirmed"
        assert "weak match" in pan.reason
        assert chains["t1"][2].extra["reference"] == chains["t1"][0].product_id


def test_chain_rejects_a_bad_template_mode(dl):
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    with pytest.raises(ValueError):
        run_chain(dl, start, [500.0, 500.0], template_mode="affine")


TRAVERSE = ROOT / "tests/data/chain/traverse-s1-straight-half.mcap"  # see tests/data/README.md


@pytest.fixture(scope="module")
def traverse_t1():
    """The whole chain on the simulator's traverse (16 stops, 10 m -> hazcams at 1 m; half-size images) for the
    flat target t1, from its mark in the first pancam image; the handoff path (its bounds were measured on it)."""
    dl = read_downlink(TRAVERSE)
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target("t1").mark_in(start.product_id)
    return dl, run_chain(dl, start, [mk.u, mk.v], target_id="t1", params=HANDOFF)


def test_traverse_chain_follows_the_target_through_every_stop(traverse_t1):
    """Every stop is visited and every tracked pixel (half-size images) stays near the mark. The bounds are the
    largest errors over four runs (as they are, designation +(0.01, 0) and (-0.007, +0.007) px, +-1 DN seeded
    noise; OpenCV 5.0.0), times 1.25, rounded up to 0.5 px: pancam tracks and handoff 0.15-1.49 px -> 2.0 px; navcam
    tracks 0.54-6.90 px -> 9.0 px. The navcam error grows stop by stop on this target (4.39-6.90 px at the last
    when the bound was set; 6.47-7.21 px over the same four runs on OpenCV 5.0 and 4.14 in session 37, so 9.0 px is
    now 1.25x the worst, the margin the rule above gives):
    a drift of about -0.4 px per stop in v that the stereo midpoint's offset partly cancelled before the chain
    kept its estimate on the tracked ray (0.55-3.52 px then; docs/stereo-and-tracking.md, "The drift's cause")."""
    dl, steps = traverse_t1
    tracked = [s for s in steps if s.camera in ("pancam", "navcam")]
    visited = {s.position for s in steps}
    assert visited == set(dl.positions())  # no stop skipped
    kinds = [(s.camera, s.kind) for s in tracked]
    assert kinds.count(("navcam", "handoff")) == 1
    assert kinds.count(("pancam", "track")) == 5 and kinds.count(("navcam", "track")) == 10
    bound_px = {"pancam": 2.0, "navcam": 9.0}
    for s in tracked:
        bound = 2.0 if s.kind == "handoff" else bound_px[s.camera]
        assert s.error_px is not None and s.error_px <= bound, (s.position, s.camera, s.kind, s.error_px)


def test_traverse_chain_hands_off_at_every_hazcam_stop(traverse_t1):
    """A navcam->hazcam handoff at each of the 5 hazcam stops; the last one (the arm's) is marked final. Its error
    bounds are the largest over the four runs of the test above, times 1.25: 3.19-5.27 px -> 7.0 px (rounded up to
    0.5 px) and, for the hazcam stereo point at the answer against the truth, 10.8-18.5 mm -> 24 mm (rounded up to
    1 mm). This target is one the change to the ray made worse (2.57 px, 8.4 mm before, one run), and it misses the
    4 px goal in one of the four runs; over 23 traverse chains of five seeds the change was neutral
    (docs/stereo-and-tracking.md, "The drift's cause"). The stereo point's error is not the handoff's alone:
    0.76 px at the first hazcam stop came with 15 mm."""
    dl, steps = traverse_t1
    haz = [s for s in steps if s.camera == "hazcam"]
    haz_positions = {p for p in dl.positions() if dl.images_at(p, "hazcam", "left")}
    assert {s.position for s in haz} == haz_positions and len(haz) == 5
    assert [s.extra["final"] for s in haz] == [False] * 4 + [True]
    assert steps[-1] is haz[-1]
    assert all(s.error_px is not None for s in haz)
    assert haz[-1].error_px <= 7.0
    assert haz[-1].error_3d_m is not None and haz[-1].error_3d_m < 0.024


def test_traverse_chain_3d_estimate_improves_as_the_rover_approaches(traverse_t1):
    """Stereo at each tracked pixel: the 3-D error (true rover frame) shrinks with range — from 0.29 m at 9.3 m
    (pancam designation) to 4 cm at 1.6 m (last navcam stop), measured (the bounds' comments)."""
    _, steps = traverse_t1
    nav = [s for s in steps if s.camera == "navcam" and s.error_3d_m is not None]
    first = steps[0]
    assert first.error_3d_m is not None and first.range_m > 9.0
    assert nav[-1].range_m < 2.0
    # the four runs of chain_perturb.py (as it is, designation +(0.01, 0) and (-0.007, +0.007) px, +-1 DN seeded
    # noise) on this traverse: 41.4-43.5 mm on OpenCV 4.14 (one thread), 42.2-43.6 mm on 5.0; as it is, the same at 1
    # and 2 threads on both. The docstring's earlier "3 cm" predates the navcam drift of the test above (6.5-7.2 px at
    # this stop in these runs, ~2.7 mm/px across the ray at 1.6 m). Bound 5 cm: only 1.15x the worst, unchanged (not
    # widened; no error model of the drift to set it from)
    assert nav[-1].error_3d_m < 0.05
    # first / last: measured 6.58-7.05 over the same eight runs; bound 5 (1.3x), unchanged
    assert nav[-1].error_3d_m < first.error_3d_m / 5


@pytest.fixture(scope="module")
def closures(dl, chains):
    """The closure check of each chain of the sol (off in run_chain by default: computed here, ~2-3 s each)."""
    from scipctl.pipeline.chain_closure import closure_check

    return {tid: closure_check(dl, steps, ChainParams()).to_dict() for tid, steps in chains.items()}


def test_the_closure_refinds_the_final_answer_from_the_pancam_track(dl, chains, closures):
    """The closure check (pipeline/chain_closure.py) starts from the last trusted pancam track when there is one
    (else the navcam handoff at the imaging stop, else 'no reference'); a closure confirmed from a pancam track lands
    within the success radius (4 hazcam px, the 1 cm goal at the hazcam's range) of the target's mark, as the chain's
    own answer must (measured: s1-straight t2, 1.5-1.8 px). From a navcam handoff it carries that coarser step's own
    error (s1-arc t1: 5.8 px), which is why the chain prefers the pancam track."""
    from scipctl.pipeline.chain_closure import closure_reference

    confirmed = 0
    for tid, steps in chains.items():
        assert "closure" not in steps[-1].extra  # off by default (ChainParams.closure)
        final = next(i for i, s in enumerate(steps) if s.camera == "hazcam" and s.extra.get("final"))
        c = closures[tid]
        ref = closure_reference(steps, final)
        if ref is None:
            assert c["status"] == "no reference" and c["uv"] is None, (tid, c)
            continue
        assert c["reference_step"] == ref and c["reference"] == steps[ref].product_id
        assert (steps[ref].camera, steps[ref].kind) in (("pancam", "track"), ("navcam", "handoff")) and steps[ref].ok
        assert c["status"] in ("confirmed", "unconfirmed", "failed"), (tid, c)
        if c["status"] != "confirmed":
            continue  # measured: s1-straight t1, from the navcam handoff (its pancam track is flagged)
        confirmed += 1
        mark = steps[final].mark_uv
        if steps[ref].camera == "pancam":
            assert np.hypot(c["uv"][0] - mark[0], c["uv"][1] - mark[1]) <= 4.0, (tid, c, mark)
        assert c["closure_px"] == pytest.approx(np.hypot(c["uv"][0] - steps[final].tracked_uv[0],
                                                         c["uv"][1] - steps[final].tracked_uv[1]), abs=1e-9)
    assert confirmed >= 1  # s1-straight t2 (from its 4.5 m pancam track), s1-arc t1 (from the navcam handoff)


def test_the_closure_does_not_depend_on_the_answer_it_checks(dl, chains, closures):
    """The closure's pixel comes from the reference image and the hazcam image alone: moving the chain's final
    answer by 10 px leaves it where it was (bit for bit) and its distance to the answer is then exactly the
    distance to the moved answer, so a drifted answer shows as a closure of about the drift."""
    import copy

    from scipctl.pipeline.chain_closure import closure_check

    found = [t for t, c in closures.items() if c["status"] == "confirmed"]
    if not found:
        pytest.skip(f"no confirmed closure in {_stem(dl)}")
    tid = found[0]
    moved = copy.deepcopy(chains[tid])
    fin = moved[-1]
    assert fin.extra.get("final")
    fin.tracked_uv = [fin.tracked_uv[0] + 6.0, fin.tracked_uv[1] - 8.0]
    c = closure_check(dl, moved, ChainParams()).to_dict()
    assert c["uv"] == closures[tid]["uv"]
    assert c["closure_px"] == pytest.approx(np.hypot(c["uv"][0] - fin.tracked_uv[0], c["uv"][1] - fin.tracked_uv[1]),
                                            abs=1e-12)
    assert c["closure_px"] >= 10.0 - closures[tid]["closure_px"]  # the triangle inequality


def test_run_chain_records_the_closure_when_asked(dl, closures):
    """ChainParams(closure=True): the final hazcam step carries the same closure the check gives afterwards."""
    if _stem(dl) != "paper-s1-straight":
        pytest.skip("one sol is enough (a whole chain, ~10 s)")
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target("t2").mark_in(start.product_id)
    steps = run_chain(dl, start, [mk.u, mk.v], target_id="t2", params=ChainParams(closure=True, answer="handoff"))
    got = dict(steps[-1].extra["closure"])
    want = dict(closures["t2"])
    # the hazcam answer carries Open3D's ICP run-to-run rounding (test_chain_stability.py): closure_px within 1e-9
    assert got.pop("closure_px") == pytest.approx(want.pop("closure_px"), abs=1e-9)
    assert got == want


def test_run_chain_answers_with_a_confirmed_closure(dl, chains, closures):
    """The default answer (ChainParams.answer "closure"): a confirmed closure becomes the final answer (its pixel bit
    for bit, the error against the mark, the handoff's own answer kept under extra["handoff"], p_success and GO
    from the packaged closure model on that closure's evidence); an unconfirmed one leaves the handoff's answer.
    The final answer is within its measured bound (EXPECTED_FINAL_PX)."""
    from scipctl.io.closure_trust_model import load_packaged_closure_trust_model
    from scipctl.pipeline.chain_closure import closure_evidence
    from tests.pipeline.chain_expected import EXPECTED_FINAL_PX

    model = load_packaged_closure_trust_model()
    assert model is not None
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    for tid, bound in EXPECTED_FINAL_PX[_stem(dl)].items():
        mk = dl.target(tid).mark_in(start.product_id)
        steps = run_chain(dl, start, [mk.u, mk.v], target_id=tid)
        fin, base = steps[-1], chains[tid][-1]
        assert fin.extra["final"] and len(steps) == len(chains[tid])
        c = closures[tid]
        assert fin.error_px <= bound, (tid, fin.error_px)
        if c["status"] == "confirmed":
            assert fin.extra["answer"] == "closure" and fin.tracked_uv == c["uv"]
            # the handoff's answer carries Open3D's ICP run-to-run rounding (test_chain_stability.py)
            assert fin.extra["handoff"]["uv"] == pytest.approx(base.tracked_uv, abs=1e-6)
            assert fin.error_px == pytest.approx(np.hypot(*(np.subtract(c["uv"], fin.mark_uv))), abs=1e-12)
            assert fin.p_success == model.probability([closure_evidence(steps, fin.extra["closure"])])[0]
            assert fin.go == (fin.ok and fin.p_success >= model.go_min_p) and fin.extra["go_min_p"] == model.go_min_p
            assert fin.extra["handoff"]["go_min_p"] == base.extra["go_min_p"]
            if steps[c["reference_step"]].camera == "pancam":
                assert fin.error_px <= 4.0  # from the pancam track: the bound of the closure test above
        else:
            assert fin.extra["answer"] == "handoff" and "handoff" not in fin.extra
            assert fin.tracked_uv == pytest.approx(base.tracked_uv, abs=1e-6)
            assert fin.p_success == pytest.approx(base.p_success, abs=1e-6)


def test_a_closure_farther_from_the_designation_than_the_model_saw_is_never_go(dl):
    """ChainParams.closure_go_max_drives: the closure model was fitted on paper approaches, whose reference is at
    most two drives from the designation; a reference farther away is never GO (on traverse-shaped approaches 2 of
    10 GO chains were wrong, one 20 px off at p 0.95). This sol's closures (their reference one or two drives away)
    are inside the default limit; with the limit lowered to 0 they fall outside it. The packaged closure model with
    its GO threshold at 1e-9 makes every stereo-backed closure GO, so that the rule is what decides: NO-GO with the
    reason and advice, the answer and its p unchanged, the chain NO-GO."""
    import dataclasses

    from scipctl.io.closure_trust_model import load_packaged_closure_trust_model
    from scipctl.pipeline.chain import reference_drives
    from scipctl.pipeline.chain_trust import chain_verdict
    from tests.pipeline.chain_expected import EXPECTED_FINAL_PX

    always = dataclasses.replace(load_packaged_closure_trust_model(), go_min_p=1e-9)
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    seen = 0
    for tid in EXPECTED_FINAL_PX[_stem(dl)]:
        mk = dl.target(tid).mark_in(start.product_id)
        steps = run_chain(dl, start, [mk.u, mk.v], target_id=tid, closure_model=always)
        fin = steps[-1]
        if fin.extra.get("answer") != "closure" or not fin.ok:
            continue
        assert reference_drives(steps, fin.extra["closure"]["reference_step"]) in (1, 2)  # the paper's approach
        assert fin.go and "drives from the designation" not in fin.reason
        low = run_chain(dl, start, [mk.u, mk.v], target_id=tid, closure_model=always,
                        params=ChainParams(closure_go_max_drives=0))
        f0 = low[-1]
        assert f0.extra["answer"] == "closure" and f0.tracked_uv == fin.tracked_uv and f0.p_success == fin.p_success
        assert not f0.go and f0.advice is not None and "drives from the designation" in f0.reason
        assert not chain_verdict(low).go
        seen += 1
    assert seen >= 1


def test_reference_drives_counts_the_stops_between():
    from scipctl.pipeline.chain import ChainStep, reference_drives

    def st(pos):
        return ChainStep(tuple(pos), "pancam", "p", "track", None, None, None, None, None, None, None, None, None,
                         True)

    steps = [st((1, 0)), st((1, 1)), st((1, 1)), st((1, 2)), st((1, 3))]  # a track and a handoff at one stop
    assert [reference_drives(steps, i) for i in range(5)] == [0, 1, 1, 2, 3]
    assert reference_drives(steps, None) is None and reference_drives(steps, 5) is None


def test_closure_go_needs_stereo_the_threshold_and_a_near_reference():
    """The closure's GO rule (one function for the chain and the rescoring scripts): each condition alone turns it
    down, and only the drives rule says why (the other two are the step's own reason and p)."""
    from scipctl.pipeline.chain import ChainStep, closure_go

    def st(pos):
        return ChainStep(tuple(pos), "pancam", "p", "track", None, None, None, None, None, None, None, None, None,
                         True)

    steps = [st((1, 0)), st((1, 1)), st((1, 2)), st((1, 3))]  # the references at 0, 1, 2, 3 drives
    assert closure_go(True, 0.98, 0.97, steps, 1, 1) == (True, "")
    assert closure_go(True, 0.97, 0.97, steps, 1, 1) == (True, "")  # the threshold itself is GO
    assert closure_go(False, 0.99, 0.97, steps, 1, 1) == (False, "")  # no point stereo at the closure's pixel
    assert closure_go(True, 0.969, 0.97, steps, 1, 1) == (False, "")
    go, note = closure_go(True, 0.99, 0.97, steps, 2, 1)
    assert not go and "2 drives" in note and "beyond the closure model's 1" in note
    go, note = closure_go(True, 0.99, 0.97, steps, None, 3)  # no reference step: never GO
    assert not go and "None drives" in note


def test_chain_params_refuse_an_unknown_answer():
    with pytest.raises(ValueError, match="ChainParams.answer"):
        ChainParams(answer="scip").check()
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="closure_go_max_drives"):
            ChainParams(closure_go_max_drives=bad).check()


@pytest.mark.parametrize("kw, match", [
    ({"ncc_median_prev_px": 0}, "ncc_median_prev_px"), ({"ncc_median_prev_px": float("nan")}, "ncc_median_prev_px"),
    ({"ncc_median_prev_px": True}, "ncc_median_prev_px"), ({"ncc_median_find": True}, "needs ncc_median_prev_px"),
    ({"ncc_median_prev_px": 3, "ncc_median_find": 1}, "ncc_median_find"),
    ({"ncc_median_prev_px": 3, "ncc_matched_blur": True}, "one filter"),
])
def test_chain_params_refuse_an_ncc_median_that_cannot_run(kw, match):
    with pytest.raises(ValueError, match=match):
        ChainParams(**kw).check()
    assert ChainParams(ncc_median_prev_px=3, ncc_median_find=True, ncc_place_flow=()).check()


@pytest.mark.parametrize("bad", [2, -1, 3.0, True])
def test_chain_params_refuse_a_median_that_is_not_an_odd_size(bad):
    with pytest.raises(ValueError, match="ChainParams.feature_median_px"):
        ChainParams(feature_median_px=bad).check()
    assert ChainParams(feature_median_px=0).check() and ChainParams(feature_median_px=5).check()


def test_a_feature_cache_shared_by_the_chains_of_a_downlink_changes_no_answer(dl, chains):
    """run_marked_chains shares the feature step's keypoints between the chains of one downlink (each image's,
    by its exact downsampling): the second chain gets the same keypoints it would compute, so the same pixels, bit
    for bit at every tracking step (the hazcam step within the ICP rounding of test_chain_stability.py)."""
    if _stem(dl) != "paper-s1-straight":
        pytest.skip("one sol is enough (two whole chains, ~10 s)")
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    cache = {}
    for tid in ("t1", "t2"):
        mk = dl.target(tid).mark_in(start.product_id)
        steps = run_chain(dl, start, [mk.u, mk.v], target_id=tid, params=HANDOFF, feature_cache=cache)
    # keyed by the exact downsampling and the median filter
    assert any(pid.startswith("s1-straight") and ds == 1.0 and med == HANDOFF.feature_median_px for pid, ds, med in cache)
    alone = chains["t2"]
    assert [s.product_id for s in steps] == [s.product_id for s in alone]
    for s, a in zip(steps, alone):
        if s.camera == "hazcam":
            assert np.allclose(s.tracked_uv, a.tracked_uv, rtol=0, atol=1e-9)
        else:
            assert s.tracked_uv == a.tracked_uv and s.extra == a.extra, s.product_id


@pytest.mark.parametrize("field, bad", [("relief_max_parallax_px", 0.0), ("relief_max_parallax_px", -1.0),
                                        ("relief_max_parallax_px", True), ("relief_disparity_error_px", -0.1),
                                        ("relief_disparity_error_px", float("nan")), ("relief_min_kept", 1.5)])
def test_chain_params_refuse_bad_relief_settings(field, bad):
    with pytest.raises(ValueError, match=f"ChainParams.{field}"):
        ChainParams(**{field: bad}).check()
    assert ChainParams(relief_max_parallax_px=None).check()


@pytest.mark.parametrize("bad", ["yes", 1, None])
def test_chain_params_refuse_a_template_surface_that_is_not_a_flag(bad):
    with pytest.raises(ValueError, match="ChainParams.template_surface"):
        ChainParams(template_surface=bad).check()
    assert ChainParams(template_surface=True).check()


@pytest.mark.parametrize("field, bad", [("template_surface_gate_px", -0.1), ("template_surface_gate_px", float("nan")),
                                        ("template_surface_gate_px", True), ("template_surface_gate_px", "0.45"),
                                        ("template_surface_level", 1), ("template_surface_level", None)])
def test_chain_params_refuse_bad_surface_template_settings(field, bad):
    with pytest.raises(ValueError, match=f"ChainParams.{field}"):
        ChainParams(**{field: bad}).check()
    assert ChainParams(template_surface_gate_px=None, template_surface_level=False).check()
    assert ChainParams(template_surface_gate_px=0.0).check()


def test_the_relief_mask_is_an_option_that_changes_only_the_tracking_steps(dl, chains):
    """ChainParams.relief_max_parallax_px (off by default: every template pixel counts, and nothing is recorded):
    set, each feature-guided tracking step records the part of its winning template the relief mask kept
    (core/relief_mask.py) and whether it was applied (not below ChainParams.relief_min_kept, nor when it keeps every
    pixel); the designation is untouched and the steps stay within the chain's measured bounds' reach (the same
    steps found, none lost)."""
    if _stem(dl) != "paper-s1-straight":
        pytest.skip("one sol is enough (a whole chain, ~10 s)")
    assert ChainParams().relief_max_parallax_px is None
    base = chains["t1"]
    assert all(s.extra.get("relief_kept") is None for s in base)
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target("t1").mark_in(start.product_id)
    params = ChainParams(answer="handoff", relief_max_parallax_px=1.0)
    steps = run_chain(dl, start, [mk.u, mk.v], target_id="t1", params=params)
    assert [(s.camera, s.kind) for s in steps] == [(s.camera, s.kind) for s in base]
    assert steps[0].tracked_uv == base[0].tracked_uv
    seen = 0
    for s in steps:
        if s.extra.get("coarse") != "features" or s.extra.get("feature_status") in (None, "failed"):
            continue
        kept = s.extra["relief_kept"]
        assert kept is not None and 0.0 <= kept <= 1.0
        assert s.extra["relief_masked"] == (params.relief_min_kept <= kept < 1.0)
        seen += 1
    assert seen >= 3


def test_the_surface_template_is_an_option_of_the_tracking_steps_only(dl, chains, monkeypatch):
    """ChainParams.template_surface (off by default): set, the feature step of each tracking step (same camera,
    next stop) gets its reference image's dense stereo to draw the NCC templates through (plane_warp
    .render_through_surface, with template_surface_gate_px and template_surface_level as set); a handoff across a
    drive never does; the designation is untouched and the same steps are found."""
    if _stem(dl) != "paper-s1-straight":
        pytest.skip("one sol is enough (a whole chain, ~10 s)")
    import scipctl.pipeline.chain as chain_module

    assert ChainParams().template_surface is False
    real = chain_module.feature_track
    calls = []

    def spy(prev, prod, *args, surface=None, **kw):
        calls.append((prev.camera, prod.camera, prev.position != prod.position, surface is not None))
        return real(prev, prod, *args, surface=surface, **kw)

    import scipctl.pipeline.feature_track as ft_module

    real_render = ft_module.render_through_surface
    drawn = set()

    def render_spy(*args, **kw):
        drawn.add(args[6:8])  # (gate, level): the parameters' values
        return real_render(*args, **kw)

    monkeypatch.setattr(chain_module, "feature_track", spy)
    monkeypatch.setattr(ft_module, "render_through_surface", render_spy)
    base = chains["t1"]
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target("t1").mark_in(start.product_id)
    steps = run_chain(dl, start, [mk.u, mk.v], target_id="t1", params=ChainParams(
        answer="handoff", template_surface=True, template_surface_gate_px=None, template_surface_level=False))
    assert drawn == {(None, False)}  # as set (not the defaults)
    assert [(s.camera, s.kind) for s in steps] == [(s.camera, s.kind) for s in base]
    assert steps[0].tracked_uv == base[0].tracked_uv
    tracks = [c for c in calls if c[0] == c[1]]
    assert len(tracks) >= 3 and all(c[2] and c[3] for c in tracks)  # every tracking step, with its stereo
    assert all(not c[3] for c in calls if c[0] != c[1])  # a handoff: the plane
    calls.clear()
    run_chain(dl, start, [mk.u, mk.v], target_id="t1", params=ChainParams(answer="handoff"))
    assert calls and not any(c[3] for c in calls)  # off: never


def test_the_texture_retry_replaces_only_a_step_that_confirmed_nothing(monkeypatch):
    """ChainParams.texture_retry_sigma_px: where the feature step confirms nothing, it runs once more on both images'
    texture_view (the previous one filtered over the same ground: sigma / scale), and a confirmed retry is the
    step's answer, recording what the first try gave; a confirmed first try is never retried. The wiring, with the
    feature step replaced by a stub that confirms only on texture views (paper-s1-straight t2's first pancam track)."""
    import scipctl.pipeline.chain as chain_mod
    from scipctl.core.tracking import TrackResult

    real = chain_mod.feature_track
    calls = []

    def stub(prev, prod, X_site, view_normals, n_site, pred_uv, scale, half, feats, params, new_stereo=None, vo=None,
             surface=None):
        calls.append((prev.product_id, prod.product_id, scale))
        if "#texture" not in prod.product_id and len(calls) == 1:  # the first step's first try: nothing confirmed
            return None, {"feature_status": "failed"}
        tr, info = real(prev, prod, X_site, view_normals, n_site, pred_uv, scale, half, feats, params, new_stereo, vo,
                        surface=surface)
        return tr, info

    monkeypatch.setattr(chain_mod, "feature_track", stub)
    dl = read_downlink(SAMPLES[0])
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target("t2").mark_in(start.product_id)
    params = ChainParams(answer="handoff", texture_retry_sigma_px=8.0)
    steps = run_chain(dl, start, [mk.u, mk.v], target_id="t2", params=params)
    (p0, n0, s0), (p1, n1, s1) = calls[0], calls[1]
    assert "#texture" not in n0 and n1 == n0 + "#texture8" and p1 == f"{p0}#texture{8.0 / s0:g}" and s1 == s0
    first = steps[1]
    assert first.extra["feature_status"] == "confirmed" and first.extra["texture_retry"] == "failed"
    # the texture views still find the target within the chain's success radius for a 4.5 m pancam track on this
    # rig (8 mm across the line of sight, 6.2 px; measured 2.59 px on OpenCV 5.0.0, also with one thread, and 2.52 px
    # on 4.14.0, against 1.3 px for the raw first try)
    assert first.ok and first.error_px < 6.0
    # every later step confirmed on its first try here, so none was retried
    assert not any("#texture" in c[1] for c in calls[2:])
    assert all("texture_retry" not in s.extra for s in steps[2:])


def test_the_texture_retry_changes_nothing_where_it_confirms_nothing():
    """paper-s1-straight t1: its first pancam track finds no feature model (21 px, flagged) and neither does the
    retry on texture, so the chain is the same step for step as without the option; the step records the retry's
    outcome."""
    dl = read_downlink(SAMPLES[0])
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target("t1").mark_in(start.product_id)
    off = run_chain(dl, start, [mk.u, mk.v], target_id="t1", params=HANDOFF)
    on = run_chain(dl, start, [mk.u, mk.v], target_id="t1", params=ChainParams(answer="handoff", texture_retry_sigma_px=8.0))
    assert on[1].extra.get("texture_retry") == "failed" and not on[1].ok
    assert [s.tracked_uv for s in on] == [s.tracked_uv for s in off]
    assert [s.p_success for s in on] == [s.p_success for s in off]


def test_the_closure_can_start_from_the_pancam_at_the_navcam_point(dl, chains):
    """ChainParams.closure_pancam_from_navcam: only a closure that would start from the navcam handoff changes, and
    only when the closure from the pancam image of that stop is confirmed (else today's closure)."""
    from scipctl.pipeline.chain_closure import closure_check, closure_evidence

    via = []
    for tid, steps in chains.items():
        off = closure_check(dl, steps, ChainParams()).to_dict()
        on = closure_check(dl, steps, ChainParams(closure_pancam_from_navcam=True)).to_dict()
        ref = steps[off["reference_step"]]
        assert on["reference_step"] == off["reference_step"]
        if ref.camera == "pancam" or on["via"] is None:
            assert on == off
            continue
        pan = dl.product(on["reference"])
        assert on["via"] == "navcam" and on["status"] == "confirmed" and ref.camera == "navcam"
        assert pan.camera == "pancam" and pan.position == ref.position
        # the chain's success radius (4 px); measured 2.27 | 1.68 px (paper-s1-straight t1; OpenCV 5.0 | 4.14)
        assert np.hypot(*np.subtract(on["uv"], steps[-1].mark_uv)) <= 4.0
        assert closure_evidence(steps, on).from_pancam == 1.0 and closure_evidence(steps, off).from_pancam == 0.0
        via.append(tid)
    # paper-s1-straight t1's 4.5 m pancam track fails: its closure starts from the navcam handoff, and the pancam
    # closure at its point is confirmed (paper-s1-arc t1's is not: today's closure stays)
    assert via == (["t1"] if _stem(dl) == "paper-s1-straight" else [])



def test_the_chain_measures_the_window_range_gap_its_designation_model_uses(dl, chains):
    """The packaged designation model uses the window range gap; the chain measures it as ``scipctl designate`` does
    (the p above is the same) and does not leave it out: without the gap the model gives another p."""
    from dataclasses import replace

    from scipctl.io.trust_model import PACKAGED_DESIGNATION, load_packaged_trust_model
    from scipctl.pipeline.designate import designate
    from scipctl.pipeline.designation_trust import assess

    model = load_packaged_trust_model(PACKAGED_DESIGNATION)
    assert "window_gap_pct" in {field for field, _ in model.features.values()}
    moved = 0
    for tid, steps in chains.items():
        d = designate(dl, dl.product(steps[0].product_id), steps[0].tracked_uv, tid, with_normal=False, trust=model)
        assert d.window_range_gap_pct is not None and steps[0].p_success == d.p_ok
        moved += assess(model, replace(d, window_range_gap_pct=None)).p_ok != steps[0].p_success
    assert moved == len(chains)


def test_a_failed_feature_step_says_in_one_clause_how_close_it_came(dl, chains):
    """s1-straight t1's 4.5 m pancam track finds no feature model at any view, plane or reach: its reason names the
    number of tries and the one that came closest (most inliers), and the step keeps every try in
    ``feature_tries`` (what an operator reads first is one clause, not the list)."""
    from scipctl.pipeline.feature_track import failure_summary

    if _stem(dl) != "paper-s1-straight":
        pytest.skip("the failed feature step is s1-straight t1's")
    pan = chains["t1"][1]
    tries = pan.extra["feature_tries"]
    assert pan.extra["feature_status"] == "failed" and len(tries) > 1
    reason = pan.extra["feature_reason"]
    assert reason.startswith(f"no feature model in {len(tries)} tries; closest: ")
    closest = reason.split("closest: ", 1)[1]
    assert closest in tries
    inliers = [int(t.split("(")[1].split(" ")[0]) for t in tries if "inliers <" in t]
    assert inliers and f"({max(inliers)} inliers <" in closest  # the most inliers of the tries that fitted a model
    assert "; x" not in pan.reason  # the step's reason carries the one clause, not the list
    assert failure_summary([], None) == "no usable feature model"
    assert failure_summary(["plane 0: the previous view does not cover the prediction"], None) == \
        "plane 0: the previous view does not cover the prediction"
    assert failure_summary(["a", "b"], None) == "a; b"
