"""The one way a whole text file is read: its text, or one line naming the file."""

from __future__ import annotations

from pathlib import Path

import pytest

from formats.errors import ConfigError, FormatError, InputError
from formats.text_file import read_text


def test_reads_the_text(tmp_path: Path) -> None:
    p = tmp_path / "a.txt"
    p.write_bytes("ä\n".encode())
    assert read_text(p, "list") == "ä\n"
    p.write_bytes(b"\xef\xbb\xbfa.bag\n")
    assert read_text(p, "manifest", encoding="utf-8-sig") == "a.bag\n"


def test_missing_unreadable_and_wrong_encoding(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"^.*none\.csv: trajectory file not found$"):
        read_text(tmp_path / "none.csv", "trajectory file")
    with pytest.raises(FormatError, match=r"d: trajectory file is a directory, not a regular file$"):
        (tmp_path / "d").mkdir()
        read_text(tmp_path / "d", "trajectory file")
    p = tmp_path / "latin1.csv"
    p.write_bytes(b"caf\xe9\n")
    with pytest.raises(FormatError, match=r"latin1\.csv: cannot read trajectory file: line 1 is not UTF-8"):
        read_text(p, "trajectory file")


def test_the_caller_chooses_the_error_classes(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="waypoint file not found"):
        read_text(tmp_path / "w.csv", "waypoint file", errors=(ConfigError, ConfigError))
