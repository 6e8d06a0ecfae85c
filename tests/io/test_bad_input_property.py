"""Property: whatever is wrong with a downlink, ``read_downlink`` either returns a downlink that validates
(harmless damage, e.g. in an MCAP index) or raises one ``InputError`` that prints as one line naming a
product or file and a field. Never another exception type, never a Python warning or a decoder message
on the process's stderr (on the command line either would be a second line).

Seeded loops (numpy) over mutations (tests/io/mutate.py) of the small valid downlink of
tests/io/builders.py, in both containers:

* MCAP bytes: truncate, flip bits, zero-fill, duplicate or delete ranges - of scipctl's own file
  (zstd chunks with CRCs) and of a plain, unchunked MCAP without CRCs (so damage reaches the JSON
  and the base64 PNGs);
* MCAP records: missing keys, wrong types, NaN/inf, huge numbers, odd strings, nudged numbers;
  non-JSON messages, missing or repeated messages, bad metadata and encodings, wrong images;
* directory: damaged downlink.yaml (bytes and records), PNGs (damaged, missing, a directory, wrong
  images), a damaged cmod file and a damaged external rover configuration, no downlink.yaml.

A successful read must also survive a write and read back unchanged (``downlink_differences == []``).
"""

from __future__ import annotations

import base64
import copy
import shutil
import warnings

import numpy as np
import pytest
import yaml

from scipctl.io.cmodfile import format_cmod
from scipctl.io.downlink import downlink_differences, read_downlink, write_downlink
from scipctl.io.downlink_dir import YamlLoader
from scipctl.model import InputError
from tests.io.builders import META, make_small_downlink, plain_records, write_raw_mcap
from tests.io.mutate import (BYTE_OPS, ODD_VALUES, dump_json, dump_yaml, error_problems, mutate_bytes,
                             mutate_tree, odd_png)

SEED = 20250612
IMG = "/downlink/image"
PLAIN = {"use_chunking": False, "enable_crcs": False}  # mcap.writer.Writer options: records plain, unchecked


# --------------------------------------------------------------------------- valid inputs
@pytest.fixture(scope="module")
def valid():
    """The downlink every mutant starts from: 6 products (pancam, navcam, hazcam pairs), targets, truth."""
    return make_small_downlink(n_positions=1)


@pytest.fixture(scope="module")
def base(tmp_path_factory, valid):
    """Valid inputs on disk: scipctl's MCAP, a plain MCAP without CRCs, a directory, and a directory with a cmod
    file and an external rover configuration. All four read back the same."""
    d = tmp_path_factory.mktemp("base")
    write_downlink(valid, d / "dl.mcap")
    write_raw_mcap(d / "plain.mcap", META, plain_records(valid), writer_options=PLAIN)
    write_downlink(valid, d / "dir", container="dir")
    ext = d / "ext"
    shutil.copytree(d / "dir", ext)
    doc = yaml.load((ext / "downlink.yaml").read_text(), Loader=YamlLoader)
    rec = doc["images"][1]
    im = valid.product(rec["product_id"])
    (ext / "models").mkdir()
    (ext / "models" / "cam.cahvor").write_text(format_cmod(im.camera_model, im.width, im.height))
    del rec["camera_model"]
    rec["camera_model_file"] = "models/cam.cahvor"
    (ext / "rover.yaml").write_text(dump_yaml(doc["rover_config"]))
    doc["rover_config"] = "rover.yaml"
    (ext / "downlink.yaml").write_text(dump_yaml(doc))
    paths = {"mcap": d / "dl.mcap", "plain": d / "plain.mcap", "dir": d / "dir", "ext": ext}
    ref = read_downlink(paths["mcap"])
    for p in paths.values():
        assert downlink_differences(ref, read_downlink(p)) == [], p
    return paths


