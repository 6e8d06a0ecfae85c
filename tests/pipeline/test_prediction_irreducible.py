"""docs/scripts/prediction_irreducible.py: the unbiased p(1 - p) estimator (exact expectation), reading campaigns
over error draws, the figures on hand-made records, and its exit codes."""

import json
import math

import numpy as np
import pytest

from scipctl.campaign.jobs import DownlinkJob, synth_jobs
from scipctl.campaign.results import DownlinkResult
from tests import doc_scripts

pi = doc_scripts.load("prediction_irreducible")


def test_variance_estimate_on_hand_values():
    got = pi.variance_unbiased(np.array([0, 1, 2, 3, 4]), 4)
    assert got.tolist() == [0.0, 3 / 12, 4 / 12, 3 / 12, 0.0]


@pytest.mark.parametrize("n_draws", [2, 3, 4, 7])
@pytest.mark.parametrize("p", [0.0, 0.1, 0.5, 0.73, 1.0])
def test_variance_estimate_is_unbiased_exactly(n_draws, p):
    """Its expectation under Binomial(K, p), summed exactly over k, is p (1 - p) (to float rounding)."""
    k = np.arange(n_draws + 1)
    pmf = np.array([math.comb(n_draws, int(i)) * p**i * (1 - p) ** (n_draws - i) for i in k])
    assert float(np.sum(pmf * pi.variance_unbiased(k, n_draws))) == pytest.approx(p * (1 - p), abs=1e-12)


def test_variance_estimate_refuses_bad_counts():
    with pytest.raises(ValueError, match="n_draws"):
        pi.variance_unbiased(np.array([0]), 1)
    with pytest.raises(ValueError, match="k"):
        pi.variance_unbiased(np.array([5]), 4)
    with pytest.raises(ValueError, match="n_draws"):
        pi.variance_unbiased(np.array([0, 1]), np.array([3, 1]))
    assert pi.variance_unbiased(np.array([1, 1]), np.array([2, 4])).tolist() == [0.5, 0.25]


def test_scene_and_draw():
    assert pi.scene_and_draw("default-551-d2") == ("default-551", 2)
    assert pi.scene_and_draw("default-551") == ("default-551", 0)
    assert pi.scene_and_draw("errors-double-563-d13") == ("errors-double-563", 13)


def _campaign(root, name, downlinks, run="s1-straight"):
    """A campaign folder: ``downlinks`` = [(scene_folder, {target: (hazcam error px or None, P, written)},
    {target: truth xyz})], each file ``paper-RUN.mcap``."""
    rec_dir = root / name / "records"
    rec_dir.mkdir(parents=True)
    for i, (folder, per_target, truth) in enumerate(downlinks):
        dl = root / "scenes" / folder / f"paper-{run}.mcap"
        dl.parent.mkdir(parents=True, exist_ok=True)
        dl.write_bytes(b"x")
        (dl.parent / f"paper-{run}.sim.json").write_text(json.dumps(
            {"targets": [{"id": t, "xyz_site_m": list(xyz)} for t, xyz in truth.items()]}))
        res = DownlinkResult(DownlinkJob(dl.name, "default", f"sha{i}", path=str(dl)), "k")
        for t, (err, p, written) in per_target.items():
            steps = [{"camera": "navcam", "error_px": 1.0}] + ([{"camera": "hazcam", "error_px": err}] if err is not None else [])
            res.chains.append({"target": t, "steps": steps})
            if p is not None:
                res.predictions.append({"target": t, "confidence": p, "sequence_written": written})
        (rec_dir / f"job{run}{i}.jsonl").write_text(res.to_jsonl())
    return root / name


