"""The true-pose logs of benchmarks/research/true_pose_refinement.py: which files each row
maps and scores."""

from __future__ import annotations

from pathlib import Path

from benchmarks.research.true_pose_refinement import true_pose_logs


def test_the_sixteen_logs_pair_each_sonar_model_with_its_truth() -> None:
    logs = true_pose_logs(Path("c"), Path("s"))
    names = [name for name, *_ in logs]
    assert len(logs) == 16 and len(set(names)) == 16
    rows = {name: paths for name, *paths in logs}
    assert rows["office"] == [Path("s/office/office.mcap"), Path("s/office/office.truth.yaml"),
                              Path("s/office/office.truth.csv")]
    assert rows["intel"] == [Path("s/intel-lab/intel.mcap"), Path("s/intel-lab/intel.laser.yaml"),
                             Path("s/intel-lab/intel.truth.csv")]
    assert rows["orebro"][0] == Path("c/orebro.mcap")
    assert rows["corridor-realistic"][1] == Path("c/corridor-realistic.truth.yaml")
    assert rows["belgioioso-realistic"] == [Path("c/belgioioso-realistic.mcap"),
                                            Path("c/belgioioso-realistic.laser.yaml"),
                                            Path("c/belgioioso-realistic.truth.csv")]
