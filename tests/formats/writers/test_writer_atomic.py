"""OutputDir and atomic single-file writes: outputs are complete or absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from formats.errors import OutputError
from formats.writers.atomic import OutputDir, atomic_write_bytes, atomic_write_text


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


def test_existing_dir_refused_without_force(tmp_path: Path) -> None:
    final = tmp_path / "run"
    final.mkdir()
    (final / "old.txt").write_text("old")
    with (
        pytest.raises(OutputError, match="exists already; use --force to replace"),
        OutputDir(final),
    ):
        pass
    assert (final / "old.txt").read_text() == "old"
    assert _siblings(tmp_path) == ["run"]


def test_force_replaces_the_old_run(tmp_path: Path) -> None:
    final = tmp_path / "run"
    final.mkdir()
    (final / "old.txt").write_text("old")
    with OutputDir(final, force=True) as out:
        out.path("new.txt").write_text("new")
        assert (final / "old.txt").exists()  # the old run stays complete until commit
    assert _siblings(final) == ["new.txt"]
    assert _siblings(tmp_path) == ["run"]  # old copy deleted, no temp left


def test_force_with_failure_keeps_the_old_run(tmp_path: Path) -> None:
    final = tmp_path / "run"
    final.mkdir()
    (final / "old.txt").write_text("old")
    with pytest.raises(ValueError), OutputDir(final, force=True) as out:
        out.path("new.txt").write_text("new")
        raise ValueError("half-way")
    assert _siblings(final) == ["old.txt"]
    assert _siblings(tmp_path) == ["run"]


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
    assert _siblings(tmp_path / "run") == ["ok.txt"]
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
    with pytest.raises(OutputError, match=r"missing_dir/f\.bin: cannot write"):
        atomic_write_bytes(p, b"x")
