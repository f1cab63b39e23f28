"""A recording in several files, one of them damaged (the last split cut by power loss):
mapped from what is intact, with the loss of each file recorded and the bytes summed."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "formats" / "ros"))
from benchmarks.log_parts import anything, before, split_mcap
from cli.app import app
from formats import open_log

OFFICE = Path(__file__).resolve().parents[2] / "sample_logs" / "office" / "office.mcap"
T0 = 1_700_000_000_000_000_000


def test_a_cut_split_is_mapped_from_its_intact_part_and_the_losses_summed(tmp_path: Path) -> None:
    parts = [tmp_path / "run_0.mcap", tmp_path / "run_1.mcap", tmp_path / "run_2.mcap"]
    split_mcap(OFFICE, [(parts[0], before(T0 + 35 * 10**9)), (parts[1], before(T0 + 70 * 10**9)),
                        (parts[2], anything())], chunk_size=16 * 1024)
    for p, keep in ((parts[1], 0.8), (parts[2], 0.6)):  # cut like a lost power supply
        data = p.read_bytes()
        p.write_bytes(data[: int(len(data) * keep)])
    lost = []
    for p in parts[1:]:
        with open_log(p) as reader:
            lost.append(reader.info().bytes_lost)
    assert all(n > 0 for n in lost)

    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["run", *map(str, parts), "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output
    inp = json.loads((out / "metrics.json").read_text())["input"]
    assert inp["bytes_lost"] == sum(lost)
    assert inp["messages_recovered"] == sum(f["messages"] for f in inp["files"]) < 10589
    assert {line.split(":")[0] for line in inp["losses"]} == {"run_1.mcap", "run_2.mcap"}
    assert any(w.startswith("data lost:") for w in json.loads(
        (out / "metrics.json").read_text())["warnings"])
    report = (out / "report.md").read_text()
    assert f"bytes lost {sum(lost):,}" in report

    result = CliRunner().invoke(app, ["validate", *map(str, parts), "--json"])
    findings = json.loads(result.stdout)["findings"]
    damaged = [f for f in findings if f["code"] == "damaged_log"]
    assert len(damaged) == 1 and damaged[0]["counts"]["bytes_lost"] == sum(lost)
