"""The chain records of campaign folders, for the measurement scripts beside this one (fit_step_trust.py,
fit_closure_trust.py, chain_answer_compare.py)."""

from __future__ import annotations

import json
from pathlib import Path


def family_of(header: dict, dirs: dict) -> str:
    """The family of a campaign record's downlink: the first ``dirs`` entry (DIR -> FAMILY) naming a component of
    its path, else the header's ``family`` (campaigns made before ``campaign`` read the family that
    ``synth --family`` records called every such downlink ``default``)."""
    path = (header.get("job") or {}).get("path")
    for part in Path(path).parts if path else ():
        if part in dirs:
            return dirs[part]
    return str(header.get("family") or "default")


def downlink_name(header: dict) -> str:
    """A downlink file named by its folder too (``scenes/def1/paper-s1-arc.mcap`` and def2's differ)."""
    path = (header.get("job") or {}).get("path")
    return f"{Path(path).parent.name}/{Path(path).name}" if path else str(header.get("downlink"))


def campaign_chains(campaigns: list, dirs: dict):
    """``(family, downlink name, chain record)`` of every chain of every downlink that ran (header status ``ok``),
    campaign by campaign, its records files in name order."""
    for out in campaigns:
        for f in sorted(Path(out, "records").glob("*.jsonl")):
            lines = [json.loads(line) for line in f.read_text(encoding="utf-8").splitlines() if line.strip()]
            header = lines[0]
            if header.get("status") != "ok":
                continue
            fam, name = family_of(header, dirs), downlink_name(header)
            for rec in lines[1:]:
                if rec.get("kind") == "chain":
                    yield fam, name, rec["record"]


def first_per_target(rows: list) -> list:
    """Table rows (each with ``family``, ``downlink`` and ``target``) with every row of a (downlink, target) seen
    before dropped (the same downlink in two campaigns, or in an added table and a campaign: its first rows kept),
    sorted by (family, downlink, target): the fit scripts' tables."""
    seen, unique = set(), []
    for r in rows:
        if (r.downlink, r.target) not in seen:
            seen.add((r.downlink, r.target))
            unique.append(r)
    return sorted(unique, key=lambda r: (r.family, r.downlink, r.target))


def recorded_chains(path) -> tuple[dict, list]:
    """One campaign records file: ``(header, [(chain record, its ChainStep list), ...])``, the chains with steps of
    a downlink that ran (none when its header's status is not ``ok``)."""
    from scipctl.pipeline.chain import ChainStep

    lines = [json.loads(line) for line in Path(path).read_text(encoding="utf-8").splitlines() if line.strip()]
    header, out = lines[0], []
    if header.get("status") == "ok":
        for rec in lines[1:]:
            if rec.get("kind") == "chain" and rec["record"].get("steps"):
                out.append((rec["record"], [ChainStep.from_dict(s) for s in rec["record"]["steps"]]))
    return header, out


def rerun_campaign(camp, run_file, workers: int = 1, initializer=None, initargs=()) -> tuple[list, int, int]:
    """``run_file(path) -> (rows, reproduced, moved)`` over every records file of the campaign folder ``camp``
    (``workers`` > 1: a process pool), summed: ``(rows, reproduced, moved)``. ValueError when ``camp`` has no
    ``records/*.jsonl``."""
    files = sorted(str(f) for f in Path(camp, "records").glob("*.jsonl"))
    if not files:
        raise ValueError(f"{camp}: no records/*.jsonl (not a campaign folder)")
    if workers > 1:
        from multiprocessing import Pool

        with Pool(workers, initializer=initializer, initargs=initargs) as pool:
            parts = pool.map(run_file, files)
    else:
        if initializer is not None:
            initializer(*initargs)
        parts = [run_file(f) for f in files]
    rows, same, moved = [], 0, 0
    for rw, sm, mv in parts:
        rows += rw
        same, moved = same + sm, moved + mv
    return rows, same, moved


def write_jsonl(path, rows: list) -> None:
    """``rows`` as JSON lines at ``path``, written to a temporary name first, then renamed."""
    import os

    tmp = f"{path}.tmp"
    with open(tmp, "w", encoding="utf-8") as fo:
        fo.write("".join(json.dumps(x) + "\n" for x in rows))
    os.replace(tmp, path)


def read_jsonl(path) -> list:
    """The JSON lines of ``path`` (OSError / ValueError as ``open`` and ``json`` raise them)."""
    return [json.loads(line) for line in Path(path).read_text(encoding="utf-8").splitlines() if line.strip()]


def rerun_parser(prog: str, description: str):
    """The command line of a script that runs parts of recorded chains again: ``run CAMP OUT [--workers N]`` and
    ``score ROWS [--json]``. Returns ``(parser, the run subparser)``, for the script's own ``run`` arguments."""
    import argparse

    ap = argparse.ArgumentParser(prog=prog, description=description)
    sub = ap.add_subparsers(dest="cmd", required=True)
    run = sub.add_parser("run")
    run.add_argument("camp")
    run.add_argument("out")
    run.add_argument("--workers", type=int, default=1)
    score = sub.add_parser("score")
    score.add_argument("rows")
    score.add_argument("--json", action="store_true")
    return ap, run


def rerun_main(ap, args, run_file, what: str, initializer=None, initargs=()) -> int:
    """The ``run`` command of a script that runs parts of recorded chains again: :func:`rerun_campaign` over
    ``args.camp`` into ``args.out``, ``{what: rows, "reproduced": N, "moved": M}`` on stderr; exit code 1 when a
    recorded answer moved, 2 (``ap.error``) when ``args.camp`` is no campaign folder."""
    import sys

    try:
        rows, same, moved = rerun_campaign(args.camp, run_file, args.workers, initializer, initargs)
    except ValueError as e:
        ap.error(str(e))
    write_jsonl(args.out, rows)
    print(json.dumps({what: len(rows), "reproduced": same, "moved": moved}), file=sys.stderr)
    return 1 if moved else 0


def score_main(ap, args, score, show) -> int:
    """The ``score`` command of such a script: ``score(rows)`` of the rows at ``args.rows``, as JSON with
    ``args.json``, else ``show(it)``; an unreadable file is refused by ``ap.error`` (exit code 2)."""
    try:
        rows = read_jsonl(args.rows)
    except (OSError, ValueError) as e:
        ap.error(f"{args.rows}: {e}")
    out = score(rows)
    if args.json:
        print(json.dumps(out))
    else:
        show(out)
    return 0


def plain_main(script: str, doc: str, run_file, what: str, score, show, argv=None) -> int:
    """``main`` of a script with ``run CAMP OUT [--workers N]`` (no variants) and ``score ROWS [--json]``: the
    parser of :func:`rerun_parser` (program ``script``'s file name, description ``doc``'s first line), then
    :func:`rerun_main` or :func:`score_main`."""
    ap, _ = rerun_parser(Path(script).name, doc.splitlines()[0])
    a = ap.parse_args(argv)
    if a.cmd == "run":
        return rerun_main(ap, a, run_file, what)
    return score_main(ap, a, score, show)


def auc(p, y):
    """The area under the ROC curve of scores ``p`` for the outcomes ``y`` (scikit-learn's ``roc_auc_score``: the
    chance that a positive outranks a negative, ties counted half); None when ``y`` holds one class only."""
    from sklearn.metrics import roc_auc_score

    y = [bool(v) for v in y]
    return float(roc_auc_score(y, list(p))) if 0 < sum(y) < len(y) else None
