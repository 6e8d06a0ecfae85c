"""SeqJSON against the schema Aerie/PlanDev validates imports with, and SeqN against Aerie's SeqN grammar
(a recogniser written from it, tests/pipeline/seqn_grammar.py); both carry the same commands and metadata."""

import copy
import json
import math
import re
from pathlib import Path

import jsonschema
import pytest

from scipctl.pipeline import sequence as Q
from scipctl.pipeline.rules import load_rules
from tests.pipeline import seqn_grammar as G
from tests.pipeline.seqjson_schema import SEQJSON_SCHEMA
from tests.pipeline.sequence_doc import sequence_doc

SCHEMA = SEQJSON_SCHEMA


@pytest.fixture(scope="module")
def doc(rc, flat_terrain):
    return sequence_doc(rc, flat_terrain, rules_used=load_rules().to_dict())[1]


def _errors(seq):
    return list(jsonschema.Draft202012Validator(SCHEMA).iter_errors(seq))


def test_seqjson_is_valid_against_the_aerie_schema(doc):
    seq = json.loads(Q.format_seqjson(doc))
    assert _errors(seq) == []
    assert seq["id"] == doc["sequence_id"] and len(seq["steps"]) == len(doc["commands"])
    # the validator is not vacuous: our own argument type "enum", a missing time, an extra key are rejected
    bad = copy.deepcopy(seq)
    bad["steps"][1]["args"][3]["type"] = "enum"
    assert _errors(bad)
    bad = copy.deepcopy(seq)
    del bad["steps"][0]["time"]
    assert _errors(bad)
    bad = copy.deepcopy(seq)
    bad["steps"][0]["stop"] = 1
    assert _errors(bad)


def test_seqjson_steps_carry_the_commands(doc):
    seq = json.loads(Q.format_seqjson(doc))
    kinds = {"enum": "symbol", "string": "string", "bool": "boolean", "int": "number", "float": "number"}
    for step, c in zip(seq["steps"], doc["commands"]):
        assert step["type"] == "command" and step["stem"] == c["stem"]
        assert step["time"] == {"type": "COMMAND_RELATIVE", "tag": c["time_tag"][1:]}
        assert [(a["name"], a["type"], a["value"]) for a in step["args"]] == \
               [(a["name"], kinds[a["type"]], a["value"]) for a in c["args"]]
        assert step.get("description", "") == c["comment"]
        assert step.get("metadata") == (None if c["stop"] is None else {"stop": c["stop"]})
    assert seq["metadata"]["notional"] is True and seq["metadata"]["rules_used"] == doc["rules_used"]
    assert seq["metadata"]["provenance"] == doc["provenance"]


def test_a_comment_with_a_line_break_is_one_line_in_both_forms(doc):
    # a comment carries names read from the input (a method name from handoff.json): SeqN wrote it on one line,
    # SeqJSON kept the break, which Aerie's conversion of the step back to SeqN writes as a broken command line
    d = copy.deepcopy(doc)
    d["commands"][0]["comment"] = "handoff by\nscip"
    seq = json.loads(Q.format_seqjson(d))
    seqn = G.parse(Q.format_seqn(d))
    assert "\n" not in seq["steps"][0]["description"]
    assert seq["steps"][0]["description"] == seqn.commands[0].comment
    assert _errors(seq) == []


def test_seqn_is_recognised_by_the_aerie_grammar_and_matches_the_document(doc):
    text = Q.format_seqn(doc)
    seqn = G.parse(text)
    assert seqn.id == doc["sequence_id"] and seqn.directives == []
    seq = json.loads(Q.format_seqjson(doc))
    assert dict(seqn.metadata) == seq["metadata"]  # the same metadata in both forms
    assert len(seqn.commands) == len(doc["commands"])
    for c, d in zip(seqn.commands, doc["commands"]):
        assert (c.time_tag, c.stem, c.comment) == (d["time_tag"], d["stem"], d["comment"])
        kinds = [k for k, _ in c.args]
        assert kinds == [{"enum": "enum", "string": "str", "bool": "bool", "int": "num", "float": "num"}[a["type"]]
                         for a in d["args"]]
        for (k, t), a in zip(c.args, d["args"]):
            if k == "num":
                assert float(t) == pytest.approx(a["value"], abs=5e-7)  # 6 decimals written
            elif k == "str":
                assert json.loads(t) == a["value"]
            else:
                assert t == str(a["value"])


@pytest.mark.parametrize("bad", [
    "R0:00:00 SCIP_BEGIN",  # hh must be two digits
    'R00:00:00 SCIP_BEGIN "t1',  # unterminated String
    "R00:00:00 SCIP_BEGIN 1.2.3",
    "R00:00:00SCIP_BEGIN",  # a time tag ends in whiteSpace
    "@METADATA key 1",  # the Key is a String
    '@METADATA "k" {"a" 1}',
    # the grammar's tokens take precedence over identifier (@precedence { TimeAbsolute, TimeRelative, TimeEpoch,
    # TimeComplete, TimeGroundEpoch, Boolean, identifier }): neither a Stem nor an Enum may read as a time tag or
    # start with a Boolean (each line checked with the Lezer parser built from tests/data/seqn/sequence.grammar)
    "R00:00:01 X C # c", "R00:00:01 X E1 2", "R00:00:01 C X", "R00:00:01 X R1 ", "R00:00:01 X E+1 2",
    "R00:00:01 X G00:00:01 2", "R00:00:01 X A2026-001T00:00:00 1",
    "R00:00:01 X true1", "R00:00:01 X false-a", "R00:00:01 trueX 1",
])
def test_the_recogniser_rejects_what_the_grammar_rejects(bad):
    with pytest.raises(G.SeqNError):
        G.parse('@ID "x"\n' + bad + "\n")


