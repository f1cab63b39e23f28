"""``run()``: a log in, a map directory out — the pipeline as named stages.

1. **ingest** — open the log (:mod:`formats`), pass 1 survey (:mod:`pipeline.stages.ingest`): the
   log is read and decoded once, its readings spilled in time order for the mapping passes;
2. **pose_sync** — each reading's robot pose and sonar geometry (:mod:`pipeline.stages.pose_sync`);
3. **pose_refinement** — with ``[pose_refinement] enabled`` (``run --refine-poses``), the pose
   track corrected from the echoes before mapping (:mod:`pipeline.refine`);
4. **scan_building** — readings grouped into scans (:mod:`pipeline.stages.scans`);
5. **mapping** — the mapper (:mod:`pipeline.mapper`): the configured ``[mapper] method``
   (the default, the paper's method ``andersone`` or the ``classic`` grid), over as many
   passes of the spilled readings as the method needs;
6. **outputs** — map.pgm/yaml, map.png, map.mcap, features.parquet, trajectory.csv,
   metrics.json, config.toml, reports, written into a temporary directory renamed into
   place when complete.

Stages 2, 4 and 5 run interleaved over the streamed readings; each stage's seconds are summed.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from formats import open_log
from formats.contract import LogInfo, LogReader, RangeBatch
from formats.errors import ConfigError, InputError
from formats.map_types import GridSpec
from formats.storage.location import Location, as_location
from formats.writers.trajectory_tum import Trajectory
from pipeline import __version__
from pipeline.config import Config, dump_config
from pipeline.mapper import Mapper, make_mapper
from pipeline.mapper.types import MapSnapshot, Scan
from pipeline.methods import Method
from pipeline.stages.ingest import Survey, survey
from pipeline.stages.mapped_share import check_mapped_share, mapped_readings
from pipeline.stages.metrics import (
    RunMetrics,
    StageTimer,
    map_cells,
    peak_rss_mb,
)
from pipeline.stages.pose_sync import (
    POSE_OK,
    POSE_REASONS,
    PoseTrack,
    interpolate_poses,
    pose_gap_limit_s,
    sonar_geometry,
)
from pipeline.stages.reading_quality import REASONS
from pipeline.stages.run_warnings import run_warnings
from pipeline.stages.scans import ScanBuilder, ScanKeys
from pipeline.stages.sensors import SensorTable, beam_problem, resolve_sensors
from pipeline.streaming.run_input import input_section, log_label, log_paths, losses_named
from pipeline.streaming.scan_spill import ScanSpill, SpilledScans

log = logging.getLogger("sonarmap")

#: ``(stage, readings done, readings total)``: stage "reading" (pass 1, the total is not
#: known yet: None), "mapping" (pass 2, the total counted by pass 1), then "writing" (the
#: outputs; once, with 0 and None).
Progress = Callable[[str, int, int | None], None]


@dataclass
class RunResult:
    """What a run produced: where, its metrics and the final map."""

    out_dir: Location
    metrics: RunMetrics
    snapshot: MapSnapshot


@dataclass
class StreamState:
    """What streaming the readings counted: readings seen, drops by reason, per sensor."""

    readings_seen: int
    dropped: Counter[str]
    per_sensor: Counter[int]
    scans: int
    max_pose_gap_s: float
    median_pose_interval_s: float


def run(
    log_path: str | Location | Sequence[str | Location],
    out_dir: str | Location,
    config: Config,
    *,
    force: bool = False,
    compare_correction: bool = False,
    progress: Progress | None = None,
    on_complete: Callable[[Path, RunMetrics], None] | None = None,
) -> RunResult:
    """Map one log into ``out_dir``. Raises SonarmapError subclasses on bad input.

    ``log_path`` is a log file or bag directory, or a sequence of the files of one
    recording (split bags, separate sonar and odometry bags), read as one log.

    ``force`` replaces a previous sonarmap output only (never the input's directory, the
    working directory or the user's files: :class:`~formats.writers.atomic.OutputDir`).
    ``on_complete(tmp_dir, metrics)`` may add files after the outputs are written and
    before the directory is committed (a batch's resume marker).

    Logs and ``out_dir`` may be URLs (``s3://bucket/prefix``): read by ranges, written by
    :class:`~formats.writers.remote_output.RemoteOutputDir` (marker last)."""
    from formats.storage.options import configure
    from formats.writers.remote_output import open_output_dir

    configure(config.storage)
    paths = log_paths(log_path)
    final = as_location(out_dir)
    label = log_label(paths)
    if compare_correction and config.mapper.method == Method.CLASSIC:
        raise ConfigError(
            "--compare-correction needs features: mapper.method 'forward', 'specular', "
            "'attribution' or 'andersone'"
        )
    timer = StageTimer()
    t_start = time.perf_counter()
    with open_output_dir(final, force=force, protect=tuple(paths)) as out:
        with timer.stage("ingest"):
            reader = open_log(paths, config)
        with reader, losses_named(reader.info):
            with timer.stage("ingest"):
                found = None if progress is None else (lambda n: progress("reading", n, None))
                sv, sensors = surveyed(reader, config, found)
                info = reader.info()
                _check_mcap_stamps(label, sv.track)
            odometry: PoseTrack | None = None
            refinement: dict[str, Any] | None = None
            if config.pose_refinement.enabled:
                with timer.stage("pose_refinement"):
                    odometry = sv.track
                    sv, refinement = _refine_poses(reader, sv, sensors, config)
            # The poses' box: with refinement the refined poses' (a drifted odometry's box
            # may be far larger than the building, beyond grid.max_cells).
            grid = grid_for(sv, sensors, config, label)
            # Thinned now, while little else is in memory (it reads the whole track).
            drawn = _drawn_trajectory(sv.track)
            log.info(
                "%s: %d readings from %d sensors, %d poses; grid %dx%d at %.3f m",
                label, sv.ranges.count, len(sv.sensor_names), len(sv.track),
                grid.width, grid.height, grid.resolution,
            )
            mappers: dict[str, Mapper] = {"main": make_mapper(config.mapper, grid)}
            if compare_correction:
                off = dataclasses.replace(config.mapper, feature_correction=False)
                mappers["no_correction"] = make_mapper(off, grid)
            passes = max(m.passes for m in mappers.values())
            # The first pass builds the scans from the readings pass 1 spilled (in time
            # order) and spills them; the later passes stream them back.
            spill = ScanSpill() if passes > 1 else None
            spilled: SpilledScans | None = None
            # trajectory.csv needs only the poses, walked by the first pass alone: written
            # on a thread of its own beside the later passes (their kernels release the GIL).
            writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="sonarmap-trajectory")
            trajectory: Future[None] | None = None
            try:
                for index in range(passes):
                    active = {k: m for k, m in mappers.items() if index < m.passes}
                    for m in active.values():
                        m.begin_pass(index)
                    each = _pass_progress(progress, index, passes)
                    if spilled is None:  # the first pass (the only one without a spill)
                        state = _map_stream(reader, sv, sensors, grid, active, config, timer,
                                            each, spill)
                        spilled = spill.finish() if spill is not None else None
                        spill = None
                        trajectory = writer.submit(_write_trajectory, out, sv.track)
                        writer.submit(_warm_writers)  # then, still beside the later passes
                    else:
                        _map_spilled(spilled, active, timer, each, sv.ranges.count)
            except InputError as err:
                if err.path is not None:
                    raise
                raise InputError(err.reason, label) from err
            finally:
                if spill is not None:
                    spill.close()
                t_trajectory = time.perf_counter()
                writer.shutdown(wait=True)  # a failed run leaves no thread writing
            del spilled  # its files go with it
        if trajectory is not None:
            trajectory.result()  # its error, if any
        timer.seconds["outputs"] = time.perf_counter() - t_trajectory
        with timer.stage("mapping"):
            snapshots = {k: m.snapshot() for k, m in mappers.items()}
        if progress is not None:
            progress("writing", 0, None)  # the outputs: no reading count to show
        metrics = _metrics(paths, info, sv, sensors, mappers, snapshots, state, config)
        metrics.pose_refinement = refinement
        # A map of (almost) nothing is an error, not an empty result with exit 0.
        with losses_named(lambda: info):
            check_mapped_share(label, metrics.counts, metrics.dropped, state.max_pose_gap_s,
                               state.median_pose_interval_s, config)
        _write_outputs(out, config, sv, drawn, snapshots, metrics, timer, t_start,
                       odometry=odometry)
        if on_complete is not None:
            on_complete(out.tmp_dir, metrics)
    return RunResult(final, metrics, snapshots["main"])


def _check_mcap_stamps(label: Location, track: PoseTrack) -> None:
    """Refuse (InputError naming the log), before mapping, a log whose stamps ``map.mcap``
    cannot carry: its messages are stamped at the last pose, its paths with every pose's
    stamp (refinement keeps them)."""
    from formats.errors import OutputError
    from formats.writers.map_mcap import check_stamps

    if len(track):
        t = np.asarray(track.t_ns)
        try:
            check_stamps(Path("map.mcap"), int(t[-1]), int(t.min()), int(t.max()))
        except OutputError as err:
            raise InputError(f"the log's {err.reason}", label) from err


def _refine_poses(
    reader: LogReader, sv: Survey, sensors: SensorTable, config: Config
) -> tuple[Survey, dict[str, Any]]:
    """Pose refinement (pipeline/refine/): one more pass over the readings for the echoes,
    then the refined track replaces the odometry for the grid and the mapping pass."""
    from pipeline.refine import collect_echoes, refine_track

    echoes = collect_echoes(
        sv.ordered_ranges(reader), sv.track, sensors,
        eps_max=config.mapper.eps_max,
        max_echo_range_m=config.pose_refinement.echo_reach_m,
        time_offset_ns=round(config.pose_sync.time_offset_s * 1e9),
        max_gap_ns=round(pose_gap_limit_s(config.pose_sync.max_pose_gap_s,
                                          sv.track.median_interval_s()) * 1e9),
    )
    refined = refine_track(sv.track, echoes, config.pose_refinement)
    old = sv.track
    track = PoseTrack(refined.t_ns, refined.x, refined.y, refined.yaw, old.parent_frame,
                      old.child_frame, backwards=old.backwards, duplicates=old.duplicates,
                      spikes=old.spikes)
    log.info("%s", refined.metrics["summary"])
    return dataclasses.replace(sv, track=track), refined.metrics


def prepare(
    reader: LogReader, config: Config, found: Callable[[int], None] | None = None
) -> tuple[Survey, SensorTable, GridSpec]:
    """Pass 1 over an open log (:func:`surveyed`) and the map grid of its poses."""
    sv, sensors = surveyed(reader, config, found)
    return sv, sensors, grid_for(sv, sensors, config, reader.path)


def surveyed(
    reader: LogReader, config: Config, found: Callable[[int], None] | None = None
) -> tuple[Survey, SensorTable]:
    """Pass 1 over an open log: its survey (the readings kept, spilled, for the mapping
    passes) and the sensor table (``found`` hears the readings counted so far)."""
    sv = survey(reader, found, keep_readings=True)
    sensors = resolve_sensors(
        sv.sensor_names,
        sv.mounts,
        config,
        used=[sv.ranges.per_sensor.get(i, 0) > 0 for i in range(len(sv.sensor_names))],
    )
    return sv, sensors


def grid_for(sv: Survey, sensors: SensorTable, config: Config,
             log: object | None = None) -> GridSpec:
    """The grid: ``[grid] extent`` if given, else the poses' box grown by the sonars' reach
    (errors name ``log``).

    The box leaves out isolated pose outliers (:meth:`PoseTrack.bulk_bounds`: an odometry
    glitch must not blow the grid up to kilometres); readings placed outside the grid are
    dropped and counted (``outside_grid``)."""
    g = config.grid
    if g.extent:
        x0, y0, x1, y1 = g.extent
    else:
        finite = [v for v in _reaches(sv, sensors) if math.isfinite(v) and v > 0]
        if not finite:
            raise InputError(
                "cannot size the grid: no sensor reports a max range > 0; set [grid] extent "
                "or [sensors] max_range", log
            )
        offsets = np.hypot(sensors.mount_x, sensors.mount_y)
        offset = float(np.nanmax(offsets)) if np.isfinite(offsets).any() else 0.0
        reach = max(finite) + offset + g.margin
        (bx0, by0, bx1, by1), _ = sv.track.bulk_bounds()
        x0, x1 = bx0 - reach, bx1 + reach
        y0, y1 = by0 - reach, by1 + reach
    # Sized in floats first: a box of 1e308 m (a mount or pose at the edge of a float)
    # must be the same one-line refusal, not an overflow in the grid's integer size.
    w_m, h_m = x1 - x0, y1 - y0
    cells_f = (w_m / g.resolution + 1.0) * (h_m / g.resolution + 1.0)
    if not math.isfinite(cells_f) or cells_f > 2.0**53:  # beyond exact integers
        _too_many_cells(f"{w_m:.3g} x {h_m:.3g} m", f"{cells_f:.3g}", g.max_cells)
    grid = GridSpec.covering(x0, y0, x1, y1, g.resolution)
    cells = grid.width * grid.height
    if cells > g.max_cells:
        _too_many_cells(f"{grid.width}x{grid.height} = {cells} cells "
                        f"({grid.width * g.resolution:.0f} x {grid.height * g.resolution:.0f} m)",
                        None, g.max_cells)
    return grid


def _too_many_cells(size: str, cells: str | None, max_cells: int) -> NoReturn:
    what = f"{size} ({cells} cells)" if cells is not None else size
    raise ConfigError(
        f"grid of {what} exceeds grid.max_cells = {max_cells}; use a coarser grid.resolution, "
        "a [grid] extent, or a larger grid.max_cells if the memory is there (~32 bytes a cell)"
    )


def _reaches(sv: Survey, sensors: SensorTable) -> list[float]:
    """Each sensor's r_max as the mapping uses it (:meth:`SensorTable.apply_limits`): a
    config or preset max_range wins over what the log's readings claim, which wins over
    the ``[sensors] max_range`` default. Sensors without readings do not widen the grid."""
    out = []
    for sid in sorted(sv.ranges.per_sensor):
        override = float(sensors.max_override[sid])
        logged = sv.ranges.max_range_by_sensor.get(sid, math.nan)
        out.append(override if not math.isnan(override)
                   else logged if not math.isnan(logged) else sensors.default_max)
    return out


def _map_stream(
    reader: LogReader,
    sv: Survey,
    sensors: SensorTable,
    grid: GridSpec,
    mappers: dict[str, Mapper],
    config: Config,
    timer: StageTimer,
    progress: Progress | None,
    spill: ScanSpill | None = None,
) -> StreamState:
    """Stages 2-4 over the time-ordered reading stream, into ``mappers`` (and ``spill``)."""

    def integrate(scans: Sequence[Scan]) -> None:
        with timer.stage("mapping"):
            _integrate(mappers, scans)

    return stream_scans(reader, sv, sensors, grid, config, integrate, timer, progress, spill)


def _map_spilled(spilled: SpilledScans, mappers: dict[str, Mapper], timer: StageTimer,
                 progress: Progress | None, total: int) -> None:
    """A later pass: the first pass's scans, batch by batch as it built them, into
    ``mappers``."""
    for scans, seen in spilled.batches():
        with timer.stage("mapping"):
            _integrate(mappers, scans)
        if progress is not None:
            progress("mapping", seen, total)


def stream_scans(
    reader: LogReader,
    sv: Survey,
    sensors: SensorTable,
    grid: GridSpec,
    config: Config,
    consume: Callable[[Sequence[Scan]], None],
    timer: StageTimer | None = None,
    progress: Progress | None = None,
    spill: ScanSpill | None = None,
) -> StreamState:
    """Pose sync and scan building over the log's time-ordered readings: ``consume`` gets
    the scans in order, chunk by chunk (any mapper, or a baseline such as OctoMap), and
    ``spill`` records each chunk's scans; readings placed outside ``grid`` are dropped
    (``outside_grid``)."""
    timer = timer if timer is not None else StageTimer()
    track = sv.track
    offset_ns = round(config.pose_sync.time_offset_s * 1e9)
    median_s = track.median_interval_s()
    gap_s = pose_gap_limit_s(config.pose_sync.max_pose_gap_s, median_s)
    max_gap_ns = round(gap_s * 1e9)
    builder = ScanBuilder(ScanKeys(config.scans, track))
    state = StreamState(0, Counter(), Counter(), 0, gap_s, median_s)
    total = sv.ranges.count
    stream = sv.ordered_ranges(reader)
    while True:
        with timer.stage("ingest"):
            item = next(stream, None)
        if item is None:
            break
        batch = item.batch
        state.dropped["late"] += item.late
        state.dropped["stamp_backwards"] += item.backwards
        state.readings_seen += len(batch) + item.late + item.backwards
        if len(batch) == 0:
            continue
        with timer.stage("pose_sync"):
            scan_ids, readings = _sync(batch, track, sensors, grid, offset_ns, max_gap_ns, state)
        with timer.stage("scan_building"):
            scans = builder.push_batch(scan_ids, readings)  # one batch: no copy per scan
        # Later readings are newer than this chunk: the poses before it are done with.
        track.release_before(int(batch.t_ns[0]) + offset_ns)
        consume(scans)
        if spill is not None:
            spill.add(scans, state.readings_seen)
        if progress is not None:
            progress("mapping", state.readings_seen, total)
    last = list(builder.flush())
    consume(last)
    if spill is not None:
        spill.add(last, state.readings_seen)
    state.scans = builder.count
    return state


def _pass_progress(progress: Progress | None, index: int, passes: int) -> Progress | None:
    """Progress over all passes: pass ``index`` of ``passes`` covers its share of the total."""
    if progress is None or passes == 1:
        return progress
    report = progress

    def scaled(phase: str, done: int, total: int | None) -> None:
        if total is None:
            report(phase, done, None)
        else:
            report(phase, index * total + done, passes * total)

    return scaled


def _integrate(mappers: dict[str, Mapper], scans: Sequence[Scan]) -> None:
    # The mappers are independent: each takes the whole list (batched stateless work).
    for m in mappers.values():
        m.integrate_many(scans)


def _sync(
    batch: RangeBatch,
    track: PoseTrack,
    sensors: SensorTable,
    grid: GridSpec,
    offset_ns: int,
    max_gap_ns: int,
    state: StreamState,
) -> tuple[np.ndarray, Scan]:
    """Pose sync of one chunk: drop readings without a pose or placed outside the grid,
    check beam widths and limits, resolve world geometry."""
    look = interpolate_poses(track, batch.t_ns + offset_ns, max_gap_ns)
    codes, counts = np.unique(look.reason, return_counts=True)
    for c, n in zip(codes.tolist(), counts.tolist(), strict=True):
        if c != POSE_OK:
            state.dropped[POSE_REASONS[c]] += n
    ok = look.reason == POSE_OK
    b = batch.take(ok)
    sid = b.sensor_id
    ox, oy, alpha = sonar_geometry(
        look.x[ok], look.y[ok], look.yaw[ok],
        sensors.mount_x[sid], sensors.mount_y[sid], sensors.mount_yaw[sid],
    )
    x0, y0 = grid.origin_x, grid.origin_y
    inside = (ox >= x0) & (ox < x0 + grid.width * grid.resolution)
    inside &= (oy >= y0) & (oy < y0 + grid.height * grid.resolution)
    if not inside.all():  # a pose outlier left out of the grid extent
        state.dropped["outside_grid"] += int((~inside).sum())
        b, ox, oy, alpha = b.take(inside), ox[inside], oy[inside], alpha[inside]
        sid = b.sensor_id
    ids, per = np.unique(sid, return_counts=True)
    state.per_sensor.update(dict(zip(ids.tolist(), per.tolist(), strict=True)))
    fov, lo, hi = sensors.apply_limits(b)
    if np.isnan(fov).any():
        bad_ids = np.unique(sid[np.isnan(fov)])
        bad = [sensors.names[i] for i in bad_ids.tolist()]
        n_nan, n_all = int(np.isnan(fov).sum()), int(np.isin(sid, bad_ids).sum())
        what = ("the log carries none" if n_nan == n_all else
                f"{n_nan} of their {n_all} readings in this part of the log carry a NaN fov")
        raise InputError(
            f"no beam width (fov) for sensor(s) {', '.join(bad)}: {what}; set "
            f"fov_deg in [sensors] or [[sensors.mounts]]"
        )
    problem = beam_problem(sensors.names, sid, fov, lo, hi)
    if problem is not None:
        raise InputError(problem)
    scan = Scan(
        t_ns=b.t_ns, sensor_id=sid, range_m=b.range_m, origin_x=ox, origin_y=oy, alpha=alpha,
        fov=fov, min_range=lo, max_range=hi,
    )
    return b.scan_id, scan


def _metrics(
    paths: list[Location],
    info: LogInfo,
    sv: Survey,
    sensors: SensorTable,
    mappers: dict[str, Mapper],
    snapshots: dict[str, MapSnapshot],
    state: StreamState,
    config: Config,
) -> RunMetrics:
    main = mappers["main"]
    counters = main.counters.as_dict()
    dropped = {name: int(state.dropped.get(name, 0)) for name in list(POSE_REASONS.values())[1:]}
    dropped["outside_grid"] = int(state.dropped.get("outside_grid", 0))
    dropped["late"] = int(state.dropped.get("late", 0))
    dropped["stamp_backwards"] = int(state.dropped.get("stamp_backwards", 0))
    for name in list(REASONS.values())[1:]:
        dropped[name] = counters.get(f"skipped_{name}", 0)
    mean_var, mean_major = main.feature_variance()
    snap = snapshots["main"]
    track = sv.track
    sensor_rows = [
        {
            "name": n,
            "readings": int(sv.ranges.per_sensor.get(i, 0)),
            "readings_mapped": int(state.per_sensor.get(i, 0)),
            "mount": [sensors.mount_x[i], sensors.mount_y[i], sensors.mount_yaw[i]],
            "mount_source": sensors.source[i],
        }
        for i, n in enumerate(sensors.names)
    ]
    comparison = None
    if "no_correction" in mappers:
        comparison = {
            label: _ablation_row(mappers[key], snapshots[key])
            for label, key in (("with_correction", "main"), ("without_correction", "no_correction"))
        }
    metrics = RunMetrics(
        input=input_section(paths, info, sv.ranges.t_min, sv.ranges.t_max,
                            sv.ranges.max_range_m),
        run={
            "tool_version": __version__,
            "method": config.mapper.method,
            "feature_correction": config.mapper.feature_correction,
            "config_hash": config.hash(),
            "scan_policy": config.scans.policy,
            "max_pose_gap_s": state.max_pose_gap_s,
            "median_pose_interval_s": state.median_pose_interval_s,
        },
        counts={
            "readings": sv.ranges.count,
            "readings_pose_synced": int(sum(state.per_sensor.values())),
            "readings_used": counters.get("readings_used", 0),
            "readings_mapped": mapped_readings(
                counters.get("readings_used", 0), dropped, config.mapper.clear_on_max_range
            ),
            "readings_stamp_backwards": sv.ranges.backwards,
            "poses": len(track),
            "poses_stamp_backwards": track.backwards,
            "poses_duplicate_stamp": track.duplicates,
            "poses_spikes": track.spikes,
            "poses_outliers": track.bulk_bounds()[1],
            "scans": state.scans,
            **{k: v for k, v in counters.items() if not k.startswith("skipped_") and k not in ("readings", "readings_used", "scans")},
            "features": len(snap.features),
        },
        dropped=dropped,
        paper_metric={
            "mean_feature_variance_m2": mean_var,
            "mean_major_axis_variance_m2": mean_major,
            "features": len(snap.features),
        },
        map=map_cells(snap),
        trajectory={
            "path_length_m": track.path_length(),
            "pose_frames": [track.parent_frame, track.child_frame],
            "start_ns": int(track.t_ns[0]),
            "end_ns": int(track.t_ns[-1]),
        },
        sensors=sensor_rows,
        comparison=comparison,
    )
    metrics.warnings = run_warnings(metrics.deterministic())
    return metrics


def _ablation_row(mapper: Mapper, snap: MapSnapshot) -> dict[str, Any]:
    c = mapper.counters.as_dict()
    mv, mm = mapper.feature_variance()
    f = snap.features
    return {
        "mean_feature_variance_m2": mv,
        "mean_major_axis_variance_m2": mm,
        "features": len(f),
        "features_created": c.get("features_created", 0),
        "features_merged": c.get("features_merged", 0),
        "features_corrected": c.get("features_corrected", 0),
        "features_deleted": c.get("features_deleted", 0),
        "features_protected": c.get("features_protected", 0),
        "features_split": c.get("features_split", 0),
        "cells_occupied": map_cells(snap)["cells_occupied"],
    }


MAX_DRAWN_POSES = 20_000


def _drawn_trajectory(track: PoseTrack) -> Trajectory:
    """The trajectory as drawn in map.png and published in map.mcap: every pose up to
    MAX_DRAWN_POSES, else evenly spaced poses plus the last one (a picture at most ~2400 px
    wide shows no more, and hours of 20 Hz odometry would make memory grow with the log)."""
    n = len(track)
    idx = np.arange(n) if n <= MAX_DRAWN_POSES else np.unique(
        np.r_[np.linspace(0, n - 1, MAX_DRAWN_POSES).astype(np.int64), n - 1]
    )
    drawn = Trajectory(
        np.asarray(track.t_ns[idx], dtype=np.int64), np.asarray(track.x[idx], dtype=np.float64),
        np.asarray(track.y[idx], dtype=np.float64), np.asarray(track.yaw[idx], dtype=np.float64),
    )
    track.release_before(None)
    return drawn


def _write_trajectory(out: Any, track: PoseTrack) -> None:
    """``trajectory.csv``: every pose of the track the map was built on (TUM format)."""
    from formats.writers.trajectory_tum import write_trajectory_tum

    write_trajectory_tum(out.path("trajectory.csv"), track.t_ns, track.x, track.y, track.yaw,
                         frame=track.parent_frame)
    track.release_before(None)


def _warm_writers() -> None:
    """``map.mcap``'s type store built and its writer imported (0.08 s of the hour's run),
    on the trajectory's thread beside the later passes, not after them; a failure here is
    the output's own, raised again where it is written."""
    from formats.writers.map_mcap import warm

    warm()


def _write_outputs(
    out: Any,
    config: Config,
    sv: Survey,
    traj: Trajectory,
    snapshots: dict[str, MapSnapshot],
    metrics: RunMetrics,
    timer: StageTimer,
    t_start: float,
    *,
    odometry: PoseTrack | None = None,
) -> None:
    """Write every output; metrics.json and the reports last, so that they can carry the
    timing of everything before them (total = up to the reports).

    ``trajectory.csv`` (:func:`_write_trajectory`, written before) holds the poses the map
    was built on; with pose refinement those are the refined ones and ``odometry.csv`` the
    odometry they started from. ``timer.seconds["outputs"]`` already holds its time."""
    from formats.writers.features_parquet import write_features
    from formats.writers.map_mcap import write_map_mcap
    from formats.writers.map_png import write_map_png
    from formats.writers.nav2_map import write_nav2_map
    from formats.writers.trajectory_tum import write_trajectory_tum
    from pipeline.stages.run_report import COMPARISON_IMAGES, write_run_reports

    t_outputs = time.perf_counter()
    snap = snapshots["main"]
    write_nav2_map(out.path("map.yaml"), snap.probability, snap.grid)
    title = f"{metrics.input['name']} - {config.mapper.method}"
    traj_xy = np.column_stack([traj.x, traj.y])
    write_map_png(out.path("map.png"), snap, trajectory_xy=traj_xy, features=snap.features,
                  title=title)
    track = sv.track
    drawn_odometry = None
    closures = np.array((metrics.pose_refinement or {}).get("loop_closure_edges", []),
                        np.float64).reshape(-1, 4)
    if odometry is not None:  # pose refinement: the odometry the trajectory started from
        from formats.writers.trajectory_png import write_trajectory_png

        write_trajectory_tum(out.path("odometry.csv"), odometry.t_ns, odometry.x, odometry.y,
                             odometry.yaw, frame=odometry.parent_frame)
        drawn_odometry = _drawn_trajectory(odometry)
        write_trajectory_png(out.path("trajectory.png"),
                             np.column_stack([drawn_odometry.x, drawn_odometry.y]), traj_xy,
                             title=f"{metrics.input['name']} - pose refinement",
                             closures=closures)
    write_map_mcap(
        out.path("map.mcap"), probability=snap.probability, grid=snap.grid,
        features=snap.features, trajectory=traj, frame_id=track.parent_frame,
        stamp_ns=int(metrics.trajectory["end_ns"]), library=f"sonarmap {__version__}",
        odometry=drawn_odometry, closures=closures,
    )
    write_features(
        out.path("features.parquet"),
        snap.features,
        metadata={
            "pose_parent_frame": sv.track.parent_frame,
            "resolution_m": repr(snap.grid.resolution),
            "config_hash": config.hash(),
            "tool_version": __version__,
            "method": config.mapper.method,
            "source_sha256": metrics.input["sha256"],
        },
    )
    (out.path("config.toml")).write_text(dump_config(config), encoding="utf-8")
    if "no_correction" in snapshots:
        other = snapshots["no_correction"]
        write_map_png(
            out.path(COMPARISON_IMAGES["without_correction"]), other, trajectory_xy=traj_xy,
            features=other.features,
            title=f"{metrics.input['name']} - without feature correction",
        )
    now = time.perf_counter()
    timer.seconds["outputs"] = timer.seconds.get("outputs", 0.0) + now - t_outputs
    timer.seconds["total"] = now - t_start
    rate = metrics.counts["readings"] / max(timer.seconds["total"], 1e-9)
    metrics.timing = {
        "stage_seconds": {k: round(v, 4) for k, v in timer.seconds.items()},
        "readings_per_s": round(rate, 1),
        "peak_rss_mb": round(peak_rss_mb(), 1),
    }
    (out.path("metrics.json")).write_text(metrics.to_json(), encoding="utf-8")
    write_run_reports(out.tmp_dir)  # from the files just written, as evaluate does
