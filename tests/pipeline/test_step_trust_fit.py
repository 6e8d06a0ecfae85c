"""The chain's step trust model: the packaged file is what its command makes from the committed chain table, and
the held-out evaluation never scores a family with a model that saw it (tests/data/chain_trust/README.md)."""

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sklearn")

ROOT = Path(__file__).resolve().parents[2]
TABLE = Path("tests/data/chain_trust/chains.jsonl.gz")
MODEL = Path("scipctl/data/step_trust_model.json")


@pytest.fixture(scope="module")
def chains():
    sys.path.insert(0, str(ROOT / "docs" / "scripts"))
    try:
        from fit_step_trust import read_table
    finally:
        sys.path.pop(0)
    return read_table(ROOT / TABLE)


def test_packaged_model_is_reproduced_bit_for_bit_by_its_command(tmp_path):
    """The command of the model's provenance, run on the committed table (same relative paths), writes the same
    bytes as the packaged file."""
    (tmp_path / TABLE.parent).mkdir(parents=True)
    shutil.copy(ROOT / TABLE, tmp_path / TABLE)
    (tmp_path / MODEL.parent).mkdir(parents=True)
    env = {"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, str(ROOT / "docs/scripts/fit_step_trust.py"), "fit", str(TABLE), "-o", str(MODEL)],
                       cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / MODEL).read_bytes() == (ROOT / MODEL).read_bytes()


def test_held_out_families_are_answered_by_models_that_never_saw_them(chains):
    from scipctl.pipeline.step_trust_fit import held_out, success_mm_of, training_steps

    smm = success_mm_of(chains)
    ho = held_out(chains, smm)
    fams = sorted({c.family for c in chains})
    assert sorted(ho) == fams and len(fams) >= 4
    for fam, (m, probs) in ho.items():
        _, y, _ = training_steps([c for c in chains if c.family != fam], smm)
        assert m.provenance == {} and len(probs) == sum(c.family == fam for c in chains)
        for c, pc in zip([c for c in chains if c.family == fam], probs):
            assert len(pc) == len(c.steps)
            for s, p in zip(c.steps, pc):
                if s.evidence is not None:
                    assert p is not None and 0.0 <= p <= 1.0
                    if not s.answered:
                        assert p == 0.0
        assert len(y) > 100  # fitted on the other families' steps


def test_packaged_model_scores_the_table_as_its_provenance_says(chains):
    from scipctl.io.step_trust_model import load_packaged_step_trust_model
    from scipctl.pipeline.step_trust_fit import GO_GRID, success_mm_of, training_steps

    m = load_packaged_step_trust_model()
    assert m is not None and m.go_min_p in GO_GRID
    assert m.success_mm == success_mm_of(chains) == m.provenance["success_mm"]
    ev, y, fams = training_steps(chains, m.success_mm)
    assert m.provenance["n_steps"] == len(y) and sorted(set(fams)) == m.provenance["training_families"]
    p = m.probability(ev)
    # in-sample, the fitted probabilities separate the outcomes (the held-out figures are in the docs)
    assert np.mean(p[y]) > np.mean(p[~y])


def test_a_table_grows_from_the_committed_one(tmp_path):
    """``table --add OLD``: the earlier table's chains kept (their campaigns need not exist any more), the campaigns'
    added. With no campaign records the committed table comes back byte for byte (read and written again, sorted and
    compressed as the command always does)."""
    import json

    (tmp_path / "camp" / "records").mkdir(parents=True)
    env = {"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, str(ROOT / "docs/scripts/fit_step_trust.py"), "table", str(tmp_path / "camp"),
                        "--add", str(ROOT / TABLE), "-o", str(tmp_path / "t.jsonl.gz")], env=env, capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stderr)
    assert out["added"] == out["chains"] > 0
    assert (tmp_path / "t.jsonl.gz").read_bytes() == (ROOT / TABLE).read_bytes()


def test_a_missing_table_to_add_is_one_line_and_exit_2(tmp_path):
    """``table --add`` of a file that is not there: one line naming it, exit code 2, nothing written."""
    (tmp_path / "camp" / "records").mkdir(parents=True)
    env = {"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    r = subprocess.run([sys.executable, str(ROOT / "docs/scripts/fit_step_trust.py"), "table", str(tmp_path / "camp"),
                        "--add", str(tmp_path / "missing.jsonl.gz"), "-o", str(tmp_path / "out.jsonl.gz")], env=env,
                       capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "missing.jsonl.gz" in r.stderr
    assert not (tmp_path / "out.jsonl.gz").exists()
