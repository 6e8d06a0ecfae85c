"""Handoff methods on simulated downlinks with exact truth.

* no injected error (tests/data/handoff/paper-s1-straight-noerr.mcap, see
  tests/data/README.md): the methods recover the hazcam mark;
* default errors (the bundled sample sol): the pure methods' errors are the
  errors the calibration / pose model predicts.
"""

from pathlib import Path

import numpy as np
import pytest

from scipctl.core.handoff import ALL_METHODS, PAPER_METHODS
from scipctl.io.downlink import read_downlink
from scipctl.pipeline.handoff import (HandoffRecord, build_setup, handoff_records_from_doc, marked_targets,
                                      run_targets, table1, table1_rows_from_doc)

ROOT = Path(__file__).resolve().parents[2]
NOERR = ROOT / "tests/data/handoff/paper-s1-straight-noerr.mcap"
SAMPLE = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"
M2020_NEAR = ROOT / "tests/data/handoff/m2020-1002-s3-straight-near.mcap"


def _run(path, methods=ALL_METHODS):
    dl = read_downlink(path)
    setup = build_setup(dl)
    recs = run_targets(dl, setup, marked_targets(dl, setup), methods=methods, downlink_name=path.name)
    return dl, setup, recs


@pytest.fixture(scope="module")
def noerr():
    if not NOERR.exists():
        pytest.skip(f"{NOERR} missing")
    return _run(NOERR)


@pytest.fixture(scope="module")
def sample():
    return _run(SAMPLE, methods=("pure-kinematic", "alt-pure-kinematic", "pure-geometric"))


def _err(recs, method, navcam, kinds, dl):
    kind = {t.id: t.kind for t in dl.targets}
    return {r.target: r.error_px for r in recs
            if r.method == method and navcam in (r.navcam, "any") and kind[r.target] in kinds}


# Targets on an occluding edge defeat window stereo by construction (the window
# straddles two ranges); the paper saw the same. They are checked separately.
SURFACE = ("flat", "point", "sand", "contrast")

# Where the bound (1 px; 2 px for mesh registration) is not met on the
# no-error sol, measured with full-resolution shared stereo (docs/handoff.md):
# expected failures with the measured reason, reported, not hidden. Empty since
# pure geometric is refined with hazcam point stereo (it was 1.4 px near / 1.0 px
# far from SGBM's range error at one pixel; the draped windows and consensus
# inherited it: 1.8 / 1.16 px) and refined-kinematic far warps the navcam window
# through the local plane (4 px with the paper's uniform scale).
NOT_MET: dict = {}


def _cases():
    for m in ALL_METHODS:
        for n in (("any",) if m == "scip" else ("near", "far")):  # scip: one answer per target, from either view
            marks = [pytest.mark.xfail(reason=NOT_MET[(m, n)], strict=False)] if (m, n) in NOT_MET else []
            yield pytest.param(m, n, marks=marks, id=f"{m}-{n}")


@pytest.mark.parametrize("method,navcam", list(_cases()))
def test_no_error_handoff_recovers_the_mark(noerr, method, navcam):
    dl, _, recs = noerr
    errs = _err(recs, method, navcam, SURFACE, dl)
    # issue #14's bound for a no-error sol: 1 px (2 px for mesh registration); the measured largest errors per
    # method and navcam, 0.03-0.79 px, are in docs/handoff.md, "With no injected error"
    bound = 2.0 if method == "mesh-registration" else 1.0
    assert errs and all(e is not None for e in errs.values()), errs
    assert max(errs.values()) <= bound, errs


