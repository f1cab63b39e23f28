"""``batch`` of URLs into an S3 prefix on a Dask cluster of separate processes: an
external ``dask scheduler`` and two ``dask worker`` processes on loopback, which read the
logs from and write the outputs to the S3 server themselves."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from loopback import LOOPBACK
from typer.testing import CliRunner

from cli.app import app

ROOT = Path(__file__).resolve().parents[2]
OFFICE = ROOT / "sample_logs" / "office"
DASK = str(Path(sys.executable).with_name("dask"))


@contextlib.contextmanager
def cluster(tmp: Path) -> Iterator[str]:
    """A scheduler and two single-threaded workers (processes of their own)."""
    sched_file = tmp / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = [subprocess.Popen(
        [DASK, "scheduler", "--host", LOOPBACK, "--port", "0", "--no-dashboard",
         "--scheduler-file", str(sched_file)],
        env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 180  # a loaded 2-core machine starts slowly
        while not sched_file.exists():
            assert time.monotonic() < deadline, "the scheduler did not start"
            time.sleep(0.2)
        for _ in range(2):
            procs.append(subprocess.Popen(
                [DASK, "worker", "--scheduler-file", str(sched_file), "--nthreads", "1",
                 "--nworkers", "1", "--host", LOOPBACK, "--no-dashboard"],
                env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith(f"tcp://{LOOPBACK}:")
        from distributed import Client

        with Client(address, timeout=120) as client:
            client.wait_for_workers(2, timeout=180)
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.mark.slow
def test_batch_of_urls_to_an_s3_prefix_on_an_external_cluster(s3, tmp_path):
    fs, bucket = s3
    fs.put_file(str(OFFICE / "office.mcap"), f"{bucket}/logs/office.mcap")
    fs.put_file(str(OFFICE / "office.bag"), f"{bucket}/logs/office.bag")
    manifest = tmp_path / "logs.txt"
    manifest.write_text(f"s3://{bucket}/logs/office.mcap\ns3://{bucket}/logs/office.bag\n")
    local = tmp_path / "local"
    runner = CliRunner()
    assert runner.invoke(app, ["run", str(OFFICE / "office.mcap"), "-o", str(local),
                               "-q"]).exit_code == 0
    out = f"s3://{bucket}/out"
    with cluster(tmp_path) as address:
        args = ["batch", f"@{manifest}", "-o", out, "--scheduler", address, "-q"]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        keys = fs.find(f"{bucket}/out")
        names = sorted({k.split("/")[2] for k in keys if k.count("/") >= 3})
        assert len(names) == 2  # office.mcap and office.bag: 'office' twice, suffixed
        for n in names:
            listed = json.loads(fs.cat(f"{bucket}/out/{n}/.sonarmap-output"))["files"]
            there = sorted(k.split(f"/out/{n}/", 1)[1] for k in keys if f"/out/{n}/" in k)
            assert sorted([*listed, ".sonarmap-output"]) == there
            assert ".sonarmap-done.json" in listed
            assert fs.cat(f"{bucket}/out/{n}/map.pgm") == (local / "map.pgm").read_bytes()
        summary = fs.cat(f"{bucket}/out/summary.md").decode()
        assert "2 logs: 2 mapped" in summary

        # Again: both finished (resume markers beside the outputs) ...
        assert runner.invoke(app, args).exit_code == 0
        assert "2 skipped" in fs.cat(f"{bucket}/out/summary.md").decode()
        # ... until one output is half-written (an upload interrupted before its marker:
        # the partial list, no marker): mapped again, and complete.
        half = f"{bucket}/out/{names[0]}"
        fs.pipe_file(f"{half}/.sonarmap-output.partial", fs.cat(f"{half}/.sonarmap-output"))
        fs.rm_file(f"{half}/.sonarmap-output")
        assert runner.invoke(app, args).exit_code == 0
        assert "2 logs: 1 mapped, 1 skipped" in fs.cat(f"{bucket}/out/summary.md").decode()
        fs.invalidate_cache()
        assert fs.exists(f"{half}/.sonarmap-output")
        assert not fs.exists(f"{half}/.sonarmap-output.partial")
