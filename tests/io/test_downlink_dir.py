"""Container B (downlink.yaml) as other producers may write it: YAML the contract allows but scipctl's writer never emits."""

import dataclasses
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


# the words PyYAML's YAML 1.1 resolver reads as booleans when bare; YAML 1.2 (core schema) reads them as strings
_YAML11_BOOL_WORDS = ("yes", "Yes", "YES", "no", "No", "NO", "on", "On", "ON", "off", "Off", "OFF")


def _downlink_named_by(names, n_images: int):
    """A small downlink whose first ``n_images`` product ids (and their marks and truth), first target's id, kind
    and description, and mission are the next of ``names``; returns it and the iterator of the names left."""
    dl = make_small_downlink(n_positions=1)
    words = iter(names)
    renamed = {}
    for im in dl.images[:n_images]:
        renamed[im.product_id] = im.product_id = next(words)
    for tm in dl.targets:
        tm.marks = [dataclasses.replace(m, product_id=renamed.get(m.product_id, m.product_id)) for m in tm.marks]
    dl.truth_images = [dataclasses.replace(t, product_id=renamed.get(t.product_id, t.product_id)) for t in dl.truth_images]
    dl.targets[0].id, dl.targets[0].kind, dl.targets[0].description = next(words), next(words), next(words)
    dl.truth_targets[0] = dataclasses.replace(dl.truth_targets[0], id=dl.targets[0].id)
    dl.mission = next(words)
    return dl, words


def test_yaml_1_1_boolean_words_are_strings(tmp_path):
    """A product id ``on``, a target id ``no``, a camera ``off`` written bare in ``downlink.yaml`` are strings
    (YAML 1.2 core schema: only true/false are booleans). PyYAML's 1.1 rules read them as True/False, so such a
    downlink was an error (``targets[0]: id: must be a string, got boolean False``) and a camera named ``on`` in
    the rover configuration a key True (``cameras.True: camera names must be strings``)."""
    dl, words = _downlink_named_by(_YAML11_BOOL_WORDS, 4)
    dl.rover_config = dataclasses.replace(dl.rover_config, name=next(words), cameras=dict(dl.rover_config.cameras))
    dl.rover_config.cameras[next(words)] = dl.rover_config.cameras["pancam"]  # a camera name as a mapping key
    dl.images[-1].camera, dl.images[-1].mast = next(words), None  # a camera the rover configuration does not know
    source = next(words)
    for im in dl.images:  # one position: one pose
        im.pose = dataclasses.replace(im.pose, source=source)
    write_downlink(dl, tmp_path / "d", container="dir")
    path = tmp_path / "d" / "downlink.yaml"
    text, n = re.subn(r"'(%s)'" % "|".join(_YAML11_BOOL_WORDS), r"\1", path.read_text())  # the writer quotes them
    assert n >= len(_YAML11_BOOL_WORDS)
    path.write_text(text)
    back = read_downlink(tmp_path / "d")
    assert [d for d in downlink_differences(dl, back) if ".pose.R" not in d] == []
    t = back.targets[0]
    assert [im.product_id for im in back.images[:4]] + [t.id, t.kind, t.description, back.mission, back.rover_config.name,
            list(back.rover_config.cameras)[-1], back.images[-1].camera, back.images[-1].pose.source] == list(_YAML11_BOOL_WORDS)


def test_yaml_1_2_booleans_stay_booleans(written):
    """Only ``true``/``false`` (and ``True``, ``TRUE``, ``False``, ``FALSE``) are booleans: where the contract
    wants a string, one is still an error, never a silent misreading."""
    from scipctl.io.downlink_dir import load_yaml
    from scipctl.model import InputError

    _, path = written
    (path.parent / "b.yaml").write_text("[true, True, TRUE, false, False, FALSE, tRUE, y, n, yes, off, null, ~]\n")
    assert load_yaml(path.parent / "b.yaml", "b") == [True] * 3 + [False] * 3 + ["tRUE", "y", "n", "yes", "off", None, None]
    text = path.read_text()
    path.write_text(re.sub(r"(?m)^mission: .*$", "mission: true", text))
    with pytest.raises(InputError, match="mission: must be a string, got boolean True"):
        read_downlink(path.parent)


