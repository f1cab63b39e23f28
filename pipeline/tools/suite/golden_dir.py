"""A golden directory: what it keeps, the marker that makes it ours, its replacement.

A golden keeps what ``regress`` compares and nothing a rerun would not reproduce:
``metrics.json`` (without ``timing``), ``map.yaml``, ``map.pgm``, ``config.toml`` (the
log's configuration as the suite gives it) and, for a log with a truth, ``evaluation.json``
(its ``run_dir`` the golden's own path) — plus :data:`GOLDEN_MARKER`, a JSON list of those
files. ``--update`` replaces only what the ownership rule of every sonarmap output proves
sonarmap wrote (:mod:`formats.writers.output_marker`: the marker, read within a bound, and
nothing but the files it lists); any other directory under ``--goldens`` is left as it is
(its row fails). An old golden is read within a bound (:func:`same_golden`).

Replacement is atomic: the new golden is written and fsynced in a hidden sibling
``.<name>.tmp-<pid>-<hex>``, then exchanged with the old one in one step
(:func:`formats.writers.dir_swap.exchange`), or, where the system cannot, renamed aside
(``.<name>.old-<pid>-<hex>``) and the new one renamed in; :func:`recover_goldens` puts an
old golden back when a kill fell between those two renames. A kill at any point leaves
each golden old or new. A new golden that is byte for byte the old one is not rewritten.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import shutil
from pathlib import Path
from typing import Any

from formats.errors import OutputError, SonarmapError
from formats.text_file import read_bounded
from formats.writers.atomic import clean_stale_entries, fsync_path
from formats.writers.dir_swap import exchange
from formats.writers.output_marker import GOLDEN_MARKER, not_replaceable_reason, written_files_in

__all__ = [
    "GOLDEN_FILES",
    "GOLDEN_MARKER",
    "alive",
    "golden_refusal",
    "recover_goldens",
    "replace_golden",
    "same_golden",
    "stage_golden",
]

GOLDEN_FILES = ("metrics.json", "map.yaml", "map.pgm", "config.toml")
EVALUATION = "evaluation.json"
_OLD = re.compile(r"\.(?P<name>.+)\.old-(?P<pid>\d+)-[0-9a-f]{8}")


def _json_text(data: dict[str, Any]) -> str:
    return json.dumps(data, indent=2) + "\n"


def golden_refusal(d: Path) -> str | None:
    """None when ``--update`` may write ``d``: absent, or a directory sonarmap can prove it
    wrote holding only what it wrote (the ownership rule of every output,
    :func:`formats.writers.output_marker.not_replaceable_reason`: a marker read within a
    bound, no symlinked directory); else why not, as a phrase for the row's reason."""
    if d.is_symlink():
        return "is a symlink"
    if not d.exists():
        return None
    if not d.is_dir():
        return "is not a directory"
    reason = not_replaceable_reason(d)
    if reason == "is not a sonarmap output":
        return (f"has no {GOLDEN_MARKER} (not a golden sonarmap wrote: remove it once to let "
                "--update write it)")
    return reason


def stage_golden(run_dir: Path, staged: Path, config_text: str,
                 evaluation: dict[str, Any] | None) -> None:
    """Write the golden of ``run_dir`` into the new directory ``staged`` (on the worker)."""
    staged.mkdir(parents=True)
    metrics = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    metrics.pop("timing", None)  # no wall times: a golden holds what reruns reproduce
    (staged / "metrics.json").write_text(_json_text(metrics), encoding="utf-8")
    for name in ("map.yaml", "map.pgm"):
        shutil.copyfile(run_dir / name, staged / name)
    (staged / "config.toml").write_text(config_text, encoding="utf-8")
    files = list(GOLDEN_FILES)
    if evaluation is not None:
        (staged / EVALUATION).write_text(_json_text(evaluation), encoding="utf-8")
        files.append(EVALUATION)
    marker = {"written_by": "sonarmap regress --update", "files": sorted(files)}
    (staged / GOLDEN_MARKER).write_text(_json_text(marker), encoding="utf-8")


def same_golden(staged: Path, final: Path) -> bool:
    """Whether ``final`` holds exactly the files of ``staged``, byte for byte."""
    if not final.is_dir():
        return False
    names = {p.name for p in staged.iterdir()}
    if names != {p.name for p in final.iterdir()}:
        return False
    for n in names:
        ours = (staged / n).read_bytes()
        try:  # the old golden's file: bounded, a regular file (never blocks on a FIFO)
            theirs = read_bounded(final / n, "golden file", len(ours))
        except SonarmapError:
            return False
        if theirs != ours:
            return False
    return True


def _sibling(final: Path, tag: str) -> Path:
    return final.parent / f".{final.name}.{tag}-{os.getpid()}-{secrets.token_hex(4)}"


def replace_golden(staged: Path, final: Path) -> None:
    """Put the files of ``staged`` under ``final`` atomically (see the module docstring).
    The caller has checked :func:`golden_refusal`; it is checked again here."""
    reason = golden_refusal(final)
    if reason is not None:
        raise OutputError(f"{reason}; not replacing it", final)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = _sibling(final, "tmp")
    try:
        tmp.mkdir()
        for src in sorted(staged.iterdir()):
            shutil.copyfile(src, tmp / src.name)
            fsync_path(tmp / src.name)
        fsync_path(tmp)
        if not final.exists():
            os.rename(tmp, final)
        elif exchange(tmp, final):
            shutil.rmtree(tmp)  # now the old golden
        else:
            old = _sibling(final, "old")
            os.rename(final, old)
            os.rename(tmp, final)  # a kill before this line: recover_goldens puts old back
            shutil.rmtree(old)
    except OSError as err:
        if tmp.exists() and final.exists():
            shutil.rmtree(tmp, ignore_errors=True)
        raise OutputError(f"cannot write the golden: {err.strerror or err}", final) from err
    with contextlib.suppress(OSError):
        fsync_path(final.parent)


def recover_goldens(goldens: Path) -> list[Path]:
    """Before an update: put back each old golden a killed update left renamed aside
    (its new one not yet in place), then remove dead updates' staging. Returns the
    goldens put back."""
    restored: list[Path] = []
    with contextlib.suppress(OSError):
        for p in sorted(goldens.iterdir()):
            m = _OLD.fullmatch(p.name)
            if m is None or not p.is_dir() or p.is_symlink():
                continue
            final = goldens / m["name"]
            if (not final.exists() and written_files_in(p) is not None
                    and not alive(int(m["pid"]))):
                os.rename(p, final)
                restored.append(final)
    clean_stale_entries(goldens)
    return restored


def alive(pid: int) -> bool:
    """Whether a process with this id exists on this host (unsure: yes)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True
