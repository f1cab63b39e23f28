"""benchmarks.sonar_outcomes: how an emulated reading compares with the laser in its cone."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
for p in (ROOT, ROOT / "tests" / "pipeline" / "tools" / "emulate"):
    if str(p) not in sys.path:  # benchmarks/ is not an installed package
        sys.path.insert(0, str(p))

from emulate_helpers import laser_log, wall_ranges  # noqa: E402

from benchmarks.sonar_outcomes import CLASSES, conditional, outcome_classes  # noqa: E402


def test_readings_are_classed_against_the_laser_in_their_cone() -> None:
    angles = np.arange(-90.0, 90.5, 1.0)
    far = np.full(angles.shape, 81.83)  # no return anywhere
    log = laser_log(np.stack([wall_ranges(2.0, angles)] * 5 + [far]), angles)
    z = np.zeros(1)
    readings = np.array([[2.05], [5.0], [1.2], [3.5], [-np.inf], [2.0]])
    cls = outcome_classes(log, z, z, z, np.array([5.0]), readings)
    assert [CLASSES[c] for c in cls[:, 0]] == [
        "agrees", "no echo", "shorter", "longer", "shorter", "no laser"]


def test_conditional_shares_leave_the_open_space_out() -> None:
    sh = conditional({"agrees": 18, "no echo": 21, "shorter": 20, "no laser": 22, "longer": 19})
    assert round(sh["agrees"], 1) == 23.1 and round(sum(sh.values()), 6) == 100.0
