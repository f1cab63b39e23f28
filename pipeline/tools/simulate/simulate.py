"""Simulate a sonar log: a robot drives through waypoints in a world, its ring fires.

``simulate`` is pure numpy and seeded: every random draw comes from one
``np.random.Generator(PCG64(seed))`` in a fixed order, so the same inputs give the same
arrays. ``write_simulation`` writes the log (any format of :mod:`formats.log_writers`)
plus the ground truth next to it: ``<stem>.truth.yaml/.pgm`` (nav2 map) and
``<stem>.truth.csv`` (true trajectory ``t,x,y,yaw``).

Frames (REP 105): the logged poses are ``odom → base_link``; ``odom`` coincides with the
world frame at the start, so with drift off the logged poses equal the true ones. With
drift on (:mod:`pipeline.drift`: scale error, heading bias per metre, noise per step) the
log carries the drifted odometry and ``<stem>.truth.csv`` the true trajectory.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from formats.arrays import F64, I32, I64
from formats.contract import PoseBatch, SensorMount, make_range_batch
from formats.errors import ConfigError
from formats.log_writers import LogContent
from formats.options import MountConfig
from formats.presets import PRESETS
from formats.writers.trajectory_tum import Trajectory
from pipeline.config import MapperConfig
from pipeline.drift import DriftModel, apply_drift
from pipeline.tools.log_with_reference import reference_paths, write_log_with_reference
from pipeline.tools.simulate.sonar import add_sensor_errors, firing_schedule, true_ranges
from pipeline.tools.simulate.trajectory import load_waypoints, plan_motion, sample_trajectory
from pipeline.tools.simulate.world import World, load_world
from pipeline.tools.sonar.echo import readings
from pipeline.tools.sonar.model import SonarPhysics, check_model_name
from pipeline.tools.sonar.world_scene import world_fans
from pipeline.tools.sonar_ring import SonarRing

_MAPPER = MapperConfig()


@dataclass(frozen=True)
class SimOptions:
    """Everything the simulator needs besides the world and the waypoints."""

    seed: int = 0
    start_ns: int = 1_700_000_000_000_000_000  # an epoch time, so ROS tools show a date
    pose_rate_hz: float = 20.0
    speed: float = 0.3  # m/s
    turn_rate: float = 0.6  # rad/s, turning in place at waypoints
    ring_rate_hz: float = 10.0  # full ring revolutions per second
    mounts: tuple[MountConfig, ...] = field(default_factory=lambda: PRESETS["pioneer-p3dx"])
    specular_cutoff_deg: float = 60.0
    ray_step_deg: float = 1.0  # spacing of the rays cast across a cone
    sigma_d0: float = _MAPPER.sigma_d0  # m
    k_d: float = _MAPPER.k_d
    p_miss: float = 0.02
    p_crosstalk: float = 0.01
    drift_xy: float = 0.0  # std of position error after 1 m travelled, m (grows as √m)
    drift_yaw: float = 0.0  # std of yaw error after 1 rad turned, rad (grows as √rad)
    drift_scale: float = 0.0  # odometry scale error (0.03: 3 % too long), see pipeline.drift
    drift_heading_bias_deg_per_m: float = 0.0  # odometry heading bias, deg per metre driven
    drift_heading_walk: float = 0.0  # heading random walk, rad per √m driven
    drift_slips_per_100m: float = 0.0  # wheel slips per 100 m (see pipeline.drift)
    drift_slip_yaw_deg: float = 0.0  # std of one slip's heading error, deg
    drift_slip_scale: float = 0.0  # std of one slip's scale error, fraction
    truth_resolution: float = 0.05  # m, cell size of the ground-truth map
    # The sonar: "realistic" (pipeline.tools.sonar with ``physics``) or "ideal" (the
    # closest echo under one specular cut-off, with the noise, misses and crosstalk above).
    sonar_model: str = "realistic"
    physics: SonarPhysics = field(default_factory=SonarPhysics)

    @property
    def drift(self) -> DriftModel:
        """The odometry drift model of these options (:mod:`pipeline.drift`)."""
        return DriftModel(
            scale_error=self.drift_scale,
            heading_bias_deg_per_m=self.drift_heading_bias_deg_per_m,
            noise_xy=self.drift_xy,
            noise_yaw=self.drift_yaw,
            heading_walk=self.drift_heading_walk,
            slips_per_100m=self.drift_slips_per_100m,
            slip_yaw_deg=self.drift_slip_yaw_deg,
            slip_scale=self.drift_slip_scale,
        )

    def with_drift(self, model: DriftModel) -> SimOptions:
        """These options with ``model``'s drift terms."""
        return dataclasses.replace(
            self, drift_scale=model.scale_error,
            drift_heading_bias_deg_per_m=model.heading_bias_deg_per_m, drift_xy=model.noise_xy,
            drift_yaw=model.noise_yaw, drift_heading_walk=model.heading_walk,
            drift_slips_per_100m=model.slips_per_100m, drift_slip_yaw_deg=model.slip_yaw_deg,
            drift_slip_scale=model.slip_scale)

    def validate(self) -> SimOptions:
        """Raise ConfigError naming the option when a value is out of range."""
        checks = [
            (self.pose_rate_hz > 0, "pose_rate_hz", "> 0"),
            (self.speed > 0, "speed", "> 0"),
            (self.turn_rate > 0, "turn_rate", "> 0"),
            (self.ring_rate_hz > 0, "ring_rate_hz", "> 0"),
            (0 < self.specular_cutoff_deg <= 90, "specular_cutoff_deg", "in (0, 90]"),
            (0 < self.ray_step_deg <= 10, "ray_step_deg", "in (0, 10]"),
            (self.sigma_d0 >= 0, "sigma_d0", ">= 0"),
            (self.k_d >= 0, "k_d", ">= 0"),
            (0 <= self.p_miss <= 1, "p_miss", "in [0, 1]"),
            (0 <= self.p_crosstalk <= 1, "p_crosstalk", "in [0, 1]"),
            (self.drift_xy >= 0, "drift_xy", ">= 0"),
            (self.drift_yaw >= 0, "drift_yaw", ">= 0"),
            (self.truth_resolution > 0, "truth_resolution", "> 0"),
        ]
        self.drift.validate()
        check_model_name(self.sonar_model)
        self.physics.validate()
        for ok, key, rule in checks:
            if not ok:
                raise ConfigError(
                    f"simulation option '{key}' must be {rule}, got {getattr(self, key)!r}"
                )
        return self


