"""Emulation at the ring's real firing rate (``sonarmap emulate --firing-rate HZ``).

A real ring fires one sonar after another, ``HZ`` readings per second for the whole ring
(a Pioneer's 16 sonars: about 25 per second), not one reading per sonar per laser scan.
The readings are fired in ring order from the first scan's stamp to the last; the robot's
pose at each is interpolated between the scan poses (linear in x, y and unwrapped yaw),
and each reading is ray-cast into the building's laser reference map
(:mod:`pipeline.tools.sonar.grid_scene`): with the realistic model its fan goes through
:mod:`pipeline.tools.sonar.echo`, with the ideal one it reads the nearest wall in its
nominal cone. Every sonar of the ring fires (the map knows the building all round, the
rear included, once the laser has seen it).
"""

from __future__ import annotations

import numpy as np

from formats.arrays import F64
from formats.contract import PoseBatch, SensorMount, make_range_batch
from formats.errors import ConfigError, InputError
from formats.laser_log import LaserLog
from formats.log_writers import LogContent
from pipeline.tools.emulate.emulation import Emulation, pose_at
from pipeline.tools.emulate.laser_map import LaserMap
from pipeline.tools.simulate.sonar import firing_schedule
from pipeline.tools.sonar.echo import readings
from pipeline.tools.sonar.grid_scene import GridScene, grid_fans, grid_nearest
from pipeline.tools.sonar.model import SonarPhysics
from pipeline.tools.sonar_ring import SonarRing

_CHUNK_RAYS = 400_000  # rays traced at once


def emulate_firing(
    log: LaserLog,
    ring: SonarRing,
    laser_map: LaserMap,
    rate_hz: float,
    *,
    physics: SonarPhysics | None = None,
    seed: int = 0,
) -> Emulation:
    """Fire ``ring`` at ``rate_hz`` readings per second through the laser map along the
    log's trajectory; ``physics`` None is the ideal sonar."""
    if not rate_hz > 0:
        raise ConfigError(f"firing rate must be > 0 readings/s, got {rate_hz!r}")
    if len(log) < 2:
        raise InputError("firing at a rate needs at least 2 laser scans (a trajectory)")
    k_n = len(ring)
    t_ns, sid = firing_schedule(k_n, rate_hz / k_n, int(log.t_ns[0]), int(log.t_ns[-1]))
    poses = PoseBatch(log.t_ns.copy(), log.x.copy(), log.y.copy(), log.yaw.copy(),
                      parent_frame=log.parent_frame, child_frame=log.child_frame)
    px, py, pyaw = pose_at(poses, t_ns)
    c, s = np.cos(pyaw), np.sin(pyaw)
    ox = px + c * ring.x[sid] - s * ring.y[sid]
    oy = py + s * ring.x[sid] + c * ring.y[sid]
    alpha = pyaw + ring.yaw[sid]
    lo, hi, fov = ring.min_range[sid], ring.max_range[sid], ring.fov[sid]
    scene = GridScene.from_probability(laser_map.probability, laser_map.grid)
    rng = np.random.Generator(np.random.PCG64(seed))
    n = t_ns.shape[0]
    out = np.empty(n)
    counts = {"ghost": 0, "missed": 0, "crosstalk": 0}
    step = max(1, _CHUNK_RAYS // 64)
    for a in range(0, n, step):
        sl = slice(a, min(n, a + step))
        if physics is None:
            d = grid_nearest(scene, ox[sl], oy[sl], alpha[sl], hi[sl], fov[sl])
            out[sl] = _ideal_reading(d, lo[sl], hi[sl])
            continue
        fan = grid_fans(scene, ox[sl], oy[sl], alpha[sl], hi[sl], physics, seed)
        e = readings(fan, lo[sl], hi[sl], physics, rng)
        out[sl] = e.range_m
        counts["ghost"] += int(e.ghost.sum())
        counts["missed"] += int(e.missed.sum())
        counts["crosstalk"] += int(e.crosstalk.sum())
    duration = (log.t_ns[-1] - log.t_ns[0]) / 1e9
    notes = [*log.notes,
             f"fired {n} readings of {k_n} sonars at {rate_hz:g} readings/s over {duration:.1f} s, "
             "ray-cast into the laser map along the trajectory interpolated between scans"]
    if physics is not None:
        notes.append(f"realistic sonar (seed {seed}): {counts['ghost']} multipath ghosts, "
                     f"{counts['missed']} missed echoes, {counts['crosstalk']} crosstalk readings")
    notes.append(f"{n} readings: {int(np.count_nonzero(np.isfinite(out) & (out < hi)))} echoes, "
                 f"{int(np.count_nonzero(out >= hi))} at max range, "
                 f"{int(np.count_nonzero(np.isneginf(out)))} too close (−inf)")
    batch = make_range_batch(t_ns, sid, out, fov, lo, hi,
                             scan_id=np.arange(n, dtype=np.int64) // k_n)
    mounts = {name: SensorMount(float(ring.x[i]), float(ring.y[i]), float(ring.yaw[i]))
              for i, name in enumerate(ring.names)}
    content = LogContent(batch, ring.names, poses, mounts)
    return Emulation(content, out, ring, (), tuple(notes))


def _ideal_reading(d: F64, lo: F64, hi: F64) -> F64:
    """Max range when nothing is in the cone, −inf when closer than the minimum range."""
    r = np.where(d < hi, d, hi)
    r = np.where(d < lo, -np.inf, r)
    return r.astype(np.float32).astype(np.float64)
