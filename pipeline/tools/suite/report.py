"""A suite's outcomes as people and CI read them: a terminal table, Markdown, JUnit XML.

The table has one row per log (status, features, F1, map cells changed, seconds, the
reason it failed), then one row per regressed metric (golden, current, tolerance), then
a count line. Updating, the rows say per log what moved. The Markdown is the same for
``$GITHUB_STEP_SUMMARY``, with a link to each log's diff picture. In JUnit every log is a
test case: a regression a ``<failure>`` listing the regressed metrics, a log that could
not run an ``<error>``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from formats.tables import markdown_table, text_table
from formats.writers.junit_xml import JUnitCase
from pipeline.tools.regress import show_value
from pipeline.tools.suite.check import CheckResult
from pipeline.tools.suite.run_suite import SuiteResult

__all__ = ["junit_cases", "moved_lines", "suite_markdown", "suite_table", "verdict"]

_LABEL = {"ok": "ok", "regressed": "REGRESSED", "error": "ERROR", "new": "new golden",
          "updated": "updated", "unchanged": "unchanged"}


def _metric_line(r: dict[str, Any]) -> str:
    return (f"{r['metric']}: golden {show_value(r['golden'])}, current {show_value(r['current'])}, "
            f"tolerance {r['tolerance']}" + (f" ({r['detail']})" if r["detail"] else ""))


def _log_rows(outcomes: Sequence[CheckResult]) -> list[list[str]]:
    rows = []
    for o in outcomes:
        s = o.summary
        rows.append([o.name, _LABEL.get(o.status, o.status), show_value(s.get("features", "")),
                     "" if s.get("f1") is None else f"{s['f1']:.4f}",
                     s.get("cells_changed", "") or "", f"{o.seconds:.1f}", o.reason])
    return rows


_LOG_HEAD = ("log", "status", "features", "F1", "map cells changed", "seconds", "reason")
_METRIC_HEAD = ("log", "metric", "golden", "current", "tolerance", "detail")


def _metric_rows(outcomes: Sequence[CheckResult]) -> list[list[str]]:
    return [[o.name, r["metric"], show_value(r["golden"]), show_value(r["current"]), r["tolerance"],
             r["detail"]] for o in outcomes if o.status == "regressed" for r in o.failed_rows]


def verdict(result: SuiteResult) -> str:
    """The count line."""
    n = len(result.outcomes)
    if result.update:
        return (f"{n} goldens: {result.count('new')} new, {result.count('updated')} updated, "
                f"{result.count('unchanged')} unchanged, {result.count('error')} failed")
    return (f"{n} logs: {result.count('ok')} hold, {result.count('regressed')} regressed, "
            f"{result.count('error')} could not run")


def moved_lines(o: CheckResult) -> list[str]:
    """Updating: what moved in one log's golden, one line per compared value."""
    if o.status == "new":
        return [f"{o.name}: new golden"]
    if o.status == "unchanged":
        return [f"{o.name}: unchanged"]
    if o.status == "error":
        return [f"{o.name}: FAILED: {o.reason}"]
    moved = [f"  {r['metric']}: {show_value(r['golden'])} -> {show_value(r['current'])}"
             + (f" ({r['detail']})" if r["detail"] else "") for r in o.rows]
    return [f"{o.name}: updated" + ("" if moved else " (compared values the same; "
                                   "other bytes moved)"), *moved, *(f"  note: {n}" for n in
                                                                     o.notes)]


def suite_table(result: SuiteResult) -> str:
    """The terminal table (see the module docstring)."""
    if result.update:
        lines = [line for o in result.outcomes for line in moved_lines(o)]
        return "\n".join([*lines, verdict(result)])
    lines = text_table(_LOG_HEAD, _log_rows(result.outcomes), rule=True)
    metrics = _metric_rows(result.outcomes)
    if metrics:
        lines += ["", "regressed metrics:", *text_table(_METRIC_HEAD, metrics, rule=True)]
    return "\n".join([*lines, "", verdict(result)])


def suite_markdown(result: SuiteResult, summary_path: Path | None = None,
                   diff_link: str | None = None) -> str:
    """The Markdown summary; each changed log links its diff picture: ``diff_link`` +
    the file's name when given (a CI artifact's address), else the picture's path
    relative to ``summary_path``'s directory."""
    title = "sonarmap regress --update" if result.update else "sonarmap regress"
    lines = [f"## {title}: {result.suite.name}", "", f"**{verdict(result)}**", ""]
    if result.update:
        lines += ["```", *[ln for o in result.outcomes for ln in moved_lines(o)], "```"]
        return "\n".join(lines) + "\n"
    rows = _log_rows(result.outcomes)
    for row, o in zip(rows, result.outcomes, strict=True):
        link = ""
        if o.diff_png is not None:
            png = Path(o.diff_png)
            if diff_link:
                target = diff_link.rstrip("/") + "/" + png.name
            elif summary_path is not None:
                target = Path(os.path.relpath(png.resolve(),
                                              summary_path.resolve().parent)).as_posix()
            else:
                target = png.as_posix()
            link = f"[{png.name}]({target})"
        row.append(link)
    lines += markdown_table([*_LOG_HEAD, "diff"], rows, right=(2, 3, 5))
    metrics = _metric_rows(result.outcomes)
    if metrics:
        lines += ["", "### Regressed metrics", "", *markdown_table(_METRIC_HEAD, metrics)]
    return "\n".join(lines) + "\n"


def junit_cases(result: SuiteResult) -> list[JUnitCase]:
    """One test case per log (see the module docstring)."""
    classname = f"sonarmap.regress.{result.suite.stem}"
    cases = []
    for o in result.outcomes:
        failure = error = None
        notes = "\n".join(f"note: {n}" for n in o.notes if "\n" not in n)
        if o.status == "regressed":
            failed = o.failed_rows
            message = (f"{len(failed)} metric(s) regressed: "
                       + "; ".join(_metric_line(r) for r in failed))
            details = "\n".join([*text_table(_METRIC_HEAD[1:], [r[1:] for r in
                                             _metric_rows([o])], rule=True), notes])
            failure = ("regression", message, details)
        elif o.status == "error":
            error = (o.error_type or "error", o.reason, "\n".join(o.notes))
        out = "\n".join(moved_lines(o)) if result.update else notes
        cases.append(JUnitCase(o.name, classname, o.seconds, failure, error, out))
    return cases
