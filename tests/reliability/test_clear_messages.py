"""Inputs that used to give unclear messages, hangs or silent skips: each is one line
naming the path and what is wrong (or, in a batch, a failed row)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from fuzz.harness import ROOT
from pipeline.config import Config
from pipeline.tools.batch import find_logs, read_manifest
from pipeline.tools.log_with_reference import reference_paths


def _run_error(*args: str) -> str:
    res = CliRunner().invoke(app, ["run", *args, "-q"])
    assert res.exit_code == 1, res.output
    assert len(res.stderr.splitlines()) == 1
    return res.stderr


def test_symlink_loop_is_named_as_such(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    a.symlink_to(b)
    b.symlink_to(a)
    err = _run_error(str(a), "-o", str(tmp_path / "out"))
    assert err == f"sonarmap: error: {a}: cannot open: Too many levels of symbolic links\n"


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_non_regular_inputs_are_refused_not_read_forever(tmp_path: Path, kind: str) -> None:
    if kind == "fifo":
        path = tmp_path / "pipe.bag"
        os.mkfifo(path)
    else:
        path = Path("/dev/zero")
    for cmd in (["run", str(path), "-o", str(tmp_path / "out"), "-q"], ["info", str(path)]):
        res = subprocess.run([sys.executable, "-m", "cli", *cmd], cwd=ROOT, capture_output=True,
                             text=True, timeout=60, check=False)
        assert res.returncode == 1
        assert res.stderr == (f"sonarmap: error: {path}: is not a regular file or directory "
                              "(a FIFO, socket or device); give a log file or a bag directory\n")


def test_metadata_yaml_points_to_its_bag_directory(tmp_path: Path) -> None:
    bag = ROOT / "sample_logs" / "office" / "office_ros2"
    err = _run_error(str(bag / "metadata.yaml"), "-o", str(tmp_path / "out"))
    assert err == (f"sonarmap: error: {bag / 'metadata.yaml'}: is a rosbag2 bag's metadata "
                   f"file; pass the bag directory {bag} instead\n")


def test_manifest_with_a_byte_order_mark(tmp_path: Path) -> None:
    (tmp_path / "a.mcap").write_bytes(b"x")
    manifest = tmp_path / "logs.txt"
    manifest.write_bytes("\ufeffa.mcap\n".encode())
    assert read_manifest(manifest) == [tmp_path / "a.mcap"]


def test_empty_bag_in_a_batch_directory_is_a_log_that_fails(tmp_path: Path) -> None:
    (tmp_path / "empty.bag").write_bytes(b"")
    (tmp_path / "notes.md").write_text("not a log")
    assert find_logs([tmp_path], Config()) == [tmp_path / "empty.bag"]


def test_reference_files_keep_every_dot_of_the_log_name() -> None:
    yaml, pgm, csv = reference_paths(Path("out/sim_0.02_0.0.mcap"), "truth")
    assert (yaml.name, pgm.name, csv.name) == (
        "sim_0.02_0.0.truth.yaml", "sim_0.02_0.0.truth.pgm", "sim_0.02_0.0.truth.csv")
    assert reference_paths(Path("out/office_ros2"), "truth")[0].name == "office_ros2.truth.yaml"


def test_batch_log_name_of_250_characters_gets_a_short_output_name() -> None:
    from pipeline.tools.batch import output_names

    p = Path("/logs") / ("x" * 250 + ".mcap")
    name = output_names([p])[p]
    assert len(name.encode()) <= 200 and name.startswith("xxx") and "-" in name
