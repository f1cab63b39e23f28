"""Decompression bombs: tiny logs whose chunks declare, or inflate to, gigabytes.

Built in a blink without compressing gigabytes: a zstd frame of ``n`` zero bytes is
written as RLE blocks (4 bytes per 128 KiB, :func:`zstd_zeros`), a bz2 or lz4 stream is
compressed once from a modest buffer. :func:`mcap_with_chunk` puts a chunk into a valid
MCAP file (read by the linear scan: the summary is dropped), :func:`ros1_declaring`
rewrites the declared size of a ROS 1 bag's chunks, :func:`mcap_declaring` that of an
MCAP file's chunks (records and chunk indexes alike).
"""

from __future__ import annotations

import struct

MCAP_MAGIC = b"\x89MCAP0\r\n"
_ZSTD_BLOCK = 128 << 10


def zstd_zeros(n: int) -> bytes:
    """A zstd frame inflating to ``n`` zero bytes, without a declared content size."""
    out = bytearray(b"\x28\xb5\x2f\xfd\x00\x38")  # magic; no content size; 128 KiB window
    while n > 0:
        size = min(n, _ZSTD_BLOCK)
        n -= size
        last = 1 if n == 0 else 0
        header = last | (1 << 1) | (size << 3)  # RLE block of `size` copies of one byte
        out += header.to_bytes(3, "little") + b"\x00"
    return bytes(out)


def mcap_record(op: int, content: bytes) -> bytes:
    return bytes([op]) + struct.pack("<Q", len(content)) + content


def mcap_chunk(records: bytes, compression: str, declared: int, t0: int = 0,
               t1: int = 0) -> bytes:
    """A Chunk record of already-compressed ``records`` that declares ``declared`` bytes."""
    name = compression.encode()
    content = (struct.pack("<QQQI", t0, t1, declared, 0) + struct.pack("<I", len(name)) + name
               + struct.pack("<Q", len(records)) + records)
    return mcap_record(0x06, content)


def _mcap_records(data: bytes) -> list[tuple[int, int, int]]:
    """(opcode, offset, record end) of the top-level records of an MCAP file."""
    out = []
    pos = len(MCAP_MAGIC)
    while pos + 9 <= len(data) - len(MCAP_MAGIC):
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        end = pos + 9 + length
        out.append((op, pos, end))
        if op == 0x02:
            break
        pos = end
    return out


def mcap_with_chunk(valid: bytes, chunk: bytes) -> bytes:
    """``valid`` MCAP bytes with ``chunk`` added after its last chunk; no summary (a
    footer that points at none), so readers scan the data section."""
    recs = _mcap_records(valid)
    data_end = next(pos for op, pos, _ in recs if op == 0x0F)
    body = valid[:data_end] + chunk + mcap_record(0x0F, struct.pack("<I", 0))
    footer = mcap_record(0x02, struct.pack("<QQI", 0, 0, 0))
    return body + footer + MCAP_MAGIC


def mcap_declaring(valid: bytes, declared: int) -> bytes:
    """``valid`` MCAP bytes with every chunk (record and chunk index) declaring
    ``declared`` uncompressed bytes."""
    out = bytearray(valid)
    for op, pos, _ in _mcap_records(valid):
        if op == 0x06:  # start, end, uncompressed size
            struct.pack_into("<Q", out, pos + 9 + 16, declared)
    for op, pos, _end in _mcap_records(valid):
        if op == 0x08:  # chunk index: start, end, chunk offset, chunk length, index map
            c = pos + 9 + 32
            (n,) = struct.unpack_from("<I", valid, c)
            c += 4 + n + 8  # message index offsets map, message index length
            (k,) = struct.unpack_from("<I", valid, c)
            c += 4 + k + 8  # compression string, compressed size
            struct.pack_into("<Q", out, c, declared)
    # The summary: chunk indexes come after DataEnd; _mcap_records stops at the footer.
    return bytes(out)


def ros1_declaring(valid: bytes, declared: int) -> bytes:
    """A ROS 1 bag with every chunk's ``size`` header field set to ``declared``."""
    out = bytearray(valid)
    key = b"\x09\x00\x00\x00size="  # the 4-byte 'size' field of chunk headers
    at = out.find(key)
    while at >= 0:
        struct.pack_into("<I", out, at + len(key), declared)
        at = out.find(key, at + 1)
    return bytes(out)
