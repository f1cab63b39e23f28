"""The suite file: paths relative to it, defaults, and one-line errors naming the entry."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from formats.errors import ConfigError
from pipeline.tools.suite.suite_file import display_path, read_suite


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    """suite/ with logs/a.mcap, logs/set/ (a directory log), truth files and configs."""
    root = tmp_path / "suite"
    (root / "logs" / "set").mkdir(parents=True)
    for name in ("logs/a.mcap", "logs/b1.bag", "logs/b2.bag", "logs/set/ranges.csv",
                 "truth.yaml", "truth.csv", "default.toml", "own.toml", "tol.toml"):
        (root / name).write_text("x\n", encoding="utf-8")
    return root


def write(root: Path, text: str) -> Path:
    path = root / "regress.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_paths_are_relative_to_the_suite_file(tree: Path, monkeypatch) -> None:
    monkeypatch.chdir(tree.parent)  # not the suite's directory
    suite = read_suite(write(tree, '''
tolerances = "tol.toml"
config = "default.toml"
[[log]]
name = "a"
path = "logs/a.mcap"
truth = "truth.yaml"
truth_trajectory = "truth.csv"
[[log]]
name = "b"
path = ["logs/b1.bag", "logs/b2.bag"]
config = "own.toml"
[[log]]
name = "set"
path = "logs/set"
'''))
    a, b, s = suite.logs
    assert suite.tolerances == tree / "tol.toml"
    assert a.paths == (tree / "logs" / "a.mcap",)
    assert (a.truth, a.truth_trajectory) == (tree / "truth.yaml", tree / "truth.csv")
    assert a.config == tree / "default.toml"  # the suite's default
    assert b.paths == (tree / "logs" / "b1.bag", tree / "logs" / "b2.bag")
    assert b.config == tree / "own.toml"  # its own replaces the default
    assert s.paths == (tree / "logs" / "set",) and s.truth is None
    assert display_path(a.paths[0]) == "suite/logs/a.mcap"


@pytest.mark.parametrize(("text", "message"), [
    ('bogus = 1\n[[log]]\nname = "a"\npath = "logs/a.mcap"\n',
     "regress.toml: unknown key 'bogus' (known: config, log, tolerances)"),
    ('[[log]]\nname = "a"\npath = "logs/a.mcap"\n[[log]]\nname = "b"\npth = "logs/a.mcap"\n',
     "regress.toml: log 'b' (entry 2): unknown key 'pth'"),
    ('[[log]]\nname = "a"\npath = "logs/missing.mcap"\n',
     "regress.toml: log 'a' (entry 1): path 'logs/missing.mcap' not found"),
    ('[[log]]\nname = "a"\npath = "logs/a.mcap"\n[[log]]\nname = "A"\npath = "logs/set"\n',
     "regress.toml: log 'A' (entry 2): duplicate name (entry 1 has it already)"),
    ('[[log]]\npath = "logs/a.mcap"\n',
     "regress.toml: [[log]] entry 1: missing key 'name'"),
    ('[[log]]\nname = "../up"\npath = "logs/a.mcap"\n',
     "regress.toml: log '../up' (entry 1): 'name' must be a plain directory name"),
    ('[[log]]\nname = ".hidden"\npath = "logs/a.mcap"\n',
     "regress.toml: log '.hidden' (entry 1): 'name' must be a plain directory name"),
    ('[[log]]\nname = "a"\npath = "logs/a.mcap"\ntruth_trajectory = "truth.csv"\n',
     "regress.toml: log 'a' (entry 1): 'truth_trajectory' needs 'truth'"),
    ('[[log]]\nname = "a"\npath = "logs/a.mcap"\nconfig = "nope.toml"\n',
     "regress.toml: log 'a' (entry 1): config 'nope.toml' not found"),
    ('[[log]]\nname = "a"\npath = []\n', "regress.toml: log 'a' (entry 1): 'path' is an empty list"),
    ('tolerances = "tol.toml"\n', "regress.toml: no logs"),
    ('[[log]]\nname = 3\npath = "logs/a.mcap"\n',
     "regress.toml: [[log]] entry 1: 'name' must be a non-empty string, got 3"),
])
def test_mistakes_are_one_line_naming_the_file_and_entry(tree: Path, text: str,
                                                         message: str) -> None:
    path = write(tree, text)
    with pytest.raises(ConfigError) as err:
        read_suite(path)
    assert str(err.value).startswith(f"{path.parent}/{message}"), str(err.value)
    assert "\n" not in str(err.value)


def test_the_command_exits_1_with_the_line(tree: Path, tmp_path: Path) -> None:
    path = write(tree, '[[log]]\nname = "a"\npath = "logs/a.mcap"\n[[log]]\nname = "a"\n'
                       'path = "logs/set"\n')
    goldens = tmp_path / "goldens"
    result = CliRunner().invoke(app, ["regress", "--suite", str(path), "--goldens", str(goldens),
                                      "--update"])
    assert result.exit_code == 1
    assert result.stderr.strip().splitlines() == [
        f"sonarmap: error: {path}: log 'a' (entry 2): duplicate name (entry 1 has it already)"]
    assert not goldens.exists()  # nothing written


@pytest.mark.parametrize(("args", "hint"), [
    (["--suite", "s.toml"], "--goldens"),
    (["--suite", "s.toml", "--goldens", "g", "run_dir"], "--suite"),
    (["run_dir", "--golden", "g", "--junit", "j.xml"], "--junit"),
    (["run_dir", "--golden", "g", "--update"], "--update"),
    (["run_dir"], "RUN"),
    (["--suite", "s.toml", "--goldens", "g", "--update", "--diff-dir", "d"], "--diff-dir"),
])
def test_the_two_forms_do_not_mix(args: list[str], hint: str) -> None:
    result = CliRunner().invoke(app, ["regress", *args])
    assert result.exit_code == 2 and hint in result.output
