"""Fixtures of the batch tests: the CLI app with ``batch`` registered, a shared cluster."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import typer

sys.path.insert(0, str(Path(__file__).parent))  # batch_helpers


@pytest.fixture(scope="session")
def cli_app() -> typer.Typer:
    """``cli.app.app`` with the ``batch`` command (registered here until the lead does)."""
    import cli.batch
    from cli.app import app

    names = {c.name or (c.callback.__name__ if c.callback else "") for c in app.registered_commands}
    if "batch" not in names:
        cli.batch.register(app)
    return app


def _shadows_our_packages(entry: str) -> bool:
    d = Path(entry or ".")
    return any(
        (d / pkg).is_dir() and not (d / pkg / "__init__.py").is_file()
        for pkg in ("pipeline", "formats", "cli")
    )


@pytest.fixture(scope="module", autouse=True)
def worker_sys_path() -> Iterator[None]:
    """Spawned Dask workers start with a copy of this process's ``sys.path``. In a full
    test run pytest has put ``tests/`` on it (for the ``tests/formats_ros2`` package), whose
    ``pipeline/`` and ``cli/`` test folders would import in the workers as namespace
    packages ahead of the editable install. Hide such entries while this module runs."""
    saved = list(sys.path)
    sys.path[:] = [p for p in saved if not _shadows_our_packages(p)]
    try:
        yield
    finally:
        sys.path[:] = saved


@pytest.fixture(scope="module")
def scheduler_address(worker_sys_path: None) -> Iterator[str]:
    """A separately started local cluster (2 worker processes on loopback), shared by a
    test module; tests reach it with ``--scheduler``."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
        dashboard_address=None, silence_logs=40,
    ) as cluster:
        yield cluster.scheduler_address
