"""Where a log or an output is: a local :class:`~pathlib.Path` or a :class:`Url`.

``Location = Path | Url``. A :class:`Url` answers the part of ``Path``'s interface the
readers use (``name``, ``suffix``, ``parent``, ``/``, ``open('rb')``, ``stat()``,
``is_file()``, ``is_dir()``, ``iterdir()``, ...) through fsspec, so a reader opens a URL
where it opened a path. ``open('rb')`` is random access: ranged reads of
``[storage] block_size_mib`` with a least-recently-used cache of ``cache_blocks`` blocks
(memory stays bounded whatever the object's size); a ROS 1 bag's index and an MCAP
summary are read where they are, not downloaded. :meth:`Url.download` copies an object
to a local file for formats that need one (sqlite).

``str(url)`` is the redacted URL (:func:`~formats.storage.urls.redact_url`): every message
and output that names a location names it without credentials; the text as given (it may
carry userinfo or a signed query) is used only to reach the object. Every failure is a
:class:`~formats.errors.StorageError` naming the redacted URL; transient ones are retried
with exponential backoff first (:mod:`formats.storage.remote_file`).
"""

from __future__ import annotations

import io
import stat as stat_mod
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, BinaryIO, Literal, TextIO, TypeAlias, TypeVar, cast, overload

from formats.errors import StorageError
from formats.storage.failures import describe, is_not_found
from formats.storage.options import filesystem
from formats.storage.remote_file import RemoteRaw, with_retries
from formats.storage.urls import is_url, redact_url, scheme_of

__all__ = ["Location", "Url", "as_location", "is_remote", "joined"]

T = TypeVar("T")


@dataclass(frozen=True)
class _Stat:
    st_size: int
    st_mode: int


