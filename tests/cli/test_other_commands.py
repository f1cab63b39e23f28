"""`info`, `validate`, `config`, `simulate`, `--version`, `--help`."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest

from cli.app import app
from pipeline import __version__
from pipeline.config import Config, dump_config

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def test_version(runner):
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.strip() == f"sonarmap {__version__}"


@pytest.mark.parametrize("command", ["run", "info", "validate", "config", "simulate", "emulate", "evaluate", "regress", "batch"])
def test_every_command_has_help_with_examples(runner, command):
    result = runner.invoke(app, [command, "--help"])
    assert result.exit_code == 0
    assert "Examples:" in result.output and "sonarmap " + command in result.output


@pytest.mark.parametrize("command", ["run", "info", "validate", "config", "simulate", "emulate", "evaluate", "regress", "batch"])
def test_help_shows_values_as_words(runner, command):
    """No type placeholders (<path>, <list[str]>, <float>) or {braces}: words like LOG, OUT."""
    result = runner.invoke(app, [command, "--help"], terminal_width=120)
    usage = result.output.splitlines()[0]
    assert "{" not in usage and "<" not in usage
    options = result.output[result.output.index("Options:"):]
    assert not re.search(r"<(path|file|str|int|float|list\[str\]|directory)>", result.output), options
    if command in ("run", "info", "validate"):
        assert usage.endswith(" LOG...")  # one log, or the files of one recording


def test_run_help_names_its_values_and_shows_defaults(runner):
    out = runner.invoke(app, ["run", "--help"], terminal_width=200).output
    assert "Usage: sonarmap run [OPTIONS] LOG" in out
    for line in ("-o, --output OUT", "-c, --config FILE", "--range-topic TOPIC", "--pose-topic TOPIC",
                 "-f, --format FORMAT", "-r, --resolution METRES"):
        assert line in out, line
    assert "[default: ([grid] resolution, 0.05)]" in out
    assert "[default: ([mapper] method, specular)]" in out
    assert "[default: (detected from the content)]" in out


def test_validate_lists_sensors_in_natural_order(runner):
    out = runner.invoke(app, ["validate", str(SAMPLES / "office" / "office.mcap"), "--json"]).output
    names = [s["name"] for s in json.loads(out)["sensors"]]
    assert names == [f"sonar_{i}" for i in range(16)]


def test_config_prints_the_defaults_as_commented_toml(runner):
    result = runner.invoke(app, ["config"])
    assert result.exit_code == 0
    assert result.output == dump_config(Config())
    assert tomllib.loads(result.output)["mapper"]["n_particles"] == 200


def test_info_lists_topics_and_counts(runner):
    result = runner.invoke(app, ["info", str(SAMPLES / "office" / "office.bag"), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    counts = {t["name"]: t["count"] for t in info["topics"]}
    assert counts["/tf_static"] == 1 and counts["/sonar"] > 1000 and counts["/odom"] > 100
    assert info["format"] == "ros1" and info["range_topics"] == ["/sonar"] and info["pose_topic"] == "/odom"
    table = runner.invoke(app, ["info", str(SAMPLES / "office" / "office.mcap")])
    assert "sensor_msgs/msg/Range" in table.output and "Duration:" in table.output


def test_validate_clean_log_exits_0_and_broken_exits_1(runner, tmp_path):
    clean = runner.invoke(app, ["validate", str(SAMPLES / "office" / "office.mcap")])
    assert clean.exit_code == 0, clean.output
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x,y,yaw,sensor,range\n1,0,0,0,s,nan\n2,0,0,0,s,1.0\n1.5,0,0,0,s,-2\n")
    broken = runner.invoke(app, ["validate", str(bad), "--json"])
    assert broken.exit_code == 1
    codes = {f["code"] for f in json.loads(broken.output)["findings"]}
    assert {"nan_readings", "negative_readings", "stamps_backwards", "unmounted_sensor"} <= codes


def test_simulate_writes_log_and_truth_and_refuses_to_overwrite(runner, tmp_path):
    out = tmp_path / "c.mcap"
    args = ["simulate", str(SAMPLES / "worlds" / "corridor.toml"), "-o", str(out), "--ring-rate", "2"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert {p.name for p in tmp_path.iterdir()} == {"c.mcap", "c.truth.yaml", "c.truth.pgm", "c.truth.csv"}
    again = runner.invoke(app, args)
    assert again.exit_code == 1 and "exists already" in again.output


def test_validate_a_real_log_without_poses_reports_instead_of_crashing(runner):
    tiago = Path(__file__).resolve().parents[1] / "data" / "ros1" / "tiago-sonar.bag"
    result = runner.invoke(app, ["validate", str(tiago), "--json"])
    assert result.exit_code == 1
    report = json.loads(result.output)
    codes = [f["code"] for f in report["findings"]]
    assert "no_poses" in codes and codes.count("unmounted_sensor") == 3


def test_info_prints_exact_nanosecond_stamps(runner):
    tiago = Path(__file__).resolve().parents[1] / "data" / "ros1" / "tiago-sonar.bag"
    result = runner.invoke(app, ["info", str(tiago)])
    assert result.exit_code == 0
    start = next(line for line in result.output.splitlines() if line.startswith("Start:"))
    # Same nanoseconds in the calendar time and in the epoch seconds.
    frac = start.split(".")[1][:9]
    assert start.rstrip(")").endswith(frac)
    assert "609 msgs" in result.output


def test_simulate_ideal_sonar_is_the_sample_log_and_realistic_is_the_default(runner, tmp_path):
    # sample_logs/regenerate.sh's office run, with the ideal sonar: the committed bytes.
    common = ["simulate", str(SAMPLES / "worlds" / "office.toml"), "--speed", "0.5",
              "--ring-rate", "5", "--seed", "1", "-f", "mcap", "--compression", "zstd"]
    ideal = tmp_path / "ideal.mcap"
    assert runner.invoke(app, [*common, "-o", str(ideal), "--sonar-model", "ideal"]).exit_code == 0
    assert ideal.read_bytes() == (SAMPLES / "office" / "office.mcap").read_bytes()
    real = tmp_path / "real.mcap"
    assert runner.invoke(app, [*common, "-o", str(real)]).exit_code == 0
    assert real.read_bytes() != ideal.read_bytes()
    bad = runner.invoke(app, [*common, "-o", str(tmp_path / "x.mcap"), "--sonar-param", "k_d=7"])
    assert bad.exit_code == 1 and "'k_d' must be in [0, 1]" in bad.output