# strings a plain (unquoted) scalar would not give back: YAML 1.2 numbers PyYAML's 1.1 rules leave strings (so its
# dumper left them bare), 1.1 booleans/nulls/numbers/dates/sexagesimals, special floats; and words that stay bare
_TRICKY_STRINGS = ("1e3", "0089", "-.5", "+.5", ".5e3", "0042", "1E-5", "+12", "-0", "yes", "No", "on", "off", "true",
                   "FALSE", "null", "~", "1_000", "0x1F", "0o17", "0b101", ".inf", "-.inf", ".nan", "12:30",
                   "2001-12-14", "2001-12-14 21:59:43.10", "=", "<<", "navcam_left", "rock 1", "e3", "1e", "1.2.3",
                   "190:20:30.15", "1_000.5", "-0x1F", "0x1_F", "1:2", "-0o17", "+0o17", "0o8", "1.", "-.nan")


@pytest.mark.parametrize("word", _TRICKY_STRINGS)
def test_every_string_written_reads_back_a_string(tmp_path, word):
    """Whatever a string field holds, the folder scipctl writes reads back equal, with scipctl's YAML 1.2 loader and
    with a YAML 1.1 reader (``yaml.safe_load``). The writer (PyYAML's 1.1 dumper) left ``1e3``, ``0089``, ``-.5``,
    ``+.5``, ``.5e3`` bare, which YAML 1.2 reads as numbers: a product id ``1e3`` written and read back gave
    ``images[0]: product_id: must be a string, got float 1000.0``."""
    import yaml

    from scipctl.io.downlink_dir import load_yaml

    dl = make_small_downlink(n_positions=1)
    old = dl.images[0].product_id
    dl.images[0].product_id = word
    for tm in dl.targets:
        tm.marks = [dataclasses.replace(m, product_id=word if m.product_id == old else m.product_id) for m in tm.marks]
    dl.truth_images = [dataclasses.replace(t, product_id=word if t.product_id == old else t.product_id)
                       for t in dl.truth_images]
    dl.targets[0].id = dl.targets[0].kind = dl.targets[0].description = word
    dl.truth_targets[0] = dataclasses.replace(dl.truth_targets[0], id=word)
    dl.mission = word
    dl.rover_config = dataclasses.replace(dl.rover_config, name=word, cameras=dict(dl.rover_config.cameras))
    dl.rover_config.cameras[word] = dl.rover_config.cameras["hazcam"]  # a camera name as a mapping key
    dl.images[-1].camera, dl.images[-1].mast = word, None
    for im in dl.images:  # one position: one pose
        im.pose = dataclasses.replace(im.pose, source=word)
    write_downlink(dl, tmp_path / "d", container="dir")
    path = tmp_path / "d" / "downlink.yaml"
    back = read_downlink(tmp_path / "d")
    assert [d for d in downlink_differences(dl, back) if ".pose.R" not in d] == []
    doc11, doc12 = yaml.safe_load(path.read_text()), load_yaml(path, "d")
    assert doc11 == doc12  # YAML 1.1 and scipctl's YAML 1.2 read the whole file alike
    assert [doc11["mission"], doc11["rover_config"]["name"], list(doc11["rover_config"]["cameras"])[-1],
            doc11["images"][0]["product_id"], doc11["images"][-1]["camera"], doc11["images"][0]["pose"]["source"],
            doc11["targets"][0]["id"], doc11["targets"][0]["kind"], doc11["targets"][0]["description"],
            doc11["truth"]["images"][0]["product_id"], doc11["truth"]["targets"][0]["id"]] == [word] * 11


def test_the_pure_python_dumper_quotes_as_the_writer_and_escapes_what_libyaml_cannot():
    """``PyYamlDumper`` (the fuzz tests' dumper, tests/io/mutate.py) quotes every tricky string as the writer does, so
    a fixture's string reads back a string with scipctl's YAML 1.2 loader (PyYAML's ``safe_dump``, which the
    fixtures used before, leaves ``1e3`` bare: a float to that loader); and it writes a lone surrogate, escaped,
    which libyaml's emitter cannot encode (the reader refuses it as malformed YAML)."""
    import yaml

    from scipctl.io.downlink_dir import PyYamlDumper, YamlLoader, parse_yaml
    from scipctl.model import InputError

    doc = {"ids": list(_TRICKY_STRINGS)}
    assert yaml.load(yaml.dump(doc, Dumper=PyYamlDumper), Loader=YamlLoader) == doc
    assert yaml.load(yaml.safe_dump(doc), Loader=YamlLoader) != doc  # what the fixtures wrote before
    text = yaml.dump({"id": "\ud800"}, Dumper=PyYamlDumper)
    assert text == 'id: "\\uD800"\n'
    with pytest.raises(InputError, match="d: yaml: malformed YAML at line 1, column 8"):
        parse_yaml(text, "d")


