"""The closure check's reference choice (pipeline/chain_closure.py); its run on real chains is in test_chain.py."""

from scipctl.pipeline.chain import ChainParams, ChainStep
from scipctl.pipeline.chain_closure import Closure, closure_reference

import pytest


def _step(camera, kind, pos, ok=True, unverified=False, uv=(1.0, 2.0), xyz=(1.0, 0.0, 0.0), final=False):
    extra = {"unverified": unverified}
    if final:
        extra["final"] = True
    return ChainStep(pos, camera, f"{camera}-{pos[1]}", kind, None, None if uv is None else list(uv), None, None, None,
                     None, None if xyz is None else list(xyz), None, None, ok, "", extra)


def test_the_reference_is_the_last_trusted_pancam_track():
    steps = [_step("pancam", "designate", (1, 0)), _step("pancam", "track", (1, 1)), _step("navcam", "handoff", (1, 1)),
             _step("pancam", "track", (1, 2)), _step("navcam", "track", (1, 3)), _step("hazcam", "handoff", (1, 3), final=True)]
    assert closure_reference(steps, 5) == 3
    steps[3] = _step("pancam", "track", (1, 2), ok=False)  # a flagged track is no reference
    assert closure_reference(steps, 5) == 1
    steps[1] = _step("pancam", "track", (1, 1), unverified=True)
    assert closure_reference(steps, 5) == 2  # no trusted pancam track: the navcam handoff at the imaging stop
    steps[1] = _step("pancam", "track", (1, 1), xyz=None)  # no stereo point: nothing to render through
    assert closure_reference(steps, 5) == 2
    steps[2] = _step("navcam", "handoff", (1, 1), ok=False)
    assert closure_reference(steps, 5) is None  # navcam tracks and the designation (~10 m) are never one


def test_closure_params_and_record():
    with pytest.raises(ValueError, match="closure"):
        ChainParams(closure="yes").check()
    d = Closure("no reference").to_dict()
    assert d["status"] == "no reference" and d["uv"] is None and d["closure_px"] is None
    assert Closure("confirmed", closure_px=float("nan")).to_dict()["closure_px"] is None
