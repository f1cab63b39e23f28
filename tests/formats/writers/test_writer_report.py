"""report.html / report.md: the answer first (summary, warnings), the map, comparison,
evaluation sections, labelled charts, readable details; escaping and determinism."""

from __future__ import annotations

import base64
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from writers_helpers import make_features, make_snapshot

from formats.errors import OutputError
from formats.map_types import FeatureTable, GridSpec
from formats.writers.map_png import write_map_png
from formats.writers.report import write_reports
from formats.writers.report_text import format_duration, format_number, format_value, label

METRICS: dict[str, Any] = {
    "input": {"path": "logs/<robot> & co.mcap", "name": "<robot> & co.mcap", "format": "mcap",
              "duration_s": 125.5, "start_ns": 1_700_000_000_250_000_000},
    "run": {"method": "andersone", "feature_correction": True},
    "counts": {"readings": 1200, "readings_used": 1000, "poses": 300, "features": 3},
    "dropped": {"before_first_pose": 0, "in_pose_gap": 150, "nan": 0, "max_range": 50},
    "paper_metric": {"mean_feature_variance_m2": 0.00868, "features": 3},
    "map": {"resolution_m": 0.05, "cells_total": 1000, "cells_occupied": 40, "cells_free": 500,
            "mapped_area_m2": 1.35},
    "trajectory": {"path_length_m": 36.59, "pose_frames": ["odom", "base_link"]},
    "sensors": [{"name": f"sonar_{i}", "readings": 100 + i, "readings_mapped": 90,
                 "mount": [0.1, 0.0, 0.5], "mount_source": "log"} for i in (10, 2, 1)],
    "warnings": ["readings dropped: 150 of 1,200 (12.5 %): 150 in pose gap"],
    "timing": {"stage_seconds": {"total": 1.234}},
}


def _map(tmp_path: Path, name: str = "map.png") -> Path:
    grid = GridSpec(0.0, 0.0, 0.1, 8, 6)
    path = tmp_path / name
    write_map_png(path, make_snapshot(grid, np.zeros(grid.shape), make_features([], [], [])),
                  trajectory_xy=None, features=None)
    return path


def _write(tmp_path: Path, features: FeatureTable, metrics: dict[str, Any] | None = None,
           **kw: Any) -> tuple[str, str]:
    write_reports(tmp_path, metrics=METRICS if metrics is None else metrics, features=features,
                  map_png=_map(tmp_path), **kw)
    return (tmp_path / "report.html").read_text(), (tmp_path / "report.md").read_text()


def test_readable_values() -> None:
    assert format_number(1234567) == "1,234,567"
    assert format_number(0.123456789) == "0.1235"
    assert format_number(0.00868) == "0.00868" and format_number(2.5e-5) == "2.500e-05"
    assert format_value("start_ns", 1_700_000_000_250_000_000) == "2023-11-14 22:13:20.250 UTC"
    assert format_value("end_ns", 32_906_000_123) == "32.906 s on the log's clock"  # not 1970
    assert format_duration(45.94) == "45.9 s"
    assert format_duration(125.5) == "2 min 5.5 s"
    assert format_duration(7384) == "2 h 03 min 04 s"
    assert format_value("x", None) == "n/a" and format_value("x", True) == "yes"
    assert label("tolerance_m") == "tolerance (m)" and label("in_pose_gap") == "in a pose gap"
    assert label("duration_s") == "duration"
    assert label("mean_feature_variance_m2") == "mean feature variance (m²)"
    assert label("search_heading_bias_deg_per_m") == "search heading bias (°/m)"
    assert label("turned_max_deg") == "turned max (°)"


def test_summary_leads_with_the_answer(tmp_path: Path, features: FeatureTable) -> None:
    html_text, md = _write(tmp_path, features)
    assert "<title>&lt;robot&gt; &amp; co.mcap — sonarmap report</title>" in html_text
    assert "<robot>" not in html_text  # escaped, never raw markup from values
    order = [html_text.index(s) for s in ("<h2>Summary</h2>", "<h2>Map</h2>",
                                          "<h2>Feature uncertainty</h2>", "<h2>Details</h2>")]
    assert order == sorted(order)
    assert ("<tr><th>Readings used</th><td>1,000 of 1,200 (83.3 %); dropped: 150 in a pose gap, "
            "50 at the max range (no echo)</td></tr>") in html_text
    assert "<th>Duration</th><td>2 min 5.5 s, from 2023-11-14 22:13:20.250 UTC</td>" in html_text
    assert "<th>Features</th><td>3; mean feature variance 0.00868 m² (the paper&#x27;s metric)" in html_text
    assert "<th>Mapped area</th><td>1.35 m²: 40 occupied and 500 free of 1,000 cells at 0.05 m" in html_text
    assert "<th>Trajectory</th><td>36.59 m, 300 poses in frame odom</td>" in html_text
    assert '<div class="warnings"><strong>Warnings</strong><ul><li>readings dropped: 150' in html_text
    assert "Quality" not in html_text  # not scored
    assert md.startswith("# <robot> & co.mcap — sonarmap report\n\n## Summary\n")
    assert "| Readings used | 1,000 of 1,200 (83.3 %); dropped: 150 in a pose gap, 50 at the max range (no echo) |" in md
    assert "- readings dropped: 150 of 1,200 (12.5 %): 150 in pose gap" in md
    assert md.index("## Summary") < md.index("## Map") < md.index("## Details")
    # Timing differs on every rerun: it is not in the reports.
    assert "1.234" not in html_text and "1.234" not in md


