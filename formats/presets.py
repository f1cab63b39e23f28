"""Sensor mount presets: sonar rings of robots people map with.

``pioneer-p3dx`` is the 16-sonar ring of the Pioneer 2/3-DX in ARIA's geometry
(``p3dx.p`` parameter file): 8 sonars at the front, 8 at the back. Its Polaroid 600-series
transducers have a beam of about 30° full width (our default β) and read 0.1-5 m.
``pioneer-p3dx-front`` is its front array alone (the 8 sonars every P3-DX carries; the
rear 8 are an option). ``udacity-8sonar`` is the ring of udacity/RoboND-OccupancyGridMappingAlgorithm's data
(beam axes −90…90°, usable 0.17-5 m, mounted at the robot centre). ``hc-sr04-sweep3`` is a
hobby robot's single sonar on a servo (an HC-SR04: 15° beam and 0.02-4 m by its datasheet)
0.1 m ahead of the centre, stepping through −40°, 0° and +40°: one mount per bearing.
"""

from __future__ import annotations

from formats.options import MountConfig

_P3DX = [
    (0.069, 0.136, 90),
    (0.114, 0.119, 50),
    (0.148, 0.078, 30),
    (0.166, 0.027, 10),
    (0.166, -0.027, -10),
    (0.148, -0.078, -30),
    (0.114, -0.119, -50),
    (0.069, -0.136, -90),
    (-0.157, -0.136, -90),
    (-0.203, -0.119, -130),
    (-0.237, -0.078, -150),
    (-0.255, -0.027, -170),
    (-0.255, 0.027, 170),
    (-0.237, 0.078, 150),
    (-0.203, 0.119, 130),
    (-0.157, 0.136, 90),
]

_UDACITY = [-90.0, -37.5, -22.5, -7.5, 7.5, 22.5, 37.5, 90.0]

PRESETS: dict[str, tuple[MountConfig, ...]] = {
    "pioneer-p3dx": tuple(
        MountConfig(
            name=f"sonar_{i}", x=x, y=y, yaw_deg=float(a), fov_deg=30.0, min_range=0.1, max_range=5.0
        )
        for i, (x, y, a) in enumerate(_P3DX)
    ),
    "pioneer-p3dx-front": tuple(
        MountConfig(
            name=f"sonar_{i}", x=x, y=y, yaw_deg=float(a), fov_deg=30.0, min_range=0.1, max_range=5.0
        )
        for i, (x, y, a) in enumerate(_P3DX[:8])
    ),
    "udacity-8sonar": tuple(
        MountConfig(name=f"sonar_{i}", x=0.0, y=0.0, yaw_deg=a, fov_deg=20.0, min_range=0.17, max_range=5.0)
        for i, a in enumerate(_UDACITY)
    ),
    "hc-sr04-sweep3": tuple(
        MountConfig(name=f"sweep_{a:+d}", x=0.1, y=0.0, yaw_deg=float(a), fov_deg=15.0, min_range=0.02,
                    max_range=4.0)
        for a in (-40, 0, 40)
    ),
}
