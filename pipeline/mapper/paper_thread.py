"""The paper's mapper inside the default method, on a second thread.

The attribution method (:mod:`pipeline.mapper.attribution`) feeds every group of scans of
its evidence pass to the paper's mapper for ``features.parquet`` and the paper's metric:
the larger part of its work. :class:`PaperThread` runs that mapper on a thread of its own
(its kernel releases the GIL), so it overlaps the rest of the run on a second core.

Deterministic by construction: the paper's mapper takes groups ``0, 1, 2, ...`` exactly
once each, in order, from one queue, on one thread; nothing it computes depends on when a
group arrives. Both passes of the attribution method build the same groups in the same
order, so a group may come from either: pass 0 offers each group while the queue has room
(:meth:`offer`: never waits) and stops at the first it cannot hand over; pass 1 hands over
the rest (:meth:`give`: waits for room). Memory is the queue's :data:`QUEUE_GROUPS` groups.

The feeding thread does each group's scan-local half before handing it over
(:meth:`AndersoneMapper.prepare`: reading features and free-space scans; and the free
layer's counts, :meth:`AndersoneMapper.add_free_space`, a sum the paper's thread never
reads): the paper's thread, the critical path, only merges and corrects.
"""

from __future__ import annotations

import contextlib
import queue
import sys
import threading
import weakref

from pipeline.mapper.andersone import AndersoneMapper, PreparedGroup
from pipeline.mapper.kernels.free_unions import NO_COUNTS
from pipeline.mapper.scan_group import ScanGroup
from pipeline.mapper.types import I32

# Prepared groups waiting for the thread (64 scans each, ~0.4 MB: reading features and free
# spaces). The more pass 0 can hand over, the less the thread waits for pass 1 to reach it:
# run() of the hour's log (in-process, after imports, quiet machine) took 3.49 s with 16, 3.31 s with
# 64, 3.20 s with 96; 64 was best with the other core busy (more groups handed in pass 0 is
# more preparing on pass 0's critical path). Peak RSS 265 -> 275 MB (16 -> 64).
QUEUE_GROUPS = 64
# While the thread runs, a thread busy in Python hands the GIL over within this many
# seconds when the paper's thread needs it back (after each kernel call, between numpy
# steps). CPython's 5 ms stalls it at every such step: measured on the quarter-hour log's
# two passes with both cores free, 1.84 s wall with 5 ms, 1.65 s with 0.5 ms, 2.0 s inline.
SWITCH_INTERVAL_S = 0.0005
_STOP = None


def _work(paper: AndersoneMapper, todo: queue.Queue[PreparedGroup | None],
          failed: list[BaseException], cancelled: threading.Event) -> None:
    """The thread: integrate groups in order until the stop mark (or the first error);
    once ``cancelled``, the groups still queued are dropped."""
    while True:
        work = todo.get()
        if work is _STOP or cancelled.is_set():
            return
        if failed:
            continue  # drain: the error is reported to the feeding thread
        try:
            paper.integrate_prepared(work)
        except BaseException as err:  # handed to the feeding thread
            failed.append(err)


def _cancel(todo: queue.Queue[PreparedGroup | None], cancelled: threading.Event,
            thread: threading.Thread) -> None:
    """Stop the thread after the group it holds (the queued ones dropped) and join it."""
    cancelled.set()
    with contextlib.suppress(queue.Full):  # full: it is working, and sees the flag next
        todo.put_nowait(_STOP)  # wakes a thread waiting for work
    thread.join()


class PaperThread:
    """Feeds an :class:`AndersoneMapper` on its own thread; :meth:`finish` waits for it."""

    def __init__(self, paper: AndersoneMapper) -> None:
        self.paper = paper
        self.handed = 0  # groups handed over so far: the index of the next one it needs
        self._offering = True  # pass 0 still offers (until the queue is first full)
        self._queue: queue.Queue[PreparedGroup | None] = queue.Queue(QUEUE_GROUPS)
        self._failed: list[BaseException] = []
        cancelled = threading.Event()
        self._thread: threading.Thread | None = threading.Thread(
            target=_work, args=(paper, self._queue, self._failed, cancelled),
            name="sonarmap-paper-mapper", daemon=True,
        )
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch_interval, SWITCH_INTERVAL_S))
        self._thread.start()
        # A mapper dropped half-way (a failed or interrupted run), or still running when
        # the interpreter exits, stops its thread after the group in hand and waits for
        # it: a daemon thread left inside the compiled kernels while the interpreter
        # finalises can crash the process (seen once: SIGSEGV after SIGTERM mid-run).
        weakref.finalize(self, _cancel, self._queue, cancelled, self._thread)

    def offer(self, index: int, group: ScanGroup, free_diff: I32 = NO_COUNTS) -> bool:
        """Pass 0: hand over group ``index`` if it is the next one needed and the queue has
        room now; after the first miss, pass 0 offers nothing more. Whether it was handed
        over (then its free cones were counted into ``free_diff``: :meth:`AndersoneMapper.
        prepare`)."""
        self._check()
        if not self._offering or index != self.handed:
            return False
        if self._queue.full():  # only this thread adds: room now is room at the put
            self._offering = False
            return False
        self._hand_over(group, block=False, free_diff=free_diff)
        return True

    def give(self, index: int, group: ScanGroup) -> None:
        """Pass 1: hand over group ``index`` if the thread has not had it (waits for room)."""
        self._check()
        if index < self.handed:
            return
        if index != self.handed:
            raise RuntimeError(f"scan group {index} given before group {self.handed}")
        self._hand_over(group, block=True)

    def _hand_over(self, group: ScanGroup, block: bool, free_diff: I32 = NO_COUNTS) -> None:
        """Prepare the group here, queue it, add its free space (once per group)."""
        work = self.paper.prepare(group, free_diff)
        self._queue.put(work, block=block)
        self.paper.add_free_space(work)
        self.handed += 1

    def finish(self) -> None:
        """Wait until every group handed over is integrated; re-raise the thread's error."""
        if self._thread is not None:
            self._queue.put(_STOP)
            self._thread.join()
            self._thread = None
            sys.setswitchinterval(self._switch_interval)
        if self._failed:
            raise self._failed[0]

    def _check(self) -> None:
        """Raise the thread's error; refuse groups once :meth:`finish` has run."""
        if self._failed:
            raise self._failed[0]
        if self._thread is None:
            raise RuntimeError("scan groups handed to the paper's mapper after it finished")
