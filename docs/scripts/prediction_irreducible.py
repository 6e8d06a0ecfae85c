"""What today's stop cannot know: the Brier score no pre-uplink prediction can beat, measured by drawing tomorrow's
errors anew (docs/sequence.md, "What today's stop cannot know").

    # the same scenes with tomorrow's random errors drawn anew (today's stop byte for byte the same)
    scipctl synth --scenario paper --seed S --family F --runs s1-straight --error-draw N -o draws/F-S-dN
    scipctl campaign draws/*/*.mcap --no-handoff --chain --predict --workers 2 -o predD
    python docs/scripts/prediction_irreducible.py PRED0 predD [--success-px 4] [--boot 2000] [--json]

Each campaign folder holds chain and prediction records; a downlink's scene is the name of the folder holding it,
without a trailing ``-dN`` (draw N; no suffix: draw 0, the seed's own errors), and the file's name, so draw 0 may come from the
campaign of the original renders (PRED0). A campaign that rendered its scenes itself
(``campaign --synth paper --seeds A-B --families ... --error-draws 0-3``) names its jobs the same way. An approach is a (scene, target) with a chain in every draw and the same
truth target in every draw (read from the ``.sim.json`` beside each downlink). Its outcome in a draw: the chain's
last hazcam answer within ``--success-px`` of the mark (no hazcam answer: a miss), as
``prediction_vs_chain.py`` scores it.

With K draws and k successes, ``k (K - k) / (K (K - 1))`` is an unbiased estimate of ``p (1 - p)``, where p is the
approach's success probability given the scene and today's stop. Its mean over the approaches, B*, is the expected
Brier score of the best prediction that knows the whole scene and today's images: a lower bound for any prediction
made from today's stop, which knows less. The interval is a bootstrap over scenes (a scene's approaches share
terrain and texture, so they are resampled together).
"""

from __future__ import annotations

import argparse
import collections
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DRAW_SUFFIX = re.compile(r"^(?P<scene>.+)-d(?P<draw>[1-9][0-9]*)$")


@dataclass
class Approach:
    """One (scene, target): ``outcomes`` ``(K,)`` bool, one per draw (draw order); ``p_predicted`` the packaged
    P(success) of draw 0 (None without a prediction record) and ``p_spread`` its max - min over the draws;
    ``written`` whether draw 0's prediction wrote a sequence; ``draws`` the draws, in the order of ``outcomes``."""

    scene: str
    target: str
    outcomes: np.ndarray
    p_predicted: float | None
    p_spread: float
    written: bool | None
    draws: list


def scene_and_draw(folder_name: str) -> tuple[str, int]:
    """``"default-551-d2"`` -> ``("default-551", 2)``; a name without the suffix is draw 0."""
    m = DRAW_SUFFIX.match(folder_name)
    return (m.group("scene"), int(m.group("draw"))) if m else (folder_name, 0)


def chain_success(chain: dict, success_px: float) -> bool:
    from scipctl.pipeline.prediction_calibration_fit import last_hazcam_error_px

    err = last_hazcam_error_px(chain.get("steps", []))
    return err is not None and err <= success_px


