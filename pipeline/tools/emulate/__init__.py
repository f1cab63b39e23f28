"""Emulate a sonar ring from real laser scans (``sonarmap emulate``).

Each virtual sonar of a ring reads, per laser scan, what the sonar physics model hears
from the laser's surfaces in its beam (``sonar_model="realistic"``, the default:
:mod:`pipeline.tools.sonar`, docs/SONAR_PHYSICS.md), or with the ideal sonar the
**shortest laser return inside its cone**: laser endpoints are put in the robot base
frame, and those whose bearing from the sonar's origin is within ±β/2 of its axis give the
reading (their minimum distance from the sonar). No echo reads the maximum range (the
mapper's "no echo"); an echo closer than the sonar's minimum range reads −inf (REP 117,
too close). Laser readings at or above the laser's maximum, below its minimum, or not
finite are not echoes. ``firing_rate_hz`` fires the ring at its real rate into the laser
map instead (:mod:`.firing`).

Only sonars the laser can see for are emitted: a sonar whose beam axis, followed to its
maximum range, lies outside the laser's field of view is dropped (with a Pioneer ring and a
180° front laser: the 8 front sonars). The two side sonars (±90°) then have part of their
cone outside the laser's view, so their readings can be too long there; the emulation
notes say how much. ``require_full_cone`` keeps only sonars whose whole cone is seen.

Inputs: CARMEN logs (``FLASER``, :mod:`formats.carmen`; the robot poses are the logged,
SLAM-corrected laser poses moved to the base by the laser offset, frame ``map``) and
``sensor_msgs/LaserScan`` in ROS 1 / ROS 2 bags and MCAP files (poses from the log's
Odometry or tf through the ROS reader, interpolated at the scan stamps; the laser mount
from ``/tf_static``, else the base origin). Scans are sorted by stamp.

Outputs (:func:`write_emulation`): the sonar log in any format of
:mod:`formats.log_writers` (one Range per emitted sonar per scan, at the scan's stamp;
Odometry from the scan poses; ``/tf_static`` mounts), the **laser occupancy map** as the
reference ``<stem>.laser.yaml/.pgm`` (log-odds of every laser beam ray-cast from the laser
pose, nav2 trinary) and the trajectory ``<stem>.truth.csv`` (``t,x,y,yaw``).
"""

from __future__ import annotations

from formats.laser_log import LaserLog
from pipeline.tools.emulate.emulation import Emulation, emulate, emulate_ranges
from pipeline.tools.emulate.laser_input import load_laser_log
from pipeline.tools.emulate.laser_map import LaserMap, LaserMapOptions, laser_occupancy_map
from pipeline.tools.emulate.ring import (
    DEFAULT_FOV_DEG,
    DEFAULT_MAX_RANGE_M,
    cone_coverage,
    laser_view,
    mounts_from_config,
    ring_from_mounts,
)
from pipeline.tools.emulate.run import (
    EmulateOptions,
    EmulationResult,
    output_paths,
    run_emulation,
    write_emulation,
)
from pipeline.tools.sonar_ring import SonarRing

__all__ = [
    "DEFAULT_FOV_DEG",
    "DEFAULT_MAX_RANGE_M",
    "EmulateOptions",
    "Emulation",
    "EmulationResult",
    "LaserLog",
    "LaserMap",
    "LaserMapOptions",
    "SonarRing",
    "cone_coverage",
    "emulate",
    "emulate_ranges",
    "laser_occupancy_map",
    "laser_view",
    "load_laser_log",
    "mounts_from_config",
    "output_paths",
    "ring_from_mounts",
    "run_emulation",
    "write_emulation",
]