def test_reads_draws_and_scores_them(tmp_path):
    T = {"t1": (1.0, 2.0, 0.0), "t2": (3.0, 1.0, 0.0), "t3": (0.0, 0.0, 0.0)}
    moved = dict(T, t3=(0.5, 0.0, 0.0))
    c0 = _campaign(tmp_path, "c0", [("a-1", {"t1": (1.0, 0.8, True), "t2": (9.0, 0.6, True), "t3": (1.0, 0.5, False)}, T),
                                    ("b-2", {"t1": (None, 0.4, False)}, {"t1": T["t1"]})])
    cd = _campaign(tmp_path, "cd", [("a-1-d1", {"t1": (2.0, 0.8, True), "t2": (1.0, 0.6, True), "t3": (1.0, 0.5, False)}, moved),
                                    ("b-2-d1", {"t1": (3.0, 0.4, False)}, {"t1": T["t1"]}),
                                    ("a-1-d2", {"t1": (3.9, 0.8, True), "t2": (5.0, 0.6, True), "t3": (1.0, 0.5, False)}, T),
                                    ("b-2-d2", {"t1": (None, 0.4, False)}, {"t1": T["t1"]})])
    apps, excluded, draws = pi.read_campaigns([c0, cd], 4.0)
    assert draws == [0, 1, 2]
    A, B = "a-1/paper-s1-straight.mcap", "b-2/paper-s1-straight.mcap"
    assert excluded == [(A, "t3", "another truth target in some draw")]
    got = {(a.scene, a.target): a.outcomes.tolist() for a in apps}
    assert got == {(A, "t1"): [True, True, True], (A, "t2"): [False, True, False], (B, "t1"): [False, True, False]}
    f = pi.figures(apps)
    # k = 3, 1, 1 of K = 3: p(1-p) estimates 0, 1/3, 1/3
    assert f["b_star"] == pytest.approx(2 / 9) and (f["all_succeed"], f["all_miss"], f["mixed"]) == (1, 0, 2)
    y = np.array([[1, 1, 1], [0, 1, 0], [0, 1, 0]], float)
    p = np.array([[0.8], [0.6], [0.4]])
    assert f["brier_predicted"] == pytest.approx(np.mean((p - y) ** 2))
    assert f["brier_base_rate"] == pytest.approx(np.mean((5 / 9 - y) ** 2))
    assert (f["written"], f["written_runs"], f["written_runs_missed"], f["successes_with_sequence"], f["successes"]) == (2, 6, 2, 4, 5)
    rows = pi.oracle_writing(apps, thresholds=(0.3, 1.0))
    assert rows[0]["written"] == 3 and rows[0]["runs_missed_share"] == pytest.approx(4 / 9)
    assert rows[1] == {"t": 1.0, "written": 1, "runs_missed_share": 0.0, "successes_with_sequence_share": pytest.approx(3 / 5)}
    lo_hi = pi.bootstrap(apps, 200)["b_star"]
    assert 0.0 <= lo_hi[0] <= f["b_star"] <= lo_hi[1] <= 1 / 3


