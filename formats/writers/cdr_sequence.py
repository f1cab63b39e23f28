"""CDR of a message whose last field is a long sequence of same-shaped messages, built with
numpy instead of one Python object per element (rosbags takes ~1 ms per marker).

The layout comes from rosbags itself: a few elements are serialised by rosbags with
sentinel values, the element boundaries and the byte offsets of the varying fields are
read off those bytes, and the elements are then written as copies of rosbags' own bytes
with the fields patched in. Elements may only differ in fixed-size numeric fields (their
strings and sequences must be the same for all), so every element has the same layout at
the same alignment phase; the phases repeat with the element size.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["sequence_cdr"]

_PROBES = 8  # elements serialised by rosbags to learn the layout (every alignment phase)


def _sentinels(dtype: np.dtype[Any], k: int, field: int) -> Any:
    """A value of ``dtype`` unique to element ``k`` and field ``field`` (and not 0)."""
    if np.issubdtype(dtype, np.integer):
        return int(0x1A2B0000 + field * 0x100 + k + 1) if dtype.itemsize >= 4 else k + 1
    return float(np.asarray(1.0 + field / 64.0 + (k + 1) / 4096.0 + 2.0**-30, dtype=dtype))


def sequence_cdr(
    ts: Any,
    msgtype: str,
    make_outer: Callable[[list[Any]], Any],
    make_element: Callable[[Mapping[str, Any]], Any],
    columns: Mapping[str, npt.NDArray[Any]],
) -> bytes:
    """CDR bytes of ``make_outer(elements)`` (type ``msgtype``; its last field is the
    sequence) where element ``i`` is ``make_element({name: columns[name][i]})``.

    ``columns``: equal-length 1-D arrays, each of the numpy dtype of its message field.
    Equal to ``ts.serialize_cdr(make_outer([...]), msgtype)`` byte for byte.
    """
    names = list(columns)
    n = len(next(iter(columns.values()))) if columns else 0
    dtypes = [np.asarray(columns[c]).dtype for c in names]
    probes = [make_element({c: _sentinels(dt, k, j) for j, (c, dt) in enumerate(zip(names, dtypes, strict=True))})
              for k in range(_PROBES)]
    sizes = [len(bytes(ts.serialize_cdr(make_outer(probes[:m]), msgtype))) for m in range(_PROBES + 1)]
    full = np.frombuffer(bytes(ts.serialize_cdr(make_outer(probes), msgtype)), dtype=np.uint8)
    head = bytes(full[: sizes[0] - 4])  # everything before the sequence's uint32 count
    # Per alignment phase (element start offset mod 8, counted after the 4-byte encapsulation
    # header): the element's size, rosbags' bytes for it and the offset of every field.
    layout: dict[int, tuple[int, npt.NDArray[np.uint8], list[int]]] = {}
    for k in range(_PROBES):
        start, stop = sizes[k], sizes[k + 1]
        phase = (start - 4) % 8
        blob = full[start:stop]
        offsets = []
        for j, (c, dt) in enumerate(zip(names, dtypes, strict=True)):
            pattern = np.asarray([_sentinels(dt, k, j)], dtype=dt.newbyteorder("<")).tobytes()
            at = bytes(blob).find(pattern)
            if at < 0 or bytes(blob).find(pattern, at + 1) >= 0:
                raise ValueError(f"cannot locate field {c!r} of {msgtype} elements")
            offsets.append(at)
        layout.setdefault(phase, (stop - start, blob, offsets))
    # Element starts, walking the phases.
    starts = np.empty(n, dtype=np.int64)
    phases = np.empty(n, dtype=np.int64)
    pos = sizes[0]
    for i in range(n):
        phase = (pos - 4) % 8
        if phase not in layout:
            raise ValueError(f"no layout learnt for alignment phase {phase} of {msgtype}")
        starts[i], phases[i] = pos, phase
        pos += layout[phase][0]
    out = np.empty(pos, dtype=np.uint8)
    out[: sizes[0] - 4] = np.frombuffer(head, dtype=np.uint8)
    out[sizes[0] - 4 : sizes[0]] = np.frombuffer(np.uint32(n).astype("<u4").tobytes(), np.uint8)
    for phase, (size, blob, offsets) in layout.items():
        sel = np.flatnonzero(phases == phase)
        if sel.size == 0:
            continue
        rows = np.repeat(blob[None, :], sel.size, axis=0)
        for c, dt, at in zip(names, dtypes, offsets, strict=True):
            values = np.ascontiguousarray(np.asarray(columns[c])[sel], dtype=dt.newbyteorder("<"))
            rows[:, at : at + dt.itemsize] = values.view(np.uint8).reshape(sel.size, dt.itemsize)
        out[starts[sel][:, None] + np.arange(size)[None, :]] = rows
    return out.tobytes()
