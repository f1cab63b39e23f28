"""CsvLogReader error paths: every bad row is a FormatError naming the file and the line."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from csvlog_helpers import make_config, read_all, write

import formats.csv_log as csv_log
from formats.csv_log import CsvLogReader
from formats.errors import FormatError

HEAD = "t,x,y,yaw,sensor,range\n"
ROW = "1,0,0,0,s,1\n"


def _fails(
    tmp_path: Path, text: str, csv: dict[str, object] | None = None, name: str = "file.csv"
) -> str:
    path = write(tmp_path, name, text)
    with pytest.raises(FormatError) as err:
        read_all(path, make_config(csv))
    return str(err.value)


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        (HEAD + ROW + "1,0,0,0,s\n", r"file\.csv: line 3: expected 6 fields .*found 5"),
        (HEAD + ROW + "1,0,0,0,s,1,9\n", r"file\.csv: line 3: expected 6 fields .*found 7"),
        (
            HEAD + ROW + "1,abc,0,0,s,1\n",
            r"file\.csv: line 3: column 'x': expected a number, found 'abc'",
        ),
        (
            HEAD + ROW + "1,0,0,0,s,\n",
            r"file\.csv: line 3: column 'range': expected a number, found an empty field",
        ),
        (HEAD + ROW + "1,0,0,0,s,1.2.3\n", r"file\.csv: line 3: column 'range'.*'1\.2\.3'"),
        (
            HEAD + ROW + "1,nan,0,0,s,1\n",
            r"file\.csv: line 3: column 'x': 'nan' is not a finite number",
        ),
        (HEAD + ROW + "1,0,0,inf,s,1\n", r"file\.csv: line 3: column 'yaw': 'inf' is not a finite"),
        (
            HEAD + ROW + "nan,0,0,0,s,1\n",
            r"file\.csv: line 3: column 't': 'nan' is not a finite time",
        ),
        (
            HEAD + ROW + "12:30,0,0,0,s,1\n",
            r"file\.csv: line 3: column 't': expected a time, found '12:30'",
        ),
        (
            HEAD + ROW + ",0,0,0,s,1\n",
            r"file\.csv: line 3: column 't': expected a time, found an empty field",
        ),
        (
            HEAD + ROW + "1e30,0,0,0,s,1\n",
            r"file\.csv: line 3: column 't'.*out of the int64 ns range",
        ),
        (HEAD + ROW + "1,0,0,0,,1\n", r"file\.csv: line 3: column 'sensor': empty sensor name"),
        (
            "t,x,y,yaw,sensor\n" + ROW,
            r"file\.csv: line 1: missing required column 'range' in header",
        ),
        ("t,x,y,yaw,sensor,range,X\n" + ROW, r"file\.csv: line 1: duplicate column 'x'"),
        (ROW + ROW, r"file\.csv: line 1: no header: the first line .* looks like data"),
        ("", r"file\.csv: empty file: no header and no data rows"),
        ("# only\n\n# comments\n", r"file\.csv: empty file"),
    ],
)
def test_bad_rows_name_file_and_line(tmp_path: Path, text: str, pattern: str) -> None:
    with pytest.raises(FormatError, match=pattern):
        read_all(write(tmp_path, "file.csv", text), make_config())


@pytest.mark.parametrize("chunk_bytes", [5, 40, 4 << 20])
def test_line_numbers_count_comments_and_blank_lines(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, chunk_bytes: int
) -> None:
    monkeypatch.setattr(csv_log, "CHUNK_BYTES", chunk_bytes)  # 5: every line spans blocks
    text = "# header follows\n" + HEAD + "\n" + ROW + "  # c\n \t\n" + ROW + "1,0,0,0,s,oops\n"
    msg = _fails(tmp_path, text)
    assert "file.csv: line 8: column 'range'" in msg


def test_error_in_a_later_chunk_has_the_right_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(csv_log, "CHUNK_BYTES", 40)
    text = HEAD + ROW * 10 + "1,0,0,0,s,x\n"
    assert "line 12:" in _fails(tmp_path, text)


def test_bad_scan_value(tmp_path: Path) -> None:
    text = "t,x,y,yaw,sensor,range,scan\n1,0,0,0,s,1,3\n1,0,0,0,s,1,3.5\n"
    with pytest.raises(
        FormatError, match=r"file\.csv: line 3: column 'scan': expected an integer, found '3\.5'"
    ):
        read_all(write(tmp_path, "file.csv", text), make_config())


def test_header_false_but_file_has_a_header(tmp_path: Path) -> None:
    msg = _fails(tmp_path, HEAD + ROW, {"header": False})
    assert "file.csv: line 1: column 't': expected a time, found 't'" in msg


def test_header_false_with_too_few_fields(tmp_path: Path) -> None:
    msg = _fails(tmp_path, "1,2,3\n", {"header": False})
    assert (
        "line 1: expected 6 to 10 fields (t,x,y,yaw,sensor,range,fov,min_range,max_range,scan), found 3"
        in msg
    )


def test_malformed_quotes(tmp_path: Path) -> None:
    msg = _fails(tmp_path, HEAD + '1,0,0,0,"s"x,1\n')
    assert "file.csv: line 2: malformed CSV" in msg


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "file.csv"
    path.write_bytes(HEAD.encode() + b"1,0,0,0,\xff\xfe,1\n")
    with pytest.raises(FormatError, match=r"file\.csv: line 2: not UTF-8 text"):
        read_all(path, make_config())


@pytest.mark.parametrize(
    ("key", "value"),
    [("time_unit", "h"), ("length_unit", "inch"), ("angle_unit", "grad")],
)
def test_unknown_unit(tmp_path: Path, key: str, value: str) -> None:
    path = write(tmp_path, "file.csv", HEAD + ROW)
    cfg = make_config()
    bad = dataclasses.replace(cfg.input.csv, **{key: value})  # type: ignore[arg-type]
    cfg = cfg.replace(input=dataclasses.replace(cfg.input, csv=bad))
    with pytest.raises(FormatError, match=rf"file\.csv: unknown {key} '{value}'"):
        CsvLogReader(path, cfg)


def test_missing_path(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"nope\.csv: no such file"):
        CsvLogReader(tmp_path / "nope.csv", make_config())


def test_a_directory_is_read_as_a_set_whatever_the_layout(tmp_path: Path) -> None:
    # layout defaults to 'single', but a directory can only be a set of files.
    with pytest.raises(FormatError, match=r"CSV log set has no ranges\.csv"):
        CsvLogReader(tmp_path, make_config())


def test_set_layout_missing_poses_file(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "t,sensor,range\n")
    with pytest.raises(FormatError, match=r"has no poses\.csv"):
        CsvLogReader(tmp_path, make_config({"layout": "set"}))


def test_set_layout_errors_name_the_right_file(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "t,sensor,range\n1,s,1\n")
    write(tmp_path, "poses.csv", "t,x,y,yaw\n1,0,0,0\n2,0,0\n")
    with pytest.raises(FormatError, match=r"poses\.csv: line 3: expected 4 fields"):
        read_all(tmp_path, make_config({"layout": "set"}))


def test_sensors_file_duplicate_sensor(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "t,sensor,range\n1,s,1\n")
    write(tmp_path, "poses.csv", "t,x,y,yaw\n1,0,0,0\n")
    write(tmp_path, "sensors.csv", "sensor,x,y,yaw\ns,0,0,0\ns,1,0,0\n")
    with pytest.raises(FormatError, match=r"sensors\.csv: line 3: sensor 's' listed twice"):
        read_all(tmp_path, make_config({"layout": "set"}))


def test_wide_header_must_start_with_t(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "time,a,b\n1,1,1\n")
    write(tmp_path, "poses.csv", "t,x,y,yaw\n1,0,0,0\n")
    with pytest.raises(
        FormatError, match=r"ranges\.csv: line 1: missing required a header 't,<sensor>"
    ):
        read_all(tmp_path, make_config({"layout": "set", "wide_ranges": True}))


def test_wide_text_in_a_range_column(tmp_path: Path) -> None:
    write(tmp_path, "ranges.csv", "t,a,b\n1,1,1\n2,1,far\n")
    write(tmp_path, "poses.csv", "t,x,y,yaw\n1,0,0,0\n")
    with pytest.raises(
        FormatError, match=r"ranges\.csv: line 3: column 'b': expected a number, found 'far'"
    ):
        read_all(tmp_path, make_config({"layout": "set", "wide_ranges": True}))


def test_closed_reader_refuses_to_read(tmp_path: Path) -> None:
    reader = CsvLogReader(write(tmp_path, "file.csv", HEAD + ROW), make_config())
    reader.close()
    with pytest.raises(FormatError, match="reader is closed"):
        list(reader.batches())


def test_errors_are_one_line(tmp_path: Path) -> None:
    msg = _fails(tmp_path, HEAD + "1,0,0,0,s,1\n2,\n")
    assert "\n" not in msg and msg.startswith(str(tmp_path / "file.csv"))


def test_prose_and_markup_are_not_taken_for_csv(tmp_path: Path) -> None:
    from formats import detect_format
    from formats.csv_log import looks_like_csv

    readme = tmp_path / "README.md"
    readme.write_text("# title\n\n**Bold prose** with words, and a comma.\n")
    assert not looks_like_csv(readme)
    with pytest.raises(FormatError, match=r"not a recognised log format.*tried ROS 1 bag"):
        detect_format(readme)
    for text in ("t,x,y,yaw,sensor,range\n1,2,3,4,s,5\n", "t_ms z1 z2\n0 100 200\n",
                 '"t","sonar_1"\n1.5,2\n', "# comment\n1700000000.5,1.0\n"):
        good = tmp_path / "log.csv"
        good.write_text(text)
        assert looks_like_csv(good), text
