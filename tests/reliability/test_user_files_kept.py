"""Issue 58, data loss: sonarmap replaces only what it can prove it wrote (docs/OUTPUTS.md) —
a batch's summary files, a run directory (marker, or content that says sonarmap wrote it),
``evaluate -o`` — never a user's file that merely has one of sonarmap's names."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from cli.app import app
from formats.writers.output_marker import OUTPUT_MARKER, ReadRange, ownership_reason, stamped
from fuzz.harness import ROOT

OFFICE = ROOT / "sample_logs" / "office"


def _tree(d: Path) -> dict[str, bytes]:
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def _memory(files: dict[str, bytes]) -> ReadRange:
    """A reader over files held in memory (the rule does not need a file system)."""

    def read(name: str, offset: int, length: int) -> bytes | None:
        data = files.get(name)
        if data is None:
            return None
        start = max(0, len(data) + offset) if offset < 0 else offset
        return data[start:start + length]

    return read


def _parquet(schema: pa.Schema) -> bytes:
    buf = io.BytesIO()
    pq.write_table(schema.empty_table(), buf)
    return buf.getvalue()


def test_names_alone_prove_nothing_content_and_marker_do() -> None:
    """The rule on a listing and a reader: the issue's experiment folder is not sonarmap's;
    metrics.json with run.tool_version/config_hash, a features.parquet with sonarmap's
    schema metadata, or the marker prove it, and only while nothing else is there."""
    user = {"metrics.json": b'{"acc": 0.9}', "features.parquet": b"x\n", "report.md": b"notes",
            "config.toml": b"lr=1"}
    assert ownership_reason(user, _memory(user)) == "is not a sonarmap output"
    metrics = json.dumps({"run": {"tool_version": "0.1.0", "config_hash": "d49"}}).encode()
    assert ownership_reason({**user, "metrics.json": metrics},
                            _memory({**user, "metrics.json": metrics})) is None
    feats = _parquet(pa.schema([pa.field("x", pa.float64())]).with_metadata(
        {"units": "{}", "tool_version": "0.1.0", "config_hash": "d49"}))
    assert ownership_reason(user, _memory({**user, "features.parquet": feats})) is None
    assert not stamped("features", "f", _memory({"f": _parquet(pa.schema([("x", pa.int8())]))}))
    notes = {**user, "metrics.json": metrics, "thesis.tex": b"mine"}
    assert ownership_reason(notes, _memory(notes)) == (
        "holds files sonarmap did not write (thesis.tex)")
    marked = {OUTPUT_MARKER: b'{"written_by": "sonarmap", "files": ["a.txt"]}', "a.txt": b""}
    assert ownership_reason(marked, _memory(marked)) is None
    forged = {OUTPUT_MARKER: b'{"files": ["a.txt"]}', "a.txt": b""}
    assert ownership_reason(forged, _memory(forged)) == "is not a sonarmap output"


def _experiment(d: Path) -> dict[str, bytes]:
    d.mkdir(parents=True)
    (d / "metrics.json").write_text('{"acc":0.9}\n')
    (d / "features.parquet").write_text("x\n")
    (d / "report.md").write_text("notes\n")
    (d / "config.toml").write_text("lr=1\n")
    return _tree(d)


def test_run_force_keeps_a_folder_that_only_has_sonarmaps_names(tmp_path: Path) -> None:
    before = _experiment(tmp_path / "office")
    res = CliRunner().invoke(app, ["run", str(OFFICE / "office.mcap"), "-o",
                                   str(tmp_path / "office"), "--force", "-q"])
    assert res.exit_code == 1
    assert res.stderr == (f"sonarmap: error: {tmp_path / 'office'}: exists and is not a "
                          "sonarmap output; not replacing it, choose another output directory\n")
    assert _tree(tmp_path / "office") == before


def test_batch_keeps_the_users_summary_and_experiment_folder(tmp_path: Path) -> None:
    """Issue 58 items 1 and 2: a user's summary.md/summary.parquet in -o are refused before
    any work; a user's OUT/<stem>/ with sonarmap's names fails that log, untouched."""
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(OFFICE / "office.mcap", logs)
    for name in ("summary.md", "summary.parquet"):
        (logs / name).write_text("my notes\n")
        before = _tree(logs)
        res = CliRunner().invoke(app, ["batch", str(logs), "-o", str(logs), "--workers", "1",
                                       "-q"])
        assert res.exit_code == 1
        assert res.stderr == (f"sonarmap: error: {logs / name}: exists and sonarmap did not "
                              "write it; not replacing it with the batch summary, choose "
                              "another output directory\n")
        assert _tree(logs) == before
        (logs / name).unlink()
    before = _experiment(logs / "office")
    res = CliRunner().invoke(app, ["batch", str(logs / "office.mcap"), "-o", str(logs),
                                   "--workers", "1", "-q"])
    assert res.exit_code == 1
    assert res.stderr == (f"sonarmap: failed: office: {logs / 'office'}: exists and is not a "
                          "sonarmap output; not replacing it, choose another output directory\n")
    assert _tree(logs / "office") == before
    # The summary it wrote is its own: the next batch replaces it.
    assert (logs / "summary.md").read_text().startswith("# sonarmap batch summary\n")
    shutil.rmtree(logs / "office")
    res = CliRunner().invoke(app, ["batch", str(logs / "office.mcap"), "-o", str(logs),
                                   "--workers", "1", "-q"])
    assert res.exit_code == 0, res.stderr
    assert pq.read_table(logs / "summary.parquet").column("status").to_pylist() == ["ok"]


@pytest.mark.parametrize("kind", ["summary_md", "summary_parquet"])
def test_a_summary_of_sonarmaps_is_recognised_by_its_content(kind: str) -> None:
    from pipeline.tools.batch import LogOutcome, summary_markdown, summary_table

    rows = [LogOutcome("/a.mcap", "a", "ok")]
    buf = io.BytesIO()
    pq.write_table(summary_table(rows), buf)
    data = summary_markdown(rows).encode() if kind == "summary_md" else buf.getvalue()
    assert stamped(kind, "s", _memory({"s": data}))
    assert not stamped(kind, "s", _memory({"s": b"# my batch summary\n"}))
