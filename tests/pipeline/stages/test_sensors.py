"""Sensor resolution against a log: mount precedence, beam-limit overrides, missing mounts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formats.contract import SensorMount, make_range_batch
from formats.errors import InputError
from pipeline.config import config_from_dict
from pipeline.stages.sensors import resolve_sensors

LOG_MOUNT = SensorMount(0.3, 0.0, 0.0)

def test_mount_precedence_config_then_log_then_preset_then_base_frame() -> None:
    cfg = config_from_dict(
        {
            "sensors": {
                "preset": "udacity-8sonar",
                "mounts": [{"name": "sonar_0", "x": 1.0, "y": 2.0, "yaw_deg": 90.0}],
            }
        }
    )
    names = ["sonar_0", "sonar_1", "sonar_2", "base_link"]
    log = {"sonar_0": LOG_MOUNT, "sonar_1": LOG_MOUNT}
    table = resolve_sensors(names, log, cfg)
    assert table.source == ("config", "log", "preset:udacity-8sonar", "base_frame")
    assert table.mount_x.tolist() == [1.0, 0.3, 0.0, 0.0]
    assert table.mount_y.tolist() == [2.0, 0.0, 0.0, 0.0]
    assert table.mount_yaw[0] == pytest.approx(math.pi / 2)
    assert table.mount_yaw[2] == pytest.approx(math.radians(-22.5))  # udacity's third beam

def test_configured_limits_override_the_log_and_defaults_fill_gaps() -> None:
    cfg = config_from_dict(
        {
            "sensors": {
                "max_range": 4.0,
                "mounts": [{"name": "a", "fov_deg": 20.0}, {"name": "b", "min_range": 0.3}],
            }
        }
    )
    table = resolve_sensors(["a", "b"], {}, cfg)
    nan = math.nan
    batch = make_range_batch(
        t_ns=[1, 2, 3],
        sensor_id=[0, 1, 1],
        range_m=[1.0, 1.0, 1.0],
        fov_rad=[0.9, 0.9, nan],
        min_range_m=[0.1, 0.1, nan],
        max_range_m=[5.0, nan, nan],
    )
    fov, lo, hi = table.apply_limits(batch)
    assert fov.tolist() == pytest.approx([math.radians(20.0), 0.9, nan], nan_ok=True)
    assert lo.tolist() == [0.1, 0.3, 0.3]
    assert hi.tolist() == [5.0, 4.0, 4.0]

def test_a_used_sensor_without_mount_is_an_input_error_naming_it() -> None:
    cfg = config_from_dict({})
    with pytest.raises(InputError, match=r"no mount for range sensor\(s\) /sonar_front"):
        resolve_sensors(["/sonar_front", "/sonar_back"], {}, cfg, used=[True, False])
    table = resolve_sensors(["/sonar_front"], {}, cfg, used=[False])
    assert table.source == ("missing",) and np.isnan(table.mount_x[0])
