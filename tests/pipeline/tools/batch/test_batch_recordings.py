"""A batch manifest line naming one recording in several files (``a.mcap + b.mcap``):
parsed, deduplicated and named, then mapped as one log — the same map as the whole log —
and skipped on a rerun however the line orders the files."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq
import pytest
import typer
from typer.testing import CliRunner

from benchmarks.log_parts import anything, before, split_mcap, topics
from formats.errors import InputError
from pipeline.config import Config
from pipeline.tools.batch import find_logs, output_names, read_manifest

ROOT = Path(__file__).resolve().parents[4]
T0 = 1_700_000_000_000_000_000
S = 1_000_000_000


@pytest.fixture(scope="module")
def parts(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The first 20 s of the office run whole, and as separate sonar and odometry files."""
    d = tmp_path_factory.mktemp("recording")
    split_mcap(ROOT / "sample_logs" / "office" / "office.mcap",
               [(d / "whole.mcap", before(T0 + 20 * S))])
    split_mcap(d / "whole.mcap", [(d / "odom.mcap", topics("/odom")),
                                  (d / "sonar.mcap", anything())])
    return d


def test_a_plus_between_paths_names_one_recording(tmp_path: Path) -> None:
    m = tmp_path / "list.txt"
    m.write_text("sonar.mcap + ../odom.mcap\n# a comment\nwhole.mcap\n")
    assert read_manifest(m) == [(tmp_path / "sonar.mcap", tmp_path / "../odom.mcap"),
                                tmp_path / "whole.mcap"]


def test_an_empty_path_beside_a_plus_is_refused_with_its_line(tmp_path: Path) -> None:
    m = tmp_path / "list.txt"
    m.write_text("whole.mcap\nsonar.mcap + \n")
    with pytest.raises(InputError, match=r"list\.txt: line 2: an empty path beside '\+'"):
        read_manifest(m)


def test_a_recording_is_found_once_in_path_order_and_named_by_its_files(parts: Path,
                                                                         tmp_path: Path) -> None:
    m = tmp_path / "list.txt"
    m.write_text(f"{parts / 'sonar.mcap'} + {parts / 'odom.mcap'}\n"
                 f"{parts / 'odom.mcap'} + {parts / 'sonar.mcap'}\n{parts / 'whole.mcap'}\n")
    found = find_logs([], Config(), manifests=[m])
    recording = (parts / "odom.mcap", parts / "sonar.mcap")
    assert found == [recording, parts / "whole.mcap"]
    assert output_names(found) == {recording: "odom+sonar", parts / "whole.mcap": "whole"}


def test_batch_maps_the_recording_as_the_whole_log_and_skips_it_on_a_rerun(
        parts: Path, tmp_path: Path, cli_app: typer.Typer) -> None:
    m = tmp_path / "list.txt"
    m.write_text(f"{parts / 'sonar.mcap'} + {parts / 'odom.mcap'}\n{parts / 'whole.mcap'}\n")
    out = tmp_path / "out"
    r = CliRunner().invoke(cli_app, ["batch", f"@{m}", "-o", str(out), "--workers", "1"])
    assert r.exit_code == 0, r.stdout + r.stderr
    rows = {row["name"]: row for row in pq.read_table(out / "summary.parquet").to_pylist()}
    assert rows["odom+sonar"]["path"] == f"{parts / 'odom.mcap'} + {parts / 'sonar.mcap'}"
    assert rows["odom+sonar"]["status"] == "ok"
    assert rows["odom+sonar"]["readings"] == rows["whole"]["readings"] > 0
    assert (out / "odom+sonar" / "map.pgm").read_bytes() == (out / "whole" / "map.pgm").read_bytes()
    # The files named the other way round: the same recording, unchanged, skipped.
    m.write_text(f"{parts / 'odom.mcap'} + {parts / 'sonar.mcap'}\n{parts / 'whole.mcap'}\n")
    r = CliRunner().invoke(cli_app, ["batch", f"@{m}", "-o", str(out), "--workers", "1"])
    assert r.exit_code == 0, r.stdout + r.stderr
    assert "2 logs: 0 mapped, 2 skipped (unchanged), 0 failed" in r.stdout
