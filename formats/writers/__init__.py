"""Writers of sonarmap's outputs: nav2 map, map picture, feature table, reports.

Every writer produces deterministic bytes (same input → same file) and writes atomically;
:class:`~formats.writers.atomic.OutputDir` makes a whole run's directory appear complete
or not at all.
"""

from __future__ import annotations

from formats.writers.atomic import OutputDir, atomic_write_bytes, atomic_write_text
from formats.writers.features_parquet import read_features, write_features
from formats.writers.map_png import write_map_png
from formats.writers.nav2_map import Nav2Map, load_nav2_map, write_nav2_map
from formats.writers.report import write_reports

__all__ = [
    "Nav2Map",
    "OutputDir",
    "atomic_write_bytes",
    "atomic_write_text",
    "load_nav2_map",
    "read_features",
    "write_features",
    "write_map_png",
    "write_nav2_map",
    "write_reports",
]
