"""Reading an object by ranges, with retries: what :meth:`Url.open` returns.

:class:`RemoteRaw` is a seekable raw stream over an fsspec file opened with
``cache_type='blockcache'``: reads of ``block_size`` bytes, at most ``cache_blocks``
blocks held (least recently used dropped). A transient failure (timeout, lost connection,
HTTP 5xx/429) is retried ``[storage] retries`` times, waiting ``backoff_s``, then twice
that, ...; the file is opened again at the same offset. A final failure is a
:class:`~formats.errors.StorageError` — never an ``OSError``, which readers would take for
a truncated log and map the part before it.
"""

from __future__ import annotations

import contextlib
import io
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from formats.errors import StorageError
from formats.storage.failures import describe, is_transient
from formats.storage.options import current

if TYPE_CHECKING:
    from formats.storage.location import Url

__all__ = ["RemoteRaw", "with_retries"]

T = TypeVar("T")


def with_retries(fn: Callable[[], T], where: Url, what: str,
                 on_retry: Callable[[], None] | None = None) -> T:
    """``fn()``, retried with exponential backoff on transient failures; any failure left
    is a StorageError ``"<url>: <what>: <why>"``."""
    o = current()
    wait = o.backoff_s
    for attempt in range(o.retries + 1):
        try:
            return fn()
        except StorageError:
            raise
        except Exception as err:
            if attempt == o.retries or not is_transient(err):
                raise StorageError(f"{what}: {describe(err)}", where) from err
        time.sleep(wait)
        wait *= 2
        if on_retry is not None:
            on_retry()
    raise AssertionError("unreachable")  # pragma: no cover


class RemoteRaw(io.RawIOBase):
    """A read-only, seekable raw stream over one object."""

    def __init__(self, url: Url, size: int) -> None:
        super().__init__()
        self.url = url
        self.size = size
        self._pos = 0
        self._file: Any = None
        self._reopen()

    def _reopen(self) -> None:
        if self._file is not None:
            with contextlib.suppress(Exception):  # read only: closing loses nothing
                self._file.close()
        o = current()
        url = self.url

        def open_it() -> Any:
            return url.fs.open(url.fs_path, "rb", block_size=o.block_size,
                               cache_type="blockcache",
                               cache_options={"maxblocks": o.cache_blocks}, size=self.size)

        self._file = with_retries(open_it, url, "cannot open")

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def tell(self) -> int:
        return self._pos

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._pos, io.SEEK_END: self.size}[whence]
        pos = base + offset
        if pos < 0:
            raise ValueError(f"negative seek position {pos}")
        self._pos = pos
        return pos

    def readinto(self, buffer: Any) -> int:
        view = memoryview(buffer).cast("B")
        n = min(len(view), max(0, self.size - self._pos))
        if n == 0:
            return 0

        def read() -> bytes:
            self._file.seek(self._pos)
            data: bytes = self._file.read(n)
            return data

        data = with_retries(read, self.url, f"cannot read bytes {self._pos}-{self._pos + n - 1}",
                            on_retry=self._reopen)
        view[: len(data)] = data
        self._pos += len(data)
        return len(data)

    def close(self) -> None:
        if self._file is not None:
            with contextlib.suppress(Exception):  # read only: closing loses nothing
                self._file.close()
            self._file = None
        super().close()
