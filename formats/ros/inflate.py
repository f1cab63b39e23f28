"""Bounded decompression of a log's chunks (ROS 1 bag chunks, MCAP chunks, rosbag2
per-message and per-file zstd): memory never follows a size a file declares.

The rule, checked before a byte is inflated (:func:`check_declared`):

* the declared uncompressed size is at most :data:`MAX_CHUNK_BYTES` (128 MiB: a ROS 1 or
  MCAP writer closes a chunk at 768 KiB-4 MiB, so only one message that large fills one);
* and at most the compressed size × the codec's largest ratio (:data:`MAX_RATIO`, what the
  codec's format can encode at best: lz4 255 bytes per byte of match length, zstd 128 KiB
  per 4-byte RLE block, bz2 ~46 MB per ~35-byte block of one repeated byte; uncompressed
  data is exactly its size).

Inflation then stops at the declared size + 1 byte (:func:`inflate`): a stream that
inflates to any other size is corrupt. Callers skip a refused or corrupt chunk and record
it as a loss (docs/FORMATS.md).
"""

from __future__ import annotations

import bz2
from collections.abc import Callable

import lz4.frame

MAX_CHUNK_BYTES = 128 << 20
# Largest uncompressed/compressed ratio each codec's format can express, plus a constant
# slack for headers of tiny streams (measured on zeros: lz4 243, zstd 32 696, bz2 1.29e6).
MAX_RATIO = {"none": 1, "lz4": 255, "zstd": 32_768, "bz2": 1_600_000}
_SLACK = 4096


class ChunkError(ValueError):
    """A chunk that is refused (implausible size) or does not inflate (corrupt)."""


def codec_name(compression: str) -> str:
    """Our codec name for a container's compression field (MCAP writes '' for none)."""
    return "none" if compression in ("", "none") else compression


def check_declared(compression: str, compressed: int, declared: int) -> None:
    """Raise :class:`ChunkError` when ``declared`` uncompressed bytes are more than the
    format allows for ``compressed`` bytes of this codec, or more than MAX_CHUNK_BYTES."""
    codec = codec_name(compression)
    if codec not in MAX_RATIO:
        raise ChunkError(f"unknown chunk compression '{compression}'")
    if declared > MAX_CHUNK_BYTES:
        raise ChunkError(
            f"declares {declared} uncompressed bytes, more than the {MAX_CHUNK_BYTES >> 20} MiB"
            " a chunk may hold"
        )
    if codec == "none":
        if declared != compressed:
            raise ChunkError(f"uncompressed chunk of {compressed} bytes declares {declared}")
        return
    if declared > compressed * MAX_RATIO[codec] + _SLACK:
        raise ChunkError(
            f"declares {declared} bytes from {compressed} {codec} bytes, more than {codec}"
            f" can inflate ({MAX_RATIO[codec]}:1)"
        )


def inflate(compression: str, data: bytes | memoryview, declared: int) -> bytes | memoryview:
    """The chunk's ``declared`` uncompressed bytes, after :func:`check_declared`; never
    more than ``declared`` + 1 bytes are produced. Raises :class:`ChunkError`."""
    codec = codec_name(compression)
    check_declared(compression, len(data), declared)
    if codec == "none":
        return data
    limit = declared + 1
    try:
        out = _INFLATERS[codec](data, limit)
    except ChunkError:
        raise
    except Exception as err:  # the codecs raise OSError, ValueError, RuntimeError, ZstdError
        text = " ".join((str(err) or type(err).__name__).split())
        raise ChunkError(f"{codec} data does not decompress ({text})") from err
    if len(out) != declared:
        more = "more than" if len(out) > declared else f"{len(out)} bytes,"
        raise ChunkError(f"{codec} data inflates to {more} {declared} bytes declared")
    return out


def inflate_prefix(compression: str, data: bytes | memoryview, declared: int) -> bytes:
    """What a cut-off stream inflates to, at most ``declared`` bytes (a chunk cut off by
    the end of the file: its intact start). Raises :class:`ChunkError`."""
    codec = codec_name(compression)
    if codec not in MAX_RATIO:
        raise ChunkError(f"unknown chunk compression '{compression}'")
    if declared > MAX_CHUNK_BYTES:
        check_declared(compression, len(data), declared)
    if codec == "none":
        return bytes(data[:declared])
    try:
        out = _INFLATERS[codec](data, declared, partial=True)
    except Exception as err:
        text = " ".join((str(err) or type(err).__name__).split())
        raise ChunkError(f"{codec} data does not decompress ({text})") from err
    return bytes(out[:declared])


def _lz4(data: bytes | memoryview, limit: int, partial: bool = False) -> bytes:
    d = lz4.frame.LZ4FrameDecompressor()
    return _drain(lambda chunk, n: d.decompress(chunk, max_length=n), lambda: d.eof,
                  lambda: d.needs_input, bytes(data), limit, partial)


def _bz2(data: bytes | memoryview, limit: int, partial: bool = False) -> bytes:
    d = bz2.BZ2Decompressor()
    return _drain(lambda chunk, n: d.decompress(chunk, max_length=n), lambda: d.eof,
                  lambda: d.needs_input, bytes(data), limit, partial)


def _drain(step: Callable[[bytes, int], bytes], eof: Callable[[], bool],
           needs_input: Callable[[], bool], data: bytes, limit: int, partial: bool) -> bytes:
    """Call a streaming decompressor until ``limit`` bytes, its end, or its input's end."""
    parts = [step(data, limit)]
    got = len(parts[0])
    while got < limit and not eof() and not needs_input():
        part = step(b"", limit - got)
        if not part:
            break
        parts.append(part)
        got += len(part)
    if not partial and not eof() and got < limit:
        raise ChunkError("stream ends before its end mark (cut off)")
    return parts[0] if len(parts) == 1 else b"".join(parts)


def _zstd(data: bytes | memoryview, limit: int, partial: bool = False) -> bytes:
    import zstandard

    # A stream reader: ``decompress`` would allocate the frame's declared content size.
    reader = zstandard.ZstdDecompressor().stream_reader(bytes(data), read_across_frames=True)
    parts: list[bytes] = []
    got = 0
    try:
        while got < limit:
            part = reader.read(limit - got)
            if not part:
                break
            parts.append(part)
            got += len(part)
    except zstandard.ZstdError:
        if not partial:
            raise
    return parts[0] if len(parts) == 1 else b"".join(parts)


_INFLATERS: dict[str, Callable[..., bytes]] = {"lz4": _lz4, "bz2": _bz2, "zstd": _zstd}


def inflate_message(data: bytes, what: str) -> bytes:
    """One zstd-compressed message (rosbag2 ``compression_mode: MESSAGE``): its frame,
    bounded like a chunk (its declared content size, else MAX_CHUNK_BYTES)."""
    import zstandard

    try:
        declared = zstandard.get_frame_parameters(data).content_size
    except zstandard.ZstdError as err:
        raise ChunkError(f"{what}: not a zstd frame ({err})") from err
    if declared == zstandard.CONTENTSIZE_UNKNOWN:
        limit = min(MAX_CHUNK_BYTES, len(data) * MAX_RATIO["zstd"] + _SLACK)
        out = _zstd(data, limit + 1)
        if len(out) > limit:
            raise ChunkError(f"{what}: inflates to more than {limit} bytes")
        return out
    try:
        out = bytes(inflate("zstd", data, declared))
    except ChunkError as err:
        raise ChunkError(f"{what}: {err}") from err
    return out
