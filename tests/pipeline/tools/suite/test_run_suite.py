"""The driver's own rules: planning a log, its work directory, what --update refuses."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

from pipeline.tools.regress import Tolerances
from pipeline.tools.suite.check import CheckJob, CheckResult
from pipeline.tools.suite.run_suite import _work_dir, plan_log
from pipeline.tools.suite.suite_file import read_suite


def test_work_dirs_of_dead_suites_are_removed(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (tmp_path / f"sonarmap-regress-{dead}-abc" / "office").mkdir(parents=True)
    (tmp_path / f"sonarmap-regress-{os.getppid()}-abc").mkdir()  # a live process's
    (tmp_path / "other").mkdir()
    with _work_dir() as work:
        assert work.parent == tmp_path and work.name.startswith(f"sonarmap-regress-{os.getpid()}-")
        names = sorted(p.name for p in tmp_path.iterdir())
        assert names == sorted([f"sonarmap-regress-{os.getppid()}-abc", "other", work.name])
    assert not work.exists()


def test_plans_refuse_goldens_that_are_inputs(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "logs" / "set").mkdir(parents=True)
    (tmp_path / "logs" / "set" / "ranges.csv").write_text("x\n")
    (tmp_path / "a.mcap").write_text("x\n")
    (tmp_path / "s.toml").write_text('[[log]]\nname = "set"\npath = "logs/set"\n'
                                     '[[log]]\nname = "a"\npath = "a.mcap"\n')
    suite = read_suite(tmp_path / "s.toml")
    work = tmp_path / "work"
    # --goldens logs: the golden 'set' would be the log directory itself.
    plan = plan_log(suite.logs[0], suite, tmp_path / "logs", True, Tolerances(), work, None)
    assert isinstance(plan, CheckResult) and plan.status == "error"
    assert "is or holds an input of the suite" in plan.reason
    # --goldens logs/set: a golden inside a log directory would change that log.
    plan = plan_log(suite.logs[1], suite, tmp_path / "logs" / "set", True, Tolerances(), work,
                    None)
    assert isinstance(plan, CheckResult) and "input of the suite" in plan.reason
    # Comparing reads only: the same goldens are a missing golden, not a refusal.
    plan = plan_log(suite.logs[1], suite, tmp_path / "goldens", False, Tolerances(), work, None)
    assert isinstance(plan, CheckResult)
    assert plan.reason.startswith("no golden for a: run with --update")
    plan = plan_log(suite.logs[1], suite, tmp_path / "goldens", True, Tolerances(), work,
                    tmp_path / "diffs")
    assert isinstance(plan, CheckJob)
    assert plan.paths == ("a.mcap",) and plan.golden_dir == "goldens/a"
    assert plan.diff_png is None  # updating draws nothing


def test_a_recording_in_several_files_is_one_log(tmp_path: Path, monkeypatch) -> None:
    """``path = [...]``: the sonar and odometry files of one recording map as the whole
    recording does (the same map bytes), into one golden."""
    import json

    from benchmarks.log_parts import anything, before, split_mcap, topics
    from pipeline.tools.suite.check import check_log
    from pipeline.tools.suite.golden_dir import replace_golden

    office = Path(__file__).resolve().parents[4] / "sample_logs" / "office" / "office.mcap"
    monkeypatch.chdir(tmp_path)
    split_mcap(office, [(tmp_path / "whole.mcap", before(1_700_000_015_000_000_000))])
    split_mcap(tmp_path / "whole.mcap", [(tmp_path / "odom.mcap", topics("/odom")),
                                         (tmp_path / "sonar.mcap", anything())])
    (tmp_path / "s.toml").write_text('[[log]]\nname = "whole"\npath = "whole.mcap"\n'
                                     '[[log]]\nname = "parts"\n'
                                     'path = ["sonar.mcap", "odom.mcap"]\n')
    suite = read_suite(tmp_path / "s.toml")
    for log in suite.logs:
        job = plan_log(log, suite, tmp_path / "goldens", True, Tolerances(),
                       tmp_path / "work", None)
        assert isinstance(job, CheckJob)
        result = check_log(job)
        assert result.status == "new" and result.staged is not None, result.reason
        replace_golden(Path(result.staged), tmp_path / "goldens" / log.name)
    whole, parts = tmp_path / "goldens" / "whole", tmp_path / "goldens" / "parts"
    assert (parts / "map.pgm").read_bytes() == (whole / "map.pgm").read_bytes()
    metrics = json.loads((parts / "metrics.json").read_text())
    assert sorted(f["path"] for f in metrics["input"]["files"]) == ["odom.mcap", "sonar.mcap"]
