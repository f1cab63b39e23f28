"""How much of a group's divisible work the calling thread keeps beside the worker thread.

A pass hands each group's work to two threads: the calling thread first does work of its
own that cannot be divided (``own``: preparing the group, numpy), then keeps a share ``s``
of the divisible work (a kernel over readings or rows) and hands ``1 − s`` to the worker
(:class:`~pipeline.mapper.row_bands.RowBands`), which runs beside it. With ``m`` and ``w``
the whole divisible work's seconds at each thread's pace (a part's seconds over its share:
the parts' costs need not be equal), both finish together when ``own + s·m = (1 − s)·w``:
``s = (w − own) / (m + w)``. ``own``, ``m`` and ``w`` are measured (thread CPU seconds) on
the groups before, as running means; the first group is split in halves.

Only the threads' balance depends on the share: the kernels' results do not (each part
adds to its own tables, or to its own rows, in reading order), so the bytes are the same
whatever the measured times are.
"""

from __future__ import annotations

MIN_SHARE = 0.1  # the calling thread keeps at least this share (and the worker as much)
MEMORY = 0.5  # weight of the groups before in the running means


class WorkShare:
    """The calling thread's share of the divisible work (module doc)."""

    def __init__(self) -> None:
        self.share = 0.5
        self._means: list[float] = []  # own, and the divisible work's cost per share on
        # this thread and on the worker

    def update(self, own_s: float, mine_s: float, theirs_s: float, share: float) -> None:
        """Add one group's measured seconds: this thread's own work, and its part (its
        ``share``) and the worker's part of the divisible work."""
        if not 0.0 < share < 1.0:
            return
        group = [own_s, mine_s / share, theirs_s / (1.0 - share)]
        if not self._means:
            self._means = group
        else:
            self._means = [MEMORY * m + (1.0 - MEMORY) * g for m, g in zip(self._means, group,
                                                                          strict=True)]
        own, mine, theirs = self._means
        if mine + theirs > 0.0:
            # own + s·mine = (1 − s)·theirs
            share = (theirs - own) / (mine + theirs)
            self.share = min(max(share, MIN_SHARE), 1.0 - MIN_SHARE)
