"""scipctl.pipeline.predict.from_downlink: resolving the designated target."""

import pytest

from scipctl.pipeline import predict as P


def test_resolve_target_prefers_targets_json_and_rejects_unknown_ids(slab_case):
    from scipctl.model import InputError

    _, dl, _ = slab_case
    rec = {"id": "t_slab", "ok": True, "product_id": "pancam_left_1_0", "pixel_uv": [1.0, 2.0], "xyz_site_m": [1, 2, 3]}
    got, now = P.resolve_target(dl, "t_slab", {"targets": [rec]})
    assert got is rec and not now
    with pytest.raises(InputError) as e:
        P.resolve_target(dl, "nope", {"targets": [rec]})
    assert "nope" in str(e.value) and "t_slab" in str(e.value)
