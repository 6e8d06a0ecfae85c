"""Fit the designation trust model (scipctl/pipeline/designation_trust.py) and report it held out.

    python docs/scripts/fit_designation_trust.py tests/data/designation/designations.jsonl.gz \\
        -o scipctl/data/designation_model.json [--report report.json] [--with-window-gap]

The packaged model is exactly this command's output on the committed table (tests/pipeline/
test_designation_trust.py re-runs it and compares the bytes). The table is made by
docs/scripts/designation_population.py.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import sys
from pathlib import Path

COMMAND = "python docs/scripts/fit_designation_trust.py tests/data/designation/designations.jsonl.gz -o scipctl/data/designation_model.json"


def read_rows(path: Path):
    from scipctl.pipeline.designation_trust import DesignationEvidence, DesignationRow

    raw = path.read_bytes()
    text = gzip.decompress(raw).decode() if path.suffix == ".gz" else raw.decode()
    rows = [json.loads(line) for line in text.splitlines() if line.strip()]
    return [DesignationRow(r["family"], DesignationEvidence.from_dict(r["evidence"]), float(r["error_pct"]))
            for r in rows], hashlib.sha256(raw).hexdigest()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("table", type=Path)
    ap.add_argument("-o", "--out", type=Path, required=True)
    ap.add_argument("--report", type=Path)
    ap.add_argument("--with-window-gap", action="store_true",
                    help="add the window range gap to the features (FEATURES_WITH_WINDOW_GAP)")
    a = ap.parse_args(argv)
    import sklearn

    from scipctl.io.atomic import atomic_write_text
    from scipctl.io.trust_model import trust_model_json
    from scipctl.pipeline.designation_trust import FEATURES, FEATURES_WITH_WINDOW_GAP, fit_designation_model, report

    rows, sha = read_rows(a.table)
    command = COMMAND + (" --with-window-gap" if a.with_window_gap else "")
    model = fit_designation_model(rows, provenance={"command": command, "input": a.table.name, "input_sha256": sha,
                                                    "scikit_learn": sklearn.__version__},
                                  features=FEATURES_WITH_WINDOW_GAP if a.with_window_gap else FEATURES)
    atomic_write_text(a.out, trust_model_json(model))
    if a.report:
        atomic_write_text(a.report, json.dumps(report(rows, model), indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
