"""Columns spilled to disk once and mapped read-only, their pages given back behind a walk.

What pass 1 gathers over the whole log and the later passes read again in time order (the
pose track, the time-ordered readings) is appended to anonymous temporary files, one per
column: unlinked from the start, so they vanish with the process, even a killed one.
:meth:`ColumnSpill.finish` maps them read-only; the columns are ordinary read-only numpy
arrays, and :meth:`MappedColumns.release_before` gives back the resident pages of the rows
a walk in row order is done with (the values stay readable, from the page cache or the
file), so what is resident does not grow with the log.
"""

from __future__ import annotations

import mmap
import tempfile
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt


class MappedColumns:
    """Equal-length columns mapped read-only from their spill files."""

    def __init__(self, columns: tuple[np.ndarray, ...], maps: tuple[mmap.mmap, ...]) -> None:
        self.columns = columns
        self._maps = maps
        self._released = 0  # rows before this one have had their pages given back

    def __len__(self) -> int:
        return int(self.columns[0].shape[0]) if self.columns else 0

    def release_before(self, row: int | None) -> None:
        """Give back the whole resident pages of every column that lie before ``row``
        (all pages with None: a new walk from the start may follow)."""
        if not self._maps or not hasattr(mmap, "MADV_DONTNEED"):
            return
        if row is None:
            for m in self._maps:
                m.madvise(mmap.MADV_DONTNEED)
            self._released = 0
            return
        if row <= self._released:
            return
        for m, col in zip(self._maps, self.columns, strict=True):
            upto = (row * col.itemsize) // mmap.PAGESIZE * mmap.PAGESIZE
            if upto:
                m.madvise(mmap.MADV_DONTNEED, 0, min(upto, len(m)))
        self._released = row


class ColumnSpill:
    """Appends equal-length chunks of columns (of ``dtypes``) to unlinked temporary files."""

    def __init__(self, dtypes: Sequence[npt.DTypeLike], prefix: str) -> None:
        self._dtypes = tuple(np.dtype(d) for d in dtypes)
        self._files = tuple(tempfile.TemporaryFile(prefix=prefix) for _ in self._dtypes)  # noqa: SIM115 (closed in finish)
        self.rows = 0

    def append(self, *columns: npt.ArrayLike) -> None:
        """Append one chunk: a value per column, all of the same length."""
        arrays = [np.ascontiguousarray(c, dtype=d) for c, d in zip(columns, self._dtypes,
                                                                   strict=True)]
        n = arrays[0].shape[0]
        if any(a.shape != (n,) for a in arrays):
            raise ValueError("spilled columns must be one-dimensional and of one length")
        for f, a in zip(self._files, arrays, strict=True):
            f.write(a.data)  # the array's bytes, not a copy of them
        self.rows += n

    def finish(self) -> MappedColumns:
        """The columns mapped read-only; the files are closed (the mappings keep them)."""
        n = self.rows
        cols: list[np.ndarray] = []
        maps: list[mmap.mmap] = []
        for f, dtype in zip(self._files, self._dtypes, strict=True):
            f.flush()
            if n:
                m = mmap.mmap(f.fileno(), n * dtype.itemsize, access=mmap.ACCESS_READ)
                maps.append(m)
                cols.append(np.frombuffer(m, dtype=dtype, count=n))
            else:
                cols.append(np.empty(0, dtype=dtype))
            f.close()
        return MappedColumns(tuple(cols), tuple(maps))

    def close(self) -> None:
        """Drop the files without mapping them (a pass that failed half-way)."""
        for f in self._files:
            f.close()
