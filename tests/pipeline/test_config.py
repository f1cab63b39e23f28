from __future__ import annotations

import tomllib

import pytest

from formats.errors import ConfigError
from pipeline.config import Config, config_from_dict, dump_config, load_config
from pipeline.methods import Method


def test_defaults_are_the_documented_ones():
    c = load_config(None)
    m = c.mapper
    assert (m.sigma_d0, m.k_d, m.c_a, m.match_distance, m.kappa_free) == (0.01, 0.01, 2.0, 0.15, 2.0)
    assert (m.n_particles, m.keep_fraction, m.protect_times) == (200, 0.05, 3)
    assert (m.p_free, m.p_clamp_min, m.p_clamp_max, m.p_occ) == (0.35, 0.12, 0.97, 0.9)
    assert m.clear_on_max_range is False and m.feature_correction is True
    assert c.grid.resolution == 0.05 and c.scans.window_s == 0.2
    assert c.scans.max_travel_m == 0.10 and c.scans.max_turn_deg == 10.0
    assert c.pose_sync.max_pose_gap_s == 0.0  # automatic: from the log's pose rate
    assert m.sigma_floor(0.05) == 0.025


def test_dump_round_trips_through_toml(tmp_path):
    cfg = config_from_dict({"mapper": {"feature_correction": False}, "sensors": {"preset": "pioneer-p3dx",
                            "mounts": [{"name": "s", "x": 0.1, "yaw_deg": 90.0}]}})
    text = dump_config(cfg)
    assert "# N, particles drawn per corrected feature" in text
    p = tmp_path / "c.toml"
    p.write_text(text)
    again = load_config(p)
    assert again == cfg and again.hash() == cfg.hash()
    assert tomllib.loads(dump_config(Config()))["mapper"]["method"] == "forward"


def test_method_is_the_one_typed_choice():
    assert Config().mapper.method is Method.FORWARD
    for m in Method:
        cfg = config_from_dict({"mapper": {"method": m.value}})
        assert cfg.mapper.method is m
        # What the hash, the dump and metrics.json see is the plain name.
        assert cfg.to_dict()["mapper"]["method"] == m.value
        assert f'method = "{m.value}"' in dump_config(cfg).splitlines()
    for bad in ("Classic", "", 3):
        with pytest.raises(ConfigError, match=r"'mapper.method' must be one of "
                           r"\['specular', 'forward', 'attribution', 'andersone', 'classic'\], got "):
            config_from_dict({"mapper": {"method": bad}})


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"mapper": {"bogus": 1}}, r"unknown key 'mapper.bogus'"),
        ({"mapperx": {}}, r"unknown key 'mapperx'"),
        ({"mapper": {"n_particles": "many"}}, r"'mapper.n_particles' must be an integer"),
        ({"mapper": {"feature_correction": 1}}, r"must be true or false"),
        ({"mapper": {"p_free": 0.7}}, r"'mapper.p_free' must be in \(0, 0.5\), got 0.7"),
        ({"mapper": {"p_occ": 1.5}}, r"'mapper.p_occ' must be in \(0.5, 1\), got 1.5"),
        ({"mapper": {"method": "magic"}}, r"'mapper.method' must be one of"),
        ({"grid": {"resolution": 0}}, r"'grid.resolution' must be in \[0.001, 100\] m, got 0"),
        ({"grid": {"extent": [0, 0, -1, 1]}}, r"xmin < xmax"),
        ({"sensors": {"min_range": 3.0, "max_range": 1.0}}, r"min_range' must be < max_range"),
        ({"sensors": {"preset": "roomba"}}, r"'sensors.preset' must be one of"),
        ({"sensors": {"mounts": [{"name": "a"}, {"name": "a"}]}}, r"duplicate names"),
        ({"scans": {"policy": "never"}}, r"'scans.policy' must be one of"),
        ({"pose_refinement": {"field_sigma_m": 0}},
         r"'pose_refinement.field_sigma_m' must be"),
        ({"pose_refinement": {"calibration_max_bias_deg_per_m": 46}},
         r"'pose_refinement.calibration_max_bias_deg_per_m' must be"),
        ({"pose_refinement": {"local_stretch_m": 20}},
         r"unknown key 'pose_refinement.local_stretch_m'"),
    ],
)
def test_bad_values_are_refused_with_the_key(data, message):
    with pytest.raises(ConfigError, match=message):
        config_from_dict(data)