def read_campaigns(dirs, success_px: float) -> tuple[list, list, list]:
    """Approaches over every draw found in the campaign folders ``dirs``; returns ``(approaches, excluded, draws)``
    (``excluded``: ``(scene, target, why)``; ``draws``: every draw seen). A scene's approaches need a chain in each
    draw of that scene (scenes may have different numbers of draws, at least 2). A (scene, draw) in two folders is
    taken from the first."""
    from scipctl.campaign.results import DownlinkResult

    seen = {}
    for d in dirs:
        for f in sorted((Path(d) / "records").glob("*.jsonl")):
            try:
                res = DownlinkResult.from_jsonl(f.read_text())
            except ValueError as e:  # named here: main's one line says which file
                raise ValueError(f"{f}: {e}") from None
            if res.status != "ok":
                continue
            job = res.job
            if job.synth is not None:  # campaign --synth --error-draws: the job's name ends in -dN, its recipe says N
                scene, draw = scene_and_draw(job.name)[0], job.synth.error_draw
            else:  # a folder may hold several runs: the scene is the folder (without -dN) and the file's name
                base, draw = scene_and_draw(Path(job.path).parent.name)
                scene = f"{base}/{Path(job.path).name}"
            if (scene, draw) in seen:
                continue
            truth = res.truth_targets
            if not truth:  # records from before the header kept them: the simulation record beside the file
                path = Path(job.path)
                sim_path = path.with_name(path.name.removesuffix(".mcap") + ".sim.json")
                try:
                    truth = {t["id"]: t["xyz_site_m"] for t in json.loads(sim_path.read_text())["targets"]}
                except (OSError, ValueError, KeyError, TypeError) as e:
                    raise ValueError(f"{sim_path}: targets: {type(e).__name__}: {e}") from None
            recs = [("chain", c) for c in res.chains] + [("prediction", p) for p in res.predictions]
            seen[(scene, draw)] = (recs, {k: tuple(float(x) for x in v) for k, v in truth.items()})
    draws_of = collections.defaultdict(list)
    for scene, draw in sorted(seen):
        draws_of[scene].append(draw)
    by = collections.defaultdict(dict)
    for (scene, draw), (recs, truth) in seen.items():
        for kind, rec in recs:
            e = by[(scene, rec["target"])].setdefault(draw, {"truth": truth.get(rec["target"])})
            e[kind] = rec
    approaches, excluded = [], []
    for (scene, tgt), v in sorted(by.items()):
        draws = draws_of[scene]
        if len(draws) < 2:
            excluded.append((scene, tgt, "one draw only"))
            continue
        if sorted(v) != draws or any("chain" not in v[d] for d in draws):
            excluded.append((scene, tgt, "no chain in some draw"))
            continue
        if len({v[d]["truth"] for d in draws}) != 1:
            excluded.append((scene, tgt, "another truth target in some draw"))
            continue
        ps = [v[d]["prediction"].get("confidence") or 0.0 for d in draws if "prediction" in v[d]]
        pred0 = v[draws[0]].get("prediction")
        approaches.append(Approach(scene, tgt, np.array([chain_success(v[d]["chain"], success_px) for d in draws]),
                                   None if pred0 is None else (pred0.get("confidence") or 0.0),
                                   float(max(ps) - min(ps)) if ps else 0.0,
                                   None if pred0 is None else bool(pred0.get("sequence_written")), draws))
    return approaches, excluded, sorted({d for _, d in seen})


def variance_unbiased(k: np.ndarray, n_draws) -> np.ndarray:
    """Unbiased estimate of ``p (1 - p)`` from ``k`` ``(N,)`` successes in ``n_draws`` (a number, or ``(N,)``) >= 2
    Bernoulli(p) draws: ``k (K - k) / (K (K - 1))`` (the sample variance with Bessel's correction)."""
    k = np.asarray(k, float)
    n = np.broadcast_to(np.asarray(n_draws, float), k.shape)
    if np.any(n < 2):
        raise ValueError(f"n_draws: need at least 2 draws, got {n_draws}")
    if np.any((k < 0) | (k > n)):
        raise ValueError("k: successes must lie in [0, n_draws]")
    return k * (n - k) / (n * (n - 1.0))


def _counts(apps: list) -> tuple[np.ndarray, np.ndarray]:
    """Per approach ``(successes k, draws K)``, each ``(N,)`` float."""
    return (np.array([a.outcomes.sum() for a in apps], float), np.array([len(a.outcomes) for a in apps], float))


def figures(apps: list) -> dict:
    """B*, the packaged prediction's Brier score, the base rate's, and how the outcomes split. Every figure is a
    mean over approaches of that approach's mean over its draws (so an approach weighs the same whatever its K)."""
    k, n = _counts(apps)
    rate = float(np.mean(k / n))
    out = {"approaches": len(apps), "runs": int(n.sum()), "draws_per_approach": sorted({int(x) for x in n}),
           "success_rate": rate, "b_star": float(variance_unbiased(k, n).mean()),
           "all_succeed": int(np.sum(k == n)), "all_miss": int(np.sum(k == 0)), "mixed": int(np.sum((k > 0) & (k < n)))}
    if all(a.p_predicted is not None for a in apps):
        out["brier_predicted"] = float(np.mean([np.mean((a.p_predicted - a.outcomes) ** 2) for a in apps]))
        out["brier_base_rate"] = float(np.mean([np.mean((rate - a.outcomes) ** 2) for a in apps]))
        w = np.array([bool(a.written) for a in apps])
        out["written"] = int(w.sum())
        out["written_runs"] = int(n[w].sum())
        out["written_runs_missed"] = int(np.sum(n[w] - k[w]))
        out["successes_with_sequence"] = int(k[w].sum())
        out["successes"] = int(k.sum())
    return out


