"""The closure's trust model: the packaged file is what its command makes from the committed closure table, the
held-out evaluation never scores a family with a model that saw it, and the table is what the chain records say
(tests/data/README.md, "closure_trust")."""

import gzip
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("sklearn")

ROOT = Path(__file__).resolve().parents[2]
TABLE = Path("tests/data/closure_trust/closures.jsonl.gz")
MODEL = Path("scipctl/data/closure_trust_model.json")


def _rows():
    from scipctl.pipeline.closure_trust_fit import ClosureRow

    text = gzip.decompress((ROOT / TABLE).read_bytes()).decode("utf-8")
    return [ClosureRow.from_dict(json.loads(line)) for line in text.splitlines() if line.strip()]


def _step(go: bool = False, **fields) -> dict:
    """A chain step's record: every optional field None, ok, no reason, then ``fields``."""
    blank = {k: None for k in ("predicted_uv", "tracked_uv", "mark_uv", "error_px", "ncc_peak", "range_m",
                               "xyz_site_m", "truth_xyz_site_m", "error_3d_m", "p_success")}
    return dict(blank, ok=True, reason="", go=go, advice=None, **fields)


def test_packaged_model_is_reproduced_bit_for_bit_by_its_command(tmp_path):
    """The command of the model's provenance, run on the committed table (same relative paths), writes the same
    bytes as the packaged file."""
    (tmp_path / TABLE.parent).mkdir(parents=True)
    shutil.copy(ROOT / TABLE, tmp_path / TABLE)
    (tmp_path / MODEL.parent).mkdir(parents=True)
    env = {"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, str(ROOT / "docs/scripts/fit_closure_trust.py"), "fit", str(TABLE), "-o",
                        str(MODEL)], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / MODEL).read_bytes() == (ROOT / MODEL).read_bytes()
    prov = json.loads((ROOT / MODEL).read_text())["provenance"]
    assert prov["command"] == f"python docs/scripts/fit_closure_trust.py fit {TABLE} -o {MODEL}"


def test_held_out_families_are_answered_by_models_that_never_saw_them(monkeypatch):
    import scipctl.pipeline.closure_trust_fit as fit

    rows = _rows()
    fams = sorted({r.family for r in rows})
    assert len(fams) >= 4 and len(rows) >= 40
    seen = []
    real = fit.fit_closure_model

    def spy(evidence, y, *a, **k):
        seen.append(len(y))
        return real(evidence, y, *a, **k)

    monkeypatch.setattr(fit, "fit_closure_model", spy)
    pairs = fit.held_out(rows)
    assert len(pairs) == sum(r.closure_error_px is not None for r in rows)
    for fam in fams:
        n_other = sum(1 for r in rows if r.family != fam and r.closure_error_px is not None)
        assert n_other in seen  # each fold fitted on the other families' rows only
    assert all(0.0 <= p <= 1.0 and w == (r.closure_error_px <= fit.SUCCESS_PX) for r, p, w in pairs)


def test_a_row_is_made_from_a_chain_record_with_a_confirmed_closure():
    """closure_row reads both forms of record: a chain that only checked its closure (the handoff's pixel is the
    final answer) and one that adopted it (the handoff's pixel under extra["handoff"]); no row without a confirmed
    closure."""
    from scipctl.pipeline.closure_trust_fit import closure_row

    ref = _step(camera="pancam", kind="track", position=[1, 1], product_id="p", p_success=0.7, extra={})
    cl = {"status": "confirmed", "uv": [103.0, 204.0], "reference_step": 0, "ncc_peak": 0.8, "closure_px": 5.0,
          "feature_local_inliers": 9, "feature_confirmed": 2, "feature_shift_px": 40.0, "scale": 0.6,
          "feature_pooled": 3, "feature_refine_px": 1.25}
    fin = _step(camera="hazcam", kind="handoff", position=[1, 3], product_id="h", mark_uv=[100.0, 200.0],
                tracked_uv=[103.0, 209.0], extra={"final": True, "closure": cl})
    row = closure_row({"target": "t1", "steps": [ref, fin]}, "fam", "d")
    assert row.closure_error_px == pytest.approx(5.0) and row.handoff_error_px == pytest.approx(3.0 * 10 ** 0.5)
    assert row.evidence["from_pancam"] == 1.0 and row.evidence["ref_p_success"] == 0.7
    assert row.evidence["pooled"] == 3.0 and row.evidence["refine_px"] == 1.25
    assert row.evidence["handoff_px"] == 5.0 and row.target == "t1"
    adopted = dict(fin, tracked_uv=cl["uv"], extra={"final": True, "closure": cl, "answer": "closure",
                                                    "handoff": {"uv": [103.0, 209.0]}})
    again = closure_row({"target": "t1", "steps": [ref, adopted]}, "fam", "d")
    assert again == row
    for status in ("unconfirmed", "failed"):
        bad = dict(fin, extra={"final": True, "closure": dict(cl, status=status)})
        assert closure_row({"target": "t1", "steps": [ref, bad]}, "fam", "d") is None


