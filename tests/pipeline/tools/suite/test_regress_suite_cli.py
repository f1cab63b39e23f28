"""``sonarmap regress --suite`` end to end on a tiny suite (the slow-odometry sample twice):
update, compare, regressions, missing and corrupt goldens, reports, what is never written."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cli.app import app
from pipeline.tools.suite.golden_dir import GOLDEN_MARKER

ROOT = Path(__file__).resolve().parents[4]
XSD = ROOT / "tests" / "data" / "junit" / "junit.xsd"

SUITE = '''config = "fine.toml"
[[log]]
name = "slow"
path = "logs/slow-odometry"
[[log]]
name = "slow-coarse"
path = "logs/slow-odometry"
config = "coarse.toml"
'''


def tree_hash(d: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(d.rglob("*")):
        h.update(str(p.relative_to(d)).encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def regress(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["regress", "--suite", "regress.toml", "--goldens",
                                      "goldens", "--workers", "1", "-q", *args])
    return result.exit_code, result.stdout


@pytest.fixture
def project(tmp_path: Path, monkeypatch) -> Path:
    shutil.copytree(ROOT / "sample_logs" / "slow-odometry", tmp_path / "logs" / "slow-odometry")
    (tmp_path / "fine.toml").write_text("[grid]\nresolution = 0.05\n", encoding="utf-8")
    (tmp_path / "coarse.toml").write_text("[grid]\nresolution = 0.1\n", encoding="utf-8")
    (tmp_path / "regress.toml").write_text(SUITE, encoding="utf-8")
    (tmp_path / "goldens" / "keep").mkdir(parents=True)
    (tmp_path / "goldens" / "keep" / "notes.txt").write_text("mine\n", encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_update_compare_regress_and_update_again(project: Path) -> None:
    etree = pytest.importorskip("lxml.etree")
    schema = etree.XMLSchema(etree.parse(str(XSD)))
    inputs = tree_hash(project / "logs")
    keep = tree_hash(project / "goldens" / "keep")

    # 1. --update writes both goldens: what regress compares, nothing a rerun would change.
    code, out = regress("--update")
    assert code == 0, out
    assert out.splitlines() == ["slow: new golden", "slow-coarse: new golden",
                                "2 goldens: 2 new, 0 updated, 0 unchanged, 0 failed"]
    golden = project / "goldens" / "slow"
    assert sorted(p.name for p in golden.iterdir()) == [
        GOLDEN_MARKER, "config.toml", "map.pgm", "map.yaml", "metrics.json"]
    metrics = json.loads((golden / "metrics.json").read_text())
    assert "timing" not in metrics and metrics["input"]["path"] == "logs/slow-odometry"
    assert "resolution = 0.1" in (project / "goldens" / "slow-coarse" / "config.toml").read_text()
    first = {p.name: p.read_bytes() for p in golden.iterdir()}

    # 2. Comparing holds, with an empty diff directory and a valid report.
    code, out = regress("--junit", "reports/report.xml", "--diff-dir", "diffs", "--summary",
                        "sum.md")
    assert code == 0, out
    assert out.splitlines()[-1] == "2 logs: 2 hold, 0 regressed, 0 could not run"
    doc = etree.parse("reports/report.xml")  # its directory made
    assert schema.validate(doc), schema.error_log
    assert [c.get("name") for c in doc.iter("testcase")] == ["slow", "slow-coarse"]
    assert not list(doc.iter("failure")) and not list(doc.iter("error"))
    assert list((project / "diffs").iterdir()) == []

    # 3. A regressed golden, a corrupt one and a log without one: three failed rows.
    metrics["counts"]["features"] *= 2
    (golden / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    pgm = (golden / "map.pgm").read_bytes()
    header, pixels = pgm[:-61360], np.frombuffer(pgm[-61360:], dtype=np.uint8).copy()
    free = np.flatnonzero(pixels == 254)[:400]
    pixels[free] = 0  # 400 free cells occupied in the golden: no longer occupied now
    (golden / "map.pgm").write_bytes(header + pixels.tobytes())
    (project / "goldens" / "slow-coarse" / "map.yaml").write_text("image: [\n")
    (project / "regress.toml").write_text(SUITE + '[[log]]\nname = "ghost"\n'
                                          'path = "logs/slow-odometry"\n')
    code, out = regress("--junit", "report.xml", "--diff-dir", "diffs", "--summary", "sum.md")
    assert code == 1
    rows = {line.split()[0]: line for line in out.splitlines()[2:5]}
    assert "REGRESSED" in rows["slow"] and "400 of 61360 cells" in rows["slow"]
    assert "ERROR" in rows["slow-coarse"] and "not a readable map YAML" in rows["slow-coarse"]
    assert "no golden for ghost: run with --update" in rows["ghost"]
    assert "regressed metrics:" in out
    assert out.splitlines()[-1] == "3 logs: 0 hold, 1 regressed, 2 could not run"
    doc = etree.parse("report.xml")
    assert schema.validate(doc), schema.error_log
    cases = {c.get("name"): c for c in doc.iter("testcase")}
    message = cases["slow"].find("failure").get("message")
    n = metrics["counts"]["features"]
    assert f"features: golden {n}, current {n // 2}, tolerance ±2 %" in message
    assert ("map_cells_differing: golden 0, current 0.0065189, tolerance ≤ 0.5 % of cells "
            "(400 of 61360 cells)") in message
    assert cases["slow-coarse"].find("error").get("type") == "FormatError"
    assert "no golden for ghost" in cases["ghost"].find("error").get("message")
    assert sorted(p.name for p in (project / "diffs").iterdir()) == ["slow.png"]
    summary = (project / "sum.md").read_text()
    assert "[slow.png](diffs/slow.png)" in summary and "### Regressed metrics" in summary

    # 4. --update again: what moved is said; a directory it did not write stays as it is.
    (project / "regress.toml").write_text(SUITE + '[[log]]\nname = "keep"\n'
                                          'path = "logs/slow-odometry"\n')
    code, out = regress("--update")
    assert code == 1
    assert f"  features: {n} -> {n // 2} (-50.00 %)" in out
    assert "slow-coarse: updated" in out
    assert "keep: FAILED:" in out and "has no .sonarmap-golden" in out
    assert {p.name: p.read_bytes() for p in golden.iterdir()} == first  # same run, same bytes
    assert tree_hash(project / "goldens" / "keep") == keep
    assert tree_hash(project / "logs") == inputs  # the inputs were never written
    assert sorted(p.name for p in (project / "goldens").iterdir()) == [
        "keep", "slow", "slow-coarse"]
