"""Shared fixtures of the command tests."""

import shutil
from pathlib import Path

import pytest

SAMPLE = Path(__file__).resolve().parents[2] / "sample_sols/mcap/paper-s1-straight.mcap"


@pytest.fixture(scope="module")
def sol(tmp_path_factory):
    """A writable copy of the bundled ``paper-s1-straight.mcap`` (one per test module)."""
    p = tmp_path_factory.mktemp("sol") / SAMPLE.name
    shutil.copy(SAMPLE, p)
    return p
