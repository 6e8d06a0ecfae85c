"""The prediction's calibration fit: the packaged files are what their command makes from the committed approach
table, the held-out evaluation never scores a family with a model that saw it (nor with the other route's), and
the table is what the campaign records say (tests/data/README.md, "prediction_calibration")."""

import gzip
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("sklearn")

ROOT = Path(__file__).resolve().parents[2]
TABLE = Path("tests/data/prediction_calibration/approaches.jsonl.gz")
MODELS = Path("scipctl/data")


def _rows():
    from scipctl.pipeline.prediction_calibration_fit import PredictionRow

    text = gzip.decompress((ROOT / TABLE).read_bytes()).decode("utf-8")
    return [PredictionRow.from_dict(json.loads(line)) for line in text.splitlines() if line.strip()]


def test_packaged_models_are_reproduced_bit_for_bit_by_their_command(tmp_path):
    (tmp_path / TABLE.parent).mkdir(parents=True)
    shutil.copy(ROOT / TABLE, tmp_path / TABLE)
    (tmp_path / MODELS).mkdir(parents=True)
    env = {"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, str(ROOT / "docs/scripts/fit_prediction_calibration.py"), "fit", str(TABLE),
                        "-o", str(MODELS)], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    for route in ("plan", "downlink"):
        name = f"prediction_calibration_{route}.json"
        assert (tmp_path / MODELS / name).read_bytes() == (ROOT / MODELS / name).read_bytes()
        prov = json.loads((ROOT / MODELS / name).read_text())["provenance"]
        assert prov["command"] == f"python docs/scripts/fit_prediction_calibration.py fit {TABLE} -o {MODELS}"
        assert prov["route"] == route


def test_held_out_families_are_answered_by_models_that_never_saw_them(monkeypatch):
    import scipctl.pipeline.prediction_calibration_fit as fit

    rows = _rows()
    assert {r.route for r in rows} == {"plan", "downlink"} and len(rows) >= 200
    seen = []
    real = fit.fit_calibration

    def spy(evidence, y, *a, **k):
        seen.append((len(y), tuple(sorted(e.p_simulated for e in evidence))))
        return real(evidence, y, *a, **k)

    monkeypatch.setattr(fit, "fit_calibration", spy)
    pairs = fit.held_out(rows)
    assert len(pairs) == len(rows)
    for route in ("plan", "downlink"):
        R = [r for r in rows if r.route == route]
        for fam in sorted({r.family for r in R}):
            train = tuple(sorted(r.p_simulated for r in R if r.family != fam))
            assert (len(train), train) in seen  # fitted on this route's other families only
    assert all(0.0 < p < 1.0 and s == r.success() for r, p, s in pairs)


def _campaign(folder: Path, route, downlinks):
    """A minimal campaign folder: manifest (with or without the route option) and one records file per downlink
    ``(sha, family, records)``."""
    (folder / "records").mkdir(parents=True)
    opts = {} if route is None else {"predict_route": route}
    (folder / "manifest.json").write_text(json.dumps({"options": opts}))
    for i, (sha, fam, recs) in enumerate(downlinks):
        head = {"kind": "downlink", "status": "ok", "downlink_sha256": sha, "family": fam,
                "job": {"path": f"/x/{fam}_1/d{i}.mcap"}}
        (folder / "records" / f"d{i}.jsonl").write_text("".join(json.dumps(r) + "\n" for r in [head] + recs))


def test_rows_join_predictions_and_chains_by_downlink_and_target(tmp_path):
    """p_simulated from the record's prediction (or, in records from before the calibration, its confidence);
    the outcome from the chain's last hazcam step (none: a miss); predictions without a chain, or that failed,
    are left out; a downlink in two chain folders is taken from the first."""
    from scipctl.pipeline.prediction_calibration_fit import approach_rows

    def pred(t, conf, p_sim=None):
        p = {} if p_sim is None else {"p_simulated": p_sim}
        return {"kind": "prediction", "record": {"target": t, "confidence": conf, "prediction": p}}

    def chain(t, errs):
        return {"kind": "chain", "record": {"target": t, "steps": [{"camera": c, "error_px": e} for c, e in errs]}}

    _campaign(tmp_path / "P", None, [("a", "fam1", [pred("t1", 0.6, 0.9), pred("t2", 0.8), pred("t3", None),
                                                    pred("t4", 0.5)]),
                                     ("b", "fam2", [pred("t1", 0.55, 0.2)])])
    _campaign(tmp_path / "C1", None, [("a", "fam1", [chain("t1", [("pancam", 0.5), ("hazcam", 9.0), ("hazcam", 3.0)]),
                                                     chain("t2", [("pancam", 0.5), ("navcam", 1.0)]),
                                                     chain("t3", [("hazcam", 1.0)])])])
    _campaign(tmp_path / "C2", "downlink", [("a", "fam1", [chain("t1", [("hazcam", 99.0)])]),
                                            ("b", "fam2", [chain("t1", [("hazcam", 4.0)])])])
    rows = approach_rows([tmp_path / "P"], [tmp_path / "C1", tmp_path / "C2"])
    got = {(r.downlink_sha256, r.target): r for r in rows}
    assert set(got) == {("a", "t1"), ("a", "t2"), ("b", "t1")}
    assert got[("a", "t1")].p_simulated == 0.9 and got[("a", "t1")].chain_error_px == 3.0 and got[("a", "t1")].success()
    assert got[("a", "t2")].p_simulated == 0.8 and got[("a", "t2")].chain_error_px is None
    assert not got[("a", "t2")].success()
    assert got[("b", "t1")].success() and got[("b", "t1")].family == "fam2" and got[("b", "t1")].route == "plan"
    assert got[("a", "t1")].downlink == "fam1_1/d0.mcap"
