"""A run killed with SIGKILL at a random moment leaves no output directory or a complete
one; the next run removes the temporary directories killed runs left behind."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from formats.errors import OutputError
from formats.writers.atomic import OutputDir, clean_stale_siblings
from fuzz.harness import ROOT

LOG = ROOT / "sample_logs" / "office" / "office.mcap"
FILES = {"map.pgm", "map.yaml", "map.png", "map.mcap", "trajectory.csv", "features.parquet",
         "metrics.json", "config.toml", "report.html", "report.md", ".sonarmap-output"}


def _start(out: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "cli", "run", str(LOG), "-o", str(out), "-q", "--force"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )


def _assert_absent_or_complete(out: Path) -> bool:
    if not out.exists():
        return False
    assert {p.name for p in out.iterdir()} == FILES
    json.loads((out / "metrics.json").read_text())
    assert (out / "map.pgm").read_bytes().startswith(b"P5")
    return True


def _dead_pid() -> int:
    """The id of a process that has exited (its slot free again)."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


@pytest.mark.skipif(not LOG.is_file(), reason="sample log missing")
def test_sigkill_at_random_moments(tmp_path: Path) -> None:
    """Runs with --force into one OUT, each killed at a seeded random moment (start-up,
    reading, mapping, writing, replacing); then one run that completes and cleans up.

    The moments are fractions of a complete run timed on this machine first, so that the
    kills land across the run on a fast laptop and on a loaded CI runner alike; the first
    is early enough that it always lands before the output is in place."""
    timed = tmp_path / "timed" / "OUT"
    timed.parent.mkdir()
    t0 = time.perf_counter()
    proc = _start(timed)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err.decode()
    whole = time.perf_counter() - t0
    rnd = random.Random(7)
    delays = [whole * f for f in (0.1, rnd.uniform(0.3, 0.7), rnd.uniform(0.7, 1.0))]
    out = tmp_path / "OUT"
    complete = 0
    for delay in delays:
        proc = _start(out)
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
        complete += _assert_absent_or_complete(out)
        leftovers = [p.name for p in tmp_path.iterdir() if p.name not in ("OUT", "timed")]
        assert all(n.startswith((".OUT.tmp-", ".OUT.old-")) for n in leftovers), leftovers
    assert complete < len(delays)  # at least one kill landed before the output was in place
    res = subprocess.run(
        [sys.executable, "-m", "cli", "run", str(LOG), "-o", str(out), "-q", "--force"],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
    )
    assert res.returncode == 0, res.stderr
    assert _assert_absent_or_complete(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["OUT", "timed"]  # stale ones removed


def test_stale_temp_siblings_of_dead_runs_are_removed(tmp_path: Path) -> None:
    final = tmp_path / "OUT"
    dead, live = _dead_pid(), os.getpid()
    stale = tmp_path / f".OUT.tmp-{dead}-0123abcd"
    busy = tmp_path / f".OUT.tmp-{live}-89abcdef"
    other = tmp_path / f".OTHER.tmp-{dead}-0123abcd"
    old = tmp_path / f".OUT.old-{dead}-00000000"
    for d in (stale, busy, other, old):
        d.mkdir()
        (d / "map.pgm").write_bytes(b"partial")
    assert clean_stale_siblings(final) == [stale]  # no OUT yet: the old copy is kept
    with OutputDir(final) as out:
        out.path("a.txt").write_text("x")
    assert (final / "a.txt").read_text() == "x"
    assert old.is_dir()
    assert clean_stale_siblings(final) == [old]  # a complete OUT exists: the copy is garbage
    assert busy.is_dir() and other.is_dir()  # a live run's and another name's are kept


def test_error_mid_run_leaves_nothing(tmp_path: Path) -> None:
    final = tmp_path / "OUT"
    with pytest.raises(OutputError, match="leads outside"), OutputDir(final) as out:
        out.path("map.pgm").write_bytes(b"P5")
        out.path("../escape.txt")
    assert sorted(p.name for p in tmp_path.iterdir()) == []
