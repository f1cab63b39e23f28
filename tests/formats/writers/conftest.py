"""Fixtures of the writer tests."""

from __future__ import annotations

import pytest
from writers_helpers import make_features

from formats.map_types import FeatureTable


@pytest.fixture
def features() -> FeatureTable:
    return make_features(
        x=[1.0, 2.5, -0.5],
        y=[0.5, 1.5, 2.0],
        cov=[(0.04, 0.0, 0.01), (0.01, 0.0, 0.04), (0.02, 0.01, 0.02)],
        measured=[5, 1, 9],
    )
