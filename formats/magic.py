"""The magic bytes that identify each binary log format (one definition for detection and
for the parsers that check them)."""

from __future__ import annotations

__all__ = ["GZIP_MAGIC", "MCAP_MAGIC", "ROS1_MAGIC", "SQLITE_MAGIC", "ZSTD_MAGIC"]

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
GZIP_MAGIC = b"\x1f\x8b"
