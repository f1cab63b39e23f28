"""The feature set as a Parquet table: one row per feature, units in the schema metadata."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from formats.errors import FormatError
from formats.map_types import FeatureTable
from formats.writers.atomic import atomic_write_bytes
from formats.writers.ellipse import covariance_axes

__all__ = ["FEATURE_SCHEMA", "UNITS", "read_feature_metadata", "read_features", "write_features"]

#: Unit of every column ("1" = dimensionless count or id).
UNITS: dict[str, str] = {
    "id": "1",
    "x": "m",
    "y": "m",
    "cov_xx": "m^2",
    "cov_xy": "m^2",
    "cov_yy": "m^2",
    "sigma_major": "m",
    "sigma_minor": "m",
    "orientation": "rad",
    "measured_times": "1",
    "first_seen_ns": "ns",
    "last_seen_ns": "ns",
    "merges": "1",
}

_INT_COLUMNS = ("id", "measured_times", "first_seen_ns", "last_seen_ns", "merges")

FEATURE_SCHEMA = pa.schema(
    [
        pa.field(
            name,
            pa.int64() if name in _INT_COLUMNS else pa.float64(),
            nullable=False,
            metadata={"unit": unit},
        )
        for name, unit in UNITS.items()
    ]
)

_RESERVED_KEYS = ("units", "frame")


def write_features(path: Path, features: FeatureTable, *, metadata: dict[str, str]) -> None:
    """Write ``features`` to a Parquet file at ``path``, atomically and byte-deterministically.

    Columns: id, x, y (m, map frame), cov_xx, cov_xy, cov_yy (m²), sigma_major, sigma_minor
    (m, square roots of the covariance eigenvalues), orientation (rad, major axis from +x,
    CCW, in (−π/2, π/2]), measured_times, first_seen_ns, last_seen_ns (ns), merges. Schema
    metadata: ``units`` (JSON column → unit), ``frame`` = ``map``, plus ``metadata``
    (resolution, config_hash, tool_version, ...; may not redefine ``units`` or ``frame``).
    """
    clash = [k for k in _RESERVED_KEYS if k in metadata]
    if clash:
        raise ValueError(f"metadata may not set the reserved key(s) {clash}")
    n = len(features)
    cols: dict[str, np.ndarray] = {}
    for name in ("id", "x", "y", "cov_xx", "cov_xy", "cov_yy", *_INT_COLUMNS[1:]):
        arr = np.asarray(getattr(features, name))
        if arr.shape != (n,):
            raise ValueError(f"FeatureTable.{name} has shape {arr.shape}, expected ({n},)")
        cols[name] = arr.astype(np.int64 if name in _INT_COLUMNS else np.float64, copy=False)
    major, minor, theta = covariance_axes(cols["cov_xx"], cols["cov_xy"], cols["cov_yy"])
    cols["sigma_major"], cols["sigma_minor"], cols["orientation"] = major, minor, theta

    schema_meta = {
        "units": json.dumps(UNITS, separators=(",", ":")),
        "frame": "map",
        **{str(k): str(v) for k, v in sorted(metadata.items())},
    }
    schema = FEATURE_SCHEMA.with_metadata(schema_meta)
    table = pa.Table.from_arrays(
        [pa.array(cols[f.name], type=f.type) for f in schema], schema=schema
    )
    buf = io.BytesIO()
    # Every option that shapes the bytes is fixed here, so a rewrite is byte-identical
    # (created_by only names the pyarrow version, constant for an installation).
    pq.write_table(
        table,
        buf,
        compression="zstd",
        compression_level=3,
        use_dictionary=False,
        write_statistics=True,
        version="2.6",
        data_page_version="1.0",
        store_schema=True,
        write_page_index=False,
        row_group_size=1 << 20,
    )
    atomic_write_bytes(Path(path), buf.getvalue())


def _open(path: Path) -> pq.ParquetFile:
    try:
        # Read by Python: pyarrow takes str paths as UTF-8, and a file name may be any
        # bytes (surrogate-escaped in Python).
        return pq.ParquetFile(pa.BufferReader(Path(path).read_bytes()))
    except FileNotFoundError as err:
        raise FormatError("no such file", path) from err
    except (OSError, pa.ArrowException) as err:
        raise FormatError(f"not a readable Parquet file ({err})", path) from err


def read_features(path: Path) -> FeatureTable:
    """Read a feature table written by :func:`write_features` (derived columns are dropped)."""
    path = Path(path)
    pf = _open(path)
    names = pf.schema_arrow.names
    need = ("id", "x", "y", "cov_xx", "cov_xy", "cov_yy", *_INT_COLUMNS[1:])
    missing = [c for c in need if c not in names]
    if missing:
        raise FormatError(f"not a sonarmap feature table: missing column(s) {missing}", path)
    try:
        table = pf.read(columns=list(need))
    except (OSError, pa.ArrowException) as err:
        raise FormatError(f"cannot read feature table ({err})", path) from err
    out: dict[str, np.ndarray] = {}
    for name in need:
        col = table.column(name)
        want = pa.int64() if name in _INT_COLUMNS else pa.float64()
        if col.type != want:
            raise FormatError(f"column {name!r} has type {col.type}, expected {want}", path)
        if col.null_count:
            raise FormatError(f"column {name!r} has {col.null_count} null value(s)", path)
        out[name] = col.to_numpy().astype(np.int64 if name in _INT_COLUMNS else np.float64)
    return FeatureTable(**out)


def read_feature_metadata(path: Path) -> dict[str, str]:
    """The schema metadata of a feature table (``units`` as its JSON text, ``frame``, ...)."""
    path = Path(path)
    meta = _open(path).schema_arrow.metadata or {}
    return {
        k.decode("utf-8", "replace"): v.decode("utf-8", "replace")
        for k, v in meta.items()
        if k != b"ARROW:schema"
    }
