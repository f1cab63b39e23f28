"""Fixtures of the reliability tests: the valid logs the mutation tests start from."""

from __future__ import annotations

import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # the fuzz package lives at the top level, not installed
    sys.path.insert(0, str(ROOT))

from fuzz.harness import Target, build_targets  # noqa: E402


@pytest.fixture(scope="session")
def targets(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Target]:
    """Every fuzz target by name (simulated logs in each format + real fixtures)."""
    return {t.name: t for t in build_targets(tmp_path_factory.mktemp("fuzz-fixtures"))}


@pytest.fixture
def quiet_numpy() -> Iterator[None]:
    """Garbage values make numpy warn about overflow; that is expected here."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield
