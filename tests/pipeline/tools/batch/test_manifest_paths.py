"""Issue 58 item 11 for batch manifests (``sonarmap batch @FILE``): a line whose path the
OS cannot take — a NUL byte, a name longer than NAME_MAX, a path longer than PATH_MAX, bytes
that are not UTF-8 — refuses the manifest with one line naming it, the line and what is
wrong, before any work; a listed file the OS refuses to look at fails its row with the
OS's reason (not "no such file")."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from batch_helpers import write_wall_log
from typer.testing import CliRunner

from cli.app import app
from formats.errors import InputError
from pipeline.config import Config
from pipeline.tools import batch
from pipeline.tools.batch import read_manifest

HOSTILE_LINES = [
    (b"a.csv\x00", r"line 2: the path 'a\.csv\\x00' contains a NUL byte"),
    (b"\x00", r"line 2: the path '\\x00' contains a NUL byte"),
    (b"x" * 5000, r"line 2: the path 'x{30}'\.\.\.'x{30}' \(5000 characters\) is 5000 bytes"
                  r" long; a path may have at most 4095"),
    (b"a.csv + " + b"y" * 300, r"line 2: the path 'y{30}'\.\.\.'y{30}' \(300 characters\) has"
                               r" a name of 300 bytes; a file or directory name may have at"
                               r" most 255"),
    (b"d/" + "é".encode() * 130 + b"/a.csv", r"has a name of 260 bytes"),
    (b"\xff\xfe.csv", r"cannot read manifest: line 2 is not UTF-8 text \(byte 0xff at offset"
                      r" 6\)"),
]


@pytest.mark.parametrize(("line", "message"), HOSTILE_LINES)
def test_a_line_the_os_cannot_take_refuses_the_manifest(tmp_path: Path, line: bytes,
                                                        message: str) -> None:
    m = tmp_path / "list.txt"
    m.write_bytes(b"a.csv\n" + line + b"\n")
    with pytest.raises(InputError, match=f"^{m}: .*{message}") as info:
        read_manifest(m)
    assert "\n" not in str(info.value)


def test_batch_of_such_a_manifest_exits_1_with_one_line(tmp_path: Path) -> None:
    write_wall_log(tmp_path / "a.csv")
    m = tmp_path / "list.txt"
    m.write_bytes(b"a.csv\nb\x00.csv\n")
    res = CliRunner().invoke(app, ["batch", f"@{m}", "-o", str(tmp_path / "out")])
    assert res.exit_code == 1
    assert res.stderr == (f"sonarmap: error: {m}: line 2: the path 'b\\x00.csv' contains a NUL"
                          " byte, which no file name may hold\n")
    assert not (tmp_path / "out").exists()


def test_a_listed_path_the_os_refuses_fails_its_row_with_the_reason(tmp_path: Path) -> None:
    """Each name fits, the joined path does not: ENAMETOOLONG, not 'no such file'."""
    deep = tmp_path
    for _ in range(17):
        deep = deep / ("d" * 250)
    long_path = deep / "a.csv"
    assert len(os.fsencode(long_path)) >= 4096
    with pytest.raises(InputError, match=r"cannot open: File name too long$"):
        batch._map_one_checked((long_path,), tmp_path / "out", "a", Config().to_dict(), False)
    with pytest.raises(InputError, match=r"a\.csv: no such file or directory$"):
        batch._map_one_checked((tmp_path / "a.csv",), tmp_path / "out", "a",
                               Config().to_dict(), False)
