"""docs/ci.md's workflows work: their ``sonarmap`` commands, as written, run against a
small suite with a regressed golden and write what the publish and upload steps pick up;
those steps run when the job failed; the suite-file example is accepted."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from cli.app import app
from pipeline.tools.suite.suite_file import read_suite

ROOT = Path(__file__).resolve().parents[4]
DOC = (ROOT / "docs" / "ci.md").read_text(encoding="utf-8")
BLOCKS = re.findall(r"```(\w*)\n(.*?)```", DOC, flags=re.S)
WORKFLOWS = [yaml.safe_load(text) for lang, text in BLOCKS if lang == "yaml"]
GITHUB = next(w for w in WORKFLOWS if "jobs" in w)
GITLAB = next(w for w in WORKFLOWS if "jobs" not in w)


def github_steps() -> list[dict[str, Any]]:
    (job,) = GITHUB["jobs"].values()
    steps: list[dict[str, Any]] = job["steps"]
    return steps


def gitlab_job() -> dict[str, Any]:
    (job,) = GITLAB.values()
    return dict(job)


def sonarmap_commands(lines: list[str]) -> list[list[str]]:
    return [shlex.split(os.path.expandvars(line))[1:] for line in lines
            if line.startswith("sonarmap ")]


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """regress.toml (one log) and its golden, made once by --update."""
    root = tmp_path_factory.mktemp("made")
    shutil.copytree(ROOT / "sample_logs" / "slow-odometry", root / "logs" / "slow")
    (root / "regress.toml").write_text('[[log]]\nname = "slow"\npath = "logs/slow"\n',
                                       encoding="utf-8")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(root)
        result = CliRunner().invoke(app, ["regress", "--suite", "regress.toml", "--goldens",
                                          "goldens", "--update", "-q", "--workers", "1"])
    assert result.exit_code == 0, result.output
    return root


@pytest.fixture
def project(made: Path, tmp_path: Path, monkeypatch) -> Path:
    """A copy of ``made`` whose golden was then regressed by hand."""
    shutil.copytree(made, tmp_path, dirs_exist_ok=True)
    monkeypatch.chdir(tmp_path)
    metrics_path = tmp_path / "goldens" / "slow" / "metrics.json"
    metrics = json.loads(metrics_path.read_text())
    metrics["counts"]["features"] += 10
    metrics_path.write_text(json.dumps(metrics, indent=2) + "\n")
    pgm = tmp_path / "goldens" / "slow" / "map.pgm"
    data = bytearray(pgm.read_bytes())
    data[-1000:] = bytes([0]) * 1000  # the last 1000 cells occupied in the golden
    pgm.write_bytes(bytes(data))
    return tmp_path


def run(args: list[str]) -> int:
    return CliRunner().invoke(app, args).exit_code


def test_github_workflow(project: Path, monkeypatch) -> None:
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(project / "step_summary.md"))
    monkeypatch.setenv("GITHUB_SERVER_URL", "https://ci.example")
    monkeypatch.setenv("GITHUB_REPOSITORY", "team/robot")
    monkeypatch.setenv("GITHUB_RUN_ID", "42")
    steps = github_steps()
    commands = sonarmap_commands([s["run"] for s in steps if "run" in s])
    assert len(commands) == 1 and commands[0][0] == "regress"
    assert run(commands[0]) == 1  # the regression fails the job ...
    publish = next(s for s in steps if "junit" in s.get("uses", ""))
    upload = next(s for s in steps if s.get("uses", "").startswith("actions/upload-artifact"))
    for step in (publish, upload):
        assert step["if"] == "always()"  # ... and the reports are still published
    report = Path(publish["with"]["report_paths"]).read_text(encoding="utf-8")
    assert '<failure type="regression"' in report and 'name="slow"' in report
    assert [p.name for p in Path(upload["with"]["path"]).iterdir()] == ["slow.png"]
    summary = (project / "step_summary.md").read_text(encoding="utf-8")
    assert "[slow.png](https://ci.example/team/robot/actions/runs/42/slow.png)" in summary


def test_gitlab_job(project: Path) -> None:
    job = gitlab_job()
    commands = sonarmap_commands(job["script"])
    assert len(commands) == 1 and run(commands[0]) == 1
    assert job["artifacts"]["when"] == "always"
    report = Path(job["artifacts"]["reports"]["junit"])
    assert report.is_file() and "<failure" in report.read_text(encoding="utf-8")
    kept = [Path(p) for p in job["artifacts"]["paths"]]
    assert any(Path("reports/diffs/slow.png").is_relative_to(p) for p in kept)
    assert (project / "reports" / "diffs" / "slow.png").is_file()
    assert "REGRESSED" in (project / "reports" / "summary.md").read_text(encoding="utf-8")


def test_suite_file_example_is_accepted(tmp_path: Path) -> None:
    example = next(text for lang, text in BLOCKS if lang == "toml")
    for name in ("tolerances.toml", "sonarmap.toml", "logs/office.mcap", "truth/office.yaml",
                 "truth/office.csv", "office.toml"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("\n", encoding="utf-8")
    (tmp_path / "regress.toml").write_text(example, encoding="utf-8")
    (log,) = read_suite(tmp_path / "regress.toml").logs
    assert log.name == "office" and log.config == tmp_path / "office.toml"
    assert log.truth_trajectory == tmp_path / "truth" / "office.csv"
