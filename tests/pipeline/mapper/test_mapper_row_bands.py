"""The specular and default methods' speed-ups keep their bytes: the row-band split between two
threads (any split row, one thread or two), the E-step's two parts of the readings, the
last attribution's two parts, any share of the work between the threads, the list of
surfaces that may be silent, the later passes' group size."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from specular_room import specular_scans

import pipeline.mapper.specular as specular
from pipeline.config import MapperConfig
from pipeline.mapper import make_mapper
from pipeline.mapper.kernels.specular import silent_candidates
from pipeline.mapper.row_bands import RowBands, balanced_split
from pipeline.mapper.synthetic import room_grid
from pipeline.mapper.work_share import WorkShare


def test_balanced_split_halves_the_cones_area() -> None:
    # Four cones along +x (centroid on the origin's row), one twice the radius (4× area).
    oy = np.array([0.5, 1.0, 1.5, 2.0])
    cones = np.zeros((4, 7))
    cones[:, 1] = oy
    cones[:, 2] = [1.0, 1.0, 1.0, 2.0]
    alpha = np.zeros(4)
    # weights 1, 1, 1, 4 by row 10, 20, 30, 40: half of 7 is reached at row 40
    assert balanced_split(cones, alpha, 0.0, 0.05, 100) == 40
    cones[:, 2] = 1.0
    assert balanced_split(cones, alpha, 0.0, 0.05, 100) == 20
    # A cone pointing up counts where its cells are: 2/3 of its radius above the origin.
    up = cones[:1].copy()
    up[0, 2] = 3.0
    assert balanced_split(up, np.array([np.pi / 2]), 0.0, 0.05, 100) == 50
    assert balanced_split(np.zeros((0, 7)), np.zeros(0), 0.0, 0.05, 100) == 50
    assert balanced_split(cones, alpha, 10.0, 0.05, 100) == 0  # clamped to the grid


def test_row_bands_run_both_bands_and_add_their_results() -> None:
    calls: list[tuple[int, int, str]] = []

    def band(lo: int, hi: int) -> int:
        calls.append((lo, hi, threading.current_thread().name))
        return 10 * lo + hi

    two = RowBands(2)
    assert two.run(band, 5, 12) == (0 + 5) + (50 + 12)
    assert sorted(c[:2] for c in calls) == [(0, 5), (5, 12)]
    assert any(name.startswith("sonarmap-band") for *_, name in calls)  # the upper band
    two.close()
    calls.clear()
    assert two.run(band, 5, 12) == 12 and [c[:2] for c in calls] == [(0, 12)]
    calls.clear()
    assert RowBands(1).run(band, 5, 12) == 12 and [c[:2] for c in calls] == [(0, 12)]

    def fails(lo: int, hi: int) -> int:
        raise ValueError(f"band {lo}")

    with pytest.raises(ValueError, match="band"):
        RowBands(2).run(fails, 5, 12)


def _specular_grids(threads: int) -> dict[str, np.ndarray]:
    grid = room_grid()
    m = make_mapper(MapperConfig(threads=threads), grid)
    scans = specular_scans(120, 20.0)
    for index in range(m.passes):
        m.begin_pass(index)
        m.integrate_many(scans)
    occupied = m.snapshot().occupied  # the grids are complete once the map is taken
    out = {k: getattr(m, k).copy() for k in ("free2", "arcs2", "hits2", "hits", "free", "stats", "reaches")}
    out["occupied"] = occupied
    out["unattributed"] = np.array([m.counters.echoes_unattributed])
    return out


def test_the_specular_maps_do_not_depend_on_threads_or_the_split(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    one = _specular_grids(1)
    assert one["occupied"].sum() > 100 and one["free2"].max() > 1.0
    assert one["stats"].sum() > 100  # the E-step's counts (its readings split in two halves)
    for split in (None, 0, 37, 10**6):
        if split is not None:
            monkeypatch.setattr(specular, "balanced_split",
                                lambda *a, s=split: min(s, a[4]))  # a[4]: the height
        two = _specular_grids(2)
        for name, grid in one.items():
            assert np.array_equal(grid, two[name]), (split, name)


@pytest.mark.parametrize("forced", [0.0, 0.3, 1.0])
def test_the_maps_do_not_depend_on_how_the_work_is_shared(
    forced: float, monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The E-step's parts, the count pass's row bands and the last attribution's two parts
    # are sized by measured times (WorkShare): any share gives the same grids and counts.
    one = _specular_grids(1)

    def fixed(self: WorkShare, *args: float) -> None:
        self.share = forced

    monkeypatch.setattr(WorkShare, "update", fixed)
    monkeypatch.setattr(WorkShare, "__init__", fixed)
    two = _specular_grids(2)
    for name, grid in one.items():
        assert np.array_equal(grid, two[name]), (forced, name)


def test_the_later_passes_do_not_depend_on_their_groups(monkeypatch: pytest.MonkeyPatch) -> None:
    # Passes 2 and up (no paper's mapper) take larger groups of scans: any size, the bytes.
    want = _specular_grids(2)
    for size in (1, 7):
        monkeypatch.setattr(specular, "LATE_GROUP", size)
        got = _specular_grids(2)
        for name, grid in want.items():
            assert np.array_equal(grid, got[name]), (size, name)


def test_silent_candidates_list_the_consistent_surfaces_row_by_row() -> None:
    surfaces = np.array([[1, 0, 1, 1], [0, 0, 0, 0], [1, 1, 0, 1]], dtype=bool)
    q = np.full(surfaces.shape, 0.9, dtype=np.float32)
    q[0, 3] = 0.5  # q ≤ ½ never stops a ray: q·(1 − visible) ≤ q
    index, cols = silent_candidates(surfaces, q)
    assert cols.tolist() == [0, 2, 0, 1, 3]
    # row r, columns c0..c1: cols[index[r, c0]:index[r, c1 + 1]]
    assert cols[index[0, 0]:index[0, 4]].tolist() == [0, 2]
    assert cols[index[0, 1]:index[0, 3]].tolist() == [2]
    assert index[1, 0] == index[1, 4] == 2
    assert cols[index[2, 1]:index[2, 4]].tolist() == [1, 3]
    assert index.dtype == np.int32 and index.shape == (3, 5)


def test_the_attributions_on_the_band_thread_keep_their_bytes_across_batches() -> None:
    # Passes 1 and 3 attribute each group on the band thread while the next group (of the
    # next batch, too) is prepared: the grids and counts of one thread, batch by batch.
    scans = specular_scans(120, 20.0)
    got = []
    for threads in (1, 2):
        m = make_mapper(MapperConfig(threads=threads), room_grid())
        for index in range(m.passes):
            m.begin_pass(index)
            for b in range(0, len(scans), 9):
                m.integrate_many(scans[b:b + 9])
        occupied = m.snapshot().occupied
        grids = {k: getattr(m, k).copy() for k in ("hits", "arc_c", "arc_s", "hits2", "free2")}
        got.append((grids, occupied, m.counters.echoes_unattributed, m._unattributed))
    (one, occ1, un1, first1), (two, occ2, un2, first2) = got
    assert one["hits2"].sum() > 10 and np.abs(one["arc_c"]).sum() > 10 and un1 > 0
    assert (un1, first1) == (un2, first2) and np.array_equal(occ1, occ2)
    for name, grid in one.items():
        assert np.array_equal(grid, two[name]), name


def test_later_runs_in_order_on_the_worker_and_hands_back_errors() -> None:
    done: list[int] = []

    def work(k: int) -> int:
        done.append(k)
        return k * 10

    for threads in (1, 2):
        done.clear()
        bands = RowBands(threads)
        futures = [bands.later(lambda k=k: work(k)) for k in range(5)]
        assert [f.result() for f in futures] == [0, 10, 20, 30, 40] and done == list(range(5))

        def fails() -> int:
            raise ValueError("attribution failed")

        if threads == 1:
            with pytest.raises(ValueError, match="attribution failed"):
                bands.later(fails)
        else:
            with pytest.raises(ValueError, match="attribution failed"):
                bands.later(fails).result()
        bands.close()


def test_a_mapper_dropped_with_an_attribution_pending_is_freed_on_the_calling_thread(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The band thread holds the attribution's arrays, not the mapper: a mapper dropped
    # mid-pass is freed (and its thread stopped) here, not on that thread (which cannot
    # join itself).
    import gc
    import sys
    import time
    import weakref

    raised: list[object] = []
    monkeypatch.setattr(sys, "unraisablehook", raised.append)
    trace = specular.trace_readings

    def slow(*args: object) -> int:  # the attribution still runs when the mapper is dropped
        time.sleep(0.3)
        return int(trace(*args))

    monkeypatch.setattr(specular, "trace_readings", slow)
    scans = specular_scans(120, 20.0)
    before = set(threading.enumerate())
    m = make_mapper(MapperConfig(threads=2), room_grid())
    for index in range(2):
        m.begin_pass(index)
        m.integrate_many(scans)  # pass 1 ends with its last group's attribution pending
    assert m._attributing is not None  # type: ignore[attr-defined]
    assert not m._attributing[0].done()  # type: ignore[attr-defined]
    band_threads = [t for t in threading.enumerate()
                    if t not in before and t.name.startswith("sonarmap-band")]
    assert len(band_threads) == 1
    alive = weakref.ref(m)
    del m
    gc.collect()
    assert alive() is None
    assert raised == []
    for t in band_threads:
        t.join(timeout=10)
    assert not any(t.is_alive() for t in band_threads)