# --------------------------------------------------------------------------- the property
def check(path, tmp_path, capfd) -> tuple[str, list]:
    """Read ``path`` -> (outcome "ok" | "error" | "leak", the property's violations: [] if none)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            dl = read_downlink(path)
            outcome, problems = "ok", []
        except InputError as e:
            outcome, problems = "error", [f"{p}: {e}" for p in error_problems(e)]
        except Exception as e:  # noqa: BLE001 - the point: nothing else may escape
            outcome, problems = "leak", [f"{type(e).__name__} escaped: {str(e)[:200]}"]
    problems += [f"warning {w.category.__name__}: {w.message}" for w in caught]
    out, err = capfd.readouterr()
    if out or err:
        problems.append(f"printed to the process's stdout/stderr: {(out + err)[:200]!r}")
    if outcome == "ok" and not problems:  # harmless damage: what was read must be writable and read back the same
        rt = tmp_path / "roundtrip.mcap"
        write_downlink(dl, rt)
        diffs = downlink_differences(dl, read_downlink(rt))
        if diffs:
            problems.append(f"read, but does not round-trip: {diffs[:3]}")
    return outcome, problems


def run_cases(kind: str, n: int, make, tmp_path, capfd) -> dict:
    """Run ``n`` seeded cases; ``make(rng, work)`` writes one mutant in (or at) ``work`` and returns (path, description).

    Fails listing every case that breaks the property; returns the outcome counts.
    """
    rng = np.random.default_rng([SEED, sum(kind.encode())])
    counts, failures = {"ok": 0, "error": 0, "leak": 0}, []
    work = tmp_path / "case"
    for i in range(n):
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir()
        path, desc = make(rng, work)
        outcome, problems = check(path, tmp_path, capfd)
        counts[outcome] += 1
        failures += [f"{kind} case {i} ({desc}): {p}" for p in problems]
    assert not failures, f"{len(failures)} failure(s):\n" + "\n".join(failures[:25])
    return counts


# --------------------------------------------------------------------------- MCAP bytes
@pytest.mark.parametrize("which, n", [("mcap", 100), ("plain", 150)], ids=["scipctl-mcap", "plain-mcap-no-crc"])
def test_damaged_mcap_bytes(base, tmp_path, capfd, which, n):
    data = base[which].read_bytes()

    def make(rng, work):
        bad, desc = mutate_bytes(data, rng)
        (work / "x.mcap").write_bytes(bad)
        return work / "x.mcap", desc

    counts = run_cases(f"{which}-bytes", n, make, tmp_path, capfd)
    assert counts["error"] >= 0.6 * n  # most damage is detected, not silently accepted


# --------------------------------------------------------------------------- MCAP records
def test_damaged_mcap_records(valid, tmp_path, capfd):
    records = plain_records(valid)
    topics_with_records = [t for t, items in records.items() if items]

    def make(rng, work):
        topics = copy.deepcopy(records)
        topic = topics_with_records[int(rng.integers(len(topics_with_records)))]
        k = int(rng.integers(len(topics[topic])))
        desc = mutate_tree(topics[topic][k], rng)
        topics[topic][k] = dump_json(topics[topic][k])
        write_raw_mcap(work / "x.mcap", META, topics)
        return work / "x.mcap", f"{topic}[{k}]: {desc}"

    counts = run_cases("mcap-records", 150, make, tmp_path, capfd)
    assert counts["error"] >= 100


RAW_MESSAGES = (b"", b"{", b"null", b"[]", b'"text"', b"\xff\xfe\xfd", b"NaN", b"1e999", b"9" * 5000, b"[" * 5000,
                b'{"product_id": "navcam_left_1_0"}', b'{"id": 5}')
ODD_META = ("", "2", "1.0", "x", " 42 ", "4.2", "1e3", "9" * 5000, "\u0664\u0662", "nul\x00", "line\nbreak")


def test_damaged_mcap_messages_metadata_and_images(valid, tmp_path, capfd):
    records = plain_records(valid)

    def make(rng, work):
        topics, meta, encoding = copy.deepcopy(records), dict(META), "json"
        op = ["raw", "drop", "repeat", "image", "metadata", "encoding"][int(rng.integers(6))]
        topic = list(topics)[int(rng.integers(len(topics)))]
        if op == "raw" and topics[topic]:
            k = int(rng.integers(len(topics[topic])))
            topics[topic][k] = RAW_MESSAGES[int(rng.integers(len(RAW_MESSAGES)))]
            desc = f"{topic}[{k}] = {topics[topic][k][:20]!r}"
        elif op == "drop":
            topics[topic] = []
            desc = f"no {topic} messages"
        elif op == "repeat" and topics[topic]:
            k = int(rng.integers(len(topics[topic])))
            topics[topic].append(copy.deepcopy(topics[topic][k]))
            desc = f"{topic}[{k}] twice"
        elif op == "image":
            k = int(rng.integers(len(topics[IMG])))
            png, what = odd_png(rng, valid.images[k].width, valid.images[k].height)
            topics[IMG][k]["image"]["data"] = base64.b64encode(png).decode()
            desc = f"{IMG}[{k}] image: {what}"
        elif op == "metadata":
            key = ["format_version", "mission", "sol", None][int(rng.integers(4))]
            if key is None:
                meta = None
                desc = "no metadata"
            elif rng.random() < 0.3:
                del meta[key]
                desc = f"metadata without {key}"
            else:
                meta[key] = ODD_META[int(rng.integers(len(ODD_META)))]
                desc = f"metadata {key} = {meta[key][:20]!r}"
        else:
            encoding = ["cdr", "", "JSON", "protobuf"][int(rng.integers(4))]
            desc = f"encoding {encoding!r}"
        write_raw_mcap(work / "x.mcap", meta, topics, encoding=encoding)
        return work / "x.mcap", desc

    run_cases("mcap-messages", 80, make, tmp_path, capfd)


# --------------------------------------------------------------------------- directory container
def test_damaged_downlink_yaml_bytes(base, tmp_path, capfd):
    text = (base["dir"] / "downlink.yaml").read_bytes()

    def make(rng, work):
        shutil.copytree(base["dir"], work, dirs_exist_ok=True)
        bad, desc = mutate_bytes(text, rng)
        (work / "downlink.yaml").write_bytes(bad)
        return work, desc

    run_cases("yaml-bytes", 70, make, tmp_path, capfd)


def test_damaged_downlink_yaml_records(base, tmp_path, capfd):
    doc = yaml.load((base["dir"] / "downlink.yaml").read_text(), Loader=YamlLoader)

    def make(rng, work):
        shutil.copytree(base["dir"], work, dirs_exist_ok=True)
        d = copy.deepcopy(doc)
        desc = mutate_tree(d, rng)
        (work / "downlink.yaml").write_text(dump_yaml(d), encoding="utf-8")
        return work, desc

    counts = run_cases("yaml-records", 120, make, tmp_path, capfd)
    assert counts["error"] >= 80


def test_damaged_files_of_a_directory_downlink(base, valid, tmp_path, capfd):
    ext = base["ext"]
    pngs = sorted(p.name for p in (ext / "images").iterdir())
    rover_doc = yaml.load((ext / "rover.yaml").read_text(), Loader=YamlLoader)

    def make(rng, work):
        shutil.copytree(ext, work, dirs_exist_ok=True)
        op = ["png-bytes", "png-missing", "png-directory", "png-odd", "cmod-bytes", "rover-bytes", "rover-records",
              "no-yaml"][int(rng.integers(8))]
        png = work / "images" / pngs[int(rng.integers(len(pngs)))]
        desc = f"{op}"
        if op == "png-bytes":
            bad, desc = mutate_bytes(png.read_bytes(), rng)
            png.write_bytes(bad)
            desc = f"{png.name}: {desc}"
        elif op == "png-missing":
            png.unlink()
            desc = f"{png.name} missing"
        elif op == "png-directory":
            png.unlink()
            png.mkdir()
            desc = f"{png.name} is a directory"
        elif op == "png-odd":
            bad, what = odd_png(rng, valid.images[0].width, valid.images[0].height)
            png.write_bytes(bad)
            desc = f"{png.name}: {what}"
        elif op == "cmod-bytes":
            f = work / "models" / "cam.cahvor"
            bad, desc = mutate_bytes(f.read_bytes(), rng)
            f.write_bytes(bad)
            desc = f"cam.cahvor: {desc}"
        elif op == "rover-bytes":
            f = work / "rover.yaml"
            bad, desc = mutate_bytes(f.read_bytes(), rng)
            f.write_bytes(bad)
            desc = f"rover.yaml: {desc}"
        elif op == "rover-records":
            d = copy.deepcopy(rover_doc)
            desc = f"rover.yaml: {mutate_tree(d, rng)}"
            (work / "rover.yaml").write_text(dump_yaml(d), encoding="utf-8")
        else:
            (work / "downlink.yaml").unlink()
        return work, desc

    run_cases("dir-files", 100, make, tmp_path, capfd)


# --------------------------------------------------------------------------- the generators themselves
def test_mutations_are_seeded_and_varied():
    data = bytes(range(256)) * 4
    a = [mutate_bytes(data, np.random.default_rng([SEED, i])) for i in range(30)]
    b = [mutate_bytes(data, np.random.default_rng([SEED, i])) for i in range(30)]
    assert a == b  # same seed, same mutants
    assert {d.split()[0] for _, d in a} == set(BYTE_OPS)
    assert all(m != data for m, d in a if not d.startswith("zero"))  # (zeroing zeros changes nothing)
    tree = {"a": [1.0, 2.0], "b": {"c": "x"}}
    descs = {mutate_tree(copy.deepcopy(tree), np.random.default_rng([SEED, i])) for i in range(40)}
    assert len(descs) > 20
    # edits put copies in the tree: the shared odd values themselves never change
    assert [repr(v) for v in ODD_VALUES if isinstance(v, (list, dict))] == [
        "[]", "{}", "[1, 2]", "[nan, nan, nan]", "{'x': 1}"]