def test_beyond_paper_refinements_are_used_and_reported(noerr):
    """The no-error figures above come from the refinements, not from a fallback to the paper's steps."""
    dl, _, recs = noerr
    kind = {t.id: t.kind for t in dl.targets}
    for r in recs:
        if kind[r.target] not in SURFACE:
            continue
        if r.method == "pure-geometric":
            assert r.diagnostics["refined_by"] == "hazcam point stereo", r.diagnostics
            # 0.5 px is the refinement's own gate (HandoffParams.geometric_max_residual_px), so this holds whenever
            # refined_by is set; measured 9e-6 to 3.1e-4 navcam px (converged in 2-5 of the 6 iterations), the same on
            # OpenCV 5.0 and 4.14, 1 and 2 threads. Not tightened: a bound from match_projection's tol_px needs the
            # hazcam-to-navcam Jacobian's norm, not measured here
            assert r.diagnostics["refinement_residual_navcam_px"] < 0.5
            # the dense answer (the paper's) is reported beside the refined one
            assert len(r.diagnostics["dense_uv"]) == 2
        if r.method == "refined-kinematic" and r.navcam == "far":
            assert r.diagnostics["warp"] == "local plane", r.diagnostics


def test_every_method_answers_and_is_timed(noerr):
    dl, setup, recs = noerr
    assert {r.method for r in recs} == set(ALL_METHODS)
    assert len(recs) == (len(ALL_METHODS) - 1) * 2 * len(dl.targets) + len(dl.targets)  # scip: one per target
    for r in recs:
        assert r.seconds >= 0
        assert r.truth_uv is not None


def _triangulate(models, uvs):
    from scipctl.core.triangulation import triangulate_rays

    (o1, d1), (o2, d2) = (m.unproject(np.asarray(uv, float)) for m, uv in zip(models, uvs))
    X, _, _ = triangulate_rays(o1, d1, o2, d2)
    return np.asarray(X).reshape(3)


@pytest.mark.parametrize("method", ["pure-kinematic", "alt-pure-kinematic"])
@pytest.mark.parametrize("navcam", ["near", "far"])
def test_kinematic_errors_are_the_modelled_errors(sample, method, navcam):
    """Triangulate the TRUE navcam marks with the downlinked (calibrated) models, move the point with the
    downlinked pose estimates, project through the downlinked hazcam model: the offset from the hazcam mark is
    the error the calibration and pose errors predict. The method's error must point the same way and be as big."""
    from scipctl.core.kinematics import T_roverB_roverA

    dl, setup, recs = sample
    left = setup.near if navcam == "near" else setup.far
    right = dl.stereo_pair(left)
    haz = setup.hazcam
    checked = 0
    for t in dl.targets:
        if t.kind == "edge":
            continue
        ml, mr, mh = t.mark_in(left.product_id), t.mark_in(right.product_id), t.mark_in(haz.product_id)
        rec = next(r for r in recs if r.target == t.id and r.method == method and r.navcam == navcam)
        if None in (ml, mr, mh) or rec.predicted_uv is None:
            continue
        X = _triangulate((left.camera_model, right.camera_model), ([ml.u, ml.v], [mr.u, mr.v]))
        X_haz = T_roverB_roverA(haz.pose, left.pose).apply(X) if left.position != haz.position else X
        modelled = haz.camera_model.project(X_haz[None])[0] - [mh.u, mh.v]
        actual = np.asarray(rec.predicted_uv) - [mh.u, mh.v]
        assert np.linalg.norm(modelled) > 5.0  # the default errors are big enough to see
        cos = float(modelled @ actual / (np.linalg.norm(modelled) * np.linalg.norm(actual)))
        ratio = np.linalg.norm(actual) / np.linalg.norm(modelled)
        # error model: actual = modelled + the method's own error, which on a no-error sol is under 1 px (issue
        # #14's bound, tested above); on a modelled error over 5 px (asserted above) that turns it by at most
        # asin(1/5) (cos > 0.9798) and scales it by 0.8-1.2. Measured (both navcams, both methods, t1 and t2;
        # modelled 17.5-29.3 px, |actual - modelled| 0.02-0.67 px): cos >= 0.99980 and ratio 0.986-1.038 on OpenCV
        # 5.0 and 4.14, 1 and 2 threads (4.14 differs in the 5th digit on one target). Bounds from the model, a
        # 100x margin on 1 - cos and 5x on the ratio's spread (were 0.95 and 0.75-1.33)
        assert cos > 0.979, (t.id, modelled, actual)
        assert 0.8 < ratio < 1.2, (t.id, modelled, actual)
        checked += 1
    assert checked >= 1


