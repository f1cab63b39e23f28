"""Reading a whole side file (configuration, manifest, map YAML, map image, ...) safely.

A side file is read whole, so it must be a regular file (a device, FIFO, socket or
directory is refused without blocking: opened with ``O_NONBLOCK``) of at most ``max_bytes``
(its size is checked before reading, and at most ``max_bytes + 1`` bytes are read, so a
file that grows meanwhile is refused too). Caps per kind: docs/OUTPUTS.md.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from formats.errors import FormatError, InputError, SonarmapError
from formats.storage.location import Url

__all__ = ["MAX_LIST_BYTES", "MAX_TEXT_BYTES", "read_bounded", "read_text"]

#: Default cap of a text side file (configuration, tolerances, world, waypoints, metrics,
#: an evaluation), bytes.
MAX_TEXT_BYTES = 16 << 20
#: Cap of a side file that grows with a log or a fleet (a trajectory, a batch manifest).
MAX_LIST_BYTES = 256 << 20

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a device"),
          (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket"))


def _mib(n: int) -> str:
    return f"{n / (1 << 20):.3g} MiB"


def read_bounded(
    path: str | Path | Url,
    what: str,
    max_bytes: int,
    *,
    errors: tuple[type[SonarmapError], type[SonarmapError]] = (InputError, FormatError),
) -> bytes:
    """The bytes of regular file ``path`` (at most ``max_bytes``). ``what`` names its role
    in messages; the first of ``errors`` says "<what> not found", the second every other
    refusal (not a regular file, too large, unreadable)."""
    missing, bad = errors
    if isinstance(path, Url):
        return _read_bounded_url(path, what, max_bytes, errors)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError as err:
        raise missing(f"{what} not found", path) from err
    except (OSError, ValueError) as err:
        reason = err.strerror if isinstance(err, OSError) and err.strerror else err
        raise bad(f"cannot read {what}: {reason}", path) from err
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = next((k for test, k in _KINDS if test(st.st_mode)), "not a regular file")
            raise bad(f"{what} is {kind}, not a regular file", path)
        if st.st_size > max_bytes:
            raise bad(f"{what} is too large ({_mib(st.st_size)}; at most {_mib(max_bytes)})",
                      path)
        os.set_blocking(fd, True)
        chunks: list[bytes] = []
        left = max_bytes + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
    except OSError as err:
        raise bad(f"cannot read {what}: {err.strerror or err}", path) from err
    finally:
        os.close(fd)
    if left <= 0:
        raise bad(f"{what} is too large (more than {_mib(max_bytes)})", path)
    return b"".join(chunks)


def _read_bounded_url(
    url: Url, what: str, max_bytes: int,
    errors: tuple[type[SonarmapError], type[SonarmapError]],
) -> bytes:
    """:func:`read_bounded` of an object named by URL."""
    missing, bad = errors
    if not url.exists():
        raise missing(f"{what} not found", url)
    size = url.stat().st_size
    if size > max_bytes:
        raise bad(f"{what} is too large ({_mib(size)}; at most {_mib(max_bytes)})", url)
    return url.read_bytes()


def read_text(
    path: str | Path | Url,
    what: str,
    *,
    errors: tuple[type[SonarmapError], type[SonarmapError]] = (InputError, FormatError),
    encoding: str = "utf-8",
    max_bytes: int = MAX_TEXT_BYTES,
) -> str:
    """The file's text (:func:`read_bounded`). ``what`` names its role in messages
    ("trajectory file"): the first of ``errors`` says "<path>: <what> not found", the
    second "<path>: cannot read <what>: <reason>" (unreadable, not a regular file, larger
    than ``max_bytes``, not ``encoding``)."""
    data = read_bounded(path, what, max_bytes, errors=errors)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        name = encoding.removesuffix("-sig").upper()
        raise errors[1](f"cannot read {what}: line {line} is not {name} text (byte"
                        f" {err.object[err.start]:#04x} at offset {err.start})", path) from err
