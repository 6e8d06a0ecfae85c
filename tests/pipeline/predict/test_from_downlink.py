"""scipctl.pipeline.predict.from_downlink: resolving the designated target."""

import pytest

from scipctl.pipeline import predict as P
from scipctl.pipeline.designate import Designation


def test_resolve_target_prefers_targets_json_and_rejects_unknown_ids(slab_case):
    from scipctl.model import InputError

    _, dl, _ = slab_case
    rec = Designation(id="t_slab", product_id="pancam_left_1_0", camera="pancam", pixel_uv=(1.0, 2.0),
                      xyz_site_m=(1.0, 2.0, 3.0))
    got, now = P.resolve_target(dl, "t_slab", [rec])
    assert got is rec and not now
    with pytest.raises(InputError) as e:
        P.resolve_target(dl, "nope", [rec])
    assert "nope" in str(e.value) and "t_slab" in str(e.value)
