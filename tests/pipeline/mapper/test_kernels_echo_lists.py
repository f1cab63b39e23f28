"""The last attribution's echoes listed, then spread (kernels.echo_lists), against the
attribution traced reading by reading (kernels.specular.trace_readings)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import pipeline.mapper.specular as specular
from pipeline.config import MapperConfig
from pipeline.mapper import make_mapper
from pipeline.mapper.kernels.echo_lists import echo_candidate_lists, spread_candidate_lists
from pipeline.mapper.kernels.specular import trace_readings
from pipeline.mapper.synthetic import ring_scans, room_grid


def _last_attribution_calls(monkeypatch: pytest.MonkeyPatch) -> list[list[Any]]:
    """The arguments of every call of the last attribution (with stops, no bearings) of the
    default method on the synthetic room, one thread."""
    calls: list[list[Any]] = []

    def capture(*args: Any) -> int:
        if args[17] and not args[18]:
            calls.append([a.copy() if isinstance(a, np.ndarray) else a for a in args])
        return int(trace_readings(*args))

    monkeypatch.setattr(specular, "trace_readings", capture)
    mapper = make_mapper(MapperConfig(method="forward", threads=1), room_grid(0.05))
    scans = ring_scans(300)
    for index in range(mapper.passes):
        mapper.begin_pass(index)
        mapper.integrate_many(scans)
    return calls


def test_listed_then_spread_is_the_traced_attribution(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = _last_attribution_calls(monkeypatch)
    assert calls
    listed = 0
    for args in calls:
        traced = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
        lost_traced = int(trace_readings(*traced))
        (cones, up_down, r_inner, _, alpha, half, gx, gy, res, offsets, stops, stopped,
         *_, free_in, arcs_in, ratio, dilution, _, _, hits, _, _, _, _) = args
        n = cones.shape[0]
        for cut in (0, n // 3, n):  # the first readings traced, the rest listed and spread
            first = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
            for k in range(6):  # the first readings only
                first[k] = first[k][:cut]
            first[9] = offsets[: cut + 1]
            first[11] = stopped[:cut]
            lost = int(trace_readings(*first)) if cut else 0
            got = first[25]
            lists = echo_candidate_lists(cones, up_down, r_inner, alpha, half, gx, gy, res,
                                         offsets, stops, stopped, free_in, arcs_in, ratio,
                                         cut, n)
            assert lists[1].dtype == np.int32 and lists[0].shape == (n - cut + 1,)
            listed += int(lists[0][-1])
            lost += int(spread_candidate_lists(got, *lists, dilution))
            assert lost == lost_traced
            assert got.tobytes() == traced[25].tobytes()
        assert hits.tobytes() != traced[25].tobytes()  # the attribution added hits
    assert listed > 0
