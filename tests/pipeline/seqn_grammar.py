"""A recogniser for the subset of Aerie's SeqN that ``scipctl.pipeline.sequence.format_seqn`` emits, written by hand
from Aerie's Lezer grammar (``tests/data/seqn/sequence.grammar``: NASA-AMMOS/aerie-ui
``src/utilities/codemirror/sequence.grammar`` at cd7c918, MIT; see tests/data/README.md).

Covered, with the grammar's rule names::

    Sequence      optSpace (commentLine* (IdDeclaration | GenericDirective))* commentLine* Metadata? Commands?
    IdDeclaration idDirective (whiteSpace (String | Enum | Number)?)? newLine
    Metadata      MetaEntry+ ; MetaEntry: "@METADATA" whiteSpace Key{String} whiteSpace Value{metaValue} newLine
    metaValue     String | Number | Boolean | Null | Array | Object (Object/Array/Property with optSpace)
    Commands      commandBlock: (Command | commentLine)+
    Command       TimeTag? Stem Args LineComment? newLine   (no per-command Metadata / Models: we emit none)
    Args          (whiteSpace arg)* whiteSpace? ; arg: Number | String | Boolean | Enum  (no RepeatArg)
    Stem, Enum    identifier, but not where the tokenizer reads a time tag or Boolean first (@precedence)
    TimeTag       TimeAbsolute | TimeEpoch | TimeRelative | TimeComplete   (not the ground epoch 'G')

Tokens are the grammar's ``@tokens`` as regular expressions. Not covered: ``@INPUT_PARAMS``, ``@LOCALS``,
``@LOAD_AND_GO``, ``@IMMEDIATE``, ``@HARDWARE``, activates/loads/ground steps, requests, ``@MODEL``. Lines are
matched whole (the grammar's ``newLine`` folds blank lines and trailing blanks, which we do not emit).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field

_HMS = r"\d\d:\d\d:\d\d(?:\.\d+)?"  # timeHhmmss
_DOY = r"\d\d\dT" + _HMS  # timeDOY
_SECOND = r"[1-9]\d*(?:\.\d+)?"  # timeSecond
TIME_TAG = re.compile(
    r"(?P<tag>A\d\d\d\d-\d\d\dT" + _HMS  # TimeAbsolute
    + r"|R(?:" + _DOY + "|" + _HMS + "|" + _SECOND + ")"  # TimeRelative (DOY before hh:mm:ss: longest match)
    + r"|E[+-]?(?:" + _DOY + "|" + _HMS + "|" + _SECOND + ")"  # TimeEpoch
    + r"|C)[ \t]+")  # TimeComplete; every time tag ends in whiteSpace
# the ground epoch tag 'G' (not emitted): only so that a Stem or an Enum which would read as one is rejected
_GROUND_EPOCH = r"G[+-]?(?:" + _DOY + "|" + _HMS + "|" + _SECOND + r")[ \t]+"
# @precedence { TimeAbsolute, TimeRelative, TimeEpoch, TimeComplete, TimeGroundEpoch, Boolean, identifier }: where a
# Stem or an Enum is expected, the tokenizer still reads a time tag (with its whiteSpace) or a leading 'true'/'false'
# (even within a longer word: "trueX" is Boolean "true" then "X"), and the parse fails
TOKEN_BEFORE_IDENTIFIER = re.compile(TIME_TAG.pattern + "|" + _GROUND_EPOCH + r"|true|false")
IDENT = r"[A-Za-z][A-Za-z0-9_-]*"  # identifier
STRING = r'"(?:[^"\\]|\\.)*"'  # String
NUMBER = (r"[+-]?(?:\d[\d_]*(?:\.[\d_]*)?|\.\d[\d_]*)(?:[eE][+-]?[\d_]+)?(?![\w.])"
          r"|\d[\d_]*n|0x[0-9A-F_]+n?")  # Number
BOOLEAN = r"(?:true|false)(?![A-Za-z0-9_-])"
ARG = re.compile(r"(?P<str>" + STRING + r")|(?P<num>" + NUMBER + r")|(?P<bool>" + BOOLEAN + r")|(?P<enum>" + IDENT + r")")
LINE_COMMENT = re.compile(r"#[^\n\r]*")
DIRECTIVE = re.compile(r"@" + IDENT)


class SeqNError(ValueError):
    pass


@dataclass
class Command:
    time_tag: str  # as written ("R00:00:05"), "" when absent
    stem: str
    args: list  # [(kind, text)]: kind in str | num | bool | enum
    comment: str  # the LineComment without "#", stripped; "" when absent


@dataclass
class SeqN:
    id: object = None  # the @ID's String (decoded) / Enum / Number text
    directives: list = field(default_factory=list)  # generic directives (name, [strings])
    metadata: list = field(default_factory=list)  # [(key, decoded value)]
    commands: list = field(default_factory=list)  # [Command]
    comments: int = 0


def parse(text: str) -> SeqN:
    """Recognise ``text`` (see the module docstring); :class:`SeqNError` names the first line that is not SeqN."""
    out = SeqN()
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines = lines[:-1]
    i = 0
    phase = "header"  # header -> metadata -> commands
    for i, ln in enumerate(lines, 1):
        try:
            if ln.startswith("#"):
                if not LINE_COMMENT.fullmatch(ln):
                    raise SeqNError("bad comment")
                out.comments += 1
                continue
            if ln.startswith("@METADATA"):
                if phase == "commands":
                    raise SeqNError("@METADATA after the commands (only the Command's own Metadata may follow)")
                phase = "metadata"
                out.metadata.append(_meta_entry(ln))
                continue
            if ln.startswith("@"):
                if phase != "header":
                    raise SeqNError("a header directive after the metadata or the commands")
                _directive(ln, out)
                continue
            phase = "commands"
            out.commands.append(_command(ln))
        except SeqNError as e:
            raise SeqNError(f"line {i}: {e}: {ln!r}") from None
    return out


def _directive(ln: str, out: SeqN) -> None:
    m = DIRECTIVE.match(ln)
    if not m:
        raise SeqNError("bad directive")
    name, rest = m.group(0), ln[m.end():]
    if name == "@ID":
        if rest == "":
            return
        m2 = re.fullmatch(r"[ \t]+(?:(" + STRING + r")|(" + NUMBER + r")|(" + IDENT + r"))?", rest)
        if not m2:
            raise SeqNError("@ID takes one String, Enum or Number")
        out.id = json.loads(m2.group(1)) if m2.group(1) else (m2.group(2) or m2.group(3))
        return
    if name in ("@METADATA", "@MODEL", "@INPUT_PARAMS", "@LOCALS", "@LOAD_AND_GO", "@IMMEDIATE", "@HARDWARE"):
        raise SeqNError(f"{name} is outside the recognised subset here")
    strings = re.findall(r"[ \t]+(" + STRING + r")", rest)
    if re.sub(r"[ \t]+" + STRING, "", rest) != "":
        raise SeqNError("a generic directive takes only Strings")
    out.directives.append((name, [json.loads(s) for s in strings]))


def _meta_entry(ln: str):
    m = re.match(r"@METADATA[ \t]+(" + STRING + r")[ \t]+", ln)
    if not m:
        raise SeqNError("MetaEntry is @METADATA whiteSpace String whiteSpace metaValue")
    value, end = _meta_value(ln, m.end())
    if ln[end:].strip(" \t"):
        raise SeqNError(f"text after the metadata value: {ln[end:]!r}")
    return json.loads(m.group(1)), value


def _skip(s: str, i: int) -> int:  # optSpace
    while i < len(s) and s[i] in " \t\n":
        i += 1
    return i


def _meta_value(s: str, i: int):
    """metaValue at ``s[i:]`` -> (decoded value, end)."""
    if s.startswith("{", i):
        i, obj = _skip(s, i + 1), {}
        if s.startswith("}", i):
            return obj, i + 1
        while True:
            m = re.compile(STRING).match(s, i)  # PropertyName
            if not m:
                raise SeqNError(f"property name expected at {i}")
            i = _skip(s, m.end())
            if not s.startswith(":", i):
                raise SeqNError(f"':' expected at {i}")
            v, i = _meta_value(s, _skip(s, i + 1))
            obj[json.loads(m.group(0))] = v
            i = _skip(s, i)
            if s.startswith(",", i):
                i = _skip(s, i + 1)
                continue
            if s.startswith("}", i):
                return obj, i + 1
            raise SeqNError(f"',' or '}}' expected at {i}")
    if s.startswith("[", i):
        i, arr = _skip(s, i + 1), []
        if s.startswith("]", i):
            return arr, i + 1
        while True:
            v, i = _meta_value(s, i)
            arr.append(v)
            i = _skip(s, i)
            if s.startswith(",", i):
                i = _skip(s, i + 1)
                continue
            if s.startswith("]", i):
                return arr, i + 1
            raise SeqNError(f"',' or ']' expected at {i}")
    for pat, conv in ((STRING, json.loads), (BOOLEAN, lambda t: t == "true"), (r"null(?![A-Za-z0-9_-])", lambda t: None),
                      (NUMBER, _number)):
        m = re.compile(pat).match(s, i)
        if m:
            return conv(m.group(0)), m.end()
    raise SeqNError(f"metaValue expected at {i}")


def _number(t: str):
    t = t.replace("_", "")
    return float(t) if any(c in t for c in ".eE") else int(t)


def _command(ln: str) -> Command:
    i, tag = 0, ""
    m = TIME_TAG.match(ln)
    if m:
        tag, i = m.group("tag"), m.end()
    elif ln[:1] in "AREGC" and re.match(r"[AREGC][\d+-]", ln):
        raise SeqNError("malformed time tag")
    if TOKEN_BEFORE_IDENTIFIER.match(ln, i):
        raise SeqNError("a time tag or Boolean where the Stem is expected (the grammar's token precedence)")
    m = re.compile(IDENT).match(ln, i)  # Stem
    if not m:
        raise SeqNError("stem expected")
    stem, i = m.group(0), m.end()
    args = []
    while i < len(ln):
        m = re.compile(r"[ \t]+").match(ln, i)
        if not m:
            raise SeqNError(f"whitespace expected before {ln[i:]!r}")
        i = m.end()
        if i == len(ln):
            break
        if ln[i] == "#":
            return Command(tag, stem, args, ln[i + 1:].strip())
        a = ARG.match(ln, i)
        if not a:
            raise SeqNError(f"argument expected at {ln[i:]!r}")
        if a.lastgroup == "enum" and TOKEN_BEFORE_IDENTIFIER.match(ln, i):
            raise SeqNError(f"a time tag or Boolean where an Enum is written at {ln[i:]!r} (the grammar's token precedence)")
        args.append((a.lastgroup, a.group(0)))
        i = a.end()
    return Command(tag, stem, args, "")
