"""Mutations of valid logs: truncations, bit flips, corrupted record headers and lengths,
random bytes over a record's head, wrong compression names, huge declared sizes, and
row-level damage to CSV text.

A :class:`Mutation` is plain data (so hypothesis can draw and shrink it, and a failure
prints a reproducer); :func:`apply` turns a valid file's bytes into the mutated bytes.
:func:`structure_points` finds the byte offsets of length/size/count fields of ROS 1 bag,
MCAP and SQLite files, where a corrupted value hurts the most.
"""

from __future__ import annotations

import random
import struct
from dataclasses import dataclass
from typing import Any

# Values written over length/size fields: zero, tiny, off-by-one of the file, and huge.
INT_VALUES: tuple[int, ...] = (0, 1, 7, 255, 2**31 - 1, 2**32 - 1, 2**63 - 1, 2**64 - 1)
# Compression names as the containers store them (same and different lengths).
CODEC_NAMES: tuple[bytes, ...] = (b"none", b"zstd", b"lz4", b"bz2", b"", b"gzip", b"zst")
# Text put into CSV fields.
CSV_VALUES: tuple[str, ...] = (
    "nan", "NaN", "inf", "-inf", "+inf", "", "abc", "1e400", "-1", "0x10", "1,5", '"',
    "9" * 30, "1.2.3", "\u00e9", "-0", "1e-400", " ",
)

BINARY_KINDS = ("truncate", "flip", "set_int", "delete", "insert", "codec", "zero_run",
                "overwrite")
CSV_KINDS = (
    "truncate", "flip", "row_field", "row_drop_field", "row_add_field", "row_swap",
    "row_dup", "row_garbage", "insert",
)


@dataclass(frozen=True)
class Mutation:
    """One change to a file. ``kind`` picks the meaning of the other fields:

    * ``truncate``: keep ``offset`` bytes; ``delete``: remove ``length`` bytes at ``offset``;
    * ``flip``: xor byte ``offset + i`` with ``bits[i]`` (i = 0..);
    * ``set_int``: write ``value`` as a little-endian ``length``-byte integer at ``offset``;
    * ``insert``: insert ``payload`` at ``offset``; ``zero_run``: ``length`` zero bytes there;
      ``overwrite``: ``payload`` written over the bytes at ``offset`` (garbage framing);
    * ``codec``: replace the ``index``-th occurrence of ``payload`` by ``other``;
    * ``row_*`` (text): on data line ``index`` (counted modulo the line count), field
      ``field``: set it to ``text`` / drop it / add one / swap with the next line /
      duplicate the line / put ``payload`` bytes into it.
    """

    kind: str
    offset: int = 0
    length: int = 0
    value: int = 0
    bits: tuple[int, ...] = ()
    payload: bytes = b""
    other: bytes = b""
    index: int = 0
    field: int = 0
    text: str = ""

    def describe(self) -> str:
        """A short, reproducible description (the repr without default fields)."""
        parts = [f"{k}={v!r}" for k, v in vars(self).items() if v not in (0, (), b"", "")]
        return f"Mutation({', '.join(parts)})"


