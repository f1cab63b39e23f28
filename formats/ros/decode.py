"""Decode a :class:`~formats.ros.source.RawBatch` into columns, whatever its encoding."""

from __future__ import annotations

from formats.errors import FormatError
from formats.ros.columns import (
    LASER_TYPES,
    POINTCLOUD_TYPES,
    SONARARRAY_TYPES,
    TF_TYPES,
    Columns,
)
from formats.ros.source import RawBatch

# Types decoded through a typestore built from the log's own message definition: a
# corrupt or foreign definition can deserialize into objects without the fields we read.
_BY_DEFINITION = TF_TYPES | POINTCLOUD_TYPES | SONARARRAY_TYPES | LASER_TYPES


def decode(raw: RawBatch) -> Columns:
    """Columns of a batch of ``ros1`` or ``cdr`` messages of one of the DECODABLE_TYPES."""
    if raw.connection.encoding == "ros1":
        from formats.ros.decode_ros1 import decode_ros1 as decoder
    else:
        from formats.ros.decode_cdr import decode_cdr as decoder
    if raw.connection.msgtype not in _BY_DEFINITION:
        return decoder(raw)
    try:
        return decoder(raw)
    except (AttributeError, TypeError, ValueError) as err:
        raise FormatError(
            f"topic {raw.connection.topic}: messages do not have the fields of "
            f"{raw.connection.msgtype} (corrupt message definition? {err})"
        ) from err
