"""docs/scripts/scip_family_summary.py: scip's answers per family from campaign folders and simulate-handoff outputs."""

import json

import pytest

from tests.doc_scripts import load

sfs = load("scip_family_summary")


def _scip(target, error_px, p, go, chosen=("mesh-registration/near",)):
    return {"method": "scip", "target": target, "downlink": "paper-s1-straight.mcap", "navcam": "near",
            "truth_uv": [1.0, 2.0], "error_px": error_px, "p_success": p, "go": go,
            "diagnostics": {"chosen": list(chosen)}}


def _campaign(root, family, records):
    (root / "records").mkdir(parents=True)
    lines = [json.dumps({"kind": "handoff", "family": family, "record": r}) for r in records]
    lines.append(json.dumps({"kind": "chain", "family": family, "record": {}}))  # not a handoff: skipped
    (root / "records" / "x.jsonl").write_text("\n".join(lines) + "\n")
    return root


def test_figures_per_family_and_the_misses(tmp_path, capsys):
    camp = _campaign(tmp_path / "camp", "sand-sheet", [
        _scip("t1", 0.5, 0.99, True), _scip("t2", 6.0, 0.95, True),  # a wrong GO
        _scip("t3", None, None, False),  # no answer: a miss, p counted as 0
        dict(_scip("t4", 0.1, 0.99, True), method="consensus"),  # not scip
        dict(_scip("t5", 0.1, 0.99, True), truth_uv=None)])  # no truth: not scored
    out_file = tmp_path / "bedrock-slabs-7.json"  # a simulate-handoff --json output, family from its name
    out_file.write_text(json.dumps({"results": [_scip("t1", 3.0, 0.5, False)]}))
    sfs.main([str(camp), str(out_file), "--misses"])
    cap = capsys.readouterr()
    got = json.loads(cap.out)
    assert got["sand-sheet"] == {"targets": 3, "within": 1, "within_pct": 33.3, "median_px": 3.25, "go": 2,
                                 "go_right": 1, "misses": 2, "misses_nogo": 1,
                                 "brier": round((0.01 ** 2 + 0.95 ** 2 + 0.0) / 3, 4)}
    assert got["bedrock-slabs"]["within"] == 1 and got["bedrock-slabs"]["go"] == 0
    assert got["all"]["targets"] == 4 and got["all"]["within"] == 2
    lines = cap.err.splitlines()
    assert len(lines) == 2  # the two sand-sheet misses, nothing else
    assert lines[0].split()[:8] == ["sand-sheet", "paper-s1-straight.mcap", "t2", "6.00", "px", "p", "0.950", "GO"]
    assert "no answer" in lines[1] and "NO-GO" in lines[1]


def test_without_misses_nothing_on_stderr(tmp_path, capsys):
    camp = _campaign(tmp_path / "camp", "default", [_scip("t1", 9.0, 0.1, False)])
    sfs.main([str(camp)])
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("what", ["missing", "no-records", "not-json", "empty"])
def test_bad_input_is_a_usage_error(tmp_path, what):
    if what == "missing":
        arg = tmp_path / "nothing-here"
    elif what == "no-records":
        arg = tmp_path / "camp"
        arg.mkdir()
    elif what == "not-json":
        arg = tmp_path / "default-1.json"
        arg.write_text("not json")
    else:  # a campaign with no scored scip answer
        arg = _campaign(tmp_path / "camp", "default", [])
    with pytest.raises(SystemExit) as ei:
        sfs.main([str(arg)])
    assert ei.value.code == 2
