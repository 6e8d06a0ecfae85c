"""Container B (downlink.yaml) as other producers may write it: YAML the contract allows but scipctl's writer never emits."""

import re

import pytest

from scipctl.io.downlink import downlink_differences, read_downlink, write_downlink
from tests.io.builders import make_small_downlink


@pytest.fixture
def written(tmp_path):
    dl = make_small_downlink()
    write_downlink(dl, tmp_path / "d", container="dir")
    return read_downlink(tmp_path / "d"), tmp_path / "d" / "downlink.yaml"


def test_yaml_1_2_floats_without_a_leading_digit(written):
    """YAML 1.2 (core schema) floats ``-.5``, ``+.5``, ``.5e3``: PyYAML's 1.1 rules read ``.5`` as a number but
    ``-.5`` as a string, which made the whole downlink an error (``must be a list of 3 numbers``)."""
    ref, path = written
    text = path.read_text()
    new, n = re.subn(r"(?<=[\s\[,])([-+]?)0\.(\d)", lambda m: (m.group(1) or "+") + "." + m.group(2), text)
    assert n > 50 and "-." in new and "+." in new
    new = re.sub(r"(?<=[\s\[,])\+\.(\d+)(?=[,\]\s])", r".\1e0", new, count=5)  # and a few '.5e0'
    path.write_text(new)
    assert downlink_differences(ref, read_downlink(path.parent)) == []


def test_yaml_decimal_integers_with_leading_zeros(written):
    """``sol: 0042`` (a zero-padded sol, as templates write it) is 42: YAML 1.1 read it as octal (34) and
    ``0089`` as a string."""
    ref, path = written
    text = path.read_text()
    for padded, value in (("0042", 42), ("0089", 89)):
        path.write_text(re.sub(r"(?m)^sol: 42$", f"sol: {padded}", text))
        assert read_downlink(path.parent).sol == value
    path.write_text(re.sub(r"site: (\d+)", r"site: 00\1", text))
    assert downlink_differences(ref, read_downlink(path.parent)) == []


def test_long_product_ids_fit_in_file_names(tmp_path):
    """The contract sets no length on a product id. A 300-character id (fine in MCAP), or 100 accented letters
    (a 205-byte name in the producer's own ``images/<product_id>.png``, which percent-encoding made 605 bytes),
    could not be written: ingest failed with 'File name too long'."""
    dl = make_small_downlink(n_positions=1, with_targets=False, with_truth=False)
    ids = ["p" * 300, "é" * 100 + "-L", "é" * 100 + "-R"]
    for im, pid in zip(dl.images, ids):
        im.product_id = pid
    write_downlink(dl, tmp_path / "d", container="dir")
    names = [p.name for p in (tmp_path / "d" / "images").iterdir()]
    assert len(names) == len(dl.images) and max(len(n.encode()) for n in names) <= 200
    back = read_downlink(tmp_path / "d")
    assert [d for d in downlink_differences(dl, back) if ".pose.R" not in d] == []
    assert [im.png for im in back.images] == [im.png for im in dl.images]