def test_map_embedded_and_linked(tmp_path: Path, features: FeatureTable) -> None:
    html_text, md = _write(tmp_path, features)
    assert "http" not in html_text  # self-contained: no CDN, fonts, xmlns or links
    src = re.search(r'<img alt="map of [^"]*" src="data:image/png;base64,([A-Za-z0-9+/=]+)"',
                    html_text)
    assert src is not None
    assert base64.b64decode(src.group(1)) == (tmp_path / "map.png").read_bytes()
    assert "![map of <robot> & co.mcap](map.png)" in md


def test_charts_labelled_natural_order_and_zero_reasons_hidden(tmp_path: Path,
                                                               features: FeatureTable) -> None:
    html_text, md = _write(tmp_path, features)
    assert html_text.count("<svg") == 3
    hist = html_text[html_text.index("<h2>Feature uncertainty</h2>"):html_text.index("<h2>Readings per sensor")]
    assert ">σ_major (m)</text>" in hist and ">features</text>" in hist
    assert len(re.findall(r'<text [^>]*text-anchor="middle">[0-9.]+</text>', hist)) >= 3  # x ticks
    sensors = html_text[html_text.index("<h2>Readings per sensor"):html_text.index("<h2>Dropped")]
    assert sensors.index(">sonar_1<") < sensors.index(">sonar_2<") < sensors.index(">sonar_10<")
    assert ">readings</text>" in sensors
    dropped = html_text[html_text.index("<h2>Dropped"):html_text.index("<h2>Details")]
    assert "in a pose gap" in dropped and "at the max range (no echo)" in dropped
    assert "NaN" not in dropped and "before the first pose" not in dropped  # all-zero: hidden
    assert md.index("| sonar_1 | 101 |") < md.index("| sonar_2 | 102 |") < md.index("| sonar_10 | 110 |")
    assert "| in a pose gap | 150 |" in md and "NaN range" not in md
    rows = re.findall(r"^\| [0-9.e-]+ – [0-9.e-]+ \| (\d+) \|$", md, flags=re.M)
    assert len(rows) == 20 and sum(map(int, rows)) == 3


def test_details_readable(tmp_path: Path, features: FeatureTable) -> None:
    html_text, md = _write(tmp_path, features)
    assert "<tr><td>start</td><td>2023-11-14 22:13:20.250 UTC</td></tr>" in html_text
    assert '<tr><td>mean feature variance (m²)</td><td class="num">0.00868</td></tr>' in html_text
    assert "| sonar_2 | 102 | 90 | 0.1 | 0 | 28.6 | log |" in md  # mount yaw in degrees
    assert "{" not in md.split("## Details")[1]  # no JSON blobs


def test_no_features_and_nothing_dropped(tmp_path: Path) -> None:
    metrics = {**METRICS, "dropped": {"nan": 0}, "warnings": []}
    html_text, md = _write(tmp_path, make_features([], [], []), metrics)
    assert "<em>no features</em>" in html_text and "_no features_" in md
    assert "No reading was dropped." in html_text and "No reading was dropped." in md
    assert '<p class="ok">No warnings.</p>' in html_text and "\nNo warnings.\n" in md


def test_pose_refinement_said_in_the_summary_and_first_in_its_details(
        tmp_path: Path, features: FeatureTable) -> None:
    line = ("pose refinement: scale error +3.1% (z 5.3); heading bias +0.80°/m; "
            "poses moved 7.01 m mean, 24.72 m max")
    metrics = {**METRICS, "pose_refinement": {
        "echoes": 6484, "compass": {"z": 0.28, "applied": False},
        "search_scale_error": 0.031, "summary": line}}
    html_text, md = _write(tmp_path, features, metrics)
    said = ("scale error +3.1% (z 5.3); heading bias +0.80°/m; "
            "poses moved 7.01 m mean, 24.72 m max")
    assert f"<tr><th>Pose refinement</th><td>{said}</td></tr>" in html_text
    assert f"| Pose refinement | {said} |" in md
    details = md[md.index("### Pose refinement"):]
    rows = [r for r in details.splitlines() if r.startswith("| ") and r != "|  |  |"
            and not r.startswith("| --- ")]
    assert rows[0] == f"| summary | {line} |"  # the line first, then the figures it sums up
    assert rows[1] == "| echoes | 6,484 |" and "| compass: z | 0.28 |" in rows
    # a run without refinement says nothing of it
    plain, plain_md = _write(tmp_path, features)
    assert "Pose refinement" not in plain and "Pose refinement" not in plain_md


