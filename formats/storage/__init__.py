"""Logs and outputs named by URL, through fsspec: :mod:`~formats.storage.location`
(a local path or a :class:`Url`), :mod:`~formats.storage.urls` (telling URLs from paths,
writing them down without credentials), :mod:`~formats.storage.options` (the
``[storage]`` section), :mod:`~formats.storage.failures` (what went wrong)."""

from formats.storage.location import Location, Url, as_location, is_remote
from formats.storage.options import StorageConfig, configure
from formats.storage.urls import is_url, redact_text, redact_url

__all__ = ["Location", "StorageConfig", "Url", "as_location", "configure", "is_remote",
           "is_url", "redact_text", "redact_url"]
