"""OutputDir and atomic single-file writes: outputs are complete or absent."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from formats.errors import OutputError
from formats.writers.atomic import OutputDir, atomic_write_bytes, atomic_write_text
from formats.writers.output_marker import OUTPUT_MARKER


def _siblings(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir())


def test_success_renames_temp_dir_to_final(tmp_path: Path) -> None:
    final = tmp_path / "run"
    with OutputDir(final) as out:
        tmp = out.tmp_dir
        assert tmp.parent == tmp_path
        assert tmp.name.startswith(f".run.tmp-{os.getpid()}-")
        assert not final.exists()  # nothing under the final name while writing
        out.path("map.yaml").write_text("a")
        out.path("charts/hist.svg").write_text("<svg/>")
    assert out.committed
    assert (final / "map.yaml").read_text() == "a"
    assert (final / "charts" / "hist.svg").read_text() == "<svg/>"
    assert _siblings(tmp_path) == ["run"]


def test_exception_leaves_nothing(tmp_path: Path) -> None:
    final = tmp_path / "run"
    with pytest.raises(RuntimeError, match="boom"), OutputDir(final) as out:
        out.path("map.pgm").write_bytes(b"P5")
        raise RuntimeError("boom")
    assert not out.committed
    assert _siblings(tmp_path) == []


def _earlier_output(final: Path, *files: str) -> Path:
    """A directory as an earlier OutputDir commit leaves it (files plus the marker)."""
    with OutputDir(final) as out:
        for f in files:
            out.path(f).write_text("old")
    return final


def test_commit_lists_every_file_in_the_marker(tmp_path: Path) -> None:
    final = _earlier_output(tmp_path / "run", "map.yaml", "charts/hist.svg")
    marker = json.loads((final / OUTPUT_MARKER).read_text())
    assert marker == {"written_by": "sonarmap", "files": ["charts/hist.svg", "map.yaml"]}


def test_earlier_output_refused_without_force_naming_force(tmp_path: Path) -> None:
    final = _earlier_output(tmp_path / "run", "old.txt")
    with (
        pytest.raises(OutputError, match=r"\(an earlier sonarmap output\); use --force to replace"),
        OutputDir(final),
    ):
        pass
    assert (final / "old.txt").read_text() == "old"
    assert _siblings(tmp_path) == ["run"]


def test_force_replaces_the_old_run(tmp_path: Path) -> None:
    final = _earlier_output(tmp_path / "run", "old.txt")
    with OutputDir(final, force=True) as out:
        out.path("new.txt").write_text("new")
        assert (final / "old.txt").exists()  # the old run stays complete until commit
    assert _siblings(final) == [OUTPUT_MARKER, "new.txt"]
    assert _siblings(tmp_path) == ["run"]  # old copy deleted, no temp left


@pytest.mark.parametrize("force", [False, True])
def test_a_directory_sonarmap_did_not_write_is_never_replaced(tmp_path: Path, force: bool) -> None:
    final = tmp_path / "run"
    final.mkdir()
    (final / "mine.txt").write_text("mine")
    with pytest.raises(OutputError, match="is not a sonarmap output") as err, OutputDir(
        final, force=force
    ):
        pass
    assert "--force" not in str(err.value)  # never pointed at the destructive flag
    assert (final / "mine.txt").read_text() == "mine"


def test_an_output_holding_the_users_files_is_not_replaced(tmp_path: Path) -> None:
    final = _earlier_output(tmp_path / "run", "map.yaml")
    (final / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match=r"holds files sonarmap did not write \(notes.txt\)"), \
            OutputDir(final, force=True):
        pass
    assert (final / "notes.txt").read_text() == "mine"


def test_legacy_output_without_marker_is_replaced_only_when_its_content_is_sonarmaps(
    tmp_path: Path,
) -> None:
    """File names prove nothing: a marker-less directory is sonarmap's only when its
    metrics.json says so (run.tool_version and run.config_hash), and then only while it
    holds nothing but a run's files."""
    final = tmp_path / "run"
    final.mkdir()
    for f in ("metrics.json", "features.parquet", "map.pgm"):
        (final / f).write_text("old")
    with pytest.raises(OutputError, match="is not a sonarmap output"), OutputDir(final, force=True):
        pass
    assert (final / "metrics.json").read_text() == "old"
    (final / "metrics.json").write_text('{"run": {"tool_version": "0.1.0", "config_hash": "ab"}}')
    with OutputDir(final, force=True) as out:
        out.path("metrics.json").write_text("new")
    assert (final / "metrics.json").read_text() == "new"
    (final / OUTPUT_MARKER).unlink()
    (final / "metrics.json").write_text('{"run": {"tool_version": "0.1.0", "config_hash": "ab"}}')
    (final / "thesis.tex").write_text("mine")
    with pytest.raises(OutputError, match=r"holds files sonarmap did not write \(thesis\.tex\)"), \
            OutputDir(final, force=True):
        pass
    assert (final / "thesis.tex").read_text() == "mine"


