"""The one reading of [sensors]: entries, per-field limits, defaults and the ring."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formats.options import MountConfig, SensorsConfig
from formats.presets import PRESETS
from formats.sensor_config import BeamLimits, sensor_setup

NAN = math.nan


def test_nothing_configured() -> None:
    setup = sensor_setup(SensorsConfig())
    assert setup.entry("sonar_0") is None
    assert all(math.isnan(v) for v in setup.configured_limits("sonar_0").as_tuple())
    assert setup.ring() is None


def test_explicit_entry_replaces_the_preset_entry_whole() -> None:
    cfg = SensorsConfig(
        preset="udacity-8sonar",
        mounts=(MountConfig(name="sonar_1", x=0.5, yaw_deg=90.0, max_range=3.0),),
    )
    setup = sensor_setup(cfg)
    one = setup.entry("sonar_1")
    assert one is not None and one.source == "config"
    assert (one.mount.x, one.mount.y, one.mount.yaw) == (0.5, 0.0, pytest.approx(math.pi / 2))
    # the preset's fov and r_min are not inherited: 0 means "not configured"
    lim = setup.configured_limits("sonar_1")
    assert math.isnan(lim.fov) and math.isnan(lim.min_range) and lim.max_range == 3.0
    zero = setup.entry("sonar_0")
    assert zero is not None and zero.source == "preset:udacity-8sonar"
    assert setup.configured_limits("sonar_0").as_tuple() == pytest.approx(
        (math.radians(20.0), 0.17, 5.0)
    )


def test_defaults_fill_each_unconfigured_limit_on_its_own() -> None:
    cfg = SensorsConfig(
        fov_deg=30.0, min_range=0.2, max_range=4.0, mounts=(MountConfig(name="a", min_range=0.5),)
    )
    setup = sensor_setup(cfg)
    assert setup.defaults.as_tuple() == pytest.approx((math.radians(30.0), 0.2, 4.0))
    assert setup.configured_limits("a").as_tuple() == pytest.approx((math.radians(30.0), 0.5, 4.0))
    assert setup.configured_limits("other").as_tuple() == pytest.approx(
        (math.radians(30.0), 0.2, 4.0)
    )


def test_beam_limits_or_else_is_per_field() -> None:
    got = BeamLimits(1.0, NAN, NAN).or_else(BeamLimits(2.0, 3.0, NAN)).as_tuple()
    assert got[:2] == (1.0, 3.0) and math.isnan(got[2])


def test_ring_is_the_explicit_mounts_in_file_order_else_the_preset() -> None:
    mounts = (
        MountConfig(name="z", x=1.0, y=2.0, fov_deg=10.0),
        MountConfig(name="a", x=-1.0, y=0.0),
    )
    ring = sensor_setup(SensorsConfig(preset="pioneer-p3dx", max_range=6.0, mounts=mounts)).ring()
    assert ring is not None and ring.names == ("z", "a") and ring.origin == "sensors.mounts"
    assert ring.x.tolist() == [1.0, -1.0] and ring.y.tolist() == [2.0, 0.0]
    assert ring.fov[0] == pytest.approx(math.radians(10.0)) and math.isnan(ring.fov[1])
    assert ring.max_range.tolist() == [6.0, 6.0]  # the [sensors] default
    preset = sensor_setup(SensorsConfig(preset="pioneer-p3dx")).ring()
    assert preset is not None and preset.origin == "preset 'pioneer-p3dx'"
    assert preset.names == tuple(m.name for m in PRESETS["pioneer-p3dx"])
    assert np.allclose(preset.y, [m.y for m in PRESETS["pioneer-p3dx"]])
    assert np.allclose(preset.min_range, 0.1) and np.allclose(preset.fov, math.radians(30.0))
    front = sensor_setup(SensorsConfig(preset="pioneer-p3dx-front")).ring()
    assert front is not None and front.names == preset.names[:8]  # the front array alone
    assert np.allclose(front.x, preset.x[:8]) and np.allclose(front.y, preset.y[:8])
    assert [m.yaw_deg for m in PRESETS["pioneer-p3dx-front"]] == [90, 50, 30, 10, -10, -30,
                                                                 -50, -90]
    sweep = sensor_setup(SensorsConfig(preset="hc-sr04-sweep3")).ring()
    assert sweep is not None and sweep.names == ("sweep_-40", "sweep_+0", "sweep_+40")
    assert np.allclose(sweep.x, 0.1) and np.allclose(sweep.y, 0.0)  # one sonar, three bearings
    assert np.allclose(sweep.fov, math.radians(15.0)) and np.allclose(sweep.max_range, 4.0)


def test_ring_mounts_are_the_configured_entries_as_written() -> None:
    mounts = (MountConfig(name="a", x=0.2), MountConfig(name="b", yaw_deg=45.0))
    assert sensor_setup(SensorsConfig(preset="udacity-8sonar", mounts=mounts)).ring_mounts == mounts
    preset = sensor_setup(SensorsConfig(preset="udacity-8sonar")).ring_mounts
    assert preset == PRESETS["udacity-8sonar"]
    assert sensor_setup(SensorsConfig()).ring_mounts == ()
