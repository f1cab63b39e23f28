"""metrics.json through its schema (pipeline.stages.metrics_schema): what a run writes reads back
typed; a declared key of the wrong type is a one-line FormatError naming it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from formats.errors import FormatError, InputError
from pipeline.stages.metrics_schema import finite, metrics_doc, read_metrics

GOLDEN = Path(__file__).resolve().parents[3] / "sample_logs" / "goldens" / "office-andersone"


def test_a_golden_run_reads_back_typed() -> None:
    m = read_metrics(GOLDEN / "metrics.json")
    assert m["run"]["method"] == "andersone"
    assert m["counts"]["features"] == m["paper_metric"]["features"] == 724
    assert m["counts"]["readings_used"] == 8062
    assert m["map"]["origin"] == [-4.6, -4.6, 0.0]
    assert m["counts"]["cells_freed"] == 3430030  # type: ignore[typeddict-item]  # undeclared: kept


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ([], "metrics is not a JSON object"),
        ({"counts": []}, "metrics counts is not an object: []"),
        ({"counts": {"features": "12"}}, "metrics counts.features is not an integer: '12'"),
        ({"counts": {"features": True}}, "metrics counts.features is not an integer: True"),
        ({"counts": {"features": 1.5}}, "metrics counts.features is not an integer: 1.5"),
        ({"paper_metric": {"mean_feature_variance_m2": "small"}},
         "metrics paper_metric.mean_feature_variance_m2 is not a number: 'small'"),
        ({"run": {"feature_correction": 1}}, "metrics run.feature_correction is not true or false: 1"),
        ({"input": {"files": [{"sha256": 3}]}}, r"metrics input.files[0].sha256 is not a string: 3"),
        ({"dropped": {"nan": None}}, "metrics dropped.nan is not an integer: None"),
        ({"warnings": "one"}, "metrics warnings is not an array: 'one'"),
    ],
)
def test_a_declared_key_of_the_wrong_type_is_named(doc: object, message: str) -> None:
    with pytest.raises(FormatError) as err:
        metrics_doc(doc, Path("run/metrics.json"))
    assert err.value.reason == message


def test_optional_and_null_values_are_accepted() -> None:
    doc = {"input": {"max_range_m": None, "duration_s": 3}, "paper_metric":
           {"mean_feature_variance_m2": None}, "counts": {}, "future_section": {"x": "y"}}
    assert metrics_doc(doc) == doc


def test_read_metrics_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"metrics\.json: metrics file not found"):
        read_metrics(tmp_path / "metrics.json")
    (tmp_path / "metrics.json").write_text("{not json", encoding="utf-8")
    with pytest.raises(FormatError, match="not valid JSON"):
        read_metrics(tmp_path / "metrics.json")


def test_finite() -> None:
    assert finite(None) is None and finite(math.nan) is None and finite(math.inf) is None
    assert finite(2) == 2.0 and isinstance(finite(2), float)
    assert finite(json.loads("NaN")) is None  # Python's json reads NaN; a metric that is not finite is no number
