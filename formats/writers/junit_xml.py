"""JUnit XML, as CI systems read test reports (Jenkins, GitLab, GitHub test-report actions).

One ``<testsuites>`` holding one ``<testsuite>`` whose ``<testcase>`` elements carry at
most one ``<failure>`` (the test ran and did not hold) or ``<error>`` (it could not run),
with a one-line ``message`` and the details as text, and an optional ``<system-out>``.
The counts (``tests``, ``failures``, ``errors``, ``skipped``) and times (s, 3 decimals)
are what the Jenkins xunit plugin's and Maven Surefire's schema require
(tests/data/junit/junit.xsd validates it in the tests). Characters XML 1.0 cannot hold
are dropped; the file is written atomically.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from formats.writers.atomic import atomic_write_bytes

__all__ = ["JUnitCase", "junit_xml", "write_junit_xml"]

# XML 1.0 characters: tab, newline, carriage return and U+0020 upwards (no surrogates,
# no U+FFFE/U+FFFF).
_NOT_XML = re.compile("[^\t\n\r\u0020-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


@dataclass(frozen=True)
class JUnitCase:
    """One test case. ``failure`` / ``error``: (type, one-line message, details)."""

    name: str
    classname: str
    seconds: float
    failure: tuple[str, str, str] | None = None
    error: tuple[str, str, str] | None = None
    system_out: str = ""


def _clean(text: str) -> str:
    return _NOT_XML.sub("", text)


def _seconds(s: float) -> str:
    return f"{max(s, 0.0):.3f}"


def junit_xml(suite_name: str, cases: Sequence[JUnitCase]) -> bytes:
    """The document as UTF-8 bytes (with its XML declaration)."""
    failures = sum(c.failure is not None for c in cases)
    errors = sum(c.error is not None and c.failure is None for c in cases)
    total = _seconds(sum(c.seconds for c in cases))
    counts = {"tests": str(len(cases)), "failures": str(failures), "errors": str(errors)}
    root = ET.Element("testsuites", {"name": _clean(suite_name), **counts, "time": total})
    suite = ET.SubElement(root, "testsuite", {"name": _clean(suite_name), **counts,
                                              "skipped": "0", "time": total})
    for c in cases:
        case = ET.SubElement(suite, "testcase", {"name": _clean(c.name),
                                                 "classname": _clean(c.classname),
                                                 "time": _seconds(c.seconds)})
        for tag, what in (("failure", c.failure), ("error", c.error)):
            if what is not None:
                kind, message, details = what
                el = ET.SubElement(case, tag, {"type": _clean(kind),
                                               "message": _clean(" ".join(message.split()))})
                el.text = _clean(details)
                break  # a case that failed is not also an error
        if c.system_out:
            ET.SubElement(case, "system-out").text = _clean(c.system_out)
    ET.indent(root, space="  ")
    body: bytes = ET.tostring(root, encoding="utf-8", xml_declaration=False)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + body + b"\n"


def write_junit_xml(path: Path, suite_name: str, cases: Sequence[JUnitCase]) -> None:
    """Write :func:`junit_xml` to ``path`` atomically."""
    atomic_write_bytes(Path(path), junit_xml(suite_name, cases))
