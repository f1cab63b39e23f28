"""URLs told apart from paths, and written down without credentials."""

from __future__ import annotations

from pathlib import Path

import pytest

from formats.errors import FormatError, StorageError
from formats.storage.failures import describe, is_transient
from formats.storage.location import Url, as_location, joined
from formats.storage.urls import is_url, redact_text, redact_url


@pytest.mark.parametrize(("url", "shown"), [
    ("s3://bucket/logs/a.bag", "s3://bucket/logs/a.bag"),
    ("https://user:secret@host.example/a.mcap", "https://host.example/a.mcap"),
    ("https://host.example:8443/a.mcap?X-Amz-Signature=abc&X-Amz-Credential=key",
     "https://host.example:8443/a.mcap"),
    ("az://container/a.bag?sv=2020&sig=abc%3D", "az://container/a.bag"),
    ("http://tok@[::1]:9000/x#frag", "http://[::1]:9000/x"),
    ("s3://bucket/prefix/", "s3://bucket/prefix/"),
])
def test_redact_url_drops_userinfo_query_and_fragment(url, shown):
    assert redact_url(url) == shown


def test_redact_text_redacts_every_url_in_a_message():
    text = "GET https://u:pw@h/x?sig=s3cr3t failed, then s3://b/k?token=t0k"
    out = redact_text(text)
    assert "pw" not in out and "s3cr3t" not in out and "t0k" not in out
    assert out == "GET https://h/x failed, then s3://b/k"


def test_a_url_prints_redacted_everywhere_but_keeps_its_text_to_reach_the_object():
    u = Url("https://user:secret@h/logs/a.mcap?sig=abc")
    assert str(u) == repr(u)[5:-2] == "https://h/logs/a.mcap"
    assert "secret" not in str(FormatError("bad", u))
    assert u.text.endswith("?sig=abc")
    assert u.name == "a.mcap" and u.suffix == ".mcap" and u.stem == "a"
    assert str(u.parent) == "https://h/logs"


def test_url_names_and_joins():
    u = Url("s3://bucket/runs/bag_dir/")
    assert u.name == "bag_dir"
    assert (u / "metadata.yaml").text == "s3://bucket/runs/bag_dir/metadata.yaml"
    assert (u / "metadata.yaml").relative_to(u).as_posix() == "metadata.yaml"
    assert Url("s3://bucket/out/a/x").is_inside(Url("s3://bucket/out/a"))
    assert not Url("s3://bucket/out/ab").is_inside(Url("s3://bucket/out/a"))
    assert str(joined([Url("s3://b/a.bag"), Path("/l/b.bag")])) == "s3://b/a.bag + /l/b.bag"


def test_as_location_keeps_urls_and_reads_file_urls_as_paths():
    assert as_location("s3://b/k.bag") == Url("s3://b/k.bag")
    assert as_location("http://h/x//y") == Url("http://h/x//y")  # no // folded
    assert as_location("file:///data/my%20log.bag") == Path("/data/my log.bag")
    assert as_location("logs/a.bag") == Path("logs/a.bag")
    assert as_location("c:/x") == Path("c:/x")
    assert is_url("S3://b/k") and not is_url("weird://x") and not is_url("/x/y")


class _Status(Exception):
    def __init__(self, status: int) -> None:
        super().__init__(f"status {status} for https://u:pw@h/x?sig=1")
        self.status = status


@pytest.mark.parametrize(("err", "words", "transient"), [
    (FileNotFoundError("k"), "not found (HTTP 404)", False),
    (FileNotFoundError("The specified bucket does not exist"), "the bucket does not exist",
     False),
    (PermissionError("denied"), "access denied (HTTP 403)", False),
    (_Status(403), "access denied (HTTP 403)", False),
    (_Status(503), "HTTP 503", True),
    (TimeoutError(), "timed out", True),
    (ConnectionRefusedError(111, "refused"), "connection refused", True),
])
def test_failures_are_described_in_a_few_words(err, words, transient):
    text = describe(err)
    assert text.startswith(words)
    assert "pw" not in text and "sig=1" not in text
    assert is_transient(err) is transient


def test_a_missing_filesystem_names_its_extra(monkeypatch):
    import fsspec

    from formats.storage import options

    def missing(protocol: str):
        raise ImportError(f"Install gcsfs to access {protocol}")

    monkeypatch.setattr(fsspec, "get_filesystem_class", missing)
    with pytest.raises(StorageError, match=r"gs:// URLs need the 'gcs' extra \(pip install "
                                           r"'sonarmap\[gcs\]'\)"):
        options.filesystem("gs")
