"""Container B: a downlink as a directory (``downlink.yaml`` + ``images/<product_id>.png``).

``downlink.yaml`` holds ``format_version``, ``mission``, ``sol``,
``rover_config`` (inline, or a path to a YAML file), ``images`` (records
whose ``image`` is a path relative to the directory), optional ``targets``
and ``truth: {images, targets}``. Wherever a ``camera_model`` may stand, a
``camera_model_file`` (JPL cmod text file) may stand instead; its path is
relative to the YAML file that names it. YAML anchors/aliases are plain YAML.
Plain scalars are read as YAML 1.2's core schema reads them (:data:`YamlLoader`):
``1e-5`` and ``-.5`` are numbers, ``0042`` is 42, ``0o17`` is 15, and
``yes``/``no``/``on``/``off`` are strings (only ``true``/``false`` are booleans),
as are dates (``2001-12-14``), ``12:30``, ``1_000`` and ``0b101``; an explicit tag
holds to the same forms (``!!int 1_000`` is malformed, not 1000). The one YAML 1.1
reading kept on purpose is the merge key ``<<``.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from urllib.parse import quote

import yaml

from ..model import Downlink, InputError
from . import downlink_records as P
from .cmodfile import read_cmod

YAML_NAME = "downlink.yaml"
IMAGES_DIR = "images"

_Base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_DumperBase = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class _Loader(_Base):  # type: ignore[misc,valid-type]
    """Safe YAML loader that resolves plain scalars exactly as YAML 1.2's core schema does (docs/downlink-format.md,
    "Types are strict"; https://yaml.org/spec/1.2.2/#1032-tag-resolution), not by PyYAML's YAML 1.1 rules:
    null ``null``/``Null``/``NULL``/``~``/empty; booleans only ``true``/``false`` (``True``, ``TRUE``, ``False``,
    ``FALSE``: ``yes``/``no``/``on``/``off`` are strings); integers ``[-+]?[0-9]+`` (decimal, leading zeros too:
    ``sol: 0042`` is 42, not 1.1 octal 34), ``0o17`` (15) and ``0x1F`` (31); floats such as ``1e-5``, ``-.5``,
    ``+.5``, ``.5e3``, ``1.``, ``.inf``, ``.nan``. Everything else is a string: dates (``2001-12-14``), base-60
    numbers (``12:30``, which 1.1 reads as 750), ``1_000``, ``0b101``, ``-0x1F``, ``=``. The one 1.1 reading kept
    on purpose is the merge key ``<<`` (``<<: *defaults`` merges an anchored mapping): a common idiom with anchors,
    which YAML 1.2 readers such as ruamel.yaml and Go's yaml.v3 keep too; without it such a file would have a key
    named ``<<`` (an unknown-key error). A bare ``<<`` is no string: write it quoted."""


# Tag resolution, first match wins (null, bool, int, float; https://yaml.org/spec/1.2.2/#1032-tag-resolution). The
# table replaces PyYAML's 1.1 one (whose int/float also read 12:30, 1_000, 0b101, -0x1F, and not 0o17 or 1e3).
_NULL = "tag:yaml.org,2002:null"
_BOOL = "tag:yaml.org,2002:bool"
_INT = "tag:yaml.org,2002:int"
_FLOAT = "tag:yaml.org,2002:float"
_MERGE = "tag:yaml.org,2002:merge"
_DECIMAL_INT = re.compile(r"^[-+]?[0-9]+$")
_NULL_RE = re.compile(r"^(?:null|Null|NULL|~|)$")
_BOOL_RE = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_INT_RE = re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$")
_FLOAT_RE = re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
                       r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$")
_Loader.yaml_implicit_resolvers = {}  # the class's own table: none of PyYAML's 1.1 resolvers
_Loader.add_implicit_resolver(_NULL, _NULL_RE, ["n", "N", "~", ""])
_Loader.add_implicit_resolver(_BOOL, _BOOL_RE, list("tTfF"))
_Loader.add_implicit_resolver(_INT, _INT_RE, list("-+0123456789"))
_Loader.add_implicit_resolver(_FLOAT, _FLOAT_RE, list("-+.0123456789"))  # after int: 12 matches both
_Loader.add_implicit_resolver(_MERGE, re.compile(r"^<<$"), ["<"])  # kept on purpose (class docstring)


def _core_scalar(loader, node, pattern, what: str) -> str:
    """The scalar's text when it is one of YAML 1.2's core forms of ``what``: a plain scalar got its tag from that
    pattern already; an explicitly tagged one (``!!int 1_000``, ``!!bool yes``) is checked here, where PyYAML's own
    constructors would read it by YAML 1.1's rules (1000, True). Otherwise a ConstructorError (malformed YAML)."""
    value = loader.construct_scalar(node)
    if not pattern.match(value):
        raise yaml.constructor.ConstructorError(None, None, f"{value!r} is not a YAML 1.2 {what}", node.start_mark)
    return value


