"""The paper's mapper on a second thread inside the default method: the same features,
map and counters as inline, wherever the hand-over from pass 0 to pass 1 falls (§9's free
counts, taken from the hand-over's spans or counted apart, the same); its errors reach the
caller."""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np
import pytest

from formats.errors import ConfigError
from pipeline.config import Config, MapperConfig
from pipeline.mapper import AttributionMapper
from pipeline.mapper import paper_thread as pt
from pipeline.mapper.andersone import AndersoneMapper, PreparedGroup
from pipeline.mapper.kernels.attribution import count_free, empty_span_counts, span_counts
from pipeline.mapper.scan_group import ScanGroup, scan_groups
from pipeline.mapper.synthetic import ring_scans, room_grid
from pipeline.mapper.types import Scan

INLINE = MapperConfig(threads=1)
THREADED = MapperConfig(threads=2)


def _map(cfg: MapperConfig, scans: list[Scan], chunk: int = 50) -> AttributionMapper:
    m = AttributionMapper(cfg, room_grid())
    for index in range(m.passes):
        m.begin_pass(index)
        for k in range(0, len(scans), chunk):  # the pipeline's chunks of scans
            m.integrate_many(scans[k : k + chunk])
    return m


def _assert_same(a: AttributionMapper, b: AttributionMapper) -> None:
    sa, sb = a.snapshot(), b.snapshot()
    assert sa.probability.tobytes() == sb.probability.tobytes()
    assert sa.counters == sb.counters
    for f in dataclasses.fields(sa.features):
        np.testing.assert_array_equal(getattr(sa.features, f.name), getattr(sb.features, f.name))
    assert a.feature_variance() == b.feature_variance()
    assert a.paper.rng.bit_generator.state == b.paper.rng.bit_generator.state


def test_threaded_features_equal_inline_when_pass_1_hands_over_most_groups(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    scans = ring_scans(700, seed=4)
    inline = _map(INLINE, scans)
    assert inline._paper_thread is None and len(inline.feature_table()) > 50
    # A slow paper's mapper and a one-group queue: pass 0 hands over only its first groups.
    slow = AndersoneMapper.integrate_prepared

    def integrate_slowly(self: AndersoneMapper, work: PreparedGroup) -> None:
        time.sleep(0.05)
        slow(self, work)

    monkeypatch.setattr(pt, "QUEUE_GROUPS", 1)
    monkeypatch.setattr(AndersoneMapper, "integrate_prepared", integrate_slowly)
    handed_in_pass_0: list[int] = []
    original_give = pt.PaperThread.give

    def give(self: pt.PaperThread, index: int, group: ScanGroup) -> None:
        if not handed_in_pass_0:
            handed_in_pass_0.append(self.handed)
        original_give(self, index, group)

    monkeypatch.setattr(pt.PaperThread, "give", give)
    threaded = _map(THREADED, scans)
    groups = -(-len(scans) // 50)  # one group per chunk of 50 scans
    assert 0 < handed_in_pass_0[0] < groups // 2
    _assert_same(threaded, inline)
    # §9's free counts: from the hand-over's spans (first groups), counted apart (the rest).
    grid, diff = room_grid(), empty_span_counts(room_grid().shape)
    for k in range(0, len(scans), 50):
        for group in scan_groups(scans[k : k + 50], THREADED):
            _, cones, up_down = group.free_cones
            count_free(cones, up_down, grid.origin_x, grid.origin_y, grid.resolution, diff)
    want = span_counts(diff)
    assert want.max() >= 2
    np.testing.assert_array_equal(threaded.free, want)
    np.testing.assert_array_equal(inline.free, want)


def test_threaded_features_equal_inline_when_pass_0_hands_over_every_group() -> None:
    scans = ring_scans(300, seed=5)
    threaded = _map(THREADED, scans, chunk=300)
    assert threaded._paper_thread is not None
    _assert_same(threaded, _map(INLINE, scans, chunk=300))


def test_an_error_of_the_paper_thread_is_raised_to_the_caller(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def fail(self: AndersoneMapper, work: PreparedGroup) -> None:
        raise FloatingPointError("kernel failed")

    monkeypatch.setattr(AndersoneMapper, "integrate_prepared", fail)
    m = AttributionMapper(THREADED, room_grid())
    m.begin_pass(0)
    scans = ring_scans(300, seed=1)
    # At the next hand-over after the failure, or when the results are asked for.
    with pytest.raises(FloatingPointError, match="kernel failed"):
        for k in range(0, 300, 10):
            m.integrate_many(scans[k : k + 10])
        m.snapshot()


def test_the_gil_switch_interval_is_short_while_the_thread_runs() -> None:
    before = sys.getswitchinterval()
    m = AttributionMapper(THREADED, room_grid())
    assert sys.getswitchinterval() == min(before, pt.SWITCH_INTERVAL_S) < 0.005
    m.feature_table()  # the thread ends
    assert sys.getswitchinterval() == before


def test_scans_after_the_results_were_read_are_refused() -> None:
    scans = ring_scans(100, seed=2)
    m = _map(THREADED, scans)
    m.feature_table()  # waits for the thread, which then ends
    m.begin_pass(1)
    with pytest.raises(RuntimeError, match="after it finished"):
        m.integrate_many(scans)


def test_threads_is_a_checked_speed_key_outside_the_config_hash() -> None:
    one = Config(mapper=INLINE)
    assert one.hash() == Config().hash()  # results do not depend on it
    assert Config(mapper=dataclasses.replace(INLINE, seed=1)).hash() != one.hash()
    with pytest.raises(ConfigError, match=r"mapper\.threads"):
        Config(mapper=MapperConfig(threads=0)).validate()


def test_a_mapper_dropped_half_way_stops_its_thread_after_the_group_in_hand(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # An interrupted run drops its mapper with groups still queued: the thread ends after
    # the one it holds and is joined there, not left inside the kernels until the
    # interpreter exits (as a daemon thread finalised mid-kernel, it can crash the process).
    import gc

    integrated: list[int] = []
    slow = AndersoneMapper.integrate_prepared

    def integrate_slowly(self: AndersoneMapper, work: PreparedGroup) -> None:
        time.sleep(0.05)
        slow(self, work)
        integrated.append(1)

    monkeypatch.setattr(pt, "QUEUE_GROUPS", 8)
    monkeypatch.setattr(AndersoneMapper, "integrate_prepared", integrate_slowly)
    m = AttributionMapper(THREADED, room_grid())
    m.begin_pass(0)
    scans = ring_scans(400, seed=3)
    for k in range(0, 400, 50):
        m.integrate_many(scans[k : k + 50])
    assert m._paper_thread is not None
    thread, handed = m._paper_thread._thread, m._paper_thread.handed
    assert thread is not None and thread.is_alive() and handed >= 4
    del m
    gc.collect()
    assert not thread.is_alive()  # joined when the mapper went
    assert len(integrated) < handed  # the queued groups were dropped
