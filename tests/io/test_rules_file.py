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


def test_yaml_numbers_are_yaml_1_2_core_schema(tmp_path):
    """Rules-file numbers are YAML 1.2's core schema's (the project's one loader): ``1e3`` is 1000.0, ``0o17`` 15;
    ``12:30`` is a string, so an error, where YAML 1.1 read it silently as 750 (``1_000`` as 1000)."""
    assert _read(tmp_path, "limits:\n  a_m: 1e3\n  n: 0o17\n  xs: [0x10, +2, .5]\n").values == {
        "limits": {"a_m": 1000.0, "n": 15, "xs": (16, 2, 0.5)}}
    for value in ("12:30", "1_000", "190:20:30.15", "0b101"):
        with pytest.raises(InputError, match=f"must be a finite number, got '{value}'"):
            _read(tmp_path, f"limits:\n  a_m: {value}\n")


@pytest.mark.parametrize("value", ["2001-13-01", "9" * 5000, "[" * 5000 + "]" * 5000],
                         ids=["month-13", "5000-digit-integer", "5000-deep-list"])
def test_yaml_python_cannot_build_is_an_input_error(tmp_path, value):
    """A value PyYAML parses but Python cannot build, or nesting the recursive loader cannot follow, is an error
    naming the file, as in downlink.yaml (one loader, one rule: downlink_dir.parse_yaml). Only YAMLError was caught,
    so ``max_drive_m: 2001-13-01`` escaped as ``internal error (ValueError): month must be in 1..12`` (exit 3), a
    5000-digit integer as ValueError and a 5000-deep list as RecursionError. (Dates are strings now: 2001-13-01
    is a value of the wrong kind.)"""
    with pytest.raises(InputError) as e:
        _read(tmp_path, f"limits:\n  a_m: {value}\n")
    assert e.value.product == str(tmp_path / "r.yaml") and "\n" not in str(e.value)
    if value.startswith("["):  # refused before the loader recursed (as downlink.yaml: libyaml crashed at ~40000)
        assert e.value.field == "rules file" and "nested more than 100 deep" in e.value.message


def test_yaml_nested_deep_enough_to_crash_libyaml(tmp_path):
    """100000 open brackets in a rules file were a segmentation fault (``scipctl sequence --rules``: exit 139), so
    this runs in a child process."""
    import subprocess
    import sys

    (tmp_path / "r.yaml").write_text("limits:\n  a_m: " + "[" * 100000)
    code = ("import sys; from scipctl.io.rules_file import read_rules_file; from scipctl.errors import InputError\n"
            "try:\n    read_rules_file(sys.argv[1], {'limits': {'a_m': 'number'}})\nexcept InputError as e:\n"
            "    print(e)")
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "r.yaml")], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-500:]
    assert r.stdout == f"{tmp_path / 'r.yaml'}: rules file: collections nested more than 100 deep at line 2, column 106\n"
