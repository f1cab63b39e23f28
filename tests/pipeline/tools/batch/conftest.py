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
    """The CLI app (``batch`` is registered by cli/app.py)."""
    from cli.app import app

    return app


@pytest.fixture(scope="module")
def scheduler_address() -> Iterator[str]:
    """A separately started local cluster (2 worker processes on loopback), shared by a
    test module; tests reach it with ``--scheduler``."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
        dashboard_address=":0", silence_logs=40,
    ) as cluster:
        yield cluster.scheduler_address