def test_table1_rows_split_refined_successes(noerr):
    _, _, recs = noerr
    rows = table1(recs)
    # scip answers once per target, from whichever view its answer used: one row with navcam "any"
    assert {(r["method"], r["navcam"]) for r in rows} == \
        {(m, n) for m in ALL_METHODS if m != "scip" for n in ("near", "far")} | {("scip", "any")}
    for r in rows:
        assert r["paper_method"] == (r["method"] in PAPER_METHODS)
        n_s = r["successes"]["n"] if r["successes"] else 0
        n_f = r["failures"]["n"] if r["failures"] else 0
        assert n_s + n_f == r["answered"]
        assert r["success_rate"] == pytest.approx(n_s / r["cases"])


def test_registration_in_a_worker_thread_changes_nothing(noerr):
    """run_targets registers the clouds in a worker thread while the other methods run; the records come in
    target, navcam, method order and the mesh-registration answers equal those of a plain serial registration."""
    dl, setup, recs = noerr
    order = [(r.target, r.navcam, r.method) for r in recs]
    # per target: every other method near, then far, then its one scip record (navcam: the view it used)
    assert [o for o in order if o[2] != "scip"] == \
        [(t.id, nc, m) for t in dl.targets for nc in ("near", "far") for m in ALL_METHODS if m != "scip"]
    per_target = [[o for o in order if o[0] == t.id] for t in dl.targets]
    assert all(o[-1][2] == "scip" and o[-1][1] in ("near", "far", "both") and sum(x[2] == "scip" for x in o) == 1
               for o in per_target)
    serial = build_setup(dl)
    for case in serial.cases.values():
        assert "whole_reg_future" not in case._cache
        case.whole_registration()  # computed here, in this thread, before run_targets
    mesh = run_targets(dl, serial, marked_targets(dl, serial), methods=("mesh-registration",))
    threaded = [r for r in recs if r.method == "mesh-registration"]
    assert [(r.target, r.navcam) for r in mesh] == [(r.target, r.navcam) for r in threaded]
    for a, b in zip(mesh, threaded):
        assert a.predicted_uv == b.predicted_uv and a.diagnostics["icp_fitness"] == b.diagnostics["icp_fitness"]
    for case in setup.cases.values():
        assert case.registration_seconds > 0 and "whole_reg_future" not in case._cache


def test_handoff_records_read_back_from_handoff_json(sample):
    """The records as simulate-handoff saves them in handoff.json read back to the same records (and bytes)."""
    import json

    from scipctl.io.workspace import dumps

    _, _, recs = sample
    text = dumps({"results": [r.to_dict() for r in recs], "table1": table1(recs)})
    back = handoff_records_from_doc(json.loads(text), "handoff.json")
    assert dumps({"results": [b.to_dict() for b in back], "table1": table1(back)}) == text
    assert [(b.target, b.method, b.navcam, b.predicted_uv, b.error_px) for b in back] == \
        [(r.target, r.method, r.navcam, r.predicted_uv, r.error_px) for r in recs]
    assert handoff_records_from_doc({"results": []}) == [] and handoff_records_from_doc(None) == []


GOOD_RECORD = HandoffRecord("sol.mcap", "t1", "pure-kinematic", "near", "nav-L", [1.0, 2.0], [3.0, 4.0], [3.5, 4.0],
                            0.5, True, True, "", {"ncc_peak": 0.9}, 0.01).to_dict()


def _scored(method, err, navcam="near"):
    """A record of ``method`` whose answer is ``err`` px below the mark (success within 4 px)."""
    return HandoffRecord("sol.mcap", "t1", method, navcam, "nav-L", [1.0, 2.0], [3.0, 4.0 + err], [3.0, 4.0], err,
                         err <= 4.0, True, "", {}, 0.01)


