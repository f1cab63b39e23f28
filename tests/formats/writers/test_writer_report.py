"""report.html / report.md: metrics, embedded map, charts, comparison, escaping."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np
import pytest
from writers_helpers import make_features, make_snapshot

from formats.errors import OutputError
from formats.map_types import FeatureTable, GridSpec
from formats.writers.map_png import write_map_png
from formats.writers.report import flatten_metrics, format_value, write_reports

METRICS = {
    "counters": {"readings": 1200, "skipped_nan": 3},
    "features": 42,
    "coverage": 0.123456789,
    "tool": "sonarmap <0.1> & co",
}
SENSORS = {"/sonar/front": 700, "/sonar/back": 500}
DROPPED = {"nan": 3, "max_range": 97}


def _map(tmp_path: Path, name: str = "map.png") -> Path:
    grid = GridSpec(0.0, 0.0, 0.1, 8, 6)
    empty = make_features([], [], [])
    path = tmp_path / name
    write_map_png(path, make_snapshot(grid, np.zeros(grid.shape), empty), trajectory_xy=None,
                  features=None)  # fmt: skip
    return path


def _write(tmp_path: Path, features: FeatureTable, **kw: object) -> tuple[str, str]:
    write_reports(
        tmp_path,
        metrics=METRICS,
        map_png=_map(tmp_path),
        features=features,
        readings_per_sensor=SENSORS,
        dropped_by_reason=DROPPED,
        **kw,  # type: ignore[arg-type]
    )
    return (tmp_path / "report.html").read_text(), (tmp_path / "report.md").read_text()


def test_flatten_and_format() -> None:
    assert list(flatten_metrics(METRICS)) == [
        "counters.readings", "counters.skipped_nan", "coverage", "features", "tool",
    ]  # fmt: skip
    assert format_value(0.123456789) == "0.123457"
    assert format_value(True) == "true"
    assert format_value(np.int64(7)) == "7"
    assert format_value([1, 2.5]) == "[1,2.5]"
    assert format_value(float("nan")) == "nan"
    assert format_value(None) == "—"


def test_html_embeds_map_and_metrics(tmp_path: Path, features: FeatureTable) -> None:
    html_text, _md = _write(tmp_path, features)
    assert "http" not in html_text  # self-contained: no CDN, fonts, xmlns or links
    src = re.search(r'<img alt="map" src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html_text)
    assert src is not None
    assert base64.b64decode(src.group(1)) == (tmp_path / "map.png").read_bytes()
    assert '<td>counters.readings</td><td class="num">1200</td>' in html_text
    assert '<td>coverage</td><td class="num">0.123457</td>' in html_text
    # escaped text, never raw markup from values
    assert "sonarmap &lt;0.1&gt; &amp; co" in html_text and "<0.1>" not in html_text
    assert html_text.count("<svg") == 3
    assert "/sonar/front" in html_text and "max_range" in html_text
    assert "3 features" in html_text


def test_markdown_content(tmp_path: Path, features: FeatureTable) -> None:
    _html, md = _write(tmp_path, features)
    assert "![map](map.png)" in md
    assert "| counters.skipped_nan | 3 |" in md
    assert "| /sonar/back | 500 |" in md
    assert md.index("| /sonar/back | 500 |") < md.index("| /sonar/front | 700 |")
    assert "| max_range | 97 |" in md
    # σ_major histogram rows sum to the feature count
    rows = re.findall(r"^\| [0-9.e-]+ – [0-9.e-]+ \| (\d+) \|$", md, flags=re.M)
    assert len(rows) == 20 and sum(map(int, rows)) == 3


def test_no_features_and_empty_charts(tmp_path: Path) -> None:
    write_reports(
        tmp_path, metrics={}, map_png=_map(tmp_path), features=make_features([], [], []),
        readings_per_sensor={}, dropped_by_reason={},
    )  # fmt: skip
    html_text = (tmp_path / "report.html").read_text()
    md = (tmp_path / "report.md").read_text()
    assert "<em>no features</em>" in html_text and "_no features_" in md
    assert html_text.count("<svg") == 0


def test_comparison_side_by_side(tmp_path: Path, features: FeatureTable) -> None:
    _map(tmp_path, "map_without_correction.png")
    comparison = {
        "with correction": {"features": 42, "iou": 0.8},
        "without correction": {"features": 57, "iou": 0.7},
        "images": {
            "with correction": "map.png",
            "without correction": "map_without_correction.png",
        },
    }
    html_text, md = _write(tmp_path, features, comparison=comparison)
    assert "<th>metric</th><th>with correction</th><th>without correction</th>" in html_text
    assert html_text.count("data:image/png;base64,") == 3
    assert '<div class="side">' in html_text
    assert "| features | 42 | 57 |" in md and "| iou | 0.8 | 0.7 |" in md
    assert "![with correction](map.png) ![without correction](map_without_correction.png)" in md


def test_missing_comparison_image_refused(tmp_path: Path, features: FeatureTable) -> None:
    comparison = {"a": {"x": 1}, "images": {"a": "gone.png"}}
    with pytest.raises(OutputError, match=r"gone\.png: cannot read map image"):
        _write(tmp_path, features, comparison=comparison)


def test_reports_are_deterministic(tmp_path: Path, features: FeatureTable) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = _write(tmp_path / "a", features)
    assert _write(tmp_path / "b", features) == first
