"""What sonarmap may replace: only what it can prove it wrote (docs/OUTPUTS.md).

A directory is sonarmap's output when it holds ``.sonarmap-output`` — a JSON object
``{"written_by": "sonarmap", "files": [...]}`` listing every file the run wrote (relative
POSIX paths, sorted: deterministic bytes); a regression golden's ``.sonarmap-golden`` says
``"written_by": "sonarmap regress --update"`` — or, for outputs written before the marker
existed, when its content says sonarmap wrote it: ``metrics.json`` whose ``run`` holds a
``tool_version`` and a ``config_hash``, or ``features.parquet`` whose schema metadata holds
``tool_version``, ``config_hash`` and ``units``. File names alone prove nothing. Such a
directory may be replaced (``run --force``, a batch re-mapping a log) only when it holds
nothing but what sonarmap wrote (the marker's list, or a run's file names).

A single file (``evaluate -o``, a batch's ``summary.md``/``summary.parquet``) may be replaced
only when its content is sonarmap's of that kind (:func:`stamped`).

The rule works on a listing of names and a reader of byte ranges (:data:`ReadRange`), so
the same function judges a local directory (:func:`not_replaceable_reason`) and any other
store of named files (an object-storage prefix). Every read is bounded: a file that does not
fit :data:`MAX_PROOF_BYTES` proves nothing.
"""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

__all__ = [
    "GOLDEN_MARKER",
    "MAX_PROOF_BYTES",
    "OUTPUT_MARKER",
    "ReadRange",
    "is_run_output",
    "local_reader",
    "not_replaceable_file_reason",
    "not_replaceable_reason",
    "ownership_reason",
    "stamped",
    "write_output_marker",
    "written_files",
    "written_files_in",
]

OUTPUT_MARKER = ".sonarmap-output"
#: A regression golden's marker (``sonarmap regress --update``): the same proof, its own
#: name and writer (goldens kept their bytes when the rule became one).
GOLDEN_MARKER = ".sonarmap-golden"
# Each marker's file name and the ``written_by`` it must say.
_MARKERS = ((OUTPUT_MARKER, "sonarmap"), (GOLDEN_MARKER, "sonarmap regress --update"))

#: ``read(name, offset, length)``: ``length`` bytes of file ``name`` from ``offset`` (a
#: negative offset counts from the end, like HTTP's ``Range: bytes=-N``); fewer at the end
#: of the file; None when it cannot be read or is not a regular file.
ReadRange = Callable[[str, int, int], bytes | None]

#: At most this many bytes are read from one file to prove who wrote it (a marker,
#: metrics.json, a Parquet footer, an evaluation JSON).
MAX_PROOF_BYTES = 4 << 20

# Every file a run or a batch log's directory has held (before the marker existed too).
RUN_FILES = frozenset({
    "map.pgm", "map.yaml", "map.png", "map_no_correction.png", "map.mcap", "features.parquet",
    "metrics.json", "config.toml", "report.html", "report.md", "trajectory.csv",
    "odometry.csv", "trajectory.png", ".sonarmap-done.json",
})
_MAX_LISTED = 3  # unknown files named in a refusal
# The kinds of file whose content proves sonarmap wrote them, by the name a run gives them.
_KIND_OF_NAME = {"metrics.json": "metrics", "features.parquet": "features",
                 "summary.md": "summary_md", "summary.parquet": "summary_parquet"}
SUMMARY_MD_TITLE = "# sonarmap batch summary"
_SUMMARY_COLUMNS = ("path", "name", "status", "error")  # a batch summary's first columns
_EVALUATION_KEYS = frozenset({"run_dir", "truth", "reach_source", "recall_scope",
                              "precision", "recall", "f1", "run_occupied_matched"})


# --------------------------------------------------------------------------- the rule


def written_files(names: Collection[str], read: ReadRange) -> frozenset[str] | None:
    """Which of ``names`` (a directory's files, relative POSIX paths) sonarmap wrote, when
    something proves the directory is its output; None when nothing does."""
    present = frozenset(names)
    for marker, writer in _MARKERS:
        if marker in present:
            listed = _marker_listing(read(marker, 0, MAX_PROOF_BYTES), writer)
            if listed is not None:
                return present & (listed | {marker})
    if any(n in present and stamped(_KIND_OF_NAME[n], n, read)
           for n in ("metrics.json", "features.parquet")):
        return present & RUN_FILES
    return None


def ownership_reason(names: Collection[str], read: ReadRange) -> str | None:
    """None when the directory of ``names`` is a sonarmap output holding only what sonarmap
    wrote, else why it must not be replaced (a phrase: "<dir> <phrase>")."""
    written = written_files(names, read)
    if written is None:
        return "is not a sonarmap output"
    unknown = sorted(set(names) - written)
    if unknown:
        shown = ", ".join(unknown[:_MAX_LISTED]) + (", ..." if len(unknown) > _MAX_LISTED else "")
        return f"holds files sonarmap did not write ({shown})"
    return None