def test_main_needs_two_draws_and_prints_json(tmp_path, capsys):
    T = {"t1": (1.0, 2.0, 0.0)}
    c0 = _campaign(tmp_path, "c0", [("a-1", {"t1": (1.0, 0.8, True)}, T)])
    assert pi.main([str(c0)]) == 2
    cd = _campaign(tmp_path, "cd", [("a-1-d1", {"t1": (7.0, 0.8, True)}, T)])
    capsys.readouterr()
    assert pi.main([str(c0), str(cd), "--json", "--boot", "50"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["draws"] == [0, 1] and rep["with_prediction"]["b_star"] == pytest.approx(0.5)


def test_reads_a_synth_campaigns_jobs_and_header_truth(tmp_path):
    rec_dir = tmp_path / "c" / "records"
    rec_dir.mkdir(parents=True)
    for draw, err in ((0, 1.0), (1, 6.0), (2, 2.0)):
        (job,) = synth_jobs("paper", [5], ["s1-straight"], ["sand-sheet"], error_draws=[draw])
        res = DownlinkResult(job, "k", truth_targets={"t1": [1.0, 2.0, 0.0]},
                             chains=[{"target": "t1", "steps": [{"camera": "hazcam", "error_px": err}]}])
        (rec_dir / f"{draw}.jsonl").write_text(res.to_jsonl())
    apps, excluded, draws = pi.read_campaigns([tmp_path / "c"], 4.0)
    assert draws == [0, 1, 2] and not excluded
    assert [(a.scene, a.target, a.outcomes.tolist(), a.p_predicted) for a in apps] == [
        ("paper-s1-straight-seed5-sand-sheet", "t1", [True, False, True], None)]


def test_scenes_with_different_numbers_of_draws_pool_per_approach(tmp_path):
    """One scene with 2 draws, one with 4: each approach is scored over its own scene's draws, each weighs the same."""
    T = {"t1": (1.0, 2.0, 0.0)}
    c = _campaign(tmp_path, "c", [("a-1", {"t1": (1.0, 0.5, True)}, T), ("a-1-d1", {"t1": (9.0, 0.5, True)}, T),
                                  ("b-2", {"t1": (1.0, 0.9, True)}, T), ("b-2-d1", {"t1": (1.0, 0.9, True)}, T),
                                  ("b-2-d2", {"t1": (1.0, 0.9, True)}, T), ("b-2-d3", {"t1": (9.0, 0.9, True)}, T),
                                  ("c-3", {"t1": (1.0, 0.9, True)}, T)])
    apps, excluded, draws = pi.read_campaigns([c], 4.0)
    assert draws == [0, 1, 2, 3] and excluded == [("c-3/paper-s1-straight.mcap", "t1", "one draw only")]
    assert [(a.scene, a.draws, a.outcomes.tolist()) for a in apps] == [
        ("a-1/paper-s1-straight.mcap", [0, 1], [True, False]), ("b-2/paper-s1-straight.mcap", [0, 1, 2, 3], [True, True, True, False])]
    f = pi.figures(apps)
    assert f["b_star"] == pytest.approx((1 * 1 / 2 + 3 * 1 / 12) / 2)
    assert f["success_rate"] == pytest.approx((0.5 + 0.75) / 2) and f["runs"] == 6
    assert f["brier_predicted"] == pytest.approx((0.25 + (3 * 0.01 + 0.81) / 4) / 2)


def test_two_runs_in_one_folder_are_two_scenes(tmp_path):
    """A folder holding s1-straight and s2-arc (as `synth --runs s1-straight,s2-arc` writes): each run is its own
    scene with its own draws, not one run taken for the other's draw."""
    T = {"t1": (1.0, 2.0, 0.0)}
    _campaign(tmp_path, "c", [("a-1", {"t1": (1.0, 0.5, True)}, T), ("a-1-d1", {"t1": (9.0, 0.5, True)}, T)])
    _campaign(tmp_path, "c2", [("a-1", {"t1": (2.0, 0.5, True)}, T), ("a-1-d1", {"t1": (3.0, 0.5, True)}, T)],
              run="s2-arc")
    apps, excluded, _ = pi.read_campaigns([tmp_path / "c", tmp_path / "c2"], 4.0)
    assert not excluded
    assert [(a.scene, a.outcomes.tolist()) for a in apps] == [("a-1/paper-s1-straight.mcap", [True, False]),
                                                              ("a-1/paper-s2-arc.mcap", [True, True])]


def test_an_unreadable_records_file_exits_2_in_one_line(tmp_path, capsys):
    (tmp_path / "c" / "records").mkdir(parents=True)
    (tmp_path / "c" / "records" / "x.jsonl").write_text("{}\n")
    assert pi.main([str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "records file" in err and "x.jsonl" in err


def test_a_missing_simulation_record_exits_2_naming_it(tmp_path, capsys):
    """Records from before the header kept the truth targets read them from the .sim.json beside the downlink; when
    it is gone the one line names that file and its field."""
    c = _campaign(tmp_path, "c", [("a-1", {"t1": (1.0, 0.5, True)}, {"t1": (1.0, 2.0, 0.0)})])
    sim = tmp_path / "scenes" / "a-1" / "paper-s1-straight.sim.json"
    sim.unlink()
    assert pi.main([str(c)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(sim) in err and "targets" in err
