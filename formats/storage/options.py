"""The ``[storage]`` section: how sonarmap reaches URLs, and the filesystems it opens.

Credentials and endpoints come from the standard places, never from sonarmap's own
configuration: ``AWS_*`` variables and ``~/.aws`` (``AWS_ENDPOINT_URL`` for S3-compatible
stores), Google's application default credentials, Azure's ``AZURE_STORAGE_*`` variables,
and fsspec's configuration (``~/.config/fsspec``, ``FSSPEC_<PROTOCOL>_<KEY>``). The
section holds only options: an endpoint, anonymous access, the ranged reads' block size
and cache bound, timeouts and retries. A process maps with one storage configuration
(:func:`configure`, called with the run's configuration; a Dask worker gets it with
each log).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

from formats.errors import StorageError
from formats.options import doc_field
from formats.storage.urls import EXTRAS, redact_url

__all__ = ["StorageConfig", "configure", "current", "filesystem"]

MIB = 1 << 20


@dataclass(frozen=True)
class StorageConfig:
    """Options for logs and outputs named by URL (credentials come from the environment)."""

    endpoint_url: str = doc_field(
        "S3-compatible endpoint (e.g. http://127.0.0.1:9000); '' = AWS_ENDPOINT_URL or AWS",
        default="",
    )
    anonymous: bool = doc_field(
        "read public buckets without credentials (s3, gs, az)", default=False
    )
    block_size_mib: float = doc_field(
        "size of one ranged read from a remote log, MiB", default=4.0
    )
    cache_blocks: int = doc_field(
        "blocks kept per open remote file (least recently used dropped first); the memory "
        "bound is block_size_mib × cache_blocks", default=8,
    )
    timeout_s: float = doc_field(
        "a connection or a read that stays silent this long fails (then is retried), s",
        default=30.0,
    )
    retries: int = doc_field(
        "retries after a transient failure (timeout, lost connection, HTTP 5xx), each after "
        "twice the previous wait", default=4,
    )
    backoff_s: float = doc_field("wait before the first retry, s", default=0.5)

    def check(self) -> None:
        """Raise ConfigError when the endpoint carries credentials (the numbers' ranges are
        declared with every other key's, pipeline/config.py RANGES)."""
        from formats.errors import ConfigError

        if self.endpoint_url and redact_url(self.endpoint_url) != self.endpoint_url.rstrip("?#"):
            raise ConfigError("storage.endpoint_url must not carry credentials or a query "
                              "string (credentials come from AWS_* variables or ~/.aws)")

    @property
    def block_size(self) -> int:
        return max(1, int(self.block_size_mib * MIB))


_lock = threading.Lock()
_current = StorageConfig()


def configure(options: StorageConfig) -> None:
    """Use ``options`` for every URL this process opens from now on."""
    global _current
    with _lock:
        _current = options


def current() -> StorageConfig:
    """The storage options in force in this process."""
    return _current


def filesystem(protocol: str) -> Any:
    """The fsspec filesystem of ``protocol`` with the options in force (fsspec caches one
    instance per protocol and options). A filesystem that is not installed is a
    StorageError naming the extra that installs it."""
    import fsspec

    try:
        fsspec.get_filesystem_class(protocol)
    except (ImportError, ValueError) as err:
        extra = EXTRAS.get(protocol)
        hint = f"pip install 'sonarmap[{extra}]'" if extra else "no fsspec filesystem for it"
        raise StorageError(f"{protocol}:// URLs need the '{extra}' extra ({hint})"
                           if extra else f"unsupported URL scheme {protocol}:// ({hint})") from err
    fs = fsspec.filesystem(protocol, **_kwargs(protocol, _current))
    if protocol in ("s3", "s3a", "gs", "gcs"):
        fs.retries = 1  # s3fs's and gcsfs's own retry loops: one attempt (see _kwargs)
    return fs


def _kwargs(protocol: str, o: StorageConfig) -> dict[str, Any]:
    kw: dict[str, Any] = {}
    if protocol in ("s3", "s3a"):
        if o.endpoint_url:
            kw["endpoint_url"] = o.endpoint_url
        if o.anonymous:
            kw["anon"] = True
        # One attempt each in botocore and s3fs: the retries are sonarmap's own, with its
        # backoff (formats/storage/remote_file.py); nested retry loops would multiply.
        kw["config_kwargs"] = {
            "connect_timeout": o.timeout_s, "read_timeout": o.timeout_s,
            "retries": {"max_attempts": 1, "mode": "standard"},
        }
    elif protocol in ("http", "https"):
        import aiohttp

        kw["client_kwargs"] = {"timeout": aiohttp.ClientTimeout(
            total=None, connect=o.timeout_s, sock_connect=o.timeout_s, sock_read=o.timeout_s)}
    elif protocol in ("gs", "gcs"):
        kw["requests_timeout"] = o.timeout_s
        if o.anonymous:
            kw["token"] = "anon"
    elif protocol in ("az", "abfs", "abfss") and o.anonymous:
        kw["anon"] = True
    return kw
