"""Issue 58, items 7, 8, 11 and 12: a batch's directory walk ends on symlink loops and finds
each log once; a directory it cannot list is a skipped row with its reason; logs inside
``-o`` are mapped, never skipped in silence; a memory limit no worker can start under is
refused at once instead of waiting forever."""

from __future__ import annotations

import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from cli.app import app
from fuzz.harness import ROOT
from pipeline.config import Config
from pipeline.tools.batch import Unread, find_logs

OFFICE = ROOT / "sample_logs" / "office"


def test_symlink_loops_end_and_each_log_is_found_once(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    (logs / "a" / "b").mkdir(parents=True)
    shutil.copy(OFFICE / "office.mcap", logs / "a")
    (logs / "a" / "b" / "up").symlink_to("..")  # a loop
    (logs / "again").symlink_to("a")  # the same directory twice
    (logs / "self").symlink_to(".")
    (logs / "same.mcap").symlink_to(logs / "a" / "office.mcap")
    (logs / "dangling").symlink_to("nowhere")
    found = find_logs([logs, logs / "again"], Config())
    assert found == [logs / "a" / "office.mcap"]


def _unlistable(monkeypatch: pytest.MonkeyPatch, locked: Path) -> None:
    """``locked`` cannot be listed (root reads any directory: the refusal is simulated)."""
    real = Path.iterdir

    def iterdir(self: Path):  # type: ignore[no-untyped-def]
        if self == locked:
            raise PermissionError(13, "Permission denied", str(self))
        return real(self)

    monkeypatch.setattr(Path, "iterdir", iterdir)


def test_an_unreadable_subdirectory_is_listed_with_its_reason(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    logs = tmp_path / "logs"
    (logs / "locked").mkdir(parents=True)
    shutil.copy(OFFICE / "office.mcap", logs)
    _unlistable(monkeypatch, logs / "locked")
    unread: list[Unread] = []
    assert find_logs([logs], Config(), unread=unread) == [logs / "office.mcap"]
    assert unread == [Unread(logs / "locked", "cannot list directory: Permission denied")]


def test_logs_in_the_output_directory_are_mapped_and_unread_ones_listed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``batch logs -o logs/sub``: the user's log in logs/sub is mapped; a directory that
    cannot be listed is a skipped row with its reason, on stderr and in the summary."""
    logs = tmp_path / "logs"
    (logs / "sub").mkdir(parents=True)
    (logs / "locked").mkdir()
    shutil.copy(OFFICE / "office.mcap", logs / "sub" / "inside.mcap")
    _unlistable(monkeypatch, logs / "locked")
    res = CliRunner().invoke(app, ["batch", str(logs), "-o", str(logs / "sub"), "--workers",
                                   "1"])
    assert res.exit_code == 0, res.output
    assert res.stderr.splitlines()[-1] == (
        f"sonarmap: skipped: {logs / 'locked'}: cannot list directory: Permission denied")
    assert res.stdout.startswith("2 logs: 1 mapped, 0 skipped (unchanged), 0 failed, "
                                 "1 directories not read;")
    rows = pq.read_table(logs / "sub" / "summary.parquet").to_pylist()
    assert [(r["path"], r["status"], r["error"]) for r in rows] == [
        (str(logs / "locked"), "skipped", "cannot list directory: Permission denied"),
        (str(logs / "sub" / "inside.mcap"), "ok", None),
    ]
    assert (logs / "sub" / "inside" / "map.pgm").is_file()
    # Again: the output it wrote there is not taken for logs.
    res = CliRunner().invoke(app, ["batch", str(logs / "sub"), "-o", str(logs / "sub"),
                                   "--workers", "1", "-q"])
    assert res.exit_code == 0, res.output
    rows = pq.read_table(logs / "sub" / "summary.parquet").to_pylist()
    assert [(r["name"], r["status"]) for r in rows] == [("inside", "skipped")]


@pytest.mark.parametrize("limit", ["100MB", "1", "511MiB"])
def test_a_memory_limit_below_a_workers_baseline_is_refused(tmp_path: Path, limit: str) -> None:
    res = CliRunner().invoke(app, ["batch", str(OFFICE / "office.mcap"), "-o",
                                   str(tmp_path / "o"), "--workers", "1", "--memory-limit", limit])
    assert res.exit_code == 1
    assert res.stderr.count("\n") == 1
    assert "is below what a worker holds before its first log; give at least 512.00 MiB (or auto)" in res.stderr


def test_workers_that_can_never_run_a_log_fail_the_rows_instead_of_hanging(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Past the floor (a machine whose workers hold more): the batch's watch fails the logs
    left, with the reason, once no worker could run one for STALL_S."""
    import pipeline.tools.batch as batch

    monkeypatch.setattr(batch, "MIN_MEMORY_LIMIT", 0)
    monkeypatch.setattr(batch, "STALL_S", 4.0)
    res = batch.run_batch([OFFICE / "office.mcap"], tmp_path / "o", None, workers=1,
                          memory_limit="150MB")
    [row] = res.outcomes
    assert row.status == "failed"
    assert row.error is not None and row.error.startswith("no Dask worker")
    assert row.error.endswith(("(killed at its memory limit?)", "give a larger --memory-limit"))


def test_a_quiet_batch_says_nothing_in_a_fresh_process(tmp_path: Path) -> None:
    """Dask's own INFO lines stay out of stderr (its import must not reset the level)."""
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-m", "cli", "batch", str(OFFICE / "office.mcap"),
                          "-o", str(tmp_path / "o"), "--workers", "1", "-q"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and res.stderr == "" and res.stdout == ""
