"""Shared fixtures of the pose refinement tests."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from formats import open_log
from pipeline.config import Config
from pipeline.refine import Echoes, collect_echoes


def log_echoes(log: Path, max_range_m: float, max_gap_ns: int = 10**9,
               arc_fraction: float = 0.8) -> tuple[tuple[np.ndarray, ...], Echoes]:
    """A log's pose track (t, x, y, yaw) and its echoes out to ``max_range_m`` (each placed
    along ``arc_fraction`` of its half beam)."""
    from pipeline.run import surveyed

    cfg = Config()
    with open_log(log, cfg) as reader:
        sv, sensors = surveyed(reader, cfg)
        echoes = collect_echoes(sv.ordered_ranges(reader), sv.track, sensors,
                                eps_max=cfg.mapper.eps_max, max_echo_range_m=max_range_m,
                                arc_fraction=arc_fraction, time_offset_ns=0,
                                max_gap_ns=max_gap_ns)
    return tuple(np.asarray(getattr(sv.track, a)) for a in ("t_ns", "x", "y", "yaw")), echoes


@pytest.fixture(scope="session")
def sample_echoes() -> Callable[[str, float], tuple[tuple[np.ndarray, ...], Echoes]]:
    """``load(name, max_range_m)``: a sample log's pose track (t, x, y, yaw) and its echoes
    out to ``max_range_m`` (read once per session)."""
    cache: dict[tuple[str, float], tuple[tuple[np.ndarray, ...], Echoes]] = {}

    def load(name: str, max_range_m: float) -> tuple[tuple[np.ndarray, ...], Echoes]:
        if (name, max_range_m) not in cache:
            log = Path(__file__).resolve().parents[3] / "sample_logs" / name / f"{name}.mcap"
            cache[(name, max_range_m)] = log_echoes(log, max_range_m)
        return cache[(name, max_range_m)]

    return load


@contextlib.contextmanager
def gates_replaced(**gates: Any) -> Iterator[None]:
    """Refinement's calibration run with ``gates`` in place of some of
    :func:`pipeline.refine.refine.calibration_gates` (e.g. ``tilt="off"``)."""
    import pipeline.refine.refine as rf

    kept = rf.calibration_gates
    rf.calibration_gates = lambda: {**kept(), **gates}  # type: ignore[assignment]
    try:
        yield
    finally:
        rf.calibration_gates = kept  # type: ignore[assignment]
