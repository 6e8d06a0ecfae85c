"""pipeline/chain_key.py: a chain's key changes with anything the chain reads, and handoff.json's keyed chains read
back (or name the field that is wrong)."""

from dataclasses import replace
from pathlib import Path

import pytest

from scipctl.core.stereo_selfcal import rotated_model
from scipctl.errors import InputError
from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import ChainParams, ChainStep
from scipctl.pipeline.chain_key import chain_key, keyed_chains_from_doc

SAMPLE = Path(__file__).resolve().parents[2] / "sample_sols/mcap/paper-s1-straight.mcap"


def test_the_key_changes_with_anything_the_chain_reads(monkeypatch):
    import scipctl.pipeline.chain_key as mod

    dl = read_downlink(SAMPLE)
    start = "s1-straight-pan10-pancam-L"
    key = chain_key(dl, start, [500.0, 400.0], "t1", ChainParams())
    assert len(key) == 64 and key == chain_key(read_downlink(SAMPLE), start, (500, 400), "t1", ChainParams())
    assert chain_key(dl, start, [500.0, 400.25], "t1", ChainParams()) != key
    assert chain_key(dl, "s1-straight-mid-pancam-L", [500.0, 400.0], "t1", ChainParams()) != key
    assert chain_key(dl, start, [500.0, 400.0], "t2", ChainParams()) != key
    assert chain_key(dl, start, [500.0, 400.0], "t1", ChainParams(answer="handoff")) != key
    right = dl.product("s1-straight-near-hazcam-R")  # a self-calibrated model is another model
    turned = replace(right, camera_model=rotated_model(right.camera_model, [0.0, 1e-9, 0.0]))
    other = replace(dl, images=[turned if im is right else im for im in dl.images])
    assert chain_key(other, start, [500.0, 400.0], "t1", ChainParams()) != key
    assert chain_key(replace(dl, source_sha256="0" * 64), start, [500.0, 400.0], "t1", ChainParams()) != key
    assert chain_key(replace(dl, source_sha256=""), start, [500.0, 400.0], "t1", ChainParams()) is None
    monkeypatch.setattr(mod, "code_identity", lambda parts: "other code")
    assert chain_key(dl, start, [500.0, 400.0], "t1", ChainParams()) != key


def _step(**kw):
    d = dict(position=[1, 0], camera="pancam", product_id="p", kind="designate", predicted_uv=None,
             tracked_uv=[1.0, 2.0], mark_uv=None, error_px=None, ncc_peak=None, range_m=9.5, xyz_site_m=None,
             truth_xyz_site_m=None, error_3d_m=None, ok=True, reason="", extra={"px_mm": 2.7}, p_success=0.9,
             go=True, advice=None)
    d.update(kw)
    return d


def test_keyed_chains_read_back_and_unkeyed_ones_are_left_out():
    doc = {"chains": [{"target": "t1", "key": "k1", "steps": [_step(), _step(kind="track", position=[1, 1])]},
                      {"target": "t2", "steps": [_step()]},  # saved before keys
                      {"target": "t3", "key": None, "error": "no stereo", "steps": []}]}
    got = keyed_chains_from_doc(doc)
    assert list(got) == ["k1"] and [s.kind for s in got["k1"]] == ["designate", "track"]
    assert all(isinstance(s, ChainStep) for s in got["k1"]) and got["k1"][1].position == (1, 1)
    assert keyed_chains_from_doc({"results": []}) == {} and keyed_chains_from_doc(None) == {}


@pytest.mark.parametrize("chains, field", [("x", "chains"), (["x"], "chains[0]"),
                                           ([{"key": 3, "steps": [_step()]}], "chains[0].key"),
                                           ([{"key": "k", "steps": []}], "chains[0].key"),
                                           ([{"key": "k", "steps": [_step(ok="yes")]}], "chains[0]: steps[0].ok")])
def test_a_malformed_chain_names_its_field(chains, field):
    with pytest.raises(InputError, match=field.replace("[", r"\[").replace("]", r"\]")):
        keyed_chains_from_doc({"chains": chains}, "handoff.json")
