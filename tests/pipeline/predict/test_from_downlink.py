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


def test_designation_position_is_the_stop_resolve_target_designates_from():
    """The stop whose pairs `sequence` self-calibrates: a saved designation's product's, else the marked image
    resolve_target designates from (the first left pancam with a mark), None where resolve_target refuses."""
    from pathlib import Path

    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.predict.from_downlink import designation_position

    dl = read_downlink(Path(__file__).resolve().parents[3] / "sample_sols" / "mcap" / "paper-s1-straight.mcap")
    saved = Designation(id="r1", product_id="s1-straight-mid-pancam-L", camera="pancam", pixel_uv=(1.0, 2.0),
                        xyz_site_m=(1.0, 2.0, 3.0))
    assert designation_position(dl, "r1", [saved]) == dl.product("s1-straight-mid-pancam-L").position == (1, 1)
    rec, now = P.resolve_target(dl, "t2", [])
    assert now and designation_position(dl, "t2", []) == dl.product(rec.product_id).position == (1, 0)
    assert designation_position(dl, "nope", [saved]) is None
    gone = Designation(id="r2", product_id="no-such-product", camera="pancam", pixel_uv=(1.0, 2.0),
                       xyz_site_m=(1.0, 2.0, 3.0))
    assert designation_position(dl, "r2", [gone]) is None