def _construct_int(loader, node):
    value = _core_scalar(loader, node, _INT_RE, "integer")
    if _DECIMAL_INT.match(value):
        return int(value, 10)  # YAML 1.2: leading zeros are not octal
    return int(value[2:], 8 if value.startswith("0o") else 16)


def _construct_float(loader, node):
    # PyYAML's constructor reads every 1.2 form (1e3, -.5, 1., .inf, .nan) once the form is checked
    _core_scalar(loader, node, _FLOAT_RE, "float")
    return yaml.SafeLoader.construct_yaml_float(loader, node)


def _construct_bool(loader, node):
    return _core_scalar(loader, node, _BOOL_RE, "boolean").lower() == "true"


def _construct_null(loader, node):
    _core_scalar(loader, node, _NULL_RE, "null")


_Loader.add_constructor(_INT, _construct_int)
_Loader.add_constructor(_FLOAT, _construct_float)
_Loader.add_constructor(_BOOL, _construct_bool)
_Loader.add_constructor(_NULL, _construct_null)
# ints and floats both through Python's int()/float(), so a 5000-digit integer is a ValueError (malformed YAML,
# parse_yaml)

#: the project's one YAML loader: downlink.yaml, an external rover configuration, rules files (io/rules_file.py)
YamlLoader = _Loader


MAX_YAML_DEPTH = 100  # downlink.yaml nests 7 deep; libyaml's loader crashes the process at ~40000