@dataclass(frozen=True)
class Url:
    """An object or object prefix named by URL (``s3://bucket/key``, ``https://host/x``)."""

    text: str = field(repr=False)

    def __str__(self) -> str:
        return redact_url(self.text)

    def __repr__(self) -> str:
        return f"Url({str(self)!r})"

    # -- names ---------------------------------------------------------------------------

    @property
    def protocol(self) -> str:
        return scheme_of(self.text) or ""

    @property
    def _split(self) -> tuple[str, str]:
        """(scheme://host part, path part without query), path without a trailing '/'."""
        head, _, rest = self.text.partition("://")
        base = rest.split("?", 1)[0].split("#", 1)[0]
        host, _, path = base.partition("/")
        return f"{head}://{host}", path.rstrip("/")

    @property
    def name(self) -> str:
        return PurePosixPath("/" + self._split[1]).name

    @property
    def suffix(self) -> str:
        return PurePosixPath(self.name).suffix

    @property
    def stem(self) -> str:
        return PurePosixPath(self.name).stem

    @property
    def parent(self) -> Url:
        root, path = self._split
        return Url(f"{root}/{path.rsplit('/', 1)[0]}" if "/" in path else root)

    def __truediv__(self, name: str | PurePosixPath) -> Url:
        root, path = self._split
        return Url(f"{root}/{path}/{name}" if path else f"{root}/{name}")

    def relative_to(self, other: Url) -> PurePosixPath:
        mine, theirs = self._split[1], other._split[1]
        if not mine.startswith(theirs + "/"):
            raise ValueError(f"{self} is not inside {other}")
        return PurePosixPath(mine[len(theirs) + 1:])

    def is_inside(self, other: Url) -> bool:
        """Whether this URL is ``other`` or under the prefix ``other``."""
        (r1, p1), (r2, p2) = self._split, other._split
        return r1 == r2 and (p1 == p2 or p1.startswith(p2 + "/") or not p2)

    # Path's interface where a URL has nothing to resolve.
    def resolve(self) -> Url:
        return self

    def absolute(self) -> Url:
        return self

    def expanduser(self) -> Url:
        return self

    def is_absolute(self) -> bool:
        return True

    def is_symlink(self) -> bool:
        return False

    # -- the filesystem ------------------------------------------------------------------

    @property
    def fs(self) -> Any:
        """The fsspec filesystem of this URL's scheme (StorageError when not installed)."""
        try:
            return filesystem(self.protocol)
        except StorageError as err:
            raise StorageError(err.reason, self) from err

    @property
    def fs_path(self) -> str:
        """The path as the filesystem takes it (the URL for http, ``bucket/key`` for s3)."""
        if self.protocol in ("http", "https"):
            return self.text
        return str(self.fs._strip_protocol(self.text))

    def call(self, what: str, fn: Callable[[], T]) -> T:
        """``fn()`` retried on transient failures; failures as StorageError (``what`` says
        what was tried: 'cannot read', 'cannot list', ...)."""
        return with_retries(fn, self, what)

    def info(self) -> dict[str, Any]:
        info: dict[str, Any] = self.call("cannot open", lambda: self.fs.info(self.fs_path))
        return info

    def exists(self) -> bool:
        try:
            self.info()
        except StorageError as err:
            if err.__cause__ is not None and is_not_found(err.__cause__):
                return False
            raise
        return True

    def _http(self) -> bool:
        return self.protocol in ("http", "https")

    def is_dir(self) -> bool:
        if self._http():  # HTTP has no directories: a bag directory is one by its metadata
            return self.text.endswith("/") or (self / "metadata.yaml").exists()
        return self.exists() and self.info().get("type") == "directory"

    def is_file(self) -> bool:
        if self._http():
            return not self.text.endswith("/") and self.exists()
        return self.exists() and self.info().get("type") == "file"

    def stat(self) -> _Stat:
        info = self.info()
        if info.get("type") == "directory":
            return _Stat(0, stat_mod.S_IFDIR | 0o755)
        size = info.get("size")
        if size is None:
            raise StorageError("the server does not report the object's size (no "
                               "Content-Length): cannot read it by ranges", self)
        return _Stat(int(size), stat_mod.S_IFREG | 0o644)

    def _child(self, fs_path: str) -> Url:
        if self._http():
            return Url(fs_path)
        return Url(f"{self.protocol}://{fs_path.lstrip('/')}")

    def iterdir(self) -> Iterator[Url]:
        names = self.call("cannot list", lambda: self.fs.ls(self.fs_path, detail=False))
        own = self.fs_path.rstrip("/")
        return iter(sorted((self._child(n) for n in names if n.rstrip("/") != own),
                           key=lambda u: u.text))

    def rglob(self, pattern: str) -> Iterator[Url]:
        """Every object under this prefix (``pattern`` must be ``'*'``)."""
        if pattern != "*":
            raise ValueError("Url.rglob supports only '*'")
        names = self.call("cannot list", lambda: self.fs.find(self.fs_path))
        return iter(sorted((self._child(n) for n in names), key=lambda u: u.text))

    @overload
    def open(self, mode: Literal["rb"] = "rb", encoding: None = None,
             errors: None = None) -> BinaryIO: ...

    @overload
    def open(self, mode: Literal["r"], encoding: str | None = None,
             errors: str | None = None) -> TextIO: ...

    def open(self, mode: str = "rb", encoding: str | None = None,
             errors: str | None = None) -> BinaryIO | TextIO:
        """The object for reading, by ranges through a bounded block cache."""
        if mode not in ("rb", "r"):
            raise StorageError(f"cannot open a URL with mode {mode!r} (read only)", self)
        size = self.stat().st_size
        reader = io.BufferedReader(RemoteRaw(self, size), buffer_size=1 << 16)
        if mode == "rb":
            return cast(BinaryIO, reader)
        return io.TextIOWrapper(reader, encoding=encoding or "utf-8", errors=errors)

    def read_bytes(self) -> bytes:
        data: bytes = self.call("cannot read", lambda: self.fs.cat_file(self.fs_path))
        return data

    def read_text(self, encoding: str = "utf-8", errors: str = "strict") -> str:
        return self.read_bytes().decode(encoding, errors)

    def download(self, dst: Path) -> None:
        """Copy the object to the local file ``dst`` (for formats that need a local file)."""
        self.call("cannot download", lambda: self.fs.get_file(self.fs_path, str(dst)))


Location: TypeAlias = Path | Url


def as_location(where: str | Path | Url) -> Location:
    """A command-line or manifest name as a Location: a URL (``file://`` URLs become local
    paths), else a local path."""
    if isinstance(where, Path | Url):
        return where
    if is_url(where):
        if scheme_of(where) == "file":
            from urllib.parse import unquote, urlsplit

            return Path(unquote(urlsplit(where).path))
        return Url(where)
    return Path(where)


def joined(locations: Sequence[Location]) -> Location:
    """Several files of one recording as messages name them, ``a + b``: a path when all
    are local, else a URL-like label (redacted; never opened)."""
    text = " + ".join(str(p) for p in locations)
    return Url(text) if any(isinstance(p, Url) for p in locations) else Path(text)


def is_remote(where: object) -> bool:
    return isinstance(where, Url)


def storage_error(err: BaseException, what: str, where: Url) -> StorageError:
    """``err`` as a StorageError naming the redacted URL."""
    return StorageError(f"{what}: {describe(err)}", where)
