"""The rows of a damaged rosbag2 ``messages`` table that sqlite can still read.

A query over the whole table (counts, the time-ordered stream of messages) fails at the
first page it cannot read, and would lose everything after it. The table's rows are
keyed by ``id`` (its rowid b-tree), so they can be read by id ranges instead: a range
that fails is split in two, down to single ids; an id whose row still cannot be read is
lost (:attr:`Salvage.rows_lost`) and every other row is read. A damaged page costs about
two queries per row on it; memory holds one range of rows at a time.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator, Sequence
from typing import Any

__all__ = ["DAMAGE_ERRORS", "RANGE_IDS", "ROW_ERRORS", "Salvage"]

RANGE_IDS = 4096  # ids per query (as many rows at most)
# What sqlite raises on a damaged database. A record whose header declares an absurd size
# makes sqlite report SQLITE_NOMEM without allocating it, which Python raises as MemoryError.
DAMAGE_ERRORS = (sqlite3.Error, MemoryError)
# ... and what a damaged row's values raise (text or NULL where a number belongs).
ROW_ERRORS = (*DAMAGE_ERRORS, TypeError, ValueError, OverflowError)


class Salvage:
    """Row reader of one database's ``messages`` table by id ranges."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self.db = db
        self.rows_lost = 0
        self.span = self._span()

    def _span(self) -> tuple[int, int] | None:
        """(smallest id, largest id + 1), None when the table is empty or its ends
        cannot be read."""
        try:
            lo, hi = self.db.execute("SELECT MIN(id), MAX(id) FROM messages").fetchone()
            return None if lo is None or hi is None else (int(lo), int(hi) + 1)
        except ROW_ERRORS:
            return None

    def rows(self, columns: str, where: str, args: Sequence[Any]) -> Iterator[list[Any]]:
        """Lists of rows (``columns``, ``where`` with its ``args`` also holding) in id
        order, one id range at a time, around what cannot be read."""
        if self.span is None:
            return
        condition = f"({where}) AND " if where else ""
        sql = f"SELECT {columns} FROM messages WHERE {condition}id >= ? AND id < ? ORDER BY id"
        lo, hi = self.span
        for start in range(lo, hi, RANGE_IDS):
            pending = [(start, min(start + RANGE_IDS, hi))]
            while pending:
                a, b = pending.pop()
                try:
                    rows = self.db.execute(sql, (*args, a, b)).fetchall()
                except ROW_ERRORS:
                    if b - a == 1:
                        self.rows_lost += 1
                    else:
                        mid = (a + b) // 2
                        pending += [(mid, b), (a, mid)]  # the lower half first
                    continue
                if rows:
                    yield rows
