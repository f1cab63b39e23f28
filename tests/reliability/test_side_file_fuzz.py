"""A seeded few seconds of every side-file class of fuzz/side_files.py (``make fuzz`` runs
them all): hostile numbers in config keys and CSV columns, damaged config text, truth
maps, tolerances, manifests and worlds end in exit 0 or one line, never a traceback."""

from __future__ import annotations

import random

import pytest

from fuzz import side_files
from fuzz.side_files import CLASSES, MANIFEST_PATH_LINES, build_fixtures, run_cli


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory: pytest.TempPathFactory) -> side_files.Fixtures:
    return build_fixtures(tmp_path_factory.mktemp("side-files"))


# Cases drawn from each class (seeded): the long run is `make fuzz`.
SAMPLE = {"config numbers": 6, "config text": 3, "truth map": 4, "tolerances": 3,
          "manifest": 4, "world": 3, "csv numbers": 6}


@pytest.mark.usefixtures("quiet_numpy")
@pytest.mark.parametrize("name", sorted(CLASSES))
def test_side_file_class_has_no_defect(fixtures: side_files.Fixtures, name: str) -> None:
    rnd = random.Random(f"58:{name}")
    make = CLASSES[name]
    cases = list(make(fixtures, rnd, 8 if name == "manifest" else 2))
    outcomes = [(c, run_cli(c)) for c in rnd.sample(cases, min(SAMPLE[name], len(cases)))]
    defects = [o.detail for _, o in outcomes if o.defect]
    assert not defects, "\n".join(defects)


def test_hostile_numbers_are_refused_with_one_line_naming_the_key(
    fixtures: side_files.Fixtures,
) -> None:
    rnd = random.Random(0)
    by_what = {c.what: c for c in side_files.config_numbers(fixtures, rnd, 0)}
    o = run_cli(by_what["pose_sync.time_offset_s = 1e10"])
    assert o.status == "rejected" and "'pose_sync.time_offset_s' must be in" in o.detail
    o = run_cli(by_what["mapper.attr_threshold = -1"])
    assert o.status == "rejected" and "'mapper.attr_threshold' must be in [0, " in o.detail
    o = run_cli(by_what["mapper.attr_threshold = 0"])
    assert o.status == "ok"
    csv = {c.what: c for c in side_files.csv_numbers(fixtures, rnd, 0)}
    o = run_cli(csv["csv single scan = '1e23'"])
    assert o.status == "rejected" and "line 41: column 'scan'" in o.detail
    o = run_cli(csv["csv set sensors.csv x = '1e308'"])
    assert o.status == "rejected" and "sensors.csv: line 3: column 'x': 1e308 must be in" in o.detail
    truth = {c.what: c for c in side_files.truth_map(fixtures, rnd, 0)}
    o = run_cli(truth["truth resolution: 1.0e-4"])
    assert o.status == "rejected" and "'resolution' must be in [0.001, 100] m" in o.detail


def test_every_manifest_path_line_is_refused_with_one_line(fixtures: side_files.Fixtures) -> None:
    """The lines whose path bytes the OS refuses, each alone (the class draws them mixed)."""
    for line in MANIFEST_PATH_LINES:
        rnd = random.Random(0)
        case = next(side_files.manifest(fixtures, rnd, 1, (line,)))
        outcome = run_cli(case)
        assert outcome.status == "rejected", outcome.detail
        assert "line 1: the path" in outcome.detail