_DATES = ("2001-12-14", "2001-12-14t21:59:43.10-05:00", "2001-12-14 21:59:43.10", "2002-12-14", "2003-1-2",
          "2004-02-29 1:02:03", "2005-06-07T08:09:10Z")


def test_yaml_dates_are_strings(tmp_path):
    """YAML 1.2's core schema has no timestamp type and the contract no date field (``time_s`` is seconds, a
    float): a product id, target id, description or mission written as a bare date is that string. PyYAML's 1.1
    resolver made it a date, and the downlink an error: ``images[0]: product_id: must be a string, got date
    datetime.date(2001, 12, 14)``; a date Python cannot build (``2001-13-01``) was malformed YAML."""
    from scipctl.io.downlink_dir import load_yaml

    dl, words = _downlink_named_by(_DATES, 2)
    write_downlink(dl, tmp_path / "d", container="dir")
    path = tmp_path / "d" / "downlink.yaml"
    text, n = re.subn(r"'(%s)'" % "|".join(map(re.escape, _DATES)), r"\1", path.read_text())  # the writer quotes them
    assert n >= len(_DATES)
    path.write_text(text)
    back = read_downlink(tmp_path / "d")
    assert [d for d in downlink_differences(dl, back) if ".pose.R" not in d] == []
    (tmp_path / "b.yaml").write_text("[2001-13-01, 2001-12-14, {2002-12-14: 2001-12-14 21:59:43.10}]\n")
    assert load_yaml(tmp_path / "b.yaml", "b") == ["2001-13-01", "2001-12-14", {"2002-12-14": "2001-12-14 21:59:43.10"}]


# plain scalars YAML 1.1 reads as numbers and YAML 1.2's core schema as strings (sexagesimals, digit separators,
# binary, signed hexadecimal), and PyYAML's 1.1 'value' key '='
_YAML11_ONLY_NUMBERS = ("12:30", "190:20:30.15", "1_000", "1_000.5", "0b101", "-0x1F", "1:2", "=")


def test_yaml_1_1_only_numbers_are_strings(tmp_path):
    """YAML 1.2's core schema has no base-60, ``_``-separated or binary numbers: a product id, target id,
    description or mission written bare as ``12:30`` is that string. PyYAML's 1.1 resolvers made ``12:30`` the
    integer 750 and the downlink an error: ``images[0]: product_id: must be a string, got int 750``
    (``190:20:30.15`` a float, ``1_000`` 1000, ``0b101`` 5; a bare ``=`` was malformed YAML)."""
    from scipctl.io.downlink_dir import load_yaml

    dl, words = _downlink_named_by(_YAML11_ONLY_NUMBERS, 3)
    dl.rover_config = dataclasses.replace(dl.rover_config, cameras=dict(dl.rover_config.cameras))
    dl.rover_config.cameras[next(words)] = dl.rover_config.cameras["hazcam"]  # a camera name as a mapping key
    write_downlink(dl, tmp_path / "d", container="dir")
    path = tmp_path / "d" / "downlink.yaml"
    text, n = re.subn(r"'(%s)'" % "|".join(map(re.escape, _YAML11_ONLY_NUMBERS)), r"\1", path.read_text())
    assert n >= len(_YAML11_ONLY_NUMBERS)  # the writer quotes them
    path.write_text(text)
    back = read_downlink(tmp_path / "d")
    assert [d for d in downlink_differences(dl, back) if ".pose.R" not in d] == []
    assert list(back.rover_config.cameras)[-1] == "="


