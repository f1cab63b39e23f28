"""Issue 58 for ``regress --suite``: a golden directory obeys the ownership rule of every
sonarmap output (formats/writers/output_marker.py) — ``--update`` never replaces or
deletes what sonarmap did not write — and golden and suite files are hostile side files,
read within a bound, never blocking on a FIFO."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from formats.writers.output_marker import MAX_PROOF_BYTES, OUTPUT_MARKER
from pipeline.tools.suite.golden_dir import GOLDEN_MARKER, golden_refusal, same_golden

ROOT = Path(__file__).resolve().parents[4]
FILES = ["config.toml", "map.pgm", "map.yaml", "metrics.json"]


def _golden(d: Path, writer: str = "sonarmap regress --update",
            marker: str = GOLDEN_MARKER) -> Path:
    d.mkdir(parents=True)
    for name in FILES:
        (d / name).write_text(name)
    (d / marker).write_text(json.dumps({"written_by": writer, "files": FILES}))
    return d


def _fifo(p: Path) -> Path:
    os.mkfifo(p)
    return p


@pytest.mark.parametrize(("make", "reason"), [
    (lambda d: _golden(d, writer="my script"), "has no .sonarmap-golden"),
    (lambda d: (d.mkdir(), _fifo(d / GOLDEN_MARKER), (d / "metrics.json").write_text("{}")),
     "has no .sonarmap-golden"),
    (lambda d: (d.mkdir(), (d / GOLDEN_MARKER).write_bytes(b" " * (MAX_PROOF_BYTES + 1)
                                                          + b'{"written_by": "sonarmap'
                                                            b' regress --update",'
                                                            b' "files": []}')),
     "has no .sonarmap-golden"),
    (lambda d: (_golden(d), (d / "sub").mkdir(), (d / "sub" / "notes.txt").write_text("x")),
     "holds files sonarmap did not write (sub/notes.txt)"),
    (lambda d: (_golden(d), (d / "link").symlink_to(d.parent)),
     "holds a symlinked directory"),
    (lambda d: (d.mkdir(), (d / "metrics.json").write_text('{"acc": 0.9}'),
                (d / "map.yaml").write_text("mine")), "has no .sonarmap-golden"),
])
def test_update_refuses_what_sonarmap_cannot_prove_it_wrote(tmp_path: Path, make,
                                                            reason: str) -> None:
    d = tmp_path / "goldens" / "office"
    d.parent.mkdir()
    make(d)
    assert (golden_refusal(d) or "").startswith(reason)


def test_a_golden_or_any_sonarmap_output_is_replaceable(tmp_path: Path) -> None:
    assert golden_refusal(_golden(tmp_path / "a")) is None
    assert golden_refusal(_golden(tmp_path / "b", "sonarmap", OUTPUT_MARKER)) is None


def test_an_old_golden_file_that_is_a_fifo_is_not_read(tmp_path: Path) -> None:
    new, old = _golden(tmp_path / "new"), _golden(tmp_path / "old")
    (old / "map.pgm").unlink()
    _fifo(old / "map.pgm")  # would block a plain read forever
    assert not same_golden(new, old)
    (old / "map.pgm").unlink()
    (old / "map.pgm").write_text("map.pgm" + "x" * 100)  # longer: read only to new's length
    assert not same_golden(new, old)


SUITE = '''[[log]]
name = "slow"
path = "logs/slow-odometry"
'''


@pytest.fixture
def project(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    shutil.copytree(ROOT / "sample_logs" / "slow-odometry", tmp_path / "logs" / "slow-odometry")
    (tmp_path / "regress.toml").write_text(SUITE)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _regress(*args: str) -> tuple[int, str, str]:
    res = CliRunner().invoke(app, ["regress", "--workers", "1", "-q", *args])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res.exit_code, res.stdout, res.stderr


def test_update_leaves_a_users_directory_under_goldens_alone(project: Path) -> None:
    user = project / "goldens" / "slow"
    user.mkdir(parents=True)
    (user / "metrics.json").write_text('{"acc": 0.9}\n')  # sonarmap's names, not its files
    (user / "map.yaml").write_text("my map\n")
    code, out, _ = _regress("--suite", "regress.toml", "--goldens", "goldens", "--update")
    assert code == 1
    assert "has no .sonarmap-golden" in out
    assert sorted(p.name for p in user.iterdir()) == ["map.yaml", "metrics.json"]
    assert (user / "metrics.json").read_text() == '{"acc": 0.9}\n'


@pytest.mark.parametrize(("text", "message"), [
    ('[[log]]\nname = "slow"\npath = "logs/slow\\u0000odometry"\n',
     "log 'slow' (entry 1): path 'logs/slow\\x00odometry' contains a NUL byte"),
    (f'[[log]]\nname = "slow"\npath = "{"p" * 300}"\n', "has a name of 300 bytes"),
])
def test_a_suite_path_the_os_cannot_take_is_one_line(project: Path, text: str,
                                                     message: str) -> None:
    (project / "bad.toml").write_text(text)
    code, _, err = _regress("--suite", "bad.toml", "--goldens", "goldens", "--update")
    assert code == 1
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (project / "goldens").exists() or not any((project / "goldens").iterdir())


def test_a_suite_file_that_is_a_fifo_is_refused_without_blocking(project: Path) -> None:
    _fifo(project / "fifo.toml")
    code, _, err = _regress("--suite", "fifo.toml", "--goldens", "goldens")
    assert code == 1
    assert err == "sonarmap: error: fifo.toml: suite file is a FIFO, not a regular file\n"
