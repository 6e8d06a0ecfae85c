"""docs/scripts/scip_evidence_summary.py: scip's choices over a folder of evidence tables, per run and family."""

import gzip
import itertools
import json
from pathlib import Path

import pytest

from scipctl.io.trust_model import load_trust_model
from tests.doc_scripts import load

ses = load("scip_evidence_summary")
TABLE = Path(__file__).resolve().parents[1] / "data" / "trust" / "evidence-36dl-16fam.jsonl.gz"


def test_one_choice_per_target_the_highest_p(tmp_path, capsys):
    lines = gzip.decompress(TABLE.read_bytes()).decode().splitlines()
    groups = [(g, list(c)) for g, c in itertools.groupby(lines, key=lambda s: json.loads(s)["group"])][:2]
    for g, chunk in groups:
        (tmp_path / (g[:-5] + ".jsonl")).write_text("\n".join(chunk) + "\n")
    model = load_trust_model(ses.PACKAGED)
    got = ses.choices_by_table(str(tmp_path), model, 4.0)
    want = sorted({(g[:-5] + ".jsonl", json.loads(s)["target"]) for g, chunk in groups for s in chunk})
    assert sorted((name, target) for name, _, target, _ in got) == want  # every target once
    for name, run, target, c in got:
        assert run == json.loads(next(s for g, ch in groups for s in ch if json.loads(s)["target"] == target
                                      and g[:-5] + ".jsonl" == name))["meta"]["run"]
        assert c.p == max(p for p, _ in c.candidates)  # scip answers with the candidate of the highest p
    ses.main([str(tmp_path)])
    out = capsys.readouterr().out
    assert out.startswith(f"visible                  n {sum(not c.occluded for *_, c in got):4d}")


def test_an_empty_folder_is_a_usage_error(tmp_path):
    with pytest.raises(SystemExit) as ei:
        ses.main([str(tmp_path)])
    assert ei.value.code == 2