def test_comparison_side_by_side_with_differences(tmp_path: Path, features: FeatureTable) -> None:
    other = _map(tmp_path, "map_no_correction.png")
    metrics = {**METRICS, "comparison": {
        "with_correction": {"features": 724, "mean_feature_variance_m2": 0.00868,
                            "cells_occupied": 4764, "features_deleted": 1058,
                            "features_corrected": 15237},
        "without_correction": {"features": 932, "mean_feature_variance_m2": 0.013,
                               "cells_occupied": 10125, "features_deleted": 0,
                               "features_corrected": 0},
    }}
    html_text, md = _write(tmp_path, features, metrics, comparison_pngs={
        "with feature correction": tmp_path / "map.png", "without feature correction": other})
    assert '<div class="side">' in html_text and html_text.count("data:image/png;base64,") == 3
    assert "<th></th><th>with feature correction</th><th>without feature correction</th>" in html_text
    assert "<li>features: 724 with correction, 932 without (-22 %)</li>" in html_text
    assert "<li>mean feature variance (m²): 0.00868 with correction, 0.013 without (-33 %)</li>" in html_text
    assert "<li>free space deleted 1,058 features and refit 15,237 times</li>" in html_text
    assert "| features | 724 | 932 |" in md
    assert ("![with feature correction](map.png) "
            "![without feature correction](map_no_correction.png)") in md


def test_missing_comparison_image_refused(tmp_path: Path, features: FeatureTable) -> None:
    with pytest.raises(OutputError, match=r"gone\.png: cannot read map image"):
        _write(tmp_path, features, comparison_pngs={"a": tmp_path / "gone.png"},
               metrics={**METRICS, "comparison": {"with_correction": {"features": 1}}})


def test_evaluation_sections_rendered_generically(tmp_path: Path, features: FeatureTable) -> None:
    evaluation = {
        "truth": "office.truth.yaml", "precision": 0.4272, "recall": 0.8825, "f1": 0.5757,
        "tolerance_m": 0.1,
        "false_occupied": {"seen_free": 120, "never_observed": 300, "near_wall": 40},
        "by_distance": {"near": {"cells": 10, "share": 0.5}, "far": {"cells": 4, "share": 0.2}},
        "notes": ["1290 cells lie outside the truth map"],
    }
    html_text, md = _write(tmp_path, features, evaluation=evaluation)
    assert "<th>Quality</th><td>F1 0.576 (precision 42.7 %, recall 88.2 %) against office.truth.yaml" in html_text
    ev = html_text[html_text.index("<h2>Evaluation</h2>"):html_text.index("<h2>Feature uncertainty")]
    assert '<tr><td>tolerance (m)</td><td class="num">0.1</td></tr>' in ev
    assert "<h3>False occupied</h3>" in ev and '<tr><td>seen free</td><td class="num">120</td></tr>' in ev
    assert "<h3>By distance</h3>" in ev and "<th></th><th>cells</th><th>share</th>" in ev
    assert '<tr><td>near</td><td class="num">10</td><td class="num">0.5</td></tr>' in ev
    assert "<li>1290 cells lie outside the truth map</li>" in ev
    assert "### False occupied" in md and "| never observed | 300 |" in md
    assert "| far | 4 | 0.2 |" in md


def test_trajectory_error_in_the_summary(tmp_path: Path, features: FeatureTable) -> None:
    evaluation = {"truth": "t.yaml", "f1": 0.85, "trajectory_error": {
        "poses_compared": 3095, "ate_rmse_m": 0.0238083, "rpe_delta": 1.0, "rpe_unit": "m",
        "rpe_trans_rmse_m": 0.00806289, "rpe_rot_rmse_deg": 0.0139998}}
    html_text, md = _write(tmp_path, features, evaluation=evaluation)
    said = ("ATE 0.0238 m RMSE (3,095 poses, SE(2)-aligned); "
            "RPE 0.00806 m and 0.014° RMSE per 1 m")
    assert f"<tr><th>Trajectory error</th><td>{said}</td></tr>" in html_text
    assert f"| Trajectory error | {said} |" in md
    _, without = _write(tmp_path, features, evaluation={"truth": "t.yaml", "f1": 0.85})
    assert "Trajectory error" not in without


def test_reports_are_deterministic(tmp_path: Path, features: FeatureTable) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = _write(tmp_path / "a", features)
    assert _write(tmp_path / "b", features) == first


def test_natural_key_orders_numbers_by_value() -> None:
    from formats.natural_order import natural_key

    names = ["sonar_10", "sonar_2", "Sonar_1", "sonar_1", "front", "sonar_02", "sonar_"]
    assert sorted(names, key=natural_key) == [
        "front", "sonar_", "Sonar_1", "sonar_1", "sonar_02", "sonar_2", "sonar_10"]
