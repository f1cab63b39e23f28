"""Fixtures for the mapper tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from mapper_helpers import build_scan

from formats.map_types import GridSpec
from pipeline.mapper.types import MapSnapshot, Scan


@pytest.fixture
def make_scan() -> Callable[..., Scan]:
    return build_scan


@pytest.fixture
def grid() -> GridSpec:
    """10 m × 10 m at 0.05 m, centred on the origin."""
    return GridSpec(-5.0, -5.0, 0.05, 200, 200)


@pytest.fixture(scope="session")
def intel_scans(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[MapSnapshot, list[Scan]]]:
    """The Intel lab log (real trajectory, emulated ring) mapped by ``run`` with the paper's
    method (one pass): its final map and the scans the pipeline fed the mapper."""
    import pipeline.run as run_mod
    from pipeline.config import Config, MapperConfig

    captured: list[Scan] = []
    original = run_mod._integrate

    def capture(mappers, scans):  # type: ignore[no-untyped-def]
        captured.extend(scans)
        original(mappers, scans)

    log = Path(__file__).resolve().parents[3] / "sample_logs" / "intel-lab" / "intel.mcap"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(run_mod, "_integrate", capture)
        paper = Config().replace(mapper=MapperConfig(method="andersone"))
        result = run_mod.run(log, tmp_path_factory.mktemp("intel") / "out", paper)
    yield result.snapshot, captured