def test_a_step_model_scores_the_reference_again():
    """With a step model, the row's ref_p_success is that model's p for the reference step (what a chain run with
    it would have), not the p recorded; the rest of the evidence is the record's."""
    from scipctl.core.step_trust import StepTrustModel
    from scipctl.pipeline.chain import ChainStep
    from scipctl.pipeline.chain_trust import step_evidence
    from scipctl.pipeline.closure_trust_fit import closure_row
    from scipctl.io.step_trust_model import load_packaged_step_trust_model

    blank = {k: None for k in ("predicted_uv", "mark_uv", "error_px", "ncc_peak", "range_m", "truth_xyz_site_m",
                               "error_3d_m", "p_success")}
    blank.update(ok=True, reason="", go=False, advice=None)
    des = dict(blank, camera="pancam", kind="designate", position=[1, 0], product_id="d", tracked_uv=[50.0, 60.0],
               xyz_site_m=[10.0, 0.0, 0.0], extra={"px_mm": 2.8})
    ref = dict(blank, camera="pancam", kind="track", position=[1, 1], product_id="p", p_success=0.123,
               tracked_uv=[40.0, 70.0], xyz_site_m=[10.0, 0.0, 0.0], range_m=4.5, ncc_peak=0.9,
               extra={"feature_status": "confirmed", "feature_local_inliers": 12, "feature_inliers": 30,
                      "feature_confirmed": 3, "feature_shift_px": 20.0, "ncc_score": 0.9, "ncc_ratio": 1.3,
                      "scale": 2.2, "px_mm": 1.3, "template": "plane, feature-guided"})
    cl = {"status": "confirmed", "uv": [103.0, 204.0], "reference_step": 1, "ncc_peak": 0.8, "closure_px": 5.0,
          "feature_local_inliers": 9, "feature_confirmed": 2, "feature_shift_px": 40.0, "scale": 0.6}
    fin = dict(blank, camera="hazcam", kind="handoff", position=[1, 3], product_id="h", mark_uv=[100.0, 200.0],
               tracked_uv=[103.0, 209.0], xyz_site_m=[10.0, 0.0, 0.0], extra={"final": True, "closure": cl})
    record = {"target": "t1", "steps": [des, ref, fin]}
    model = load_packaged_step_trust_model()
    assert isinstance(model, StepTrustModel)
    recorded = closure_row(record, "fam", "d")
    again = closure_row(record, "fam", "d", model)
    steps = [ChainStep.from_dict(s) for s in record["steps"]]
    want = float(model.probability([step_evidence(steps, 1)])[0])
    assert recorded.evidence["ref_p_success"] == 0.123
    assert again.evidence["ref_p_success"] == want != 0.123
    # the reference names no earlier step: its lineage is itself, so the path's p is its own
    assert recorded.evidence["path_p"] == 0.123 and again.evidence["path_p"] == want
    rescored = ("ref_p_success", "path_p")
    assert {k: v for k, v in again.evidence.items() if k not in rescored} == \
        {k: v for k, v in recorded.evidence.items() if k not in rescored}


def test_a_table_grows_from_the_committed_one(tmp_path):
    """``table --add OLD``: the earlier table's rows kept (their campaigns need not exist any more), the campaigns'
    added. With no campaign records the committed table comes back byte for byte (the rows read and written
    again, sorted and compressed as the command always does)."""
    (tmp_path / "camp" / "records").mkdir(parents=True)
    env = {"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, str(ROOT / "docs/scripts/fit_closure_trust.py"), "table", str(tmp_path / "camp"),
                        "--add", str(ROOT / TABLE), "-o", str(tmp_path / "t.jsonl.gz")], env=env, capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stderr
    n = len(_rows())
    assert json.loads(r.stderr) == {"chains": 0, "added": n, "confirmed_closures": n}
    assert (tmp_path / "t.jsonl.gz").read_bytes() == (ROOT / TABLE).read_bytes()


def test_chains_keep_an_adopted_closure_without_stereo_no_go(tmp_path):
    """``chains`` scores each adopted closure again as run_chain does: GO needs point stereo at the closure's pixel
    (the final step's ok) as well as p at the model's threshold. A closure recorded at a p above the threshold but
    NO-GO for want of stereo gives its record back (before, the check called it another model's and exited 2)."""
    sys.path.insert(0, str(ROOT / "docs" / "scripts"))
    import fit_closure_trust as fct
    from scipctl.core.closure_trust import ClosureEvidence
    from scipctl.io.closure_trust_model import load_packaged_closure_trust_model
    from scipctl.pipeline.closure_trust_fit import closure_row

    model = load_packaged_closure_trust_model()
    ref = _step(go=True, camera="pancam", kind="track", position=[1, 1], product_id="p", p_success=0.99, extra={})
    cl = {"status": "confirmed", "uv": [101.0, 201.0], "reference_step": 0, "ncc_peak": 0.99, "closure_px": 0.5,
          "feature_local_inliers": 40, "feature_confirmed": 4, "feature_shift_px": 10.0, "scale": 0.7,
          "feature_pooled": 6, "feature_refine_px": 0.1}
    fin = _step(camera="hazcam", kind="handoff", position=[1, 3], product_id="h", mark_uv=[100.0, 200.0],
                tracked_uv=[101.0, 201.0], error_px=2.0 ** 0.5,
                extra={"final": True, "closure": cl, "answer": "closure", "handoff": {"uv": [101.5, 201.0]}})
    row = closure_row({"target": "t1", "steps": [ref, fin]}, "fam", "d")
    p = float(model.probability([ClosureEvidence.from_dict(row.evidence)])[0])
    # the case the check must get right: a p that alone would be GO (0.974 against 0.97 with the packaged model of
    # session 43, a numpy logistic of this fixed evidence: the margin does not depend on the build)
    assert p >= model.go_min_p
    fin.update(p_success=p, ok=False, go=False, reason="stereo: no match")
    (tmp_path / "camp" / "records").mkdir(parents=True)
    header = {"kind": "downlink", "status": "ok", "family": "fam", "job": {"path": str(tmp_path / "x" / "d.mcap")}}
    chain = {"kind": "chain", "record": {"target": "t1", "go": False, "steps": [ref, fin]}}
    (tmp_path / "camp" / "records" / "d.jsonl").write_text(json.dumps(header) + "\n" + json.dumps(chain) + "\n")
    out = fct.chain_scores([str(tmp_path / "camp")], {"packaged": model})
    assert out["chains"] == 1 and out["within"] == 1
    assert out["models"]["packaged"]["chain_go"] == 0 and out["models"]["packaged"]["p_ge_0_9"] == 1


@pytest.mark.parametrize("args", [
    ["chains", "{tmp}/none", "--model", str(MODEL)],
    ["chains", "{tmp}/camp", "--model", "{tmp}/missing.json"],
    ["chains", "{tmp}/camp", "--model", "{tmp}/camp/bad.json"],
    ["table", "{tmp}/camp", "--add", "{tmp}/missing.jsonl.gz", "-o", "{tmp}/out.jsonl.gz"],
    ["chains", "{tmp}/camp", "--model", str(MODEL), "--closure-go-max-drives", "-1"],
])
def test_bad_input_is_one_line_and_exit_2(args, tmp_path):
    """A folder that is no campaign, a missing or unreadable model, a missing table to add, a negative drives limit:
    one line naming it, exit code 2, nothing written."""
    (tmp_path / "camp" / "records").mkdir(parents=True)
    (tmp_path / "camp" / "bad.json").write_text("not json")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in args]
    env = {"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, str(ROOT / "docs/scripts/fit_closure_trust.py"), *argv], cwd=ROOT, env=env,
                       capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and r.stderr.startswith(f"fit_closure_trust.py {argv[0]}:")
    assert not (tmp_path / "out.jsonl.gz").exists()