def test_directory_holding_the_input_or_the_cwd_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    final = _earlier_output(tmp_path / "run", "map.yaml")
    log = final / "sub" / "robot.mcap"
    log.parent.mkdir()
    log.write_bytes(b"log")
    with pytest.raises(OutputError, match=r"is or contains the input .*robot\.mcap"), \
            OutputDir(final, force=True, protect=(log,)):
        pass
    assert log.read_bytes() == b"log"
    log.unlink()
    log.parent.rmdir()
    monkeypatch.chdir(final)
    with pytest.raises(OutputError, match="is or contains the working directory"), \
            OutputDir(Path("..") / "run", force=True):
        pass
    assert (final / "map.yaml").exists()


def test_force_with_failure_keeps_the_old_run(tmp_path: Path) -> None:
    final = _earlier_output(tmp_path / "run", "old.txt")
    with pytest.raises(ValueError), OutputDir(final, force=True) as out:
        out.path("new.txt").write_text("new")
        raise ValueError("half-way")
    assert _siblings(final) == [OUTPUT_MARKER, "old.txt"]
    assert _siblings(tmp_path) == ["run"]


def test_parent_that_is_a_file_is_named(tmp_path: Path) -> None:
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(OutputError, match=r"afile: is a file, not a directory"), \
            OutputDir(afile / "sub"):
        pass


def test_name_too_long_for_the_temporary_sibling_names_the_output(tmp_path: Path) -> None:
    final = tmp_path / ("n" * 240)
    with pytest.raises(OutputError, match=r"n{240}: output directory name is too long \(240 bytes"), \
            OutputDir(final):
        pass
    assert _siblings(tmp_path) == []


def test_os_error_while_writing_names_the_output_not_the_temporary(tmp_path: Path) -> None:
    final = tmp_path / "OUT"
    with pytest.raises(OutputError) as err, OutputDir(final) as out:
        raise OSError(28, "No space left on device", str(out.path("map.pgm")))
    assert str(err.value) == f"{final / 'map.pgm'}: cannot write: No space left on device"
    assert _siblings(tmp_path) == []


def test_force_refuses_to_replace_a_file(tmp_path: Path) -> None:
    final = tmp_path / "run"
    final.write_text("not a dir")
    with pytest.raises(OutputError, match="not a directory"), OutputDir(final, force=True):
        pass
    assert final.read_text() == "not a dir"


def test_symlinked_final_refused(tmp_path: Path) -> None:
    target = tmp_path / "elsewhere"
    target.mkdir()
    link = tmp_path / "run"
    link.symlink_to(target)
    for force in (False, True):
        with pytest.raises(OutputError, match="is a symlink"), OutputDir(link, force=force):
            pass
    assert link.is_symlink() and _siblings(target) == []


def test_symlinked_parent_refused(tmp_path: Path) -> None:
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "linked").symlink_to(real)
    with (
        pytest.raises(OutputError, match="parent of the output directory is a symlink"),
        OutputDir(tmp_path / "linked" / "run"),
    ):
        pass
    assert _siblings(real) == []


def test_dangling_symlink_final_refused(tmp_path: Path) -> None:
    link = tmp_path / "run"
    link.symlink_to(tmp_path / "missing")
    with pytest.raises(OutputError, match="is a symlink"), OutputDir(link):
        pass


@pytest.mark.parametrize("name", ["../x", "a/../../x", "/etc/passwd", "..", "", "."])
def test_escaping_names_refused(tmp_path: Path, name: str) -> None:
    with OutputDir(tmp_path / "run") as out:
        with pytest.raises(OutputError, match="leads outside the output directory"):
            out.path(name)
        out.path("ok.txt").write_text("ok")
    assert _siblings(tmp_path / "run") == [OUTPUT_MARKER, "ok.txt"]
    assert _siblings(tmp_path) == ["run"]


def test_symlink_inside_cannot_lead_out(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    with pytest.raises(OutputError, match="leads outside"), OutputDir(tmp_path / "run") as out:
        (out.tmp_dir / "sneaky").symlink_to(outside)
        out.path("sneaky/file.txt")
    assert not (tmp_path / "run").exists()


def test_path_outside_with_block_refused(tmp_path: Path) -> None:
    out = OutputDir(tmp_path / "run")
    with pytest.raises(OutputError, match="not open"):
        out.path("x")


def test_parent_is_created(tmp_path: Path) -> None:
    final = tmp_path / "a" / "b" / "run"
    with OutputDir(final) as out:
        out.path("f").write_bytes(b"1")
    assert (final / "f").read_bytes() == b"1"


def test_atomic_write_replaces_and_leaves_no_temp(tmp_path: Path) -> None:
    p = tmp_path / "f.bin"
    atomic_write_bytes(p, b"one")
    atomic_write_bytes(p, b"two")
    atomic_write_text(tmp_path / "t.txt", "σ\n")
    assert p.read_bytes() == b"two"
    assert (tmp_path / "t.txt").read_bytes() == "σ\n".encode()
    assert _siblings(tmp_path) == ["f.bin", "t.txt"]


def test_atomic_write_error_is_output_error(tmp_path: Path) -> None:
    p = tmp_path / "missing_dir" / "f.bin"
    with pytest.raises(OutputError, match=r"missing_dir/f\.bin: parent directory does not exist"):
        atomic_write_bytes(p, b"x")