def apply(data: bytes, m: Mutation) -> bytes:
    """The bytes of ``data`` changed by ``m`` (never longer than data + a few KiB)."""
    n = len(data)
    if m.kind == "truncate":
        return data[: max(0, min(m.offset, n))]
    if m.kind == "delete":
        o = m.offset % max(n, 1)
        return data[:o] + data[o + max(1, m.length) :]
    if m.kind == "flip":
        b = bytearray(data)
        for i, bit in enumerate(m.bits):
            if n:
                b[(m.offset + i * 997) % n] ^= bit & 0xFF or 1
        return bytes(b)
    if m.kind == "set_int":
        if n < m.length:
            return data
        o = m.offset % (n - m.length + 1)
        v = m.value % (1 << (8 * m.length))
        return data[:o] + v.to_bytes(m.length, "little") + data[o + m.length :]
    if m.kind == "insert":
        o = m.offset % (n + 1)
        return data[:o] + m.payload + data[o:]
    if m.kind == "zero_run":
        o = m.offset % max(n, 1)
        return data[:o] + bytes(min(m.length, n - o)) + data[o + m.length :]
    if m.kind == "overwrite":
        o = m.offset % max(n, 1)
        return data[:o] + m.payload[: n - o] + data[o + len(m.payload) :]
    if m.kind == "codec":
        hits = _find_all(data, m.payload)
        if not m.payload or not hits:
            return data
        o = hits[m.index % len(hits)]
        return data[:o] + m.other + data[o + len(m.payload) :]
    if m.kind.startswith("row_"):
        return _apply_row(data, m)
    raise ValueError(f"unknown mutation kind {m.kind!r}")


def _find_all(data: bytes, needle: bytes, limit: int = 64) -> list[int]:
    out: list[int] = []
    i = data.find(needle)
    while i >= 0 and len(out) < limit:
        out.append(i)
        i = data.find(needle, i + 1)
    return out


def _apply_row(data: bytes, m: Mutation) -> bytes:
    lines = data.split(b"\n")
    # Line 0 is usually the header; damage to it is what "truncate"/"flip" cover.
    body = [i for i, ln in enumerate(lines) if i > 0 and ln.strip()]
    if not body:
        return data
    i = body[m.index % len(body)]
    fields = lines[i].split(b",")
    j = m.field % len(fields)
    if m.kind == "row_field":
        fields[j] = m.text.encode("utf-8")
    elif m.kind == "row_drop_field" and len(fields) > 1:
        del fields[j]
    elif m.kind == "row_add_field":
        fields.insert(j, m.text.encode("utf-8"))
    elif m.kind == "row_garbage":
        fields[j] = m.payload
    elif m.kind == "row_swap":
        k = body[(body.index(i) + 1 + m.field) % len(body)]
        lines[i], lines[k] = lines[k], lines[i]
        return b"\n".join(lines)
    elif m.kind == "row_dup":
        lines.insert(i, lines[i])
        return b"\n".join(lines)
    lines[i] = b",".join(fields)
    return b"\n".join(lines)


# --------------------------------------------------------------------------- structure


def structure_points(data: bytes, fmt: str) -> list[tuple[int, int]]:
    """``(offset, width)`` of the integer fields that frame a file's records: lengths,
    sizes, counts and positions. Empty for formats without a walker (CSV)."""
    try:
        if fmt == "ros1":
            return _ros1_points(data)
        if fmt == "mcap":
            return _mcap_points(data)
        if fmt == "sqlite":
            return _sqlite_points(data)
    except (struct.error, IndexError, ValueError):
        pass  # a file the walker cannot follow: whatever it found is enough
    return []


def _ros1_points(data: bytes, limit: int = 400) -> list[tuple[int, int]]:
    """Record header/data lengths and every 4/8-byte header field value of a ROS 1 bag."""
    out: list[tuple[int, int]] = []
    pos = len(b"#ROSBAG V2.0\n")
    stack = [(pos, len(data))]
    while stack and len(out) < limit:
        pos, end = stack.pop()
        while pos + 8 <= end and len(out) < limit:
            (hlen,) = struct.unpack_from("<I", data, pos)
            if pos + 8 + hlen > end:
                break
            out.append((pos, 4))
            h, hend = pos + 4, pos + 4 + hlen
            is_chunk = False
            while h + 4 <= hend:
                (flen,) = struct.unpack_from("<I", data, h)
                out.append((h, 4))
                entry = data[h + 4 : h + 4 + flen]
                eq = entry.find(b"=")
                if eq > 0 and len(entry) - eq - 1 in (4, 8):
                    out.append((h + 4 + eq + 1, len(entry) - eq - 1))
                if entry == b"compression=none":
                    is_chunk = True
                h += 4 + flen
            (dlen,) = struct.unpack_from("<I", data, hend)
            out.append((hend, 4))
            if is_chunk:  # uncompressed chunk: its message records are visible too
                stack.append((hend + 4, min(hend + 4 + dlen, end)))
            pos = hend + 4 + dlen
    return out


