"""The sonar ring simulate and emulate fire from: units, order, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formats.errors import ConfigError
from formats.options import MountConfig
from pipeline.tools.sonar_ring import SonarRing


def test_ring_from_mounts_converts_units() -> None:
    ring = SonarRing.from_mounts(
        [MountConfig("a", 0.1, 0.2, 90.0, 30.0, 0.1, 5.0), MountConfig("b", 0, 0, -45, 20, 0, 3)]
    )
    assert ring.names == ("a", "b") and len(ring) == 2
    np.testing.assert_allclose(ring.x, [0.1, 0.0])
    np.testing.assert_allclose(ring.yaw, [math.pi / 2, -math.pi / 4])
    np.testing.assert_allclose(ring.fov, np.radians([30.0, 20.0]))
    np.testing.assert_allclose(ring.min_range, [0.1, 0.0])
    np.testing.assert_allclose(ring.max_range, [5.0, 3.0])
    back = ring.take(np.array([1, 0]))
    assert back.names == ("b", "a") and back.max_range.tolist() == [3.0, 5.0]


@pytest.mark.parametrize(
    ("mounts", "message"),
    [
        ([], "the sonar ring has no mounts"),
        ([MountConfig("a", fov_deg=10, max_range=1)] * 2, "must be unique and non-empty"),
        ([MountConfig("", fov_deg=10, max_range=1)], "must be unique and non-empty"),
        ([MountConfig("c", fov_deg=0.0, max_range=5.0)], r"sonar c: beam width 0.0° is not in"),
        ([MountConfig("c", fov_deg=180.0, max_range=5.0)], "beam width 180.0°"),
        ([MountConfig("d", fov_deg=30, min_range=2, max_range=1)],
         "sonar d: min range 2 m is not below max range 1 m"),
        ([MountConfig("e", fov_deg=30, max_range=math.inf)], "sonar e: min range"),
    ],
)
def test_ring_from_mounts_refuses(mounts: list[MountConfig], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        SonarRing.from_mounts(mounts)
