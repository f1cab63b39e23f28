"""Issue 58, items 3, 5 and 6: ``evaluate -o`` never replaces an input or a file sonarmap did
not write; side files (configuration, truth map and its image, tolerances, golden maps,
manifests, worlds) must be regular files within a cap, and what a header declares or two
maps span is checked against ``[grid] max_cells`` before anything is allocated."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.app import app
from fuzz.harness import ROOT

OFFICE = ROOT / "sample_logs" / "office"


def _cli(*args: str | Path) -> tuple[int, str]:
    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res.exit_code, res.stderr


@pytest.fixture(scope="module")
def office_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("side")
    for f in OFFICE.glob("office.truth.*"):
        shutil.copy(f, d)
    code, err = _cli("run", OFFICE / "office.mcap", "-o", d / "run", "-q")
    assert code == 0, err
    return d


def _bytes(d: Path) -> dict[str, bytes]:
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*"))
            if p.is_file()}


def test_evaluate_output_never_replaces_an_input_or_a_users_file(office_run: Path) -> None:
    d = office_run
    truth = d / "office.truth.yaml"
    (d / "notes.json").write_text('{"mine": 1}\n')
    before = _bytes(d)
    cases = {
        truth: f"{truth}: is the truth map, an input of this command",
        d / "office.truth.pgm": f"{d / 'office.truth.pgm'}: is the truth map's image, an input",
        d / "run" / "metrics.json": "is inside the run directory, an input of this command",
        d / "notes.json": f"{d / 'notes.json'}: exists and sonarmap did not write it; not "
                          "replacing it, choose another output file",
    }
    for out, message in cases.items():
        for force in ((), ("--force",)):
            code, err = _cli("evaluate", d / "run", "--truth", truth, "-o", out, *force)
            assert code == 1 and err.count("\n") == 1 and message in err, err
            assert "--force" not in err
    assert _bytes(d) == before
    # Its own earlier evaluation: --force is suggested, and replaces it.
    assert _cli("evaluate", d / "run", "--truth", truth, "-o", d / "ev.json")[0] == 0
    code, err = _cli("evaluate", d / "run", "--truth", truth, "-o", d / "ev.json")
    assert code == 1 and "(an earlier sonarmap output); use --force to replace it" in err
    assert _cli("evaluate", d / "run", "--truth", truth, "-o", d / "ev.json", "--force")[0] == 0
    (d / "ev.json").unlink()
    (d / "notes.json").unlink()


@pytest.mark.parametrize("kind", ["fifo", "dir", "dev", "big"])
def test_side_files_must_be_regular_and_within_their_cap(
    office_run: Path, tmp_path: Path, kind: str
) -> None:
    """Every side file, through each command that reads one: refused in one line, without
    blocking (a FIFO nobody writes) or reading /dev/zero forever."""
    bad = tmp_path / "side"
    if kind == "fifo":
        os.mkfifo(bad)
        what = "is a FIFO, not a regular file"
    elif kind == "dir":
        bad.mkdir()
        what = "is a directory, not a regular file"
    elif kind == "dev":
        bad = Path("/dev/zero")
        what = "is a device, not a regular file"
    else:
        with bad.open("wb") as f:  # sparse: 400 MiB of size, no disk
            f.truncate(400 << 20)
        what = "is too large (400 MiB; at most"
    d = office_run
    run, truth = d / "run", d / "office.truth.yaml"
    commands = [
        ("run", OFFICE / "office.mcap", "-o", tmp_path / "o", "-c", bad),
        ("evaluate", run, "--truth", bad),
        ("evaluate", run, "--truth", truth, "--trajectory", bad),
        ("regress", run, "--golden", run, "--tolerances", bad),
        ("batch", f"@{bad}", "-o", tmp_path / "b"),
        ("simulate", bad, "-o", tmp_path / "s.mcap"),
    ]
    image_yaml = tmp_path / "m.yaml"
    image_yaml.write_text(truth.read_text().replace("office.truth.pgm", str(bad)))
    commands.append(("evaluate", run, "--truth", image_yaml))
    for args in commands:
        code, err = _cli(*args)
        assert code == 1, (args, err)
        assert err.count("\n") == 1 and f"{bad}: " in err and what in err, (args, err)
    assert not (tmp_path / "o").exists() and not (tmp_path / "s.mcap").exists()


def test_a_truth_image_declaring_a_huge_size_is_refused_before_reading_it(
    office_run: Path, tmp_path: Path
) -> None:
    pgm = tmp_path / "huge.pgm"
    pgm.write_bytes(b"P5\n100000 100000\n255\n" + b"\0" * 64)
    yaml = tmp_path / "huge.yaml"
    yaml.write_text((office_run / "office.truth.yaml").read_text()
                    .replace("office.truth.pgm", "huge.pgm"))
    code, err = _cli("evaluate", office_run / "run", "--truth", yaml)
    assert code == 1
    assert err == (f"sonarmap: error: {pgm}: map image declares 100000x100000 pixels, more "
                   "than grid.max_cells = 40000000\n")


def test_a_truth_map_far_from_the_run_obeys_max_cells(office_run: Path, tmp_path: Path) -> None:
    """Issue 58 item 6: the grid covering both maps is checked before it is allocated."""
    d = office_run
    far = d / "far.truth.yaml"
    far.write_text((d / "office.truth.yaml").read_text().replace(
        "origin: [", "origin: [100000.0, 100000.0, 0.0] #"))
    code, err = _cli("evaluate", d / "run", "--truth", far)
    assert code == 1 and err.count("\n") == 1
    assert "the grid covering the run and the truth map would have" in err
    assert "more than grid.max_cells = 40000000" in err


def test_a_yaml_1_1_string_number_is_a_number(office_run: Path) -> None:
    """``resolution: 5e-2`` is a string to YAML 1.1 and a number to map_server."""
    d = office_run
    text = (d / "office.truth.yaml").read_text()
    assert "resolution: 0.05" in text
    (d / "e.truth.yaml").write_text(text.replace("resolution: 0.05", "resolution: 5e-2"))
    code, err = _cli("evaluate", d / "run", "--truth", d / "e.truth.yaml", "--json")
    assert code == 0, err
