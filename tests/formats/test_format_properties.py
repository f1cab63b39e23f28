"""Hypothesis properties of the ground floor: the exact CSV time parser against Decimal,
covariance axes against numpy's eigh, and the nav2 write → load round trip."""

from __future__ import annotations

import math
import tempfile
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from formats.contract import RangeBatch
from formats.csv_log import CsvLogReader
from formats.map_types import GridSpec
from formats.writers.ellipse import covariance_axes
from formats.writers.nav2_map import load_nav2_map, write_nav2_map
from pipeline.config import config_from_dict

_UNITS = {"s": 9, "ms": 6, "us": 3, "ns": 0}


@st.composite
def _time_text(draw: st.DrawFn, unit: str) -> str:
    """A decimal time whose value in ns fits int64: sign, integer part, any fraction."""
    ns_limit = 2**62  # leaves room for rounding of the digits below 1 ns
    whole = draw(st.integers(0, ns_limit // 10 ** _UNITS[unit]))
    frac = draw(st.text("0123456789", max_size=15))
    sign = draw(st.sampled_from(["", "-", "+"]))
    int_part = draw(st.sampled_from([str(whole), f"{whole:03d}"]))
    if frac and whole == 0 and draw(st.booleans()):
        int_part = ""  # ".5" is a time too
    return f"{sign}{int_part}.{frac}" if frac or not int_part else f"{sign}{int_part}"


@settings(max_examples=40, deadline=None)
@given(data=st.data(), unit=st.sampled_from(sorted(_UNITS)))
def test_csv_time_parser_matches_decimal(data: st.DataObject, unit: str) -> None:
    texts = data.draw(st.lists(_time_text(unit), min_size=1, max_size=30))
    cfg = config_from_dict({"input": {"csv": {"time_unit": unit}}})
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.csv"
        rows = "".join(f"{t},0,0,0,s0,1.0\n" for t in texts)
        path.write_text("t,x,y,yaw,sensor,range\n" + rows, encoding="utf-8")
        with CsvLogReader(path, cfg) as reader:
            got = np.concatenate(
                [b.t_ns for b in reader.batches(("ranges",)) if isinstance(b, RangeBatch)]
            )
    want = [
        int(Decimal(t).scaleb(_UNITS[unit]).to_integral_value(rounding=ROUND_HALF_UP))
        for t in texts
    ]
    assert got.tolist() == want


@given(
    a=st.floats(0, 1e6, allow_subnormal=False),
    c=st.floats(0, 1e6, allow_subnormal=False),
    rho=st.floats(-1, 1),
)
def test_covariance_axes_match_eigh(a: float, c: float, rho: float) -> None:
    b = rho * math.sqrt(a * c)  # a positive semi-definite covariance
    major, minor, theta = covariance_axes(np.array([a]), np.array([b]), np.array([c]))
    w, v = np.linalg.eigh(np.array([[a, b], [b, c]]))
    scale = max(a, c, 1e-300)
    assert math.isclose(major[0] ** 2, max(w[1], 0.0), rel_tol=1e-9, abs_tol=1e-9 * scale)
    assert math.isclose(minor[0] ** 2, max(w[0], 0.0), rel_tol=1e-9, abs_tol=1e-9 * scale)
    assert major[0] >= minor[0] >= 0.0
    assert -math.pi / 2 < theta[0] <= math.pi / 2
    if w[1] - w[0] > 1e-6 * scale:  # a unique major axis: theta is its direction
        axis = np.array([math.cos(theta[0]), math.sin(theta[0])])
        assert abs(float(axis @ v[:, 1])) > 1 - 1e-6


_probabilities = hnp.arrays(
    np.float32,
    hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=12),
    elements=st.one_of(st.just(np.float32("nan")), st.floats(0, 1, width=32)),
)


@settings(max_examples=60, deadline=None)
@given(
    prob=_probabilities,
    origin=st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4)),
    resolution=st.floats(1e-3, 10.0),
)
def test_nav2_write_load_round_trip(
    prob: np.ndarray, origin: tuple[float, float], resolution: float
) -> None:
    grid = GridSpec(origin[0], origin[1], resolution, prob.shape[1], prob.shape[0])
    with tempfile.TemporaryDirectory() as tmp:
        yaml_path = Path(tmp) / "map.yaml"
        write_nav2_map(yaml_path, prob, grid)
        loaded = load_nav2_map(yaml_path)
    assert loaded.grid == grid
    with np.errstate(invalid="ignore"):
        want = np.where(prob > 0.65, 1, np.where(prob < 0.196, 0, -1))
    assert loaded.classes.tolist() == want.tolist()
    assert loaded.occupancy.tolist() == np.choose(want + 1, [-1, 0, 100]).tolist()

