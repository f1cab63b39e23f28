"""Damaged logs through ``sonarmap run`` and ``sonarmap info``: exit 1 with one line on
stderr and no traceback (or exit 0 when what survived is still a usable log)."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from fuzz.harness import ROOT, Target
from fuzz.mutators import Mutation, apply, random_mutation

FAMILY_TARGETS = {"ros1": "ros1-lz4", "ros2": "ros2-db3", "mcap": "mcap-zstd", "csv": "csv-single"}


def _sonarmap(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cli", *map(str, args)],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
    )


def _assert_one_line_error(stderr: str, name: str) -> None:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("sonarmap: error: "), stderr
    assert name in lines[0]
    assert "Traceback" not in stderr


def _broken(t: Target, kind: str, work: Path) -> Path:
    """A copy of the target damaged so that reading it must fail."""
    data = t.valid_bytes()
    if kind == "header":  # cut inside the container header / CSV header
        m = Mutation("truncate", offset=10)
    else:  # text in a numeric field (CSV) / zeros over every record (binary: a damaged
        # first record alone is skipped, the records after it read)
        m = (Mutation("row_field", index=3, field=2, text="abc") if t.text
             else Mutation("zero_run", offset=13 if t.walker != "sqlite" else 0,
                           length=len(data)))
    return t.materialize(work, apply(data, m))


@pytest.mark.parametrize("family", sorted(FAMILY_TARGETS))
def test_subprocess_run_and_info_fail_with_one_line(targets: dict[str, Target], family: str,
                                                     tmp_path: Path) -> None:
    t = targets[FAMILY_TARGETS[family]]
    for kind in ("header", "body"):
        log = _broken(t, kind, tmp_path / kind)
        out = tmp_path / f"out-{kind}"
        res = _sonarmap("run", log, "-o", out)
        assert res.returncode == 1, (kind, res.stdout, res.stderr)
        _assert_one_line_error(res.stderr, t.file.name)
        assert not out.exists()  # nothing half-written
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(f".out-{kind}")]
        if kind == "header":
            res = _sonarmap("info", log)
            assert res.returncode == 1, res.stdout
            _assert_one_line_error(res.stderr, t.file.name)


@pytest.mark.usefixtures("quiet_numpy")
@pytest.mark.parametrize("family", sorted(FAMILY_TARGETS))
def test_in_process_cli_on_random_mutations(targets: dict[str, Target], family: str,
                                            tmp_path: Path) -> None:
    """Seeded random mutations through the typer app: only exit 0 or a one-line exit 1."""
    runner = CliRunner()
    t = targets[FAMILY_TARGETS[family]]
    data, points = t.valid_bytes(), t.points()
    rnd = random.Random(f"cli-{family}")
    failed = 0
    for i in range(8):
        m = random_mutation(rnd, data, points, t.text)
        log = t.materialize(tmp_path / f"in{i}", apply(data, m))
        for args in (["info", str(log)], ["run", str(log), "-o", str(tmp_path / f"out{i}"), "-q"]):
            res = runner.invoke(app, args)
            assert res.exit_code in (0, 1), (m.describe(), args[0], res.output, res.exception)
            if res.exit_code == 1:
                failed += 1
                _assert_one_line_error(res.stderr, "")
            assert res.exception is None or isinstance(res.exception, SystemExit), (
                m.describe(), repr(res.exception))
    assert failed >= 1  # the damage is real for at least some of them
