"""The campaign aggregate on records made here (no cluster): per-family sections, GO/NO-GO counts and
reliability from records that carry ``p_success`` / ``go`` (the trust work adds them), and a clean skip when
records carry neither; the HTML page shows what there is."""

import json
import math

import numpy as np
import pytest

from scipctl.campaign.jobs import DownlinkJob
from scipctl.campaign.options import CampaignOptions, job_key
from scipctl.campaign.results import DownlinkResult
from scipctl.campaign.store import FORMAT, CampaignStore, manifest_entry
from scipctl.campaign.summary import summarize, write_summary

OPTIONS = CampaignOptions(methods=("pure-kinematic",), pairs=(("pure-kinematic", "near"),), success_px=4.0)


def _handoff(name, target, err, p=None, go=None):
    rec = {"downlink": name, "target": target, "method": "pure-kinematic", "navcam": "near", "source_product": "n",
           "source_uv": [1.0, 2.0], "predicted_uv": [3.0, 4.0], "truth_uv": [3.0, 4.0 + err], "error_px": err,
           "success": err <= 4.0, "ok": True, "reason": "", "diagnostics": {}, "seconds": 0.1}
    if p is not None:
        rec.update(p_success=p, go=go)
    return rec


def _make_store(tmp_path, with_trust: bool, n_per_family: int = 30):
    """Two families of downlinks, one target each: a handoff record, a chain and a prediction; seeded."""
    rng = np.random.default_rng(7)
    store = CampaignStore(tmp_path / "out")
    store.make()
    manifest = {"format": FORMAT, "options": OPTIONS.to_dict(), "options_key": OPTIONS.key(), "downlinks": {}}
    truth = []  # (family, p, err, go, chain final err, chain p, confidence)
    for fam in ("flat", "rocky"):
        for i in range(n_per_family):
            name = f"{fam}-{i}"
            job = DownlinkJob(name, fam, f"{i:02d}{fam}".ljust(64, "0"))
            res = DownlinkResult(job, job_key(job.input_sha256, OPTIONS.key()))
            p, err = float(rng.uniform()), float(rng.exponential(6.0))
            ch_err, ch_p, conf = float(rng.exponential(6.0)), float(rng.uniform()), float(rng.uniform())
            go = p > 0.5
            res.handoff = [_handoff(name, "t1", err, p if with_trust else None, go)]
            step = {"camera": "hazcam", "error_px": ch_err, "mark_uv": [10.0, 20.0], "ok": True,
                    "extra": {"final": True}}
            first = {"camera": "navcam", "error_px": 1.0, "mark_uv": [1.0, 2.0], "ok": True, "extra": {}}
            if with_trust:
                step.update(p_success=ch_p, go=ch_p > 0.5)
                # a tracking step's p_success is for the step model's radius in mm, not success_px: left out
                first.update(p_success=0.3, go=False)
            res.chains = [{"downlink": name, "target": "t1", "steps": [first, step]}]
            res.predictions = [{"target": "t1", "confidence": conf, "sequence_written": conf > 0.3}]
            res.seconds, res.cpu_s = {"total": 1.0 + i, "handoff": 0.5}, 2.0
            store.write(res)
            manifest["downlinks"][job.job_id] = manifest_entry(job, res.key, "ok", res)
            truth.append((fam, p, err, go, ch_err, ch_p, conf))
    store.save_manifest(manifest)
    return store, truth


def _brier(pairs):
    return sum((p - float(y)) ** 2 for p, y in pairs) / len(pairs)


