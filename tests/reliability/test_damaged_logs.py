"""A truncated log is mapped from its intact part and the loss is recorded everywhere a
user looks: metrics.json (input section and warnings), validate, the batch summary."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from cli.app import app
from fuzz.harness import ROOT
from pipeline.config import Config
from pipeline.tools.batch import _map_one

OFFICE = ROOT / "sample_logs" / "office" / "office.mcap"


def _truncated(tmp_path: Path) -> tuple[Path, int]:
    data = OFFICE.read_bytes()
    cut = int(len(data) * 0.7)
    log = tmp_path / "cut.mcap"
    log.write_bytes(data[:cut])
    return log, cut


def test_truncated_log_records_the_loss_in_metrics_and_validate(tmp_path: Path) -> None:
    log, _ = _truncated(tmp_path)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    inp = m["input"]
    assert inp["bytes_lost"] > 0 and inp["messages_recovered"] > 0
    assert inp["losses"] and all(isinstance(x, str) for x in inp["losses"])
    assert any(w.startswith("data lost:") for w in m["warnings"])
    res = CliRunner().invoke(app, ["validate", str(log), "--json"])
    found = {f["code"]: f for f in json.loads(res.stdout)["findings"]}
    assert found["damaged_log"]["severity"] == "WARNING"
    assert found["damaged_log"]["counts"]["bytes_lost"] == inp["bytes_lost"]
    intact = CliRunner().invoke(app, ["validate", str(OFFICE), "--json"])
    assert "damaged_log" not in intact.stdout


def test_intact_log_records_no_loss(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert CliRunner().invoke(app, ["run", str(OFFICE), "-o", str(out), "-q"]).exit_code == 0
    inp = json.loads((out / "metrics.json").read_text())["input"]
    assert (inp["bytes_lost"], inp["messages_recovered"], inp["losses"]) == (0, None, [])


def test_batch_summary_row_carries_the_loss(tmp_path: Path) -> None:
    log, _ = _truncated(tmp_path)
    row = _map_one(str(log), str(tmp_path / "out"), "cut", Config().to_dict(), False)
    assert row["status"] == "ok", row
    assert row["warnings"].startswith("data lost: the log is damaged")


BAG = ROOT / "sample_logs" / "office" / "office.bag"


def _zeroed_bag(tmp_path: Path, chunk: int) -> Path:
    """office.bag with 256 zero bytes inside its ``chunk``-th lz4 chunk (0-based)."""
    data = bytearray(BAG.read_bytes())
    at = -1
    for _ in range(chunk + 1):
        at = data.index(b"compression=lz4", at + 1)
    data[at + 3000 : at + 3256] = bytes(256)
    log = tmp_path / "zeroed.bag"
    log.write_bytes(bytes(data))
    return log


def test_a_corrupt_chunk_loses_that_chunk_not_the_log(tmp_path: Path) -> None:
    log = _zeroed_bag(tmp_path, 1)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "warning: data lost: the log is damaged" in res.output
    m = json.loads((out / "metrics.json").read_text())
    inp = m["input"]
    (loss,) = inp["losses"]
    assert loss.startswith(f"{log}: corrupt chunk at byte 168904 skipped (")
    assert inp["bytes_lost"] == 163_477  # the chunk and its index records
    assert 0 < inp["messages_recovered"] < 10_589
    assert 0 < m["counts"]["readings_used"] < 8469
    res = CliRunner().invoke(app, ["validate", str(log), "--json"])
    assert res.exit_code == 0, res.output
    found = {f["code"]: f for f in json.loads(res.stdout)["findings"]}
    assert found["damaged_log"]["counts"]["bytes_lost"] == 163_477


def test_a_lost_chunk_that_held_the_mounts_is_named_in_the_error(tmp_path: Path) -> None:
    log = _zeroed_bag(tmp_path, 0)
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(log), "-o", str(out), "-q"])
    assert res.exit_code == 1 and not out.exists()
    (line,) = res.stderr.splitlines()
    assert "no mount for range sensor(s)" in line
    assert "the log is damaged, 164795 bytes lost (" in line and "corrupt chunk at byte 4109" in line


def test_trailing_bytes_that_are_no_record_are_a_loss(tmp_path: Path) -> None:
    from formats import open_log

    junk = b"\x07not a record at all" * 10
    for src in (BAG, OFFICE):
        log = tmp_path / f"tail{src.suffix}"
        log.write_bytes(src.read_bytes() + junk)
        with open_log(log) as reader:
            info = reader.info()
        assert info.bytes_lost == len(junk), src
        (loss,) = [w for w in info.losses if "not a record" in w]
        assert loss.startswith(f"{log.name}: ") or loss.startswith(f"{log}: ")
        assert f"{len(junk)} bytes after the" in loss