def _mcap_points(data: bytes, limit: int = 400) -> list[tuple[int, int]]:
    """Record lengths of an MCAP file, chunk header fields, and records inside
    uncompressed chunks; the footer's summary offsets."""
    out: list[tuple[int, int]] = []
    stack = [(8, len(data))]
    while stack and len(out) < limit:
        pos, end = stack.pop()
        while pos + 9 <= end and len(out) < limit:
            op = data[pos]
            (length,) = struct.unpack_from("<Q", data, pos + 1)
            if pos + 9 + length > end:
                break
            out.append((pos + 1, 8))
            c = pos + 9
            if op == 0x06:  # chunk: start, end, uncompressed size, crc, compression, records
                out += [(c, 8), (c + 8, 8), (c + 16, 8), (c + 24, 4), (c + 28, 4)]
                (clen,) = struct.unpack_from("<I", data, c + 28)
                rec_len_at = c + 32 + clen
                out.append((rec_len_at, 8))
                if clen == 0:
                    (rlen,) = struct.unpack_from("<Q", data, rec_len_at)
                    stack.append((rec_len_at + 8, rec_len_at + 8 + rlen))
            elif op == 0x08:  # chunk index: offsets and lengths
                out += [(c + 16, 8), (c + 24, 8), (c + 32, 4)]
            elif op == 0x07:  # message index: array byte length
                out.append((c + 2, 4))
            elif op in (0x03, 0x04, 0x05):  # schema/channel/message: first length field
                out.append((c + 4 if op != 0x05 else c, 4 if op != 0x05 else 2))
            elif op == 0x02:  # footer: summary start and summary offset start
                out += [(c, 8), (c + 8, 8)]
            pos = c + length
    return out


def _sqlite_points(data: bytes) -> list[tuple[int, int]]:
    """SQLite header fields and every b-tree page's header counts and pointers."""
    if len(data) < 100:
        return []
    out = [(16, 2), (28, 4), (32, 4), (36, 4), (44, 4), (56, 4)]
    (page,) = struct.unpack_from(">H", data, 16)
    page = 65536 if page == 1 else page
    if page < 512:
        return out
    for start in range(0, len(data), page):
        h = start + (100 if start == 0 else 0)
        if h + 12 <= len(data) and data[h] in (2, 5, 10, 13):
            out += [(h + 1, 2), (h + 3, 2), (h + 5, 2)]
            if data[h] in (2, 5):
                out.append((h + 8, 4))
    return out


# --------------------------------------------------------------------------- drawing


