"""The reorder window: a log's readings, interleaved chunk by chunk, released in time order.

Logs interleave topics and connections chunk by chunk, so the range batches a reader yields
are not globally sorted. :class:`ReorderWindow` holds readings until the stream has moved
``window_ns`` past them, then releases them sorted (stable, so equal stamps keep log
order). A reading older than what was already released is *late*: it is dropped and
counted, since its scan has already been mapped. Readings whose stamp went backwards
(:class:`pipeline.stages.ingest.StampOrder`) are dropped and counted before they enter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.arrays import B
from formats.contract import RangeBatch

REORDER_WINDOW_NS = 2_000_000_000


@dataclass
class RangeChunk:
    """Time-ordered readings released by the window, with what was dropped on the way
    since the previous chunk."""

    batch: RangeBatch
    late: int = 0
    backwards: int = 0


class ReorderWindow:
    """Push the log's range batches in log order; get time-ordered chunks back."""

    def __init__(self, window_ns: int = REORDER_WINDOW_NS) -> None:
        self.window_ns = window_ns
        self._pending: list[RangeBatch] = []
        self._released_up_to: int | None = None
        self._newest: int | None = None

    def push(self, batch: RangeBatch, backwards: B) -> RangeChunk | None:
        """Add a batch (``backwards``: its readings whose stamp went backwards, dropped);
        returns the readings now ready, or None when nothing is released or dropped."""
        n_back = int(backwards.sum())
        if n_back:
            batch = batch.take(~backwards)
        late = 0
        if self._released_up_to is not None and len(batch):
            is_late = batch.t_ns < self._released_up_to
            late = int(is_late.sum())
            if late:
                batch = batch.take(~is_late)
        if len(batch):
            self._pending.append(batch)
            bmax = int(batch.t_ns.max())
            self._newest = bmax if self._newest is None else max(self._newest, bmax)
        ready_chunk: RangeBatch | None = None
        if self._newest is not None and self._pending:
            merged = RangeBatch.concat(self._pending)
            ready = merged.t_ns < self._newest - self.window_ns
            if ready.any():
                out = merged.take(ready)
                self._pending = [merged.take(~ready)]
                order = np.argsort(out.t_ns, kind="stable")
                self._released_up_to = int(out.t_ns[order[-1]])
                ready_chunk = out.take(order)
            else:
                self._pending = [merged]
        if ready_chunk is None and not late and not n_back:
            return None
        return RangeChunk(ready_chunk if ready_chunk is not None else RangeBatch.concat([]),
                          late, n_back)

    def flush(self) -> RangeChunk | None:
        """The readings still held, sorted, at the end of the stream (None if none)."""
        if not self._pending:
            return None
        merged = RangeBatch.concat(self._pending)
        self._pending = []
        if not len(merged):
            return None
        return RangeChunk(merged.take(np.argsort(merged.t_ns, kind="stable")))
