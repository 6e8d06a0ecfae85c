"""Reading a rules file: YAML, known sections and keys, value kinds; every error one line naming file and key."""

import pytest

from scipctl.errors import InputError
from scipctl.io.rules_file import DEFAULT_RULES_PATH, read_rules_file

SPEC = {"limits": {"a_m": "number", "b": "number?", "n": "int", "xs": "numbers", "r": "camera_numbers",
                   "h": "camera_ints"}}


def _read(tmp_path, text):
    p = tmp_path / "r.yaml"
    p.write_text(text)
    return read_rules_file(p, SPEC)


def test_values_come_back_typed_with_the_file_hash(tmp_path):
    import hashlib

    text = "version: 1\nlimits:\n  a_m: 2\n  b: null\n  n: 3\n  xs: [1, 2.5]\n  r: {pancam: 3}\n  h: {navcam: 4}\n"
    c = _read(tmp_path, text)
    assert c.values == {"limits": {"a_m": 2, "b": None, "n": 3, "xs": (1, 2.5), "r": {"pancam": 3},
                                   "h": {"navcam": 4}}}
    assert c.sha256 == hashlib.sha256(text.encode()).hexdigest()
    assert _read(tmp_path, "").values == {}  # an empty file changes nothing


@pytest.mark.parametrize("text, key, words", [
    ("limits:\n  a_m: x\n", "limits.a_m", "finite number"),
    ("limits:\n  a_m: true\n", "limits.a_m", "finite number"),
    ("limits:\n  a_m: .nan\n", "limits.a_m", "finite number"),
    ("limits:\n  n: 2.5\n", "limits.n", "integer"),
    ("limits:\n  xs: 3\n", "limits.xs", "list"),
    ("limits:\n  h: {navcam: 1.5}\n", "limits.h", "camera -> integer"),
    ("limits:\n  h: {navcam: 2, mastcam: 5}\n", "limits.h.mastcam", "unknown camera"),  # was carried silently
    ("limits:\n  nope: 1\n", "limits.nope", "unknown key"),
    ("other:\n  a_m: 1\n", "other", "unknown section"),
    ("version: 2\n", "version", "version"),
    ("limits: [1, 2]\n", "limits", "mapping"),
    ("- 1\n", "rules file", "mapping"),
    ("limits: {a_m: 1\n", "rules file", "YAML"),
])
def test_a_bad_file_names_the_file_and_the_key(tmp_path, text, key, words):
    with pytest.raises(InputError) as e:
        _read(tmp_path, text)
    assert e.value.product == str(tmp_path / "r.yaml") and e.value.field == key and words in e.value.message
    assert "\n" not in str(e.value)


def test_a_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError) as e:
        read_rules_file(tmp_path / "missing.yaml", SPEC)
    assert "cannot read" in e.value.message


def test_the_default_file_ships_inside_the_package():
    assert DEFAULT_RULES_PATH.is_file() and DEFAULT_RULES_PATH.parent.parent.name == "scipctl"


def test_yaml_is_read_as_downlink_yaml_is_yaml_1_2(tmp_path):
    """The rules file goes through the project's YAML loader (scipctl/io/downlink_dir.py), as downlink.yaml does:
    YAML 1.2 numbers and booleans. PyYAML's 1.1 rules made ``1e-3`` a string (an error), ``n: 0010`` octal 8
    (silently) and ``off`` the boolean False (an error quoting ``False``, not what the file says)."""
    assert _read(tmp_path, "limits:\n  a_m: 1e-3\n  xs: [-.5, .5e1]\n  n: 0010\n").values == {
        "limits": {"a_m": 1e-3, "xs": (-0.5, 5.0), "n": 10}}
    for word in ("off", "on", "no", "yes"):
        with pytest.raises(InputError, match=f"must be a finite number, got '{word}'"):
            _read(tmp_path, f"limits:\n  a_m: {word}\n")
    with pytest.raises(InputError, match="must be a finite number, got True"):  # true is still a boolean
        _read(tmp_path, "limits:\n  a_m: true\n")
