"""moto's S3 API server on loopback, shared by the storage tests and the storage benchmark.

:func:`s3_server` starts it on 127.0.0.1 (a random port, in this process) and yields its
endpoint; :func:`s3_env` gives the ``AWS_*`` variables that point boto (and the child
processes of a run) at it; :func:`loopback_s3` does both, the variables set for the block
and restored after it.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator, Mapping

LOOPBACK = "127.0.0.1"
S3_ENV = {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing-secret",
          "AWS_DEFAULT_REGION": "us-east-1", "AWS_SESSION_TOKEN": "testing-token"}


@contextlib.contextmanager
def s3_server() -> Iterator[str]:
    """moto's S3 API server on loopback; yields its endpoint URL."""
    from moto.server import ThreadedMotoServer

    logging.getLogger("werkzeug").setLevel(logging.ERROR)
    server = ThreadedMotoServer(ip_address=LOOPBACK, port=0, verbose=False)
    server.start()
    _host, port = server.get_host_and_port()
    try:
        yield f"http://{LOOPBACK}:{port}"
    finally:
        server.stop()


def s3_env(endpoint: str) -> dict[str, str]:
    """The variables that send S3 requests to ``endpoint`` (never through a proxy)."""
    return {**S3_ENV, "AWS_ENDPOINT_URL": endpoint, "NO_PROXY": LOOPBACK,
            "no_proxy": LOOPBACK, "HOME": os.environ.get("HOME", "/tmp")}


@contextlib.contextmanager
def environment(env: Mapping[str, str]) -> Iterator[None]:
    """``os.environ`` with ``env`` set inside the block, as it was after it."""
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextlib.contextmanager
def loopback_s3() -> Iterator[str]:
    """:func:`s3_server` with :func:`s3_env` set for the block; yields the endpoint."""
    with s3_server() as endpoint, environment(s3_env(endpoint)):
        yield endpoint
