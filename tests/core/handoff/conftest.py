"""Fixtures of the scipctl/core/handoff/ tests: the tiny synthetic case of synthetic.py."""

import pytest

from tests.core.handoff.synthetic import HandoffScene, build_scene


@pytest.fixture(scope="module")
def handoff_scene() -> HandoffScene:
    """The scene's near and far cases with default parameters, shared by a test module (products cached)."""
    return build_scene()


@pytest.fixture
def make_handoff_scene():
    """``make_handoff_scene(params=None)``: fresh cases (nothing cached) of the same scene."""
    return build_scene
