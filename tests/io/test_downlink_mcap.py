"""Container A (MCAP) as other producers may write it: encodings the contract allows but scipctl's writer never emits."""

import base64

from scipctl.io.downlink import downlink_differences, read_downlink
from tests.io.builders import META, make_small_downlink, plain_records, write_raw_mcap


def test_line_wrapped_base64_image_data(tmp_path):
    """``image.data`` in MIME-style base64 (76-character lines, ``\\n`` or ``\\r\\n``), as Python's
    ``base64.encodebytes`` writes it, is the same PNG; it was refused as 'not valid base64'."""
    dl = make_small_downlink(n_positions=1)
    topics = plain_records(dl)
    for i, rec in enumerate(topics["/downlink/image"]):
        wrapped = base64.encodebytes(base64.b64decode(rec["image"]["data"])).decode()
        assert "\n" in wrapped
        rec["image"]["data"] = wrapped.replace("\n", "\r\n") if i % 2 else wrapped
    write_raw_mcap(tmp_path / "w.mcap", META, topics)
    got = read_downlink(tmp_path / "w.mcap")
    assert [im.png for im in got.images] == [im.png for im in dl.images]
    assert [d for d in downlink_differences(dl, got) if ".pose.R" not in d] == []
