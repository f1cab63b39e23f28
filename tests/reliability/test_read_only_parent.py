"""Issue 58, messages that mislead: an output whose parent refuses new entries is reported
by the name the user gave (OUT), never by the hidden temporary sibling sonarmap creates
there; an OS error of a file the work *reads* is not reported as a write failure.

The tests run as root, for whom chmod denies nothing: the refusal is made by patching the
calls that create directories and files."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cli.app import app
from formats.writers import atomic
from fuzz.harness import ROOT

OFFICE = ROOT / "sample_logs" / "office"


def _cli(*args: str | Path) -> tuple[int, str]:
    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res.exit_code, res.stderr


@pytest.fixture
def denied(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A directory in which creating a directory or a file raises PermissionError."""
    parent = tmp_path / "read-only"
    parent.mkdir()
    real_mkdir, real_open = os.mkdir, open

    def mkdir(path: Any, *args: Any, **kwargs: Any) -> None:
        if str(path).startswith(str(parent)):
            raise PermissionError(13, "Permission denied", str(path))
        real_mkdir(path, *args, **kwargs)

    def open_(path: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        if "x" in mode and str(path).startswith(str(parent)):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, mode, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", mkdir)
    monkeypatch.setattr(atomic, "open", open_, raising=False)
    return parent


@pytest.mark.parametrize("where", ["out", "a/b/out"])
def test_run_names_out_when_its_parent_refuses(denied: Path, where: str) -> None:
    out = denied / where
    code, err = _cli("run", OFFICE / "office.mcap", "-o", out, "-q")
    assert code == 1
    lines = err.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith(f"sonarmap: error: {out}: cannot create the output directory: "
                               "Permission denied")
    assert ".tmp-" not in err
    assert list(denied.iterdir()) == []


def test_batch_names_out_when_its_parent_refuses(denied: Path) -> None:
    out = denied / "maps"
    code, err = _cli("batch", OFFICE / "office.mcap", "-o", out, "--workers", "1")
    assert code == 1
    assert err.splitlines()[-1] == (f"sonarmap: error: {out}: cannot create the output directory:"
                                    " Permission denied")
    assert ".tmp-" not in err


def test_a_file_output_names_the_file_when_its_directory_refuses(denied: Path,
                                                                 tmp_path: Path) -> None:
    out = denied / "office.mcap"
    code, err = _cli("simulate", ROOT / "sample_logs" / "worlds" / "office.toml", "-o", out)
    assert code == 1
    # the first reference file written beside the log is named, never a ".tmp-"; the log
    # written before it is removed: all or nothing
    assert err == f"sonarmap: error: {denied}/office.truth.csv: cannot write: Permission denied\n"
    assert list(denied.iterdir()) == []


def test_a_file_output_in_a_missing_directory_says_so(tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert _cli("run", OFFICE / "office.mcap", "-o", run, "-q")[0] == 0
    out = tmp_path / "missing" / "eval.json"
    code, err = _cli("evaluate", run, "--truth", OFFICE / "office.truth.yaml", "-o", out)
    assert code == 1
    assert err == f"sonarmap: error: {out}: parent directory does not exist\n"


def test_an_input_the_os_refuses_is_not_reported_as_a_write(tmp_path: Path) -> None:
    """A CSV log set whose configured file name the OS refuses (ENAMETOOLONG at open):
    the configuration is refused where it is read, naming the key."""
    logs = tmp_path / "set"
    shutil.copytree(OFFICE / "office_csv", logs)
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[input.csv]\nlayout = "set"\nranges_file = "{"r" * 300}.csv"\n')
    code, err = _cli("run", logs, "-o", tmp_path / "out", "-c", cfg, "-q")
    assert code == 1
    assert err == (f"sonarmap: error: {cfg}: 'input.csv.ranges_file' has a name of 304 bytes;"
                   " a file or directory name may have at most 255\n")


def test_an_os_error_reading_inside_an_output_block_names_the_input(tmp_path: Path) -> None:
    out = tmp_path / "out"
    src = tmp_path / ("x" * 300)
    with pytest.raises(atomic.InputError) as info, atomic.OutputDir(out) as d:
        (d.tmp_dir / "a").write_text("a")
        src.read_bytes()
    assert str(info.value) == f"{src}: cannot open: File name too long"
    assert not out.exists()
    with pytest.raises(atomic.InputError) as info, atomic.atomic_open(tmp_path / "f") as f:
        f.write(src.read_bytes())
    assert str(info.value) == f"{src}: cannot open: File name too long"
    assert sorted(p.name for p in tmp_path.iterdir()) == []
