"""Outputs under an S3 prefix: marker last, --force only over sonarmap's own complete (or
interrupted) output, nothing deleted that sonarmap did not write."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from formats.storage.location import Url
from formats.writers.remote_output import PARTIAL_MARKER, remote_state

ROOT = Path(__file__).resolve().parents[2]
MCAP = ROOT / "sample_logs" / "office" / "office.mcap"
runner = CliRunner()


def _run(out: str, *extra: str):
    return runner.invoke(app, ["run", str(MCAP), "-o", out, "-q", *extra])


@pytest.fixture(scope="module")
def local_map(tmp_path_factory) -> bytes:
    out = tmp_path_factory.mktemp("local") / "office"
    assert _run(str(out)).exit_code == 0
    return (out / "map.pgm").read_bytes()


def test_run_writes_every_file_then_the_marker_listing_exactly_them(s3, local_map):
    fs, bucket = s3
    result = runner.invoke(app, ["run", str(MCAP), "-o", f"s3://{bucket}/maps/office", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["out_dir"] == f"s3://{bucket}/maps/office"
    assert summary["outputs"]["map.pgm"] == f"s3://{bucket}/maps/office/map.pgm"
    state = remote_state(Url(f"s3://{bucket}/maps/office"))
    assert state.complete and PARTIAL_MARKER not in state.present
    assert {"map.pgm", "map.yaml", "metrics.json", "features.parquet"} <= state.files
    assert fs.cat(f"{bucket}/maps/office/map.pgm") == local_map


def test_an_interrupted_upload_leaves_no_marker_and_force_completes_it(s3, monkeypatch):
    _fs, bucket = s3
    out = f"s3://{bucket}/maps/cut"
    target = Url(out).fs  # the filesystem instance the run will use
    real = target.put_file
    calls = []

    def cut_after_three(lpath, rpath, *a, **kw):
        calls.append(rpath)
        if len(calls) > 3:
            raise KeyboardInterrupt  # Ctrl-C in the middle of the upload
        return real(lpath, rpath, *a, **kw)

    monkeypatch.setattr(target, "put_file", cut_after_three)
    result = _run(out)
    assert result.exit_code != 0
    monkeypatch.undo()
    state = remote_state(Url(out))
    assert ".sonarmap-output" not in state.present  # incomplete, and says so
    assert PARTIAL_MARKER in state.present and len(state.files) == 3
    assert not state.complete
    # Without --force the incomplete output is refused, naming what it is ...
    result = _run(out)
    assert result.exit_code == 1
    assert "incomplete sonarmap output: an upload was interrupted" in result.output
    # ... with --force it is replaced: sonarmap wrote every object there.
    assert _run(out, "--force").exit_code == 0
    state = remote_state(Url(out))
    assert state.complete and PARTIAL_MARKER not in state.present


def test_force_replaces_only_a_prefix_whose_marker_lists_exactly_what_is_there(s3):
    fs, bucket = s3
    out = f"s3://{bucket}/maps/mine"
    assert _run(out).exit_code == 0
    fs.pipe_file(f"{bucket}/maps/mine/notes.txt", b"the user's")
    result = _run(out, "--force")
    assert result.exit_code == 1
    assert "holds objects sonarmap did not write (notes.txt)" in result.output
    assert fs.cat(f"{bucket}/maps/mine/notes.txt") == b"the user's"
    assert remote_state(Url(out)).listed is not None  # the old output is untouched


def test_a_prefix_of_someone_elses_objects_is_never_replaced(s3):
    fs, bucket = s3
    fs.pipe_file(f"{bucket}/data/report.csv", b"a,b\n")
    result = _run(f"s3://{bucket}/data", "--force")
    assert result.exit_code == 1
    assert "is not a sonarmap output" in result.output
    assert fs.cat(f"{bucket}/data/report.csv") == b"a,b\n"


def test_force_over_a_complete_output_leaves_only_the_new_files(s3):
    fs, bucket = s3
    out = f"s3://{bucket}/maps/twice"
    assert _run(out, "--compare-correction").exit_code == 0
    assert fs.exists(f"{bucket}/maps/twice/map_no_correction.png")
    assert _run(out, "--force").exit_code == 0
    state = remote_state(Url(out))
    assert state.complete
    assert "map_no_correction.png" not in state.present  # the old output's extra file


def test_an_output_inside_the_input_prefix_is_refused(s3):
    fs, bucket = s3
    fs.put_file(str(MCAP), f"{bucket}/in/office.mcap")
    result = runner.invoke(app, ["run", f"s3://{bucket}/in/office.mcap", "-o",
                                 f"s3://{bucket}/in", "-q", "--force"])
    assert result.exit_code == 1
    assert "contains the input" in result.output


def test_regress_and_evaluate_read_a_complete_prefix_and_refuse_an_incomplete_one(s3):
    fs, bucket = s3
    out = f"s3://{bucket}/maps/eval"
    assert _run(out).exit_code == 0
    golden = str(ROOT / "sample_logs" / "goldens" / "office")
    truth = str(ROOT / "sample_logs" / "office" / "office.truth.yaml")
    before = fs.cat(f"{bucket}/maps/eval/report.html")
    result = runner.invoke(app, ["regress", out, "--golden", golden])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["evaluate", out, "--truth", truth, "--json"])
    assert result.exit_code == 0, result.output
    assert 0 < json.loads(result.output)["f1"] <= 1
    fs.invalidate_cache()
    assert fs.cat(f"{bucket}/maps/eval/report.html") == before  # the prefix is not rewritten
    fs.rm_file(f"{bucket}/maps/eval/.sonarmap-output")  # as if the upload never finished
    for args in (["regress", out, "--golden", golden], ["evaluate", out, "--truth", truth]):
        result = runner.invoke(app, args)
        assert result.exit_code == 1
        assert f"{out}: run output incomplete: no .sonarmap-output marker" in result.output


def test_a_batch_never_replaces_a_summary_it_did_not_write_under_a_prefix(s3):
    fs, bucket = s3
    fs.pipe_file(f"{bucket}/b/summary.md", b"# my notes\n")
    result = runner.invoke(app, ["batch", str(MCAP), "-o", f"s3://{bucket}/b", "-q"])
    assert result.exit_code == 1
    assert f"s3://{bucket}/b/summary.md: exists and sonarmap did not write it" in result.output
    assert fs.cat(f"{bucket}/b/summary.md") == b"# my notes\n"
