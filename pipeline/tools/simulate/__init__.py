"""The sonar simulator: worlds, trajectories, a sonar ring's physics, simulated logs."""

from __future__ import annotations

from formats.writers.trajectory_tum import Trajectory
from pipeline.tools.simulate.simulate import (
    SimOptions,
    SimRanges,
    SimulatedLog,
    run_simulation,
    simulate,
    truth_paths,
    write_simulation,
)
from pipeline.tools.simulate.trajectory import load_waypoints
from pipeline.tools.simulate.world import World, load_world, world_from_occupancy

__all__ = [
    "SimOptions",
    "SimRanges",
    "SimulatedLog",
    "Trajectory",
    "World",
    "load_waypoints",
    "load_world",
    "run_simulation",
    "simulate",
    "truth_paths",
    "world_from_occupancy",
    "write_simulation",
]