def test_table1_statistics_carry_their_unit():
    # a Table-1 row's statistics held hazcam pixels under keys without the unit (mean, std, min, max)
    from scipctl.pipeline.sequence import choose_handoff

    recs = ([_scored("refined-geometric", e) for e in (1.0, 2.0)] + [_scored("pure-kinematic", e) for e in (5.0, 7.0)]
            + [_scored("pure-geometric", e) for e in (8.0, 10.0)])
    rows = {r["method"]: r for r in table1(recs)}
    assert rows["pure-kinematic"]["all"] == {"n": 2, "mean_px": 6.0, "std_px": 1.0, "min_px": 5.0, "max_px": 7.0}
    assert rows["pure-kinematic"]["failures"] == rows["pure-kinematic"]["all"] and rows["pure-kinematic"]["successes"] is None
    assert rows["refined-geometric"]["successes"] == {"n": 2, "mean_px": 1.5, "std_px": 0.5, "min_px": 1.0, "max_px": 2.0}
    # and what reads them: the sequence's fallback method is the one with the smaller mean error, 6 px against 9 px
    ch = choose_handoff(list(rows.values()), "best-single")
    assert (ch["primary"], ch["fallback"]) == ("refined-geometric", "pure-kinematic")


def test_table1_rows_of_an_older_handoff_json_read_with_the_unit():
    """handoff.json files written before the statistics' keys carried the unit are read with the new keys."""
    from scipctl.io.report_html import _stats

    old = {"method": "pure-kinematic", "navcam": "near", "paper_method": True, "cases": 2, "answered": 2,
           "success_rate": 0.0, "all": {"n": 2, "mean": 6.0, "std": 1.0, "min": 5.0, "max": 7.0}, "successes": None,
           "failures": {"n": 2, "mean": 6.0, "std": 1.0, "min": 5.0, "max": 7.0}, "refined": False}
    row, = table1_rows_from_doc({"results": [], "table1": [old]})
    assert row == table1([_scored("pure-kinematic", e) for e in (5.0, 7.0)])[0]
    assert _stats(row["all"]) == "6.0±1.0 (5.0-7.0)"


def test_a_scip_record_reads_back_with_its_trust():
    # from_dict dropped p_success and go: the report showed a saved scip answer without its verdict
    scip = HandoffRecord("sol.mcap", "t1", "scip", "both", "nav-L", [1.0, 2.0], [3.0, 4.0], [3.5, 4.0], 0.5, True, True,
                         "", {"ncc_peak": 0.9}, 0.01, p_success=0.97, go=True).to_dict()
    back = HandoffRecord.from_dict(scip)
    assert (back.p_success, back.go) == (0.97, True) and back.to_dict() == scip
    from scipctl.model import InputError

    with pytest.raises(InputError, match=r"results\[1\]\.p_success"):
        handoff_records_from_doc({"results": [scip, dict(scip, p_success="high")]}, "handoff.json")


@pytest.mark.parametrize("change, field", [
    ({"predicted_uv": [3.0]}, "results[1].predicted_uv"),
    ({"success": "yes"}, "results[1].success"),
    ({"ok": None}, "results[1].ok"),
    ({"diagnostics": []}, "results[1].diagnostics"),
    ({"method": None}, "results[1].method"),
    ({"error_px": float("nan")}, "results[1].error_px"),
])
def test_a_bad_handoff_record_field_is_named(change, field):
    from scipctl.model import InputError

    assert HandoffRecord.from_dict(GOOD_RECORD).to_dict() == GOOD_RECORD
    with pytest.raises(InputError) as e:
        handoff_records_from_doc({"results": [GOOD_RECORD, dict(GOOD_RECORD, **change)]}, "handoff.json")
    assert str(e.value).startswith(f"handoff.json: {field}: ") and "\n" not in str(e.value), str(e.value)
    missing = {k: v for k, v in GOOD_RECORD.items() if k != "seconds"}
    with pytest.raises(InputError, match=r"^handoff.json: results\[0\]\.seconds: missing"):
        handoff_records_from_doc({"results": [missing]})


def test_scip_is_go_within_1px_with_no_error(noerr):
    """Issue #14 item 6: a no-error case is GO within 1 px (surface targets; edge targets are checked apart)."""
    dl, _, recs = noerr
    kind = {t.id: t.kind for t in dl.targets}
    scip = [r for r in recs if r.method == "scip" and kind[r.target] in SURFACE]
    assert scip
    for r in scip:
        assert r.go is True and r.p_success is not None, (r.target, r.p_success)
        assert r.error_px <= 1.0, (r.target, r.error_px)


