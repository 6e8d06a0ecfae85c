"""Choosing targets: visible in every key image, all kinds over the paper runs (scipctl/sim/targets.py)."""

from scipctl.sim.build import build_run
from scipctl.sim.scenarios import KINDS, list_runs

from .conftest import SMALL


def test_targets_visible_in_every_key_image(run_errors):
    dl = run_errors.downlink
    for tm in dl.targets:
        marked = {m.product_id for m in tm.marks}
        for stop, cam in run_errors.plan.key_images:
            for eye in "LR":
                assert f"s1-straight-{stop}-{cam}-{eye}" in marked, (tm.id, stop, cam, eye)


def test_paper_has_18_cases_of_all_kinds():
    kinds = []
    for run in list_runs("paper"):
        sim = build_run("paper", run, 1, image_scale=SMALL, supersample=1, render=False)
        assert len(sim.downlink.targets) == 3
        assert len({t.kind for t in sim.downlink.targets}) == 3
        assert len({t.id for t in sim.downlink.targets}) == 3
        kinds += [t.kind for t in sim.downlink.targets]
        pos = sim.downlink.positions()
        assert len(pos) == len(set(pos)) == 4
    assert len(kinds) == 18
    assert set(kinds) == set(KINDS)
