"""What went into a run: the log's path(s) as given, and ``metrics.json``'s input section.

A log is one file or bag directory, or one recording in several files (split bags,
separate sonar and odometry bags: :class:`formats.ros.multi_source.MultiSource`). The
input section names every file with its sha256 and span; for several files ``sha256``
is the hash of their hashes in time order, so naming the files in another order changes
nothing in a run's outputs.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from formats.contract import LogInfo
from formats.errors import OutputError, SonarmapError
from formats.storage.location import Location, Url, as_location, joined
from pipeline.stages.metrics import sha256_of


def log_paths(log: str | Location | Sequence[str | Location]) -> list[Location]:
    """The location(s) of a log as a list (one path or URL, or the files of one
    recording)."""
    if isinstance(log, str | Path | Url):
        return [as_location(log)]
    return [as_location(p) for p in log]


def files_sha256(paths: Sequence[Location]) -> str:
    """sha256 of a log's input: of its one file (or bag directory), or for several files
    :func:`hashes_sha256` of theirs — the same files named in any order (or moved) hash
    the same."""
    if len(paths) == 1:
        return sha256_of(paths[0])
    return hashes_sha256([sha256_of(p) for p in paths])


def hashes_sha256(hashes: Sequence[str]) -> str:
    """sha256 of several files' sha256 hex digests, sorted (independent of their order)."""
    return hashlib.sha256("".join(f"{h}\n" for h in sorted(hashes)).encode()).hexdigest()


def log_label(paths: Sequence[Location]) -> Location:
    """The log as messages name it: its path, or every file joined by `` + ``."""
    return paths[0] if len(paths) == 1 else joined(paths)


def log_name(names: Sequence[str]) -> str:
    """A short name for titles: ``a.bag``, ``a.bag + b.bag``, ``a_0.bag … a_9.bag (10 files)``."""
    if len(names) <= 3:
        return " + ".join(names)
    return f"{names[0]} … {names[-1]} ({len(names)} files)"


def input_section(paths: Sequence[Location], info: LogInfo, start_ns: int | None,
                  end_ns: int | None, max_range_m: float) -> dict[str, Any]:
    """``metrics.json`` → ``input``: path(s), sha256, format, duration, losses summed over
    the files (``bytes_lost``, ``messages_recovered``, one line per loss naming its file)."""
    section: dict[str, Any] = {}
    if len(paths) == 1:
        path = paths[0]
        section |= {"path": str(path), "name": path.name, "sha256": sha256_of(path)}
    else:
        files: list[dict[str, Any]] = []
        by_name = {str(p): p for p in paths}  # LogFile.path is str(location): redacted
        for f in info.files:  # in time order
            p = by_name.get(f.path) or as_location(f.path)
            files.append({
                "path": f.path, "name": p.name, "sha256": sha256_of(p),
                "start_ns": f.start_ns, "end_ns": f.end_ns, "messages": f.message_count,
            })
        joined = "".join(f"{f['sha256']}  {f['name']}\n" for f in files)
        section |= {
            "path": str(log_label([by_name.get(f.path) or as_location(f.path)
                                   for f in info.files])),
            "name": log_name([str(f["name"]) for f in files]),
            "sha256": hashlib.sha256(joined.encode()).hexdigest(),
        }
    section |= {
        "format": info.format,
        "duration_s": info.duration_s,
        "start_ns": start_ns,
        "end_ns": end_ns,
        "max_range_m": max_range_m,
        # A damaged log is mapped from its intact part; what was lost is recorded.
        "bytes_lost": info.bytes_lost,
        "messages_recovered": info.message_count if info.losses else None,
        "losses": list(info.losses),
    }
    if len(paths) > 1:
        section["files"] = files
        section["duplicates_read_once"] = info.duplicates_read_once
    return section


@contextmanager
def losses_named(info: Callable[[], LogInfo]) -> Iterator[None]:
    """An error raised while mapping a damaged log also says what was lost (the loss may
    be its cause: a lost chunk held the mounts, or most readings): its first loss, how
    many more, and the bytes lost."""
    try:
        yield
    except SonarmapError as err:
        if isinstance(err, OutputError) or "damaged" in err.reason:
            raise
        try:
            found = info()
        except SonarmapError:
            raise err from None
        if not found.losses:
            raise
        more = f" and {len(found.losses) - 1} more" if len(found.losses) > 1 else ""
        raise type(err)(
            f"{err.reason}; the log is damaged, {found.bytes_lost} bytes lost"
            f" ({found.losses[0]}{more})", err.path,
        ) from err
