"""rosbags typestores built from the message definitions a log carries.

Shared by the ROS 1 and CDR decoders for the low-volume types they deserialize one
message at a time (tf, PointCloud, SonarArray, LaserScan). A log's own definitions win
over rosbags' built-in ones, so custom types (p2os_msgs/SonarArray) and old revisions
(ROS 1 Header with ``seq``) decode as recorded. Stores are cached by (encoding, msgtype,
msgdef, msgdef_format): building one parses the definition text.
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg
from rosbags.typesys import get_typestore as _rosbags_typestore

from formats.errors import FormatError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from formats.ros.source import Connection


def default_typestore(encoding: str) -> Typestore:
    """rosbags' built-in store for an encoding: ROS 1 Noetic for 'ros1', latest ROS 2 else."""
    return _default(encoding)


# Types sonarmap decodes that rosbags' built-in stores lack (its Noetic store has no tf
# messages), as their standard definitions; used only when a log carries no definition.
EXTRA_DEFINITIONS = {
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms",
    "tf/msg/tfMessage": "geometry_msgs/TransformStamped[] transforms",
    "p2os_msgs/msg/SonarArray": "std_msgs/Header header\nint32 ranges_count\nfloat64[] ranges",
}


@lru_cache(maxsize=4)
def _default(encoding: str) -> Typestore:
    store = _rosbags_typestore(Stores.ROS1_NOETIC if encoding == "ros1" else Stores.LATEST)
    for name, text in EXTRA_DEFINITIONS.items():
        if name not in store.fielddefs:
            store.register(get_types_from_msg(text, name))
    return store


def typestore_for(connection: Connection) -> Typestore:
    """A typestore that knows ``connection.msgtype`` and its dependencies.

    Built from the connection's own definition (``ros1msg``/``ros2msg``/``ros2idl``); the
    default store of its encoding when it carries none. Raises :class:`FormatError`
    (without a path; the reader adds it) when the definition does not parse or the type
    is unknown.
    """
    return _store(
        connection.encoding, connection.msgtype, connection.msgdef, connection.msgdef_format
    )


@lru_cache(maxsize=64)
def _store(encoding: str, msgtype: str, msgdef: str, msgdef_format: str) -> Typestore:
    if not msgdef.strip():
        store = _default(encoding)
        if msgtype not in store.fielddefs:
            raise FormatError(
                f"topic type {msgtype} has no message definition in the log and is not a "
                f"standard type"
            )
        return store
    try:
        if msgdef_format == "ros2idl":
            types = get_types_from_idl(msgdef)
        else:
            types = get_types_from_msg(msgdef, msgtype)
        # Start from an empty store: a log's definitions must not mix with another
        # distribution's revision of the same type.
        store = _rosbags_typestore(Stores.EMPTY)
        store.register(types)
    except (TypesysError, ValueError, KeyError) as err:
        raise FormatError(f"message definition of {msgtype} does not parse: {err}") from err
    if msgtype not in store.fielddefs:
        raise FormatError(f"message definition does not define {msgtype}")
    return store
