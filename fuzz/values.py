"""Hostile values, not hostile bytes: configurations and small logs carrying non-finite,
zero, negative, tiny and absurd numbers (config keys, beam widths and limits from the
log, pose glitches, every range at max range).

Property (:func:`check_config`, :func:`check_log`): the configuration loads or is refused
with one ConfigError line; the run maps (the output complete) or is refused with one
SonarmapError line and leaves no output — never another exception, a traceback, a grid
beyond ``grid.max_cells``, or an output with nothing mapped.
"""

from __future__ import annotations

import dataclasses
import math
import random
import traceback
from pathlib import Path
from typing import Any

from fuzz.harness import Outcome

HOSTILE = (math.inf, -math.inf, math.nan, 0.0, -0.0, 1e-300, 1e-9, -1.0, 1e6, 1e300)
SCALAR_TYPES = (float, int)


def numeric_keys() -> list[tuple[str, str]]:
    """Every (section, key) of the configuration holding a number (top-level sections)."""
    from pipeline.config import Config

    out = []
    cfg = Config()
    for sec in dataclasses.fields(cfg):
        obj = getattr(cfg, sec.name)
        if not dataclasses.is_dataclass(obj):
            continue
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if isinstance(v, SCALAR_TYPES) and not isinstance(v, bool):
                out.append((sec.name, f.name))
    return out


def check_config(section: str, key: str, value: float) -> Outcome:
    """A configuration with one hostile number loads (finite, in range) or is refused."""
    from formats.errors import ConfigError
    from pipeline.config import config_from_dict

    try:
        cfg = config_from_dict({section: {key: value}})
    except ConfigError as err:
        line = str(err)
        if "\n" in line or key not in line:
            return Outcome("defect", f"config {section}.{key}={value!r}: unclear error {line!r}")
        return Outcome("rejected", line)
    except Exception as err:
        return Outcome("defect", f"config {section}.{key}={value!r}: {type(err).__name__}: {err}")
    got = getattr(getattr(cfg, section), key)
    if isinstance(got, float) and not math.isfinite(got):
        return Outcome("defect", f"config {section}.{key}={value!r}: accepted a non-finite value")
    return Outcome("ok")


def write_log(path: Path, rnd: random.Random) -> dict[str, Any]:
    """A small single-layout CSV log with hostile values drawn from ``rnd``; returns what
    was planted (for the defect report)."""
    def pick(normal: Any, hostile: tuple[Any, ...]) -> Any:
        return normal if rnd.random() < 0.6 else rnd.choice(hostile)  # mostly one at a time

    fov = pick(0.5, HOSTILE)
    lo = pick(0.1, (0.0, -1.0, math.nan, 5.0))
    hi = pick(5.0, (0.05, math.inf, math.nan, 1e6))
    glitch = pick(None, (2000.0, 1e9, -650.0))
    at_max = rnd.random() < 0.15
    n = 120
    rows = ["t,x,y,yaw,sensor,range,fov,min_range,max_range"]
    for i in range(n):
        x = glitch if glitch is not None and i == n // 2 else 0.02 * i
        r = 5.0 if at_max else 1.5 + 0.01 * (i % 5)
        rows.append(f"{0.05 * i:.3f},{x},0,0,s0,{r},{fov},{lo},{hi}")
    path.write_text("\n".join(rows) + "\n")
    return {"fov": fov, "min_range": lo, "max_range": hi, "glitch": glitch, "at_max": at_max}


def check_log(work: Path, rnd: random.Random, index: int) -> Outcome:
    """Map one hostile log: success with a complete output, or one SonarmapError line."""
    from formats.errors import SonarmapError
    from pipeline.config import config_from_dict
    from pipeline.run import run

    log = work / f"hostile-{index}.csv"
    planted = write_log(log, rnd)
    out = work / f"out-{index}"
    cfg = config_from_dict({"sensors": {"mounts": [{"name": "s0", "yaw_deg": 90.0}]},
                            "grid": {"resolution": 0.1}})
    try:
        result = run(log, out, cfg)
    except SonarmapError as err:
        if out.exists():
            return Outcome("defect", f"{planted}: refused but left {out.name}")
        return Outcome("rejected", str(err))
    except Exception as err:
        frame = traceback.extract_tb(err.__traceback__)[-1]
        return Outcome("defect", f"{planted}: {type(err).__name__}: {err} "
                                 f"({Path(frame.filename).name}:{frame.lineno})")
    counts = result.metrics.counts
    if counts["readings_mapped"] == 0:
        return Outcome("defect", f"{planted}: exit 0 with nothing mapped")
    if not (out / "map.pgm").is_file():
        return Outcome("defect", f"{planted}: output incomplete")
    return Outcome("ok", records=int(counts["readings_mapped"]))
