"""Record-level readings of values the contract allows but scipctl's own writer never produces."""

import copy

from scipctl.io.downlink import downlink_differences, read_downlink
from tests.io.builders import META, make_small_downlink, plain_records, write_raw_mcap


def _floats_for_ints(x):
    if isinstance(x, dict):
        return {k: _floats_for_ints(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_floats_for_ints(v) for v in x]
    if isinstance(x, int) and not isinstance(x, bool):
        return float(x)
    return x


def test_integers_written_as_json_floats_read_as_integers(tmp_path):
    """JSON has one number type: a producer whose numbers are doubles writes ``"site": 1.0``, ``"width": 64.0``,
    ``"cahvore_type": 3.0``, and JSON Schema's ``integer`` accepts them. They mean the integers."""
    dl = make_small_downlink()
    topics = copy.deepcopy(plain_records(dl))
    plain = {t: [_floats_for_ints(r) for r in recs] for t, recs in topics.items()}
    rec = plain["/downlink/image"][0]
    assert isinstance(rec["position"]["site"], float) and isinstance(rec["width"], float)
    write_raw_mcap(tmp_path / "f.mcap", META, plain)
    write_raw_mcap(tmp_path / "i.mcap", META, topics)
    got = read_downlink(tmp_path / "f.mcap")
    assert downlink_differences(read_downlink(tmp_path / "i.mcap"), got) == []
    assert all(type(im.site) is int and type(im.width) is int for im in got.images)


def _with_escaped_surrogate(topics, topic, index, key):
    """Raw JSON messages where ``key`` of message ``index`` is ``"nav\\udc80cam"`` (valid JSON syntax)."""
    import json

    raw = {t: [json.dumps(r).encode() for r in recs] for t, recs in topics.items()}
    r = topics[topic][index]
    raw[topic][index] = raw[topic][index].replace(json.dumps(r[key]).encode(), b'"nav\\udc80cam"', 1)
    return raw


def test_lone_surrogate_in_a_string_is_refused_not_a_crash(tmp_path):
    """JSON can spell a lone surrogate (``"\\udc80"``), which is no Unicode text: such a product id was read,
    and ingest then crashed writing the workspace (exit 3, UnicodeEncodeError). Now it is an input error that
    names the record by position (its id cannot be printed) and the field."""
    import pytest

    from scipctl.model import InputError

    topics = plain_records(make_small_downlink(n_positions=1))
    cases = [("/downlink/image", 0, "product_id", "/downlink/image[0]", "product_id"),
             ("/downlink/targets", 0, "kind", topics["/downlink/targets"][0]["id"], "kind"),
             ("/truth/image", 1, "product_id", "/truth/image[1]", "product_id")]
    for topic, index, key, product, field in cases:
        write_raw_mcap(tmp_path / "s.mcap", META, _with_escaped_surrogate(topics, topic, index, key))
        with pytest.raises(InputError) as ei:
            read_downlink(tmp_path / "s.mcap")
        assert (ei.value.product, ei.value.field) == (product, field), str(ei.value)
        str(ei.value).encode("utf-8")  # printable as one UTF-8 line
