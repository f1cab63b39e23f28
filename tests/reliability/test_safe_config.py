"""Configuration and metadata are data, never code; outputs stay inside their directory;
symlinked or existing outputs are refused."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from formats import open_log
from formats.errors import ConfigError, FormatError, OutputError
from formats.writers.atomic import OutputDir
from formats.writers.nav2_map import load_nav2_map
from fuzz.harness import ROOT, Target
from pipeline.config import load_config


def _payload(marker: Path) -> str:
    return f"!!python/object/apply:os.system ['touch {marker}']"


def test_toml_with_object_payload_is_only_a_string(tmp_path: Path) -> None:
    marker = tmp_path / "PWNED"
    cfg = tmp_path / "evil.toml"
    cfg.write_text(f'[mapper]\nmethod = "{_payload(marker)}"\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"evil\.toml.*mapper\.method"):
        load_config(cfg)
    cfg.write_text(f'[input]\npose_topic = "{_payload(marker)}"\n', encoding="utf-8")
    assert load_config(cfg).input.pose_topic.startswith("!!python/object")  # inert text
    assert not marker.exists()


def test_rosbag2_metadata_with_python_tag_is_refused(targets: dict[str, Target], tmp_path: Path) -> None:
    marker = tmp_path / "PWNED"
    t = targets["ros2-db3"]
    meta = t.log / "metadata.yaml"
    evil = f"rosbag2_bagfile_information: {_payload(marker)}\n" + meta.read_text()
    bag = t.materialize(tmp_path / "w", t.valid_bytes())
    (bag / "metadata.yaml").write_text(evil, encoding="utf-8")
    with pytest.raises(FormatError, match=r"metadata\.yaml: unreadable rosbag2 metadata"):
        open_log(bag)
    assert not marker.exists()


def test_nav2_map_yaml_with_python_tag_is_refused(tmp_path: Path) -> None:
    marker = tmp_path / "PWNED"
    y = tmp_path / "map.yaml"
    y.write_text(f"image: {_payload(marker)}\nresolution: 0.05\n", encoding="utf-8")
    with pytest.raises(FormatError, match=r"map\.yaml: not a readable map YAML"):
        load_nav2_map(y)
    assert not marker.exists()


def test_no_unsafe_loaders_in_the_code() -> None:
    """Every YAML load is yaml.safe_load; nothing unpickles or evaluates input."""
    unsafe = re.compile(r"yaml\.(load|unsafe_load|full_load)\(|pickle\.loads?\(|\beval\(|\bexec\(")
    hits = [
        f"{p.relative_to(ROOT)}:{i}"
        for pkg in ("pipeline", "formats", "cli")
        for p in sorted((ROOT / pkg).rglob("*.py"))
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if unsafe.search(line)
    ]
    assert hits == []


@pytest.mark.parametrize("name", ["../escape.txt", "/tmp/abs.txt", "a/../../b.txt", "", "."])
def test_output_names_are_confined(tmp_path: Path, name: str) -> None:
    with pytest.raises(OutputError, match="leads outside"), OutputDir(tmp_path / "OUT") as out:
        out.path(name)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing committed, no temp left


def test_symlink_inside_the_output_cannot_lead_outside(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    with pytest.raises(OutputError, match="leads outside"), OutputDir(tmp_path / "OUT") as out:
        (out.tmp_dir / "sub").symlink_to(outside)
        out.path("sub/map.pgm")
    assert list(outside.iterdir()) == []


def test_cli_refuses_symlinked_and_existing_outputs(targets: dict[str, Target], tmp_path: Path) -> None:
    runner = CliRunner()
    log = str(targets["mcap-zstd"].log)
    real = tmp_path / "real"
    real.mkdir()
    (real / "keep.txt").write_text("mine")
    link = tmp_path / "link"
    link.symlink_to(real)
    res = runner.invoke(app, ["run", log, "-o", str(link), "-q", "--force"])
    assert res.exit_code == 1
    assert "symlink" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    res = runner.invoke(app, ["run", log, "-o", str(link / "OUT"), "-q"])
    assert res.exit_code == 1 and "symlink" in res.stderr
    for force in ([], ["--force"]):
        res = runner.invoke(app, ["run", log, "-o", str(real), "-q", *force])
        assert res.exit_code == 1 and "is not a sonarmap output" in res.stderr
        assert "--force" not in res.stderr
    assert sorted(p.name for p in real.iterdir()) == ["keep.txt"]
    assert (real / "keep.txt").read_text() == "mine"
