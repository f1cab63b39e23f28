"""Decode a :class:`~formats.ros.source.RawBatch` into columns, whatever its encoding."""

from __future__ import annotations

from formats.ros.columns import Columns
from formats.ros.source import RawBatch


def decode(raw: RawBatch) -> Columns:
    """Columns of a batch of ``ros1`` or ``cdr`` messages of one of the DECODABLE_TYPES."""
    if raw.connection.encoding == "ros1":
        from formats.ros.decode_ros1 import decode_ros1

        return decode_ros1(raw)
    from formats.ros.decode_cdr import decode_cdr

    return decode_cdr(raw)