@dataclass(frozen=True)
class SimRanges:
    """Simulated readings in firing order: time (ns), sensor index, range (m).

    ``range_m`` is what the log carries (float32-representable, REP 117 values);
    ``true_range_m`` the noise-free echo distance (+inf: no echo within r_max).
    ``scan_id`` numbers the ring revolutions.
    """

    t_ns: I64
    sensor: I32
    range_m: F64
    true_range_m: F64
    scan_id: I64

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])


@dataclass(frozen=True)
class SimulatedLog:
    """A simulated run: readings, logged (odometry) and true poses, mounts and world."""

    ranges: SimRanges
    sensor_names: tuple[str, ...]
    mounts: tuple[MountConfig, ...]
    poses: Trajectory  # logged: odom → base_link
    true_poses: Trajectory  # world → base_link
    world: World
    options: SimOptions
    parent_frame: str = "odom"
    child_frame: str = "base_link"

    def to_content(self) -> LogContent:
        """The log as the writers take it (mount angles in rad, limits per reading)."""
        ring = SonarRing.from_mounts(self.mounts)
        s = self.ranges.sensor
        ranges = make_range_batch(
            self.ranges.t_ns,
            s,
            self.ranges.range_m,
            ring.fov[s],
            ring.min_range[s],
            ring.max_range[s],
            scan_id=self.ranges.scan_id,
        )
        poses = PoseBatch(
            self.poses.t_ns.copy(),
            self.poses.x.copy(),
            self.poses.y.copy(),
            self.poses.yaw.copy(),
            self.parent_frame,
            self.child_frame,
        )
        mounts = {
            name: SensorMount(float(ring.x[i]), float(ring.y[i]), float(ring.yaw[i]))
            for i, name in enumerate(ring.names)
        }
        return LogContent(ranges=ranges, sensor_names=self.sensor_names, poses=poses, mounts=mounts)


