"""Readers never write next to their input: a rosbag2 sqlite3 bag is opened read-only and
immutable (no ``-shm``/``-wal`` files appear), and a bag on read-only storage is readable."""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from test_ros2_fixture_bags import PY
from typer.testing import CliRunner

from cli.app import app

ROOT = Path(__file__).resolve().parents[3]


def _copy_talker(ros2_fixtures: Path, dest: Path) -> Path:
    """The sqlite3 talker bag (a WAL-mode database) as rosbag2 leaves it when closed: the
    fixture ships sqlite's -shm/-wal side files, which are left out of the copy."""
    shutil.copytree(ros2_fixtures / PY / "sqlite3" / "talker", dest,
                    ignore=shutil.ignore_patterns("*-shm", "*-wal"))
    assert _files(dest) == ["metadata.yaml", "talker.db3"]
    return dest


def _files(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir())


@contextlib.contextmanager
def _read_only(d: Path) -> Iterator[None]:
    """``d`` and its files unwritable, even for root (the immutable attribute), as on an
    archive mount; skips when the file system cannot make it so."""
    modes = {p: p.stat().st_mode for p in [d, *d.iterdir()]}
    for p, m in modes.items():
        p.chmod(m & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    immutable = False
    try:
        if os.geteuid() == 0:
            res = subprocess.run(["chattr", "+i", str(d)], capture_output=True, check=False)
            if res.returncode != 0:
                pytest.skip("cannot make a directory read-only for root here (chattr)")
            immutable = True
        try:
            (d / "probe").touch()
        except OSError:
            pass
        else:
            pytest.skip("the directory is still writable")
        yield
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(d)], check=False)
        for p, m in modes.items():
            p.chmod(m)


def test_info_and_run_leave_no_sqlite_side_files(ros2_fixtures: Path, tmp_path: Path) -> None:
    bag = _copy_talker(ros2_fixtures, tmp_path / "talker")
    before = _files(bag)
    for cmd in ("info", "validate"):  # whole processes: sqlite's files outlive a connection
        subprocess.run([sys.executable, "-m", "cli", cmd, str(bag)], cwd=ROOT,
                       capture_output=True, check=False, timeout=120)
        assert _files(bag) == before  # no talker.db3-shm / talker.db3-wal


def test_bag_on_read_only_storage_is_readable(ros2_fixtures: Path, tmp_path: Path) -> None:
    bag = _copy_talker(ros2_fixtures, tmp_path / "talker")
    before = _files(bag)
    with _read_only(bag):
        res = CliRunner().invoke(app, ["info", str(bag), "--json"])
        assert res.exit_code == 0, res.output
        assert '"message_count": 20' in res.output
    assert _files(bag) == before
