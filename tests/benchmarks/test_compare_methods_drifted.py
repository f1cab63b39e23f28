"""benchmarks.compare_methods --drifted: which logs a drifted case is made of, with either
sonar model (the simulator and emulator replaced by recorders: nothing is simulated)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from benchmarks import compare_methods
from benchmarks.compare_methods import _drift_cases, main
from pipeline.drift import DriftModel


@pytest.fixture
def made(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, Path, Any]]:
    """(tool, output, options) of every simulation and emulation asked for, the repository
    moved to ``tmp_path / "repo"`` (its worlds present, its logs absent)."""
    import pipeline.tools.emulate as emulate
    import pipeline.tools.simulate as simulate

    repo = tmp_path / "repo"
    (repo / "sample_logs" / "worlds").mkdir(parents=True)
    (repo / "sample_logs" / "worlds" / "office.toml").write_text("")
    monkeypatch.setattr(compare_methods, "REPO", repo)
    calls: list[tuple[str, Path, Any]] = []

    def recorder(tool: str) -> Any:
        def run(src: Path, out: Path, fmt: str, options: Any) -> None:
            calls.append((tool, out, options))
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text("")
        return run

    monkeypatch.setattr(simulate, "run_simulation", recorder("simulate"))
    monkeypatch.setattr(emulate, "run_emulation", recorder("emulate"))
    return calls


def test_realistic_cases_are_made_with_the_realistic_sonar_beside_make_compares(
        tmp_path: Path, made: list[tuple[str, Path, Any]]) -> None:
    work = tmp_path / "work"
    cases = _drift_cases(work, ("office", "orebro", "intel-lab"), sonar_model="realistic")
    repo = tmp_path / "repo"
    compare = repo / "build" / "compare"
    assert [c[0] for c in cases] == ["office", "orebro", "intel-lab"]
    office, orebro, intel = cases
    # true-pose runs: make compare's realistic logs, truths beside them
    assert office[1:] == (compare / "office-realistic.mcap", work / "office_drifted-realistic.mcap",
                          compare / "office-realistic.truth.yaml",
                          compare / "office-realistic.truth.csv")
    assert orebro[1:] == (compare / "orebro-realistic.mcap", work / "orebro_drifted-realistic.mcap",
                          compare / "orebro-realistic.laser.yaml",
                          compare / "orebro-realistic.truth.csv")
    assert intel[1] == compare / "intel-realistic.mcap"
    assert intel[3] == compare / "intel-realistic.laser.yaml"
    # every log made with the realistic sonar; the drifted ones drifted, the true ones not
    assert len(made) == 6
    for tool, out, options in made:
        assert options.sonar_model == "realistic", (tool, out)
        drifted = out.parent == work
        if tool == "emulate":
            assert options.drift == (DriftModel(0.03, 0.8) if drifted else DriftModel())
        else:
            assert (options.drift_scale == 0.03) == drifted
    assert sorted(out.name for _, out, _ in made) == sorted([
        "office-realistic.mcap", "office_drifted-realistic.mcap", "orebro-realistic.mcap",
        "orebro_drifted-realistic.mcap", "intel-realistic.mcap",
        "intel-lab_drifted-realistic.mcap"])


def test_ideal_cases_keep_their_sample_logs_and_names(
        tmp_path: Path, made: list[tuple[str, Path, Any]]) -> None:
    work = tmp_path / "work"
    (office,) = _drift_cases(work, ("office",))
    assert office[2] == work / "office_drifted.mcap"
    assert all(options.sonar_model == "ideal" for _, _, options in made)


def test_the_option_reaches_the_cases(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    asked: dict[str, Any] = {}

    def comparison(work: Path, tolerance: float, names: tuple[str, ...], config: Any, *,
                   walk: bool, drift_seed: int, sonar_model: str) -> list[Any]:
        asked.update(names=names, sonar_model=sonar_model, walk=walk)
        return []

    monkeypatch.setattr(compare_methods, "drifted_comparison", comparison)
    assert main(["--drifted", "--cases", "orebro", "--sonar-model", "realistic",
                 "--keep", str(tmp_path)]) == 0
    assert asked == {"names": ("orebro",), "sonar_model": "realistic", "walk": False}
    assert "F1 true poses refined" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["--drifted", "--sonar-model", "perfect"])