def simulate(
    world: World, waypoints: npt.ArrayLike, options: SimOptions | None = None
) -> SimulatedLog:
    """Drive through ``waypoints`` (N×2, m) in ``world`` and fire the sonar ring."""
    opt = (options or SimOptions()).validate()
    ring = SonarRing.from_mounts(opt.mounts)
    rng = np.random.Generator(np.random.PCG64(opt.seed))
    plan = plan_motion(waypoints, opt.speed, opt.turn_rate)
    truth = sample_trajectory(plan, opt.pose_rate_hz, opt.start_ns)
    t_ns, sensor = firing_schedule(len(ring), opt.ring_rate_hz, opt.start_ns, int(truth.t_ns[-1]))
    # True pose at each reading, then the sonar origin and axis in the world (ALGORITHM §1).
    px, py, pyaw = plan.pose_at((t_ns - opt.start_ns) / 1e9)
    c, s = np.cos(pyaw), np.sin(pyaw)
    mx, my = ring.x[sensor], ring.y[sensor]
    ox = px + c * mx - s * my
    oy = py + s * mx + c * my
    alpha = pyaw + ring.yaw[sensor]
    if opt.sonar_model == "realistic":
        fan = world_fans(world, ox, oy, alpha, ring.max_range[sensor], opt.physics, opt.seed,
                         ray_step_rad=math.radians(opt.ray_step_deg))
        echoes = readings(fan, ring.min_range[sensor], ring.max_range[sensor], opt.physics, rng)
        measured = echoes.range_m
        first = echoes.first_echo_m
        d_true = np.where(first < ring.max_range[sensor], first, np.inf)
    else:
        d_true = true_ranges(
            world,
            ox,
            oy,
            alpha,
            ring.fov[sensor],
            ring.max_range[sensor],
            ray_step_rad=math.radians(opt.ray_step_deg),
            specular_cutoff_rad=math.radians(opt.specular_cutoff_deg),
        )
        measured = add_sensor_errors(
            d_true,
            ring.min_range[sensor],
            ring.max_range[sensor],
            rng,
            sigma_d0=opt.sigma_d0,
            k_d=opt.k_d,
            p_miss=opt.p_miss,
            p_crosstalk=opt.p_crosstalk,
        )
    ox_, oy_, oyaw = apply_drift(truth.x, truth.y, truth.yaw, opt.drift, rng)
    logged = Trajectory(truth.t_ns.copy(), ox_, oy_, oyaw)
    ranges = SimRanges(
        t_ns=t_ns,
        sensor=sensor,
        range_m=measured,
        true_range_m=d_true,
        scan_id=np.arange(t_ns.shape[0], dtype=np.int64) // len(ring),
    )
    return SimulatedLog(
        ranges=ranges,
        sensor_names=ring.names,
        mounts=tuple(opt.mounts),
        poses=logged,
        true_poses=truth,
        world=world,
        options=opt,
    )


# --------------------------------------------------------------------------- writing


def truth_paths(out_path: Path) -> tuple[Path, Path, Path]:
    """``<stem>.truth.yaml``, ``<stem>.truth.pgm`` and ``<stem>.truth.csv`` beside a log."""
    return reference_paths(out_path, "truth")


def write_simulation(
    sim: SimulatedLog, out_path: str | Path, fmt: str, *, compression: str = "none"
) -> list[Path]:
    """Write the log, the ground-truth map and the true trajectory; return the paths.

    Refuses (OutputError) when any of them exists already, before writing anything.
    """
    grid = sim.world.grid(sim.options.truth_resolution, margin=sim.options.truth_resolution)
    return write_log_with_reference(
        sim.to_content(), out_path, fmt, compression=compression, kind="truth",
        probability=sim.world.rasterize(grid), grid=grid, trajectory=sim.true_poses,
    )


def run_simulation(
    world_path: str | Path,
    out_path: str | Path,
    fmt: str,
    *,
    waypoints_path: str | Path | None = None,
    options: SimOptions | None = None,
    compression: str = "none",
) -> list[Path]:
    """The ``sonarmap simulate`` command: load a world and its waypoints, simulate, write.

    ``waypoints_path`` defaults to ``<world stem>.waypoints.csv`` beside the world file.
    Returns the written paths (log first).
    """
    wp = Path(world_path)
    world = load_world(wp)
    if waypoints_path is None:
        waypoints_path = wp.with_name(f"{wp.name.split('.')[0]}.waypoints.csv")
    waypoints = load_waypoints(waypoints_path)
    sim = simulate(world, waypoints, options)
    return write_simulation(sim, out_path, fmt, compression=compression)
