"""What a user must know about a finished run, as one-line warnings (metrics.json
``warnings``, the reports' summary, ``run --json``): data lost from the input, readings
dropped, an empty map. One place for these rules."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["DROPPED_WARN_FRACTION", "NO_ECHO_REASONS", "NO_ECHO_WARN_FRACTION", "run_warnings"]

#: Readings dropped for reasons other than "no echo" above this fraction are a warning.
DROPPED_WARN_FRACTION = 0.01
#: No-echo readings (nothing within range: normal for a sonar) above this fraction are one.
NO_ECHO_WARN_FRACTION = 0.5
NO_ECHO_REASONS = ("max_range", "pos_inf")


def _pct(part: int, whole: int) -> str:
    return f"{100.0 * part / whole:.1f} %"


def run_warnings(metrics: Mapping[str, Any]) -> list[str]:
    """The warnings of a run's metrics (the sections of metrics.json), in a fixed order."""
    out: list[str] = []
    inp = metrics.get("input", {})
    lost = {k: v for k, v in inp.items() if "lost" in k and isinstance(v, int | float) and v > 0}
    if lost:
        what = ", ".join(f"{k.replace('_', ' ')} {v:,}" for k, v in sorted(lost.items()))
        n = len(inp.get("losses") or [])
        places = f" in {n} places" if n > 1 else ""
        out.append(f"data lost: the log is damaged{places}, its intact part was read ({what};"
                   " metrics.json input.losses names each)")
    counts = metrics.get("counts", {})
    readings = int(counts.get("readings", 0))
    dropped = {k: int(v) for k, v in metrics.get("dropped", {}).items() if int(v) > 0}
    other = {k: v for k, v in dropped.items() if k not in NO_ECHO_REASONS}
    n_other = sum(other.values())
    if readings and n_other > DROPPED_WARN_FRACTION * readings:
        top = sorted(other.items(), key=lambda kv: (-kv[1], kv[0]))[:3]
        reasons = ", ".join(f"{n:,} {k.replace('_', ' ')}" for k, n in top)
        out.append(f"readings dropped: {n_other:,} of {readings:,} ({_pct(n_other, readings)}): "
                   f"{reasons}")
    n_echo = sum(v for k, v in dropped.items() if k in NO_ECHO_REASONS)
    if readings and n_echo > NO_ECHO_WARN_FRACTION * readings:
        out.append(f"no echo: {n_echo:,} of {readings:,} readings ({_pct(n_echo, readings)}) "
                   "saw nothing within their max range")
    used = int(counts.get("readings_used", 0))
    grid = metrics.get("map", {})
    if used == 0:
        out.append("empty map: no reading was mapped")
    elif int(grid.get("cells_occupied", 0)) == 0:
        out.append("empty map: no occupied cell")
    elif metrics.get("run", {}).get("method") != "classic" and int(counts.get("features", 0)) == 0:
        out.append("empty map: no features")
    if used and int(grid.get("cells_free", 0)) == 0:
        out.append("no free space: no cell was observed free")
    return out
