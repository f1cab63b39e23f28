"""Which directories sonarmap may replace: only its own outputs, recognised by a marker.

Every output directory a run commits holds ``.sonarmap-output``: a JSON list of the files
the run wrote (relative POSIX paths, sorted, so the bytes are deterministic). A directory
may be replaced (``run --force``, a batch re-mapping a log) only when it holds that marker
and nothing but the files it lists, or, for outputs written before the marker existed,
only sonarmap's own output files with ``metrics.json`` and ``features.parquet`` among them.
Anything else — an input log, the user's files, the working directory — is refused.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

__all__ = [
    "OUTPUT_MARKER",
    "is_run_output",
    "not_replaceable_reason",
    "write_output_marker",
]

OUTPUT_MARKER = ".sonarmap-output"

# The files outputs held before the marker existed (a run's and a batch's resume marker).
_LEGACY_FILES = frozenset({
    "map.pgm", "map.yaml", "map.png", "map_no_correction.png", "features.parquet",
    "metrics.json", "config.toml", "report.html", "report.md", ".sonarmap-done.json",
})
_LEGACY_REQUIRED = frozenset({"metrics.json", "features.parquet"})
_MAX_LISTED = 3  # unknown files named in a refusal


def _files_under(root: Path) -> set[str] | None:
    """Relative POSIX paths of every non-directory entry under ``root``; None when a
    subdirectory is a symlink or cannot be listed (then nothing is replaced)."""
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


def _listed_files(d: Path) -> set[str] | None:
    try:
        data = json.loads((d / OUTPUT_MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    files = data.get("files") if isinstance(data, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return None
    return set(files)


def not_replaceable_reason(d: Path) -> str | None:
    """None when ``d`` is a sonarmap output holding only what sonarmap wrote into it, else
    why it must not be replaced (one phrase, for an error message)."""
    try:
        present = _files_under(d)
    except OSError as err:
        return f"cannot be listed ({err.strerror or err})"
    if present is None:
        return "holds a symlinked directory"
    listed = _listed_files(d)
    if listed is None:
        if not _LEGACY_REQUIRED.issubset(present):
            return "is not a sonarmap output"
        listed = set(_LEGACY_FILES)
    unknown = sorted(present - listed - {OUTPUT_MARKER})
    if unknown:
        shown = ", ".join(unknown[:_MAX_LISTED]) + (", ..." if len(unknown) > _MAX_LISTED else "")
        return f"holds files sonarmap did not write ({shown})"
    return None


def is_run_output(d: Path) -> bool:
    """Whether ``d`` is a directory a sonarmap run wrote (marker, or the legacy files)."""
    if not d.is_dir() or d.is_symlink():
        return False
    if (d / OUTPUT_MARKER).is_file():
        return True
    return all((d / f).is_file() for f in _LEGACY_REQUIRED)