def stamped(kind: str, name: str, read: ReadRange) -> bool:
    """Whether file ``name`` holds what sonarmap writes as ``kind``: "metrics",
    "features", "summary_md", "summary_parquet" or "evaluation"."""
    if kind == "metrics":
        run = _json(read(name, 0, MAX_PROOF_BYTES)).get("run")
        return (isinstance(run, dict) and isinstance(run.get("tool_version"), str)
                and isinstance(run.get("config_hash"), str))
    if kind == "evaluation":
        return set(_json(read(name, 0, MAX_PROOF_BYTES))) >= _EVALUATION_KEYS
    if kind == "summary_md":
        head = read(name, 0, len(SUMMARY_MD_TITLE) + 2) or b""
        return head.split(b"\n", 1)[0].rstrip(b"\r") == SUMMARY_MD_TITLE.encode()
    schema = _parquet_schema(name, read) if kind in ("features", "summary_parquet") else None
    if schema is None:
        return False
    if kind == "features":
        meta = schema.metadata or {}
        return all(k in meta for k in (b"tool_version", b"config_hash", b"units"))
    return tuple(schema.names[: len(_SUMMARY_COLUMNS)]) == _SUMMARY_COLUMNS


def _json(data: bytes | None) -> dict[str, Any]:
    try:
        out = json.loads(data or b"")
    except (ValueError, RecursionError):
        return {}
    return out if isinstance(out, dict) else {}


def _marker_listing(data: bytes | None, writer: str) -> frozenset[str] | None:
    d = _json(data)
    files = d.get("files")
    if d.get("written_by") != writer or not isinstance(files, list):
        return None
    if not all(isinstance(f, str) for f in files):
        return None
    return frozenset(files)


def _parquet_schema(name: str, read: ReadRange) -> Any:
    """The Arrow schema in a Parquet file's footer (read alone: two bounded range reads),
    or None."""
    tail = read(name, -8, 8)
    if tail is None or len(tail) != 8 or tail[4:] != b"PAR1":
        return None
    size = int.from_bytes(tail[:4], "little")
    if not 0 < size <= MAX_PROOF_BYTES:
        return None
    footer = read(name, -(8 + size), size)
    if footer is None or len(footer) != size:
        return None
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        # The footer is self-contained: a file of just it has the same metadata.
        return pq.read_schema(pa.BufferReader(b"PAR1" + footer + tail))
    except (pa.ArrowException, OSError, ValueError):
        return None


# --------------------------------------------------------------------------- local files


def local_reader(root: Path) -> ReadRange:
    """A :data:`ReadRange` over the regular files under ``root`` (devices, FIFOs and
    directories read as None, without blocking)."""

    def read(name: str, offset: int, length: int) -> bytes | None:
        try:
            fd = os.open(root / name, os.O_RDONLY | os.O_NONBLOCK)
        except (OSError, ValueError):
            return None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                return None
            start = max(0, st.st_size + offset) if offset < 0 else offset
            return os.pread(fd, max(0, min(length, MAX_PROOF_BYTES)), start)
        except OSError:
            return None
        finally:
            os.close(fd)

    return read


def _files_under(root: Path) -> set[str] | None:
    """Relative POSIX paths of every non-directory entry under ``root``; None when a
    subdirectory is a symlink (then nothing is replaced). OSError when one cannot be
    listed."""
    out: set[str] = set()
    for dirpath, dirnames, filenames in os.walk(root, onerror=_raise):
        base = Path(dirpath)
        for d in dirnames:
            if (base / d).is_symlink():
                return None
        for f in filenames:
            out.add((base / f).relative_to(root).as_posix())
    return out


def _raise(err: OSError) -> None:
    raise err


def write_output_marker(tmp_dir: Path) -> None:
    """List every file of the finished ``tmp_dir`` in its marker (called before commit)."""
    files = _files_under(tmp_dir) or set()
    files.discard(OUTPUT_MARKER)
    text = json.dumps({"written_by": "sonarmap", "files": sorted(files)}, indent=1) + "\n"
    (tmp_dir / OUTPUT_MARKER).write_text(text, encoding="utf-8")


def not_replaceable_reason(d: Path) -> str | None:
    """:func:`ownership_reason` of local directory ``d`` (a phrase, or None)."""
    try:
        present = _files_under(d)
    except OSError as err:
        return f"cannot be listed ({err.strerror or err})"
    if present is None:
        return "holds a symlinked directory"
    return ownership_reason(present, local_reader(d))


def written_files_in(d: Path) -> frozenset[str] | None:
    """:func:`written_files` of local directory ``d`` (None also when it cannot be listed)."""
    try:
        present = _files_under(d)
    except OSError:
        return None
    return None if present is None else written_files(present, local_reader(d))


def is_run_output(d: Path) -> bool:
    """Whether ``d`` is a directory something proves sonarmap wrote (marker or content)."""
    if not d.is_dir() or d.is_symlink():
        return False
    return written_files_in(d) is not None


def not_replaceable_file_reason(path: Path, kind: str) -> str | None:
    """None when the existing file ``path`` is sonarmap's ``kind`` (:func:`stamped`), else
    why it must not be replaced (a phrase)."""
    try:
        st = path.lstat()
    except OSError as err:
        return f"cannot be examined ({err.strerror or err})"
    if stat.S_ISLNK(st.st_mode):
        return "is a symlink"
    if not stat.S_ISREG(st.st_mode):
        return "is not a regular file"
    if not stamped(kind, path.name, local_reader(path.parent)):
        return "exists and sonarmap did not write it"
    return None
