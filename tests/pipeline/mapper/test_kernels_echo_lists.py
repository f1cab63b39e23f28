"""The last attribution's echoes listed, then spread (kernels.echo_lists), against the
attribution traced reading by reading (kernels.specular.trace_readings)."""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
import pytest

import pipeline.mapper.specular as specular
from pipeline.config import MapperConfig
from pipeline.mapper import make_mapper
from pipeline.mapper.kernels.echo_lists import echo_candidate_lists, spread_candidate_lists
from pipeline.mapper.kernels.specular import TraceArgs, trace_readings
from pipeline.mapper.synthetic import ring_scans, room_grid


def _copy(args: TraceArgs) -> TraceArgs:
    return TraceArgs(*[a.copy() if isinstance(a, np.ndarray) else a for a in args])


def _last_attribution_calls(monkeypatch: pytest.MonkeyPatch) -> list[TraceArgs]:
    """The arguments of every call of the last attribution (with stops, no bearings) of the
    default method on the synthetic room, one thread."""
    calls: list[TraceArgs] = []

    def capture(*args: Any) -> int:
        named = TraceArgs(*args[:-2])
        if named.attribute and not named.bearings:
            calls.append(_copy(named))
        return int(trace_readings(*args))

    monkeypatch.setattr(specular, "trace_readings", capture)
    mapper = make_mapper(MapperConfig(method="forward", threads=1), room_grid(0.05))
    scans = ring_scans(300)
    for index in range(mapper.passes):
        mapper.begin_pass(index)
        mapper.integrate_many(scans)
    return calls


def test_trace_args_name_trace_readings_arguments_in_order() -> None:
    names = list(inspect.signature(trace_readings.py_func).parameters)
    assert list(TraceArgs._fields) == names[:-2]
    assert names[-2:] == ["row_lo", "row_hi"]


def test_listed_then_spread_is_the_traced_attribution(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _last_attribution_calls(monkeypatch)
    assert calls
    listed = 0
    for a in calls:
        traced = _copy(a)
        rows = a.free_in.shape[0]
        lost_traced = int(trace_readings(*traced, 0, rows))
        n = a.cones.shape[0]
        for cut in (0, n // 3, n):  # the first readings traced, the rest listed and spread
            first = _copy(a).first(cut)
            assert first.cones.shape[0] == first.stopped_in.shape[0] == cut
            assert first.offsets.shape[0] == cut + 1
            lost = int(trace_readings(*first, 0, rows)) if cut else 0
            lists = echo_candidate_lists(a.cones, a.up_down, a.r_inner, a.alpha, a.half_fov,
                                         a.gx, a.gy, a.res, a.offsets, a.stops, a.stopped_in,
                                         a.free_in, a.arcs_in, a.ratio, cut, n)
            assert lists[1].dtype == np.int32 and lists[0].shape == (n - cut + 1,)
            listed += int(lists[0][-1])
            lost += int(spread_candidate_lists(first.hits, *lists, a.dilution))
            assert lost == lost_traced
            assert first.hits.tobytes() == traced.hits.tobytes()
        assert a.hits.tobytes() != traced.hits.tobytes()  # the attribution added hits
    assert listed > 0