def _check_depth(text: str, label: str, field: str = "yaml") -> None:
    """InputError if collections nest more than :data:`MAX_YAML_DEPTH` deep (checked on the parser's events,
    which need no recursion, before the recursive loader sees the text)."""
    depth = 0
    for ev in yaml.parse(text, Loader=_Loader):
        if isinstance(ev, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                mark = ev.start_mark
                raise InputError(label, field, f"collections nested more than {MAX_YAML_DEPTH} deep "
                                                f"at line {mark.line + 1}, column {mark.column + 1}")
        elif isinstance(ev, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            depth -= 1


def load_yaml(path: Path, label: str):
    """Parse a YAML file; :class:`InputError` ``(label, "yaml", ...)`` on unreadable or malformed text."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(label, "file", f"no such file: {path}") from None
    except (OSError, ValueError) as e:  # ValueError: not UTF-8, or a NUL in the path
        raise InputError(label, "file", f"cannot read {path}: {getattr(e, 'strerror', None) or e}") from None
    return parse_yaml(text, label)


def parse_yaml(text: str, label: str, field: str = "yaml"):
    """``text`` read with :data:`YamlLoader`: every YAML file scipctl reads (downlink.yaml, an external rover
    configuration, rules files) goes through here. :class:`InputError` ``(label, field, ...)`` for malformed YAML,
    collections nested more than :data:`MAX_YAML_DEPTH` deep, or a scalar Python cannot build."""
    try:
        _check_depth(text, label, field)
        return yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise InputError(label, field, f"malformed YAML{where}: {problem}") from None
    except (ValueError, RecursionError) as e:  # a scalar the constructors refuse: a 5000-digit integer
        raise InputError(label, field, f"malformed YAML: {str(e)[:120]}") from None


class _Resolver12(yaml.resolver.BaseResolver):
    """:data:`YamlLoader`'s implicit resolvers alone (the same table, not a copy): the tag scipctl's reader gives a
    plain (unquoted) scalar."""

    yaml_implicit_resolvers = _Loader.yaml_implicit_resolvers


_READ_12 = _Resolver12()


class _QuoteWhatReadersTypeDifferently:
    """A scalar is written plain only if YAML 1.1 readers (PyYAML's own resolvers, e.g. ``yaml.safe_load``) and
    :data:`YamlLoader` (YAML 1.2) give it the same type; otherwise the emitter quotes it, as it quotes the string
    ``'yes'``. PyYAML's dumper asks only its 1.1 resolvers, so it left the strings ``1e3``, ``0089``, ``-.5``,
    ``+.5``, ``.5e3`` (and ``0o17``) bare, which YamlLoader reads as numbers. A mixin before a PyYAML dumper."""

    def resolve(self, kind, value, implicit):
        tag = super().resolve(kind, value, implicit)  # type: ignore[misc]
        if kind is yaml.ScalarNode and implicit[0] and _READ_12.resolve(kind, value, implicit) != tag:
            return "tag:scipctl:read-differently"  # no node has this tag: never plain
        return tag


class _Dumper(_QuoteWhatReadersTypeDifferently, _DumperBase):  # type: ignore[misc,valid-type]
    """PyYAML's safe dumper (libyaml's when there), quoting as :class:`_QuoteWhatReadersTypeDifferently` says."""


class PyYamlDumper(_QuoteWhatReadersTypeDifferently, yaml.SafeDumper):
    """The writer's dumper in PyYAML's pure-Python emitter, which escapes (``allow_unicode=False``) what libyaml's
    cannot encode, a lone surrogate: for tests that write odd values for the reader to refuse."""


def dump_yaml(obj) -> str:
    """YAML text that :data:`YamlLoader` and YAML 1.1 readers both read back as ``obj``."""
    return yaml.dump(obj, Dumper=_Dumper, sort_keys=False, default_flow_style=None, width=4096, allow_unicode=True)


def _model_file_resolver(base_dir: Path):
    def resolve(rel: str, product: str, field: str):
        path = base_dir / rel
        try:
            return read_cmod(path)
        except InputError as e:
            raise InputError(product, field, f"{rel}: {e.field}: {e.message}") from None

    return resolve


def read_dir(root: Path) -> Downlink:
    """Read container B into a :class:`Downlink` (no cross-record validation)."""
    ypath = root / YAML_NAME
    label = str(ypath)
    if not ypath.is_file():
        raise InputError(str(root), YAML_NAME, "missing: not a downlink directory, not a workspace, and no real "
                         "product scipctl reads in it (PDS3, VICAR, PDS4 label, Mars 2020 raw JSON)")
    doc = load_yaml(ypath, label)
    top = P.Fields(doc, label, "")
    fmt_version = P.check_format_version(top.req("format_version"), label)
    mission = top.str_("mission")
    sol = top.int_("sol")
    resolve_here = _model_file_resolver(root)

    rc = top.req("rover_config")
    if isinstance(rc, str):
        rc_path = root / rc
        rover_config = P.rover_config_from_plain(load_yaml(rc_path, str(rc_path)), _model_file_resolver(rc_path.parent),
                                                 product=f"rover_config ({rc})")
    else:
        rover_config = P.rover_config_from_plain(rc, resolve_here)

    records = top.list_("images")
    if not records:
        raise InputError(label, "images", "no image products")
    images = []
    for i, d in enumerate(records):
        pl = P.product_label(d, i, "images")
        fs = P.Fields(d, pl, "")
        rel = fs.str_("image")
        ipath = root / rel
        try:
            png = ipath.read_bytes()
        except FileNotFoundError:
            raise InputError(pl, "image", f"file not found: {rel}") from None
        except (OSError, ValueError) as e:  # ValueError: a NUL in the path
            raise InputError(pl, "image", f"cannot read {rel}: {getattr(e, 'strerror', None) or e}") from None
        images.append(P.product_from_plain(d, png, rover_config, pl, resolve_here))

    targets = [P.target_from_plain(d, f"targets[{i}]") for i, d in enumerate(top.list_("targets", required=False))]
    truth_images, truth_targets = [], []
    truth = top.map_("truth", required=False)
    if truth is not None:
        truth_images = [P.truth_image_from_plain(d, f"truth.images[{i}]", resolve_here)
                        for i, d in enumerate(truth.list_("images", required=False))]
        truth_targets = [P.truth_target_from_plain(d, f"truth.targets[{i}]")
                         for i, d in enumerate(truth.list_("targets", required=False))]

    from .provenance import sha256_path

    return Downlink(
        mission=mission, sol=sol, rover_config=rover_config, images=images, targets=targets,
        truth_images=truth_images, truth_targets=truth_targets, format_version=fmt_version,
        source=str(root), source_sha256=sha256_path(root),
    )


_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+\-]*$")


_MAX_NAME_BYTES = 200  # file systems allow 255 bytes per name; keep a margin


def image_file_name(product_id: str) -> str:
    """``<product_id>.png``; ids that are not plain file names are percent-encoded (injective). A name longer
    than :data:`_MAX_NAME_BYTES` (the contract sets no length on ids, and percent-encoding triples non-ASCII
    bytes) is cut and ends in ``%~`` + a SHA-256 of the id, which no percent-encoded name contains."""
    if _SAFE_NAME.match(product_id):
        q = product_id
    else:
        q = quote(product_id, safe="")
        if q.startswith("."):
            q = "%2E" + q[1:]
    if len(q) + 4 > _MAX_NAME_BYTES:  # q is ASCII
        q = q[:120] + "%~" + hashlib.sha256(product_id.encode("utf-8", "surrogatepass")).hexdigest()[:32]
    return q + ".png"


def downlink_yaml_text(dl: Downlink) -> str:
    doc = {
        "format_version": int(dl.format_version) if str(dl.format_version).isdigit() else str(dl.format_version),
        "mission": str(dl.mission),
        "sol": int(dl.sol),
        "rover_config": P.rover_config_to_plain(dl.rover_config),
        "images": [],
    }
    for im in dl.images:
        rec = P.product_to_plain(im)
        rec["image"] = f"{IMAGES_DIR}/{image_file_name(im.product_id)}"
        doc["images"].append(rec)
    if dl.targets:
        doc["targets"] = [P.target_to_plain(t) for t in dl.targets]
    if dl.truth_images or dl.truth_targets:
        doc["truth"] = {
            "images": [P.truth_image_to_plain(t) for t in dl.truth_images],
            "targets": [P.truth_target_to_plain(t) for t in dl.truth_targets],
        }
    header = "# SCIP downlink, format version 1 (container B). Written by scipctl.\n"
    return header + dump_yaml(doc)


def write_dir_contents(dl: Downlink, directory: Path) -> None:
    """Write ``downlink.yaml`` and ``images/`` into an existing (normally empty, temporary) directory."""
    (directory / IMAGES_DIR).mkdir(parents=True, exist_ok=True)
    for im in dl.images:
        (directory / IMAGES_DIR / image_file_name(im.product_id)).write_bytes(im.png)
    (directory / YAML_NAME).write_text(downlink_yaml_text(dl), encoding="utf-8")


def check_replaceable(path: Path, what: str, marker: str) -> None:
    """Refuse to replace ``path`` unless it is absent, an empty directory, or contains ``marker``."""
    if not path.exists():
        return
    if not path.is_dir():
        raise InputError(str(path), "output", f"exists and is not a directory; refusing to replace it with {what}")
    if any(path.iterdir()) and not (path / marker).exists():
        raise InputError(str(path), "output", f"exists, is not empty and is not {what}; refusing to replace it")


def write_dir(dl: Downlink, path: Path) -> Path:
    from .atomic import atomic_directory, recover_interrupted

    recover_interrupted(path)  # before deciding what `path` is (atomic_directory)
    check_replaceable(path, "a downlink directory", YAML_NAME)
    with atomic_directory(path) as tmp:
        write_dir_contents(dl, tmp)
    return path
