"""Fixtures: the loopback S3 and HTTP servers (see loopback.py), sample logs on both."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from loopback import http_server, s3_env, s3_server

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def s3_endpoint() -> Iterator[str]:
    """moto's S3 server; the AWS_* variables point boto at it for the whole session."""
    with s3_server() as endpoint:
        old = {k: os.environ.get(k) for k in s3_env(endpoint)}
        os.environ.update(s3_env(endpoint))
        try:
            yield endpoint
        finally:
            for k, v in old.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v


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
