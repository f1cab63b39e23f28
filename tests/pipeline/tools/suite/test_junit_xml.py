"""JUnit XML: valid against the schema CI systems read (tests/data/junit/junit.xsd), one
test case per log, failures and errors where they belong."""

from __future__ import annotations

from pathlib import Path

import pytest

from formats.writers.junit_xml import JUnitCase, junit_xml, write_junit_xml

etree = pytest.importorskip("lxml.etree")  # the dev extra installs it

XSD = Path(__file__).resolve().parents[3] / "data" / "junit" / "junit.xsd"


def schema():
    return etree.XMLSchema(etree.parse(str(XSD)))


def validate(data: bytes):
    doc = etree.fromstring(data)
    s = schema()
    assert s.validate(doc), s.error_log
    return doc


CASES = [
    JUnitCase("office", "sonarmap.regress.suite", 6.25),
    JUnitCase("corridor", "sonarmap.regress.suite", 1.5,
              failure=("regression", "1 metric(s) regressed: features: golden 360, current 300, "
                       "tolerance ±2 %", "metric  golden  current\nfeatures  360  300")),
    JUnitCase("udacity", "sonarmap.regress.suite", 0.0,
              error=("InputError", "no golden for udacity: run with --update", "")),
    JUnitCase("weird\x00name", "sonarmap.regress.suite", 0.1, system_out="note: a\x1bb <&>"),
]


def test_document_is_valid_and_counts_match(tmp_path: Path) -> None:
    path = tmp_path / "report.xml"
    write_junit_xml(path, "sonarmap regress suite.toml", CASES)
    doc = validate(path.read_bytes())
    suite = doc.find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("4", "1", "1")
    assert doc.get("time") == suite.get("time") == "7.850"
    cases = suite.findall("testcase")
    assert [c.get("name") for c in cases] == ["office", "corridor", "udacity", "weirdname"]
    assert len(cases[0]) == 0  # a log that holds: an empty test case
    failure = cases[1].find("failure")
    assert failure.get("type") == "regression"
    assert "features: golden 360, current 300, tolerance ±2 %" in failure.get("message")
    assert "features  360  300" in failure.text
    error = cases[2].find("error")
    assert error.get("message") == "no golden for udacity: run with --update"
    assert cases[3].find("system-out").text == "note: ab <&>"  # ESC dropped, & escaped


def test_schema_rejects_what_ci_would_reject() -> None:
    """The schema is not a rubber stamp: a case without a name, a count that is not a
    number, a case with two outcomes all fail it."""
    s = schema()
    good = junit_xml("s", CASES[:2])
    assert s.validate(etree.fromstring(good))
    for bad in (good.replace(b'name="office" ', b""),
                good.replace(b'failures="1"', b'failures="one"'),
                good.replace(b"</failure>", b'</failure><error message="x" />')):
        assert not s.validate(etree.fromstring(bad)), bad


def test_same_cases_same_bytes() -> None:
    assert junit_xml("s", CASES) == junit_xml("s", CASES)