def bootstrap(apps: list, boot: int, seed: int = 32) -> dict:
    """90 % intervals of B* and of the packaged Brier score, resampling whole scenes (``boot`` resamples)."""
    scenes = sorted({a.scene for a in apps})
    of = {s: [a for a in apps if a.scene == s] for s in scenes}
    rng = np.random.default_rng(seed)
    got = collections.defaultdict(list)
    for _ in range(boot):
        sel = [a for i in rng.integers(0, len(scenes), len(scenes)) for a in of[scenes[i]]]
        f = figures(sel)
        for key in ("b_star", "brier_predicted"):
            if key in f:
                got[key].append(f[key])
    return {key: [float(np.quantile(v, 0.05)), float(np.quantile(v, 0.95))] for key, v in got.items()}


def oracle_writing(apps: list, thresholds=(0.25, 0.5, 0.75, 1.0)) -> list:
    """A prediction that knew each approach's k / K and wrote a sequence when it is >= t: written approaches, the
    share of their runs that missed and the share of all successes that had a sequence (in-sample: the same draws
    set p and score it, so this flatters the oracle)."""
    k, n = _counts(apps)
    rows = []
    for t in thresholds:
        w = k / n >= t - 1e-12
        runs = float(n[w].sum())
        rows.append({"t": t, "written": int(w.sum()), "runs_missed_share": (runs - float(k[w].sum())) / runs if runs else 0.0,
                     "successes_with_sequence_share": float(k[w].sum() / k.sum()) if k.sum() else 0.0})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaigns", nargs="+", type=Path)
    ap.add_argument("--success-px", type=float, default=4.0)
    ap.add_argument("--boot", type=int, default=2000)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    try:
        apps, excluded, draws = read_campaigns(a.campaigns, a.success_px)
    except (OSError, ValueError, KeyError) as e:  # a records file or a simulation record that cannot be read
        print(f"prediction_irreducible: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    if not apps:
        print(f"need approaches in at least 2 draws (draws found: {draws})", file=sys.stderr)
        return 2
    with_p = [x for x in apps if x.p_predicted is not None]
    report = {"draws": draws, "excluded": excluded, "all": figures(apps),
              "with_prediction": figures(with_p) if with_p else None,
              "interval_90": bootstrap(with_p or apps, a.boot),
              "max_prediction_spread_over_draws": max((x.p_spread for x in apps), default=0.0),
              "oracle_writing": oracle_writing(with_p or apps),
              "per_draw_success": {d: float(np.mean([x.outcomes[x.draws.index(d)] for x in apps if d in x.draws]))
                                   for d in draws},
              "per_scene": {s: {x.target: int(x.outcomes.sum()) for x in apps if x.scene == s}
                            for s in sorted({x.scene for x in apps})}}
    if a.json:
        print(json.dumps(report, indent=1))
        return 0
    f = report["with_prediction"] or report["all"]
    lo, hi = report["interval_90"]["b_star"]
    print(f"draws {draws} ({f['draws_per_approach']} per approach); approaches {f['approaches']} "
          f"({len(excluded)} excluded); runs {f['runs']}; "
          f"chain within {a.success_px:g} px {100 * f['success_rate']:.0f} %")
    print(f"outcome the same in every draw: {f['all_succeed']} succeed, {f['all_miss']} miss; mixed {f['mixed']}")
    print(f"B* = {f['b_star']:.4f} (90 % {lo:.4f} - {hi:.4f})")
    if "brier_predicted" in f:
        plo, phi = report["interval_90"]["brier_predicted"]
        print(f"packaged prediction: Brier {f['brier_predicted']:.3f} (90 % {plo:.3f} - {phi:.3f}); base rate "
              f"{f['brier_base_rate']:.3f}; its P differs between draws by at most "
              f"{report['max_prediction_spread_over_draws']:.3g}")
        print(f"packaged sequences: {f['written']} written, {f['written_runs_missed']} of their "
              f"{f['written_runs']} runs missed; {f['successes_with_sequence']} of {f['successes']} successes had one")
    for r in report["oracle_writing"]:
        print(f"oracle writes when k/K >= {r['t']:.2f}: {r['written']} approaches, "
              f"{100 * r['runs_missed_share']:.0f} % of their runs missed, "
              f"{100 * r['successes_with_sequence_share']:.0f} % of the successes had one")
    return 0


if __name__ == "__main__":
    sys.exit(main())
