"""Output-directory safety: `run --force` and `batch` replace only sonarmap's own outputs —
never an input, the working directory or the user's files — a batch never deletes another
live batch's staging, dead staging is cleaned, and SIGTERM cleans up like Ctrl-C."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from fuzz.harness import ROOT

OFFICE = ROOT / "sample_logs" / "office"


def _tree(d: Path) -> dict[str, bytes]:
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_batch_into_the_parent_of_its_inputs_keeps_the_inputs(tmp_path: Path) -> None:
    """The issue's command: a ROS 2 bag directory and a CSV set, -o their parent."""
    logs = tmp_path / "logs"
    shutil.copytree(OFFICE / "office_ros2", logs / "office_ros2")
    shutil.copytree(OFFICE / "office_csv", logs / "office_csv")
    before = _tree(logs)
    res = CliRunner().invoke(app, ["batch", str(logs / "office_ros2"), str(logs / "office_csv"),
                                   "-o", str(logs), "--workers", "1", "-q"])
    assert res.exit_code == 1
    failures = res.stderr.strip().splitlines()
    assert failures == [
        f"sonarmap: failed: {n}: {logs / n}: is or contains the input {logs / n}; not "
        "replacing it, choose another output directory" for n in ("office_csv", "office_ros2")
    ]
    after = _tree(logs)
    assert {k: v for k, v in after.items() if not k.startswith("summary.")} == before


def test_run_force_never_replaces_the_inputs_directory_or_the_cwd(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    t = tmp_path / "t"
    t.mkdir()
    log = t / "office.mcap"
    shutil.copy(OFFICE / "office.mcap", log)
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(t), "-q", "--force"])
    assert res.exit_code == 1
    assert res.stderr == (f"sonarmap: error: {t}: is or contains the input {log}; not "
                          "replacing it, choose another output directory\n")
    assert log.read_bytes() == (OFFICE / "office.mcap").read_bytes()
    cwd = tmp_path / "work"
    cwd.mkdir()
    (cwd / "thesis.tex").write_text("mine")
    monkeypatch.chdir(cwd)
    res = CliRunner().invoke(app, ["run", str(log), "-o", "../work", "-q", "--force"])
    assert res.exit_code == 1 and "is or contains the working directory" in res.stderr
    assert (cwd / "thesis.tex").read_text() == "mine"


def test_batch_keeps_live_staging_and_removes_dead_staging_even_when_skipping(
    tmp_path: Path,
) -> None:
    """A second batch on the same OUT must not delete a live batch's staging (its process
    is alive); staging of dead processes goes, even for logs that are skipped."""
    log = tmp_path / "office.mcap"
    shutil.copy(OFFICE / "office.mcap", log)
    out = tmp_path / "out"
    args = ["batch", str(log), "-o", str(out), "--workers", "1", "-q"]
    assert CliRunner().invoke(app, args).exit_code == 0
    dead, live = _dead_pid(), os.getpid()
    stale = [out / f".office.tmp-{dead}-0123abcd", out / f".office.run-{dead}-0123abcd",
             out / f"..office.run-{dead}-0123abcd.tmp-{dead}-89abcdef",
             out / f".other.tmp-{dead}-0123abcd"]
    busy = [out / f".office.tmp-{live}-89abcdef", out / f".office.run-{live}-89abcdef"]
    for d in stale + busy:
        d.mkdir()
        (d / "map.pgm").write_bytes(b"P5")
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert [d for d in stale if d.exists()] == []
    assert all((d / "map.pgm").is_file() for d in busy)


def test_sigterm_on_run_leaves_no_temporary_directory(tmp_path: Path) -> None:
    out = tmp_path / "OUT"
    proc = subprocess.Popen(
        [sys.executable, "-m", "cli", "run", str(OFFICE / "office.mcap"), "-o", str(out), "-q"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 60
    while not any(p.name.startswith(".OUT.tmp-") for p in tmp_path.iterdir()):
        assert proc.poll() is None and time.monotonic() < deadline, "run never started"
        time.sleep(0.02)
    time.sleep(0.5)  # well inside the run (reading, mapping)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143
    assert err.decode().strip() == "sonarmap: terminated"
    assert list(tmp_path.iterdir()) == []
