"""Aerie's SeqJSON JSON Schema (tests/data/seqjson/schema.json: NASA-AMMOS/seq-json-schema at 8ee390d, MIT)."""

import json
from pathlib import Path

SEQJSON_SCHEMA = json.loads((Path(__file__).resolve().parents[1] / "data" / "seqjson" / "schema.json").read_text())