def test_yaml_1_2_core_schema_numbers(tmp_path):
    """Integers and floats exactly as YAML 1.2's core schema resolves them: ``[-+]?[0-9]+`` (decimal, leading zeros
    too), ``0o[0-7]+`` (octal: ``0o17`` is 15, a string in YAML 1.1), ``0x[0-9a-fA-F]+``; floats
    ``[-+]?(\\.[0-9]+|[0-9]+(\\.[0-9]*)?)([eE][-+]?[0-9]+)?``, ``[-+]?.inf``, ``.nan``. Anything else is a string."""
    import math

    from scipctl.io.downlink_dir import load_yaml

    (tmp_path / "n.yaml").write_text(
        "[0o17, 0o0, 0x1F, 0xff, +12, -12, 0042, -0042, 0089, 0, -0, 1e3, 1E-5, -.5, +.5, .5e3, 1., -1., 1.5, 0.,"
        " 1e+3, .inf, -.Inf, +.INF,"
        " 12:30, 190:20:30.15, 1_000, 1_000.5, 0b101, -0x1F, +0x1F, 0x1_F, -0o17, 0o8, 0o, 0x, 1__0, 1._5, -.nan, 1:2,"
        " =, e3, 1e, ._5]\n")
    got = load_yaml(tmp_path / "n.yaml", "n")
    assert got[:24] == [15, 0, 31, 255, 12, -12, 42, -42, 89, 0, 0, 1000.0, 1e-5, -0.5, 0.5, 500.0, 1.0, -1.0, 1.5,
                        0.0, 1000.0, math.inf, -math.inf, math.inf]
    assert [type(v) for v in got[:11]] == [int] * 11 and [type(v) for v in got[11:24]] == [float] * 13
    assert got[24:] == ["12:30", "190:20:30.15", "1_000", "1_000.5", "0b101", "-0x1F", "+0x1F", "0x1_F", "-0o17",
                        "0o8", "0o", "0x", "1__0", "1._5", "-.nan", "1:2", "=", "e3", "1e", "._5"]
    (tmp_path / "f.yaml").write_text("[.nan, .NaN, .NAN]\n")
    assert all(math.isnan(v) for v in load_yaml(tmp_path / "f.yaml", "f"))


def test_explicit_tags_hold_to_yaml_1_2_forms():
    """An explicit core tag is read by YAML 1.2's forms as a plain scalar is (``!!int 0o17`` 15, ``!!float 2``
    2.0, ``!!int '12'`` 12); a value that is not one of them is malformed YAML with a one-line error, where
    PyYAML's own constructors read it by YAML 1.1 (``!!int 1_000`` 1000, ``!!int 0b101`` 5, ``!!int 12:30`` 750,
    ``!!bool yes`` true, ``!!float 1_000.5`` 1000.5)."""
    from scipctl.io.downlink_dir import parse_yaml
    from scipctl.model import InputError

    got = parse_yaml("[!!int 12, !!int 0o17, !!int 0x1F, !!int '12', !!float 1e3, !!float 2, !!bool true, !!bool FALSE,"
                     " !!null ~, !!null '', !!str 12, 1_000]", "t")
    assert got == [12, 15, 31, 12, 1000.0, 2.0, True, False, None, None, "12", "1_000"]
    assert [type(v) for v in got[:6]] == [int] * 4 + [float] * 2
    for text, what in (("!!int 1_000", "integer"), ("!!int 0b101", "integer"), ("!!int 12:30", "integer"),
                       ("!!bool yes", "boolean"), ("!!bool on", "boolean"), ("!!float 1_000.5", "float"),
                       ("!!float 12:30", "float"), ("!!null nothing", "null"), ("sol: !!int -0x1F", "integer")):
        with pytest.raises(InputError, match=f"malformed YAML at line 1, column .*is not a YAML 1.2 {what}") as e:
            parse_yaml(text, "t")
        assert "\n" not in str(e.value)


def test_yaml_sol_as_yaml_1_2_reads_it(written):
    """``sol: 0o17`` is the integer 15 (YAML 1.2 octal; 1.1 read a string, an error); a sexagesimal or
    ``_``-separated sol is a string, so an error, where YAML 1.1 read ``sol: 12:30`` silently as 750."""
    from scipctl.model import InputError

    _, path = written
    text = path.read_text()
    path.write_text(re.sub(r"(?m)^sol: 42$", "sol: 0o17", text))
    assert read_downlink(path.parent).sol == 15
    for value in ("12:30", "1_000", "0b101"):
        path.write_text(re.sub(r"(?m)^sol: 42$", f"sol: {value}", text))
        with pytest.raises(InputError, match="sol: must be an integer, got str"):
            read_downlink(path.parent)