def random_mutation(
    rnd: random.Random, data: bytes, points: list[tuple[int, int]], text: bool
) -> Mutation:
    """One mutation drawn with ``rnd`` (the long fuzz runner's generator)."""
    n = max(len(data), 1)
    kind = rnd.choice(CSV_KINDS if text else BINARY_KINDS)
    if kind == "set_int" and points and rnd.random() < 0.8:
        off, width = rnd.choice(points)
        value = rnd.choice((*INT_VALUES, n, n + 1, rnd.randrange(2**32)))
        return Mutation("set_int", offset=off, length=width, value=value)
    if kind == "truncate":
        return Mutation("truncate", offset=rnd.randrange(n))
    if kind == "flip":
        k = rnd.randint(1, 8)
        return Mutation("flip", offset=rnd.randrange(n), bits=tuple(1 << rnd.randrange(8) for _ in range(k)))
    if kind == "set_int":
        return Mutation("set_int", offset=rnd.randrange(n), length=rnd.choice((2, 4, 8)),
                        value=rnd.choice(INT_VALUES))
    if kind == "delete":
        return Mutation("delete", offset=rnd.randrange(n), length=rnd.randint(1, 64))
    if kind == "insert":
        size = rnd.choice((1, 4, 9, 64))
        return Mutation("insert", offset=rnd.randrange(n), payload=rnd.randbytes(size))
    if kind == "zero_run":
        return Mutation("zero_run", offset=rnd.randrange(n), length=rnd.choice((4, 16, 256)))
    if kind == "overwrite":  # random bytes over a record head (a length field's place)
        off = rnd.choice(points)[0] - rnd.randrange(16) if points else rnd.randrange(n)
        return Mutation("overwrite", offset=max(0, off),
                        payload=rnd.randbytes(rnd.choice((64, 128, 256))))
    if kind == "codec":
        return Mutation("codec", payload=rnd.choice(CODEC_NAMES[:4]), other=rnd.choice(CODEC_NAMES),
                        index=rnd.randrange(8))
    if kind == "row_garbage":
        return Mutation(kind, index=rnd.randrange(1 << 16), field=rnd.randrange(12),
                        payload=rnd.choice((b"\xff\xfe", b"\x00", b"\xe9", b"1\r2", b'"a\nb"')))
    return Mutation(kind, index=rnd.randrange(1 << 16), field=rnd.randrange(12),
                    text=rnd.choice(CSV_VALUES))


def mutation_strategy(data: bytes, points: list[tuple[int, int]], text: bool) -> Any:
    """A hypothesis strategy of mutations of ``data`` (imported lazily: a dev dependency)."""
    from hypothesis import strategies as st

    n = max(len(data), 1)
    offsets = st.integers(0, n - 1)
    ints = st.one_of(st.sampled_from((*INT_VALUES, n, n + 1)), st.integers(0, 2**64 - 1))
    common = [
        st.builds(Mutation, kind=st.just("truncate"), offset=offsets),
        st.builds(Mutation, kind=st.just("flip"), offset=offsets,
                  bits=st.lists(st.sampled_from([1, 2, 4, 8, 16, 32, 64, 128]), min_size=1,
                                max_size=8).map(tuple)),
        st.builds(Mutation, kind=st.just("insert"), offset=offsets,
                  payload=st.binary(min_size=1, max_size=64)),
    ]
    if text:
        rows = [
            st.builds(Mutation, kind=st.sampled_from(
                ("row_field", "row_drop_field", "row_add_field", "row_swap", "row_dup")),
                index=st.integers(0, 1 << 16), field=st.integers(0, 11),
                text=st.sampled_from(CSV_VALUES)),
            st.builds(Mutation, kind=st.just("row_garbage"), index=st.integers(0, 1 << 16),
                      field=st.integers(0, 11), payload=st.binary(min_size=1, max_size=8)),
        ]
        return st.one_of(*common, *rows)
    binary = [
        st.builds(Mutation, kind=st.just("set_int"), offset=offsets,
                  length=st.sampled_from((2, 4, 8)), value=ints),
        st.builds(Mutation, kind=st.just("delete"), offset=offsets, length=st.integers(1, 64)),
        st.builds(Mutation, kind=st.just("zero_run"), offset=offsets,
                  length=st.sampled_from((4, 16, 256))),
        st.builds(Mutation, kind=st.just("overwrite"), offset=offsets,
                  payload=st.binary(min_size=64, max_size=256)),
        st.builds(Mutation, kind=st.just("codec"), payload=st.sampled_from(CODEC_NAMES[:4]),
                  other=st.sampled_from(CODEC_NAMES), index=st.integers(0, 7)),
    ]
    if points:
        binary.append(
            st.tuples(st.sampled_from(points), ints).map(
                lambda pv: Mutation("set_int", offset=pv[0][0], length=pv[0][1], value=pv[1])
            )
        )
    return st.one_of(*common, *binary)