def test_scip_is_go_within_1px_at_success_px_1_with_no_error(noerr):
    """Issue #14 item 6 at the 1 px radius itself (`--success-px 1`: the model's 1 px probability and its 1 px GO
    threshold): every surface target of the no-error downlink is GO, and within 1 px. Edge targets are checked
    apart (window stereo straddles two ranges there). Reuses the fixture's setup: only scip's scoring reruns."""
    dl, setup, _ = noerr
    kind = {t.id: t.kind for t in dl.targets}
    recs = run_targets(dl, setup, marked_targets(dl, setup), methods=("scip",), success_px=1.0,
                       downlink_name=NOERR.name)
    scip = [r for r in recs if kind[r.target] in SURFACE]
    assert scip and all(r.method == "scip" and r.diagnostics["success_px"] == 1.0 for r in scip)
    for r in scip:
        assert r.go is True and r.p_success is not None, (r.target, r.p_success)
        assert r.error_px <= 1.0, (r.target, r.error_px)


def test_shared_setups_reuse_cases_only_for_the_same_products_and_params():
    """build_setup(shared=True) hands the chain's hazcam handoff the handoff's own cases (same downlink object,
    products and equal params; so their dense stereo and registration are computed once); anything else, or
    shared=False, gets fresh ones."""
    from scipctl.core.handoff import HandoffParams

    dl = read_downlink(SAMPLE)
    a = build_setup(dl, shared=True)
    b = build_setup(dl, hazcam=a.hazcam.product_id, near=a.near.product_id, shared=True)  # as the chain asks
    assert b.cases["near"] is a.cases["near"] and b.cases["far"] is a.cases["far"]
    assert a.cases["near"].haz is a.cases["far"].haz  # one hazcam view per setup, as without sharing
    fresh = build_setup(dl)
    assert fresh.cases["near"] is not a.cases["near"] and fresh.cases["near"].haz is fresh.cases["far"].haz
    fast = build_setup(dl, HandoffParams(dense_downsample=2), shared=True)
    assert fast.cases["near"] is not a.cases["near"] and fast.cases["near"].nav is not a.cases["near"].nav
    other = build_setup(read_downlink(SAMPLE), shared=True)  # another downlink object: its own cases
    assert other.cases["near"] is not a.cases["near"]


def _near_registration_errors(dl, params=None) -> np.ndarray:
    setup = build_setup(dl, params)  # not shared: each params gets its own cases
    recs = run_targets(dl, setup, marked_targets(dl, setup), methods=("mesh-registration",), navcams=("near",))
    errs = [r.error_px for r in recs]
    assert len(errs) == 9 and all(e is not None for e in errs)  # 3 marked + 6 extra targets, every one answered
    return np.array(errs)


def test_the_near_registration_of_the_mars_2020_rig_ends_at_1_cm():
    """The Mars 2020 rig with default errors (tests/data/README.md): the near registration's 1 cm finest scale puts
    every target within 4 px, the success radius. Measured max 1.9 px, a 2x margin; Open3D ICP's run-to-run rounding
    is <= 1e-9 relative (docs/campaign.md), and the margin is for what another OpenCV/Open3D build does to the dense
    stereo and the ICP (measured on this machine's builds only). Ending at 2 cm, as before session 46, the
    registration stops 1.5-4.5 cm short at the targets: 2 of 9 within 4 px, median 8.2 px."""
    from dataclasses import replace

    from scipctl.core.handoff import HandoffParams

    dl = read_downlink(M2020_NEAR)
    assert HandoffParams().registration_near_scales_m[-1] == 0.01
    errs = _near_registration_errors(dl)
    assert np.all(errs <= 4.0), errs
    old = _near_registration_errors(dl, replace(HandoffParams(), registration_near_scales_m=(0.08, 0.04, 0.02)))
    assert np.median(old) > 4.0, old  # the failure the 1 cm scale mends (a check that this file still shows it)
