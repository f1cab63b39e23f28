"""Feature table Parquet: schema, units, derived axes, byte-identical rewrites, read back."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from writers_helpers import make_features

from formats.errors import FormatError
from formats.map_types import FeatureTable
from formats.writers.ellipse import covariance_axes
from formats.writers.features_parquet import read_feature_metadata, read_features, write_features

META = {"resolution": "0.05", "config_hash": "abc123", "tool_version": "0.1.0"}


def test_schema_names_types_and_metadata(tmp_path: Path, features: FeatureTable) -> None:
    write_features(tmp_path / "f.parquet", features, metadata=META)
    schema = pq.read_schema(tmp_path / "f.parquet")
    assert schema.names == [
        "id", "x", "y", "cov_xx", "cov_xy", "cov_yy", "sigma_major", "sigma_minor",
        "orientation", "measured_times", "first_seen_ns", "last_seen_ns", "merges",
    ]  # fmt: skip
    ints = {"id", "measured_times", "first_seen_ns", "last_seen_ns", "merges"}
    for field in schema:
        assert field.type == (pa.int64() if field.name in ints else pa.float64()), field.name
    meta = read_feature_metadata(tmp_path / "f.parquet")
    assert meta["frame"] == "map"
    assert {k: meta[k] for k in META} == META
    units = json.loads(meta["units"])
    assert units["x"] == "m" and units["cov_xy"] == "m^2" and units["sigma_major"] == "m"
    assert units["orientation"] == "rad" and units["first_seen_ns"] == "ns"
    assert set(units) == set(schema.names)
    assert schema.field("x").metadata == {b"unit": b"m"}


def test_values_and_known_axes(tmp_path: Path, features: FeatureTable) -> None:
    write_features(tmp_path / "f.parquet", features, metadata={})
    t = pq.read_table(tmp_path / "f.parquet").to_pydict()
    assert t["id"] == [1, 2, 3]
    assert t["x"] == [1.0, 2.5, -0.5]
    assert t["measured_times"] == [5, 1, 9]
    assert t["merges"] == [0, 1, 2]
    assert t["first_seen_ns"][1] == 1_700_000_001_000_000_000
    # cov diag(0.04, 0.01): major σ 0.2 along x
    assert t["sigma_major"][0] == pytest.approx(0.2)
    assert t["sigma_minor"][0] == pytest.approx(0.1)
    assert t["orientation"][0] == pytest.approx(0.0)
    # diag(0.01, 0.04): major along y → +π/2 (not −π/2)
    assert t["orientation"][1] == pytest.approx(math.pi / 2)
    # [[0.02, 0.01], [0.01, 0.02]]: eigenvalues 0.03, 0.01, major at 45°
    assert t["sigma_major"][2] == pytest.approx(math.sqrt(0.03))
    assert t["sigma_minor"][2] == pytest.approx(0.1)
    assert t["orientation"][2] == pytest.approx(math.pi / 4)


def test_orientation_range_and_eigen_agreement() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=(500, 2, 2))
    cov = a @ a.transpose(0, 2, 1)
    cov[:5, 0, 1] = cov[:5, 1, 0] = -0.0  # signed zero edge case
    major, minor, theta = covariance_axes(cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1])
    assert np.all(theta > -math.pi / 2) and np.all(theta <= math.pi / 2)
    w, v = np.linalg.eigh(cov)
    np.testing.assert_allclose(major, np.sqrt(w[:, 1]), rtol=1e-9)
    np.testing.assert_allclose(minor, np.sqrt(np.maximum(w[:, 0], 0)), rtol=1e-6, atol=1e-9)
    direction = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    # the major eigenvector is parallel to (cos θ, sin θ)
    np.testing.assert_allclose(np.abs(np.sum(direction * v[:, :, 1], axis=1)), 1.0, rtol=1e-9)


def test_rewrites_are_byte_identical(tmp_path: Path, features: FeatureTable) -> None:
    write_features(tmp_path / "a.parquet", features, metadata=META)
    write_features(tmp_path / "b.parquet", features, metadata=dict(reversed(META.items())))
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes()


def test_round_trip(tmp_path: Path, features: FeatureTable) -> None:
    write_features(tmp_path / "f.parquet", features, metadata=META)
    back = read_features(tmp_path / "f.parquet")
    for name in ("id", "x", "y", "cov_xx", "cov_xy", "cov_yy", "measured_times",
                 "first_seen_ns", "last_seen_ns", "merges"):  # fmt: skip
        np.testing.assert_array_equal(getattr(back, name), getattr(features, name))
        assert getattr(back, name).dtype == getattr(features, name).dtype


def test_empty_table(tmp_path: Path) -> None:
    empty = make_features([], [], [])
    write_features(tmp_path / "e.parquet", empty, metadata={})
    assert len(read_features(tmp_path / "e.parquet")) == 0
    assert pq.read_table(tmp_path / "e.parquet").num_rows == 0


def test_reserved_metadata_refused(tmp_path: Path, features: FeatureTable) -> None:
    with pytest.raises(ValueError, match="reserved key"):
        write_features(tmp_path / "f.parquet", features, metadata={"frame": "odom"})
    assert not (tmp_path / "f.parquet").exists()


def test_read_errors(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"nope\.parquet: no such file"):
        read_features(tmp_path / "nope.parquet")
    (tmp_path / "junk.parquet").write_bytes(b"PAR1 garbage")
    with pytest.raises(FormatError, match=r"junk\.parquet: not a readable Parquet file"):
        read_features(tmp_path / "junk.parquet")
    pq.write_table(pa.table({"id": [1], "x": [0.0]}), tmp_path / "other.parquet")
    with pytest.raises(FormatError, match=r"missing column\(s\) \['y', 'cov_xx'"):
        read_features(tmp_path / "other.parquet")
