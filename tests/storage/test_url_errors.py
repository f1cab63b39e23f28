"""Every failure at a URL: exit 1, one line naming the (redacted) URL and what went wrong,
no traceback; no credential in any output; an interrupted upload leaves no marker."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from loopback import LOOPBACK, closed_port
from typer.testing import CliRunner

from cli.app import app

ROOT = Path(__file__).resolve().parents[2]
MCAP = ROOT / "sample_logs" / "office" / "office.mcap"
runner = CliRunner()


@pytest.fixture
def fast(tmp_path: Path) -> Path:
    """A configuration that gives up quickly: 1 s timeout, one retry after 50 ms."""
    cfg = tmp_path / "fast.toml"
    cfg.write_text("[storage]\ntimeout_s = 1.0\nretries = 1\nbackoff_s = 0.05\n")
    return cfg


def _fails(args: list[str], *words: str) -> str:
    result = runner.invoke(app, args)
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert "Traceback" not in result.output
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


@pytest.fixture
def served(http, http_root) -> str:
    shutil.copy(MCAP, http_root / "office.mcap")
    return http.url


def test_http_404(served, fast):
    _fails(["info", f"{served}/missing.mcap", "-c", str(fast)],
           f"{served}/missing.mcap", "HTTP 404")


def test_http_403(served, fast):
    _fails(["info", f"{served}/forbidden/office.mcap", "-c", str(fast)],
           f"{served}/forbidden/office.mcap", "access denied (HTTP 403)")


def test_http_timeout_is_retried_then_fails(served, http, fast):
    start = len(http.requests)
    _fails(["info", f"{served}/slow/office.mcap", "-c", str(fast)],
           f"{served}/slow/office.mcap", "timed out")
    tries = [r for r in http.requests[start:] if r[1].startswith("/slow/office.mcap")]
    assert len(tries) >= 2  # the first attempt and one retry


def test_connection_refused(fast):
    url = f"http://{LOOPBACK}:{closed_port()}/office.mcap"
    _fails(["info", url, "-c", str(fast)], url, "connect")


def test_s3_missing_object_and_missing_bucket(s3, fast):
    _fs, bucket = s3
    _fails(["info", f"s3://{bucket}/nope.bag", "-c", str(fast)],
           f"s3://{bucket}/nope.bag", "HTTP 404")
    _fails(["info", "s3://no-such-bucket-here/a.bag", "-c", str(fast)],
           "s3://no-such-bucket-here/a.bag", "the bucket does not exist")


def test_s3_connection_refused(s3, fast, tmp_path):
    cfg = tmp_path / "endpoint.toml"
    cfg.write_text(f"[storage]\nendpoint_url = 'http://{LOOPBACK}:{closed_port()}'\n"
                   "timeout_s = 1.0\nretries = 1\nbackoff_s = 0.05\n")
    _fails(["info", "s3://bucket/a.bag", "-c", str(cfg)], "s3://bucket/a.bag", "connect")


def test_credentials_in_a_url_appear_in_no_message_and_no_output(served, tmp_path):
    host = served.removeprefix("http://")
    url = f"http://alice:pa55word@{host}/office.mcap?X-Amz-Signature=s1gnature"
    result = runner.invoke(app, ["run", url, "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "pa55word" not in result.output and "s1gnature" not in result.output
    for f in (tmp_path / "out").rglob("*"):
        data = f.read_bytes()
        assert b"pa55word" not in data and b"s1gnature" not in data and b"alice" not in data, f
    assert f"http://{host}/office.mcap".encode() in (tmp_path / "out" / "metrics.json").read_bytes()
    line = _fails(["info", f"http://alice:pa55word@{host}/missing.mcap?sig=s1gnature"],
                  "HTTP 404")
    assert "pa55word" not in line and "s1gnature" not in line


def test_outputs_cannot_go_to_http(served, tmp_path):
    _fails(["run", str(MCAP), "-o", f"{served}/out"], "cannot be written to http(s) URLs")
