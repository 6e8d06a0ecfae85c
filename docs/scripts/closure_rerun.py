"""Run every recorded chain's closure check again with today's code, so that campaign records made before a new
closure field existed carry it (docs/stereo-and-tracking.md, "The closure's own consistency").

    python docs/scripts/closure_rerun.py OUTROOT CAMP1 CAMP2 ...   # -> OUTROOT/<name of CAMPi>/records/*.jsonl

Each chain whose final hazcam step has a closure record gets :func:`~scipctl.pipeline.chain_closure.closure_check`
again, from its own recorded steps (the handoff path's pixel as the final answer, as the chain checks it, also when
the chain adopted the closure); everything else in the records is kept. The closure's status and pixel must come out
as recorded (the chain is deterministic and the check depends only on the recorded steps and the downlink); a
closure that moves is reported on stderr and counted, and its new record is kept. Finished files are skipped, so a
stopped run resumes. Prints ``{"same": N, "moved": M}``. Downlinks of the real-texture families need
``SCIPCTL_SHARED_REAL``.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np


def rerun_file(src: Path, dst: Path, params) -> tuple[int, int]:
    """Re-run the closures of one campaign records file into ``dst``: ``(same, moved)``."""
    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.chain import ChainStep
    from scipctl.pipeline.chain_closure import closure_check

    lines = [json.loads(line) for line in src.read_text(encoding="utf-8").splitlines() if line.strip()]
    same = moved = 0
    header = lines[0]
    if header.get("status") == "ok":
        dl = read_downlink(header["job"]["path"])
        feats: dict = {}  # one keypoint cache per downlink, as the chain shares it between its targets
        for rec in lines[1:]:
            if rec.get("kind") != "chain" or not rec["record"].get("steps"):
                continue
            steps = [ChainStep.from_dict(s) for s in rec["record"]["steps"]]
            fi = next((i for i, s in enumerate(steps) if s.camera == "hazcam" and s.extra.get("final")), None)
            if fi is None or "closure" not in steps[fi].extra:
                continue
            check = [copy.deepcopy(s) for s in steps]
            if check[fi].extra.get("answer") == "closure":
                check[fi].tracked_uv = check[fi].extra["handoff"]["uv"]  # the check measures against the handoff's
            new = closure_check(dl, check, params, feats).to_dict()
            old = steps[fi].extra["closure"]
            same_uv = (old.get("uv") is None) == (new.get("uv") is None) and (
                old.get("uv") is None or float(np.max(np.abs(np.subtract(old["uv"], new["uv"])))) <= 1e-6)
            if same_uv and old.get("status") == new.get("status"):
                same += 1
            else:
                moved += 1
                print(f"moved: {src.name} {rec['record'].get('target')}: {old.get('status')} {old.get('uv')} -> "
                      f"{new.get('status')} {new.get('uv')}", file=sys.stderr)
            rec["record"]["steps"][fi]["extra"]["closure"] = new
    tmp = dst.with_suffix(".tmp")
    tmp.write_text("".join(json.dumps(x) + "\n" for x in lines), encoding="utf-8")
    tmp.replace(dst)
    return same, moved


def main(argv=None) -> None:
    from scipctl.pipeline.chain import ChainParams

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outroot")
    ap.add_argument("campaigns", nargs="+")
    args = ap.parse_args(argv)
    params = ChainParams()
    same = moved = 0
    for camp in args.campaigns:
        out = Path(args.outroot, Path(camp).name, "records")
        out.mkdir(parents=True, exist_ok=True)
        for f in sorted(Path(camp, "records").glob("*.jsonl")):
            if (out / f.name).exists():
                continue
            s, m = rerun_file(f, out / f.name, params)
            same, moved = same + s, moved + m
            print(f"{f.name}: same {same}, moved {moved}", file=sys.stderr, flush=True)
    print(json.dumps({"same": same, "moved": moved}))


if __name__ == "__main__":
    main()