def test_go_and_reliability_from_records_that_carry_them(tmp_path):
    store, truth = _make_store(tmp_path, with_trust=True)
    s = summarize(store)
    assert set(s["families"]) == {"flat", "rocky"} and s["counts"]["downlinks"] == 60
    for fam, sec in list(s["families"].items()) + [("overall", s["overall"])]:
        rows = [t for t in truth if fam in ("overall", t[0])]
        go = sec["go"]["handoff"]["pure-kinematic"]
        assert go["go_success"] == sum(1 for t in rows if t[3] and t[2] <= 4.0)
        assert go["nogo_miss"] == sum(1 for t in rows if not t[3] and t[2] > 4.0)
        assert go["n"] == len(rows) and sum(go["error_hist"]["go"]) + sum(go["error_hist"]["nogo"]) == len(rows)
        rel = sec["reliability"]["handoff"]["pure-kinematic"]
        assert rel["n"] == len(rows)
        assert math.isclose(rel["brier"], _brier([(t[1], t[2] <= 4.0) for t in rows]), rel_tol=1e-12)
        for b in rel["bins"]:
            inside = [t for t in rows if b["lo"] <= t[1] < b["hi"]]
            assert b["n"] == len(inside)
            if inside:
                assert math.isclose(b["observed"], sum(t[2] <= 4.0 for t in inside) / len(inside), rel_tol=1e-12)
        # chain steps with p_success: the hazcam handoffs only (scip's p is for success_px; the tracking steps' is not)
        steps = sec["reliability"]["chain_steps"]
        assert math.isclose(steps["brier"], _brier([(t[5], t[4] <= 4.0) for t in rows]), rel_tol=1e-12)
        assert sec["go"]["chain_final"]["n"] == len(rows)
        # the prediction's P(success) against what the chain then did
        pv = sec["reliability"]["prediction_vs_chain"]
        assert math.isclose(pv["brier"], _brier([(t[6], t[4] <= 4.0) for t in rows]), rel_tol=1e-12)
        assert sec["chain"]["within_success_px"] == sum(1 for t in rows if t[4] <= 4.0)
    assert [x["seconds"]["total"] for x in s["slowest"]] == sorted([1.0 + i for i in range(30)] * 2, reverse=True)[:10]
    assert s["cpu"]["downlinks_per_core_hour"] == pytest.approx(3600 / 2.0)
    js, page = write_summary(store, s)
    html = page.read_text()
    assert "GO / NO-GO" in html and "Reliability" in html and html.count("<img") >= 3 * 4
    # strict JSON (a parser that refuses NaN/Infinity reads it): the histograms' open last edge is null
    def refuse(c):
        raise ValueError(c)

    doc = json.loads(js.read_text(), parse_constant=refuse)
    assert doc["overall"]["go"]["chain_final"]["error_edges_px"][-1] is None


def test_no_trust_fields_means_no_go_tables_and_no_handoff_reliability(tmp_path):
    store, _ = _make_store(tmp_path, with_trust=False, n_per_family=3)
    s = summarize(store)
    assert s["overall"]["go"] == {"handoff": {}, "chain_final": None}
    assert s["overall"]["reliability"]["handoff"] == {} and s["overall"]["reliability"]["chain_steps"] is None
    assert s["overall"]["reliability"]["prediction_vs_chain"]["n"] == 6  # confidence is there without the trust work
    js, page = write_summary(store, s)
    assert "GO / NO-GO" not in page.read_text()


def test_chain_go_is_the_chains_verdict_when_recorded():
    """A chain record with its verdict (``go``: every step up to the final hazcam answer GO) counts as that, not
    as its final step's GO: a GO hazcam handoff after a NO-GO track is a NO-GO chain."""
    from scipctl.campaign.summary import _section

    job = DownlinkJob("d", "flat", "0" * 64)
    res = DownlinkResult(job, job_key(job.input_sha256, OPTIONS.key()))
    haz = {"camera": "hazcam", "error_px": 9.0, "mark_uv": [1.0, 1.0], "ok": True, "extra": {"final": True},
           "p_success": 0.99, "go": True}
    res.chains = [{"downlink": "d", "target": "t1", "steps": [haz], "go": False, "advice": "new image at this stop"},
                  {"downlink": "d", "target": "t2", "steps": [dict(haz, error_px=1.0)], "go": True}]
    go = _section([res], 4.0)["go"]["chain_final"]
    assert (go["nogo_miss"], go["go_success"], go["go_miss"], go["nogo_success"]) == (1, 1, 0, 0)


def test_the_summary_names_every_downlink_it_counts(tmp_path):
    # its provenance listed no inputs: a summary over a folder that two campaigns wrote could not say what it held
    store, _ = _make_store(tmp_path, with_trust=False, n_per_family=2)
    s = summarize(store)
    inputs = s["provenance"]["inputs"]
    assert len(inputs) == s["counts"]["downlinks"] == 4
    assert sorted(v["sha256"] for v in inputs.values()) == sorted(f"{i:02d}{f}".ljust(64, "0")
                                                                 for f in ("flat", "rocky") for i in range(2))


def test_an_unwritable_campaign_folder_is_exit_2_not_a_bug(tmp_path):
    from scipctl.errors import InputError

    store, _ = _make_store(tmp_path, with_trust=False, n_per_family=1)
    (store.out / "summary.json").mkdir()  # cannot be replaced by the summary
    with pytest.raises(InputError, match="cannot write the summary"):
        write_summary(store, summarize(store))
    (store.out / ".lock").unlink(missing_ok=True)
    (store.out / ".lock").mkdir()  # the lock cannot be opened: as on a read-only mount (root ignores chmod)
    with pytest.raises(InputError, match="cannot write here"):
        with store.locked():
            pass