@pytest.mark.parametrize("good", ["R00:00:01 X C", "R00:00:01 X R1", "R00:00:01 X Cx", "R00:00:01 X E1X",
                                  "R00:00:01 TRUE_X TRUE", "R00:00:01 X nullx", "R00:00:01 CONTACT ON"])
def test_the_recogniser_keeps_what_the_grammar_keeps(good):  # each checked with the Lezer parser, as above
    assert len(G.parse('@ID "x"\n' + good + "\n").commands) == 1


def test_the_recogniser_rejects_metadata_after_the_commands():
    with pytest.raises(G.SeqNError, match="after the commands"):
        G.parse('@ID "x"\nR00:00:01 A_B 1\n@METADATA "k" 1\n')
    ok = G.parse('# c\n@ID "x"\n@METADATA "k" {"a": [1, -2.5e-3, null, true]}\nC A_B ON "s" 3 # note\nA2026-327T12:00:00 X\n')
    assert ok.metadata == [("k", {"a": [1, -2.5e-3, None, True]})]
    assert [(c.time_tag, c.stem, c.args, c.comment) for c in ok.commands] == [
        ("C", "A_B", [("enum", "ON"), ("str", '"s"'), ("num", "3")], "note"), ("A2026-327T12:00:00", "X", [], "")]


def test_long_time_tags_and_missing_numbers_stay_in_the_grammar():
    assert Q.time_tag(23 * 3600 + 59 * 60 + 59) == "R23:59:59"
    assert Q.time_tag(24 * 3600) == "R001T00:00:00"  # Aerie's linter: hours beyond 23 are unbalanced; DDDThh:mm:ss
    assert Q.time_tag(99 * 3600 + 59 * 60 + 59) == "R004T03:59:59"
    assert G.parse(f"{Q.time_tag(100 * 3600 + 61)} X\n").commands[0].time_tag == "R004T04:01:01"
    assert Q._arg_doc("x_m", math.nan) == {"name": "x_m", "type": "enum", "value": "UNKNOWN"}


AERIE_TIME = json.loads((Path(__file__).resolve().parents[1] / "data" / "seqn" / "aerie_relative_time.json").read_text())


def _aerie_balanced(seconds: int) -> str:
    """aerie-ui's ``getBalancedDuration`` for whole non-negative seconds (src/utilities/time.ts): ``hh:mm:ss.000``,
    with ``DDDT`` in front from one day on."""
    d, r = divmod(seconds, 86400)
    return (f"{d:03d}T" if d else "") + f"{r // 3600:02d}:{r % 3600 // 60:02d}:{r % 60:02d}.000"


def _aerie_lints_relative(tag: str) -> str:
    """aerie-ui's sequence linter on a relative time tag without its ``R`` (validateTimeTags, for the forms
    ``RELATIVE_TIME`` matches): "ok", "invalid", "max" or "unbalanced" (the last three are errors there)."""
    m = re.fullmatch(AERIE_TIME["RELATIVE_TIME"].replace("(?<", "(?P<"), tag)
    if not m:
        return "invalid"
    d, h, mi, s = (int(m.group(k) or 0) for k in ("doy", "hr", "mins", "secs"))
    total = ((d * 24 + h) * 60 + mi) * 60 + s
    if total >= 366 * 86400:
        return "max"
    return "ok" if _aerie_balanced(total).split(".")[0] == tag.split(".")[0] else "unbalanced"


def test_the_aerie_time_rules_here_agree_with_aeries_own_cases():
    for tag, ok in AERIE_TIME["isTimeBalanced_relative"]:
        assert (_aerie_lints_relative(tag) == "ok") == ok, tag
    for tag, ok in AERIE_TIME["isTimeMax_relative"]:
        assert (_aerie_lints_relative(tag) == "max") == ok, tag
    assert _aerie_balanced(1) == dict(AERIE_TIME["getBalancedDuration"])["1"]
    assert _aerie_balanced(45600) == dict(AERIE_TIME["getBalancedDuration"])["45600"]
    assert _aerie_balanced(24 * 3600 + 60 * 60 + 60) == dict(AERIE_TIME["getBalancedDuration"])["24:60:60"]


@pytest.mark.parametrize("seconds", [0, 0.4, 59.2, 3725, 86399, 86400, 86401, 90000, 99 * 3600 + 3599, 100 * 3600,
                                     30 * 86400 + 7, 365 * 86400 + 86399])
def test_relative_time_tags_are_what_aeries_sequence_editor_takes(seconds):
    """The tag is in the grammar, passes Aerie's linter (valid, not max, balanced: hours below 24, days as DDDT) and
    is Aerie's own balanced form of the duration, as its SeqN-to-SeqJSON conversion writes it."""
    tag = Q.time_tag(seconds)
    assert G.parse(f"{tag} X\n").commands[0].time_tag == tag
    assert tag[0] == "R" and _aerie_lints_relative(tag[1:]) == "ok", tag
    assert tag[1:] + ".000" == _aerie_balanced(math.ceil(seconds)), tag