def test_file_errors_name_the_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[mapper\n")
    with pytest.raises(ConfigError, match=r"bad\.toml: invalid TOML"):
        load_config(p)
    p.write_text("[mapper]\nk_d = -1\n")
    with pytest.raises(ConfigError, match=r"bad\.toml: 'mapper.k_d' must be in \[0, 1\], got -1"):
        load_config(p)
    with pytest.raises(ConfigError, match=r"missing\.toml: configuration file not found"):
        load_config(tmp_path / "missing.toml")


def test_refinement_reaches_the_farther_of_its_matched_and_scale_echoes():
    pr = Config().pose_refinement
    assert (pr.max_echo_range_m, pr.calibration_far_range_m, pr.echo_reach_m) == (3.0, 5.0, 5.0)
    near_only = config_from_dict({"pose_refinement": {"calibration_far_range_m": 0.0}})
    assert near_only.pose_refinement.echo_reach_m == 3.0


def test_every_numeric_key_has_a_physical_range_and_the_defaults_lie_in_it():
    from formats.options import MountConfig, SensorsConfig
    from pipeline.config import RANGES, GridConfig, numeric_keys

    cfg = Config(sensors=SensorsConfig(mounts=(MountConfig("a"),)),
                 grid=GridConfig(extent=(0.0, 0.0, 1.0, 1.0)))
    found = {generic: value for _, generic, value in numeric_keys(cfg)}
    assert set(found) == set(RANGES)  # every key has one, no range names a missing key
    outside = {k: v for k, v in found.items() if k != "grid.extent" and not RANGES[k].holds(v)}
    assert outside == {}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"pose_sync": {"time_offset_s": 1e10}},
         r"'pose_sync.time_offset_s' must be in \[-4e\+09, 4e\+09\] s, got 10000000000.0"),
        ({"pose_sync": {"max_pose_gap_s": 1e300}},
         r"'pose_sync.max_pose_gap_s' must be in \[0, 86400\] s \(0 = automatic\)"),
        ({"scans": {"window_s": 1e12}}, r"'scans.window_s' must be in \[1e-06, 3600\] s"),
        ({"mapper": {"n_particles": 10**12}}, r"'mapper.n_particles' must be in \[3, 100000\]"),
        ({"mapper": {"attr_threshold": -0.5}}, r"'mapper.attr_threshold' must be in \[0, 1e\+06\]"),
        ({"mapper": {"attr_free_weight": -1}}, r"'mapper.attr_free_weight' must be in"),
        ({"mapper": {"p_clamp_max": 0.4}}, r"'mapper.p_clamp_max' must be in \(0.5, 1\)"),
        ({"mapper": {"sigma_d0": 0}}, r"'mapper.sigma_d0' must be in \(0, 1\] m"),
        ({"mapper": {"attr_dilution": 2}}, r"'mapper.attr_dilution' must be in \[0, 1\]"),
        ({"grid": {"max_cells": 2**40}}, r"'grid.max_cells' must be in \[1, 2\*\*31 - 1\]"),
        ({"input": {"csv": {"no_echo_value": 1e300}}}, r"'input.csv.no_echo_value' must be in"),
        ({"sensors": {"mounts": [{"name": "a"}, {"name": "b", "x": 1e300}]}},
         r"'sensors.mounts\[1\].x' must be in \[-100, 100\] m, got 1e\+300"),
        ({"grid": {"extent": [0, 0, 1e300, 1]}}, r"'grid.extent\[2\]' must be in \[-1e\+07, 1e\+07\] m"),
        ({"sensors": {"mounts": [{"name": "s" * 300}]}}, r"name' must be at most 256 characters"),
    ],
)
def test_numbers_beyond_their_physical_range_are_refused_naming_the_key(data, message):
    with pytest.raises(ConfigError, match=message):
        config_from_dict(data)
