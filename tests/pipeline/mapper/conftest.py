"""Fixtures for the mapper tests."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from mapper_helpers import build_scan

from formats.map_types import GridSpec
from pipeline.mapper.types import Scan


@pytest.fixture
def make_scan() -> Callable[..., Scan]:
    return build_scan


@pytest.fixture
def grid() -> GridSpec:
    """10 m × 10 m at 0.05 m, centred on the origin."""
    return GridSpec(-5.0, -5.0, 0.05, 200, 200)
