"""docs/scripts/first_track_truth.py: the first pancam track from the exact mark with templates drawn through the
true scene and through the chain's plane and measured surfaces (docs/stereo-and-tracking.md, "The first pancam
track's template"), on the bundled paper-s1-straight (a simulated downlink with its .sim.json)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.doc_scripts import load

ROOT = Path(__file__).resolve().parents[2]
SOL = ROOT / "sample_sols/mcap/paper-s1-straight.mcap"


def test_the_true_scene_template_lands_on_the_mark_and_the_plane_does_not(capsys):
    ftt = load("first_track_truth")
    assert ftt.main([str(SOL), "--json"]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    rows = {r["target"]: r["templates"] for r in lines[:-1]}
    assert set(rows) == {"t1", "t2", "t3"} and set(lines[-1]["summary"]) == set(ftt.TEMPLATES)

    def err(t, name):
        return float(np.hypot(*rows[t][name][:2]))

    # t2 and t3 sit on relief the 10 m -> 4.5 m step sees along its line of sight: drawn through the simulator's
    # own mesh with the true poses and models the template is a perfect warp up to resampling and the NCC's
    # sub-pixel fit (measured 0.19 and 0.23 px, NCC 0.91 and 0.94, the same with OpenCV 5.0 and 4.14 and with one
    # thread: no SGBM in it; bound 0.5 px), through the chain's plane it is pulled off (its normal is from the 10 m
    # SGBM: measured 4.59 and 2.95 px with OpenCV 5.0, one thread or many, 3.99 and 2.56 with 4.14; bound 1.5 px).
    # t1's texture changes too much between the two views for either (12.1 and 12.0 px, NCC 0.33): not asserted.
    for t in ("t2", "t3"):
        assert err(t, "surface") < 0.5 and rows[t]["surface"][2] > 0.8, (t, rows[t]["surface"])
        assert err(t, "plane") > 1.5, (t, rows[t]["plane"])
    s = lines[-1]["summary"]["surface"]
    assert s["n"] == 3 and s["within_0.5"] >= 2


def test_a_downlink_without_its_sim_record_is_refused_in_one_line(tmp_path, capsys):
    ftt = load("first_track_truth")
    dl = tmp_path / "copy.mcap"
    shutil.copy(SOL, dl)
    with pytest.raises(SystemExit) as e:
        ftt.main([str(dl)])
    err = capsys.readouterr().err.strip().splitlines()
    # argparse's usage, then the one line naming the record; no traceback
    assert e.value.code == 2 and "simulator record copy.sim.json" in err[-1] and not any("Traceback" in x for x in err)
