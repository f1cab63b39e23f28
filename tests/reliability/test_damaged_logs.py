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
