"""Fixtures: the loopback S3 (benchmarks/loopback_s3.py) and HTTP (loopback.py) servers,
sample logs on both."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from loopback import http_server

from benchmarks.loopback_s3 import loopback_s3

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def default_storage_options() -> Iterator[None]:
    """Every test starts with the default storage options: a run configures the process's
    options from its config (formats.storage.options.configure), and a test that takes
    ``Url(...).fs`` before its run must get the instance the run will use, not one made
    with the options an earlier test's run left behind."""
    from formats.storage.options import StorageConfig, configure

    configure(StorageConfig())
    yield
    configure(StorageConfig())


@pytest.fixture(scope="session")
def s3_endpoint() -> Iterator[str]:
    """moto's S3 server; the AWS_* variables point boto at it for the whole session."""
    with loopback_s3() as endpoint:
        yield endpoint


@pytest.fixture
def s3(s3_endpoint: str):
    """The S3 filesystem (fsspec) with a fresh bucket per test: yields (fs, bucket)."""
    import secrets

    import fsspec

    fs = fsspec.filesystem("s3", skip_instance_cache=True)
    bucket = f"sonarmap-{secrets.token_hex(4)}"
    fs.mkdir(bucket)
    return fs, bucket


@pytest.fixture(scope="session")
def http_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("http-root")


@pytest.fixture(scope="session")
def http(http_root: Path):
    with http_server(http_root, slow_s=3.0) as server:
        yield server
