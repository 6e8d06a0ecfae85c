"""The scripts of docs/scripts imported as modules by the tests that check them (they are not a package)."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load(name: str):
    """``docs/scripts/<name>.py`` as a fresh module."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "docs" / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # as importlib's recipe does: dataclasses look their module up while it executes
    spec.loader.exec_module(mod)
    return mod
