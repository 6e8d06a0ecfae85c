"""Shared, session-scoped simulated runs (small images so the suite stays fast)."""

import pytest

from scipctl.sim.build import build_run
from scipctl.sim.errors import ErrorSettings

SMALL = 0.125  # 1024 -> 128 px


@pytest.fixture(scope="session")
def run_errors():
    """paper s1-straight, all default errors, 128 x 128 images, rendered (1 sample per pixel)."""
    return build_run("paper", "s1-straight", 1, image_scale=SMALL, supersample=1, render=True)


@pytest.fixture(scope="session")
def run_exact():
    """paper s1-arc without errors, 128 x 128 images, rendered."""
    return build_run("paper", "s1-arc", 1, errors=ErrorSettings.none(), image_scale=SMALL, supersample=1, render=True)


@pytest.fixture(scope="session")
def run_full_exact():
    """paper s1-straight without errors at full size (geometry only, no pixels)."""
    return build_run("paper", "s1-straight", 1, errors=ErrorSettings.none(), render=False)
