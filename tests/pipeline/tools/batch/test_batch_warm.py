"""The batch workers' preload: it warms the process (kernels loaded, the type store
built), and ``sonarmap batch``'s local clusters start their workers with it."""

from __future__ import annotations

from typing import Any

import pytest

from pipeline.tools import batch, batch_warm


def test_dask_setup_loads_the_kernels_and_the_type_store() -> None:
    from formats.writers import map_mcap
    from pipeline.mapper.kernels.andersone_scans import integrate_scans
    from pipeline.mapper.kernels.attribution import attribute_echoes
    from pipeline.mapper.kernels.free_unions import free_unions

    batch_warm.dask_setup(None)
    for kernel in (integrate_scans, free_unions, attribute_echoes):
        assert kernel.signatures, kernel  # compiled or loaded for the types a run passes
    assert map_mcap._typestore.cache_info().currsize == 1


def test_local_clusters_preload_the_warm_up(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: dict[str, Any] = {}

    class Stop(Exception):
        pass

    def cluster(**kwargs: Any) -> None:
        seen.update(kwargs)
        raise Stop

    import distributed

    monkeypatch.setattr(distributed, "LocalCluster", cluster)
    with pytest.raises(Stop), batch._client(1, None):
        pass
    assert seen["preload"] == [batch.WORKER_PRELOAD] == ["pipeline.tools.batch_warm"]


def test_a_failed_warm_up_is_logged_and_the_worker_starts(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    from pipeline.mapper.kernels import warm

    def broken() -> float:
        raise OSError("cache directory not writable")

    monkeypatch.setattr(warm, "warm", broken)
    with caplog.at_level("WARNING", logger="sonarmap.batch"):
        batch_warm.dask_setup(None)  # does not raise
    assert "warm-up failed: OSError: cache directory not writable" in caplog.text
