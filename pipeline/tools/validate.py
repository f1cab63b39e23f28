"""``sonarmap validate``: check a log for what breaks sonar maps, before mapping it.

A sonar-aware counterpart of ``cartographer_rosbag_validate``. :func:`validate_log` streams
a reader once (ranges, poses and mounts) and reports findings, each with a severity
(``ERROR``: the map would be wrong or cannot be built; ``WARNING``: worth a look), a code,
a one-line message and counts:

========================  ========  =====================================================
code                      severity  what
========================  ========  =====================================================
``no_ranges``             ERROR     the log has no range readings
``no_poses``              ERROR     the log has no poses
``stamps_backwards``      ERROR     a sensor's header stamp is older than an earlier one
                                    (the running maximum, as the pipeline drops them)
``stamp_skew``            WARNING   header stamp vs record time differ by more than 0.1 s
``pose_gap``              WARNING   pose gaps longer than the pose gap limit (set, or
                                    automatic from the pose rate), with the readings
                                    they drop; ERROR when a run would map too few
``pose_jump``             WARNING   consecutive poses further apart than a robot moves
                                    (MAX_POSE_SPEED_MPS): odometry glitches
``pose_stamps_backwards`` WARNING   pose stamps go backwards (the pipeline sorts them)
``bad_beam``              ERROR     a beam width (fov) or range limits from the log that
                                    cannot be mapped
``damaged_log``           WARNING   the log is truncated or corrupt: what was lost (the
                                    intact part is mapped)
``outside_pose_coverage`` WARNING   readings before the first / after the last pose
``nan_readings``          ERROR     NaN ranges (REP 117: erroneous reading)
``negative_readings``     ERROR     negative finite ranges
``below_min_readings``    WARNING   ranges below the sensor's r_min
``unmounted_sensor``      ERROR     a range sensor with no mount (log, config or preset)
``stuck_sensor``          WARNING   the same exact value ≥ 50 times in a row
========================  ========  =====================================================

+inf / −inf (REP 117) and max-range readings are normal for sonars: they are reported as
per-sensor counts, not findings. Memory is bounded by per-sensor running state (counts,
a skew histogram, the current run of equal values), the pose timestamps (8 bytes a pose),
and the stamps of readings not (yet) inside the pose span seen so far — few, unless a log
stores all its ranges before its poses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from formats.contract import Kind, LogReader, MountBatch, PoseBatch, RangeBatch, SensorMount
from formats.natural_order import natural_key
from formats.tables import text_table
from pipeline.config import Config
from pipeline.stages.ingest import StampOrder
from pipeline.stages.mapped_share import MIN_MAPPED_FRACTION
from pipeline.stages.pose_sync import (
    MAX_POSE_SPEED_MPS,
    is_pose_jump,
    pose_gap_limit_s,
    pose_spikes,
)
from pipeline.stages.reading_quality import (
    MAX_RANGE,
    NAN,
    NEG_INF,
    POS_INF,
    REASONS,
    classify_readings,
    count_reasons,
)
from pipeline.stages.sensors import SensorTable, beam_problem, resolve_sensors

Severity = Literal["ERROR", "WARNING"]

SKEW_WARN_NS = 100_000_000  # 0.1 s
STUCK_RUN = 50  # equal readings in a row that make a sensor look stuck
MAX_LISTED_GAPS = 5
# |skew| histogram: bin 0 = below 1 ns, then 50 log bins a decade up to 10⁴ s (±2.3 %).
_SKEW_EDGES = np.logspace(0.0, 13.0, 13 * 50 + 1)
# Reasons that are a sonar's normal "no echo" answers, not values a stuck sensor repeats.
_NOT_STUCK = np.array([NAN, POS_INF, NEG_INF, MAX_RANGE], dtype=np.int8)
_SEVERITY_ORDER = {"ERROR": 0, "WARNING": 1}
# Reading-quality reasons that are findings: (reason, code, severity, what they are).
_QUALITY_FINDINGS: tuple[tuple[str, str, Severity, str], ...] = (
    ("nan", "nan_readings", "ERROR", "NaN ranges (REP 117: erroneous reading)"),
    ("negative", "negative_readings", "ERROR", "negative ranges"),
    ("below_min", "below_min_readings", "WARNING", "ranges below r_min"),
)


@dataclass(frozen=True)
class Finding:
    """One problem found in a log. ``counts`` holds JSON-ready numbers (s, m, counts)."""

    severity: Severity
    code: str
    message: str
    sensor: str = ""
    counts: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "severity": self.severity,
            "code": self.code,
            "sensor": self.sensor,
            "message": self.message,
            "counts": dict(self.counts),
        }


@dataclass(frozen=True)
class SensorSummary:
    """Per range sensor: reading count, time span (ns), reasons (REP 117 etc.) and mount."""

    name: str
    readings: int
    first_ns: int | None
    last_ns: int | None
    reasons: dict[str, int]
    outside_poses: int
    mount: str  # where the mount comes from: 'config', 'log', 'preset:<name>', 'missing'

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "readings": self.readings,
            "first_ns": self.first_ns,
            "last_ns": self.last_ns,
            "reasons": dict(self.reasons),
            "outside_poses": self.outside_poses,
            "mount": self.mount,
        }


@dataclass
class ValidationReport:
    """What :func:`validate_log` found: findings (ERROR first), sensors and pose summary."""

    path: str
    format: str
    findings: list[Finding]
    sensors: list[SensorSummary]
    pose_count: int
    pose_first_ns: int | None
    pose_last_ns: int | None

    @property
    def ok(self) -> bool:
        """True when there is no ERROR (warnings allowed)."""
        return not any(f.severity == "ERROR" for f in self.findings)

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "ERROR"]

    @property
    def warnings(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "WARNING"]

    def codes(self) -> list[str]:
        """The finding codes, in report order (handy in tests and scripts)."""
        return [f.code for f in self.findings]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, in a fixed order (same log → same document)."""
        return {
            "path": self.path,
            "format": self.format,
            "ok": self.ok,
            "errors": len(self.errors),
            "warnings": len(self.warnings),
            "findings": [f.to_dict() for f in self.findings],
            "sensors": [s.to_dict() for s in self.sensors],
            "poses": {
                "count": self.pose_count,
                "first_ns": self.pose_first_ns,
                "last_ns": self.pose_last_ns,
            },
        }

    def format_table(self) -> str:
        """A plain-text report for the terminal: findings, then a per-sensor table."""
        out = [f"Log: {self.path} ({self.format})", ""]
        if self.findings:
            out += text_table(
                ["SEVERITY", "CODE", "SENSOR", "MESSAGE"],
                [[f.severity, f.code, f.sensor or "-", f.message] for f in self.findings],
            )
        else:
            out.append("No findings.")
        out.append("")
        names = list(REASONS.values())
        if self.sensors:
            out += text_table(
                ["SENSOR", "READINGS", *(n.upper() for n in names), "OUTSIDE_POSES", "MOUNT"],
                [
                    [
                        s.name,
                        str(s.readings),
                        *(str(s.reasons[n]) for n in names),
                        str(s.outside_poses),
                        s.mount,
                    ]
                    for s in self.sensors
                ],
                right=range(1, len(names) + 3),
            )
        else:
            out.append("No range sensors.")
        if self.pose_count and self.pose_first_ns is not None and self.pose_last_ns is not None:
            span = (self.pose_last_ns - self.pose_first_ns) / 1e9
            out.append(f"Poses: {self.pose_count} over {span:.3f} s")
        else:
            out.append("Poses: none")
        verdict = "OK" if self.ok else "FAILED"
        out.append(f"Result: {verdict} ({len(self.errors)} errors, {len(self.warnings)} warnings)")
        return "\n".join(out)




# --------------------------------------------------------------------------- running state


class _SensorState:
    """Running per-sensor statistics, updated one batch (not one reading) at a time."""

    def __init__(self) -> None:
        self.readings = 0
        self.t_min: int | None = None
        self.t_max: int | None = None
        self.backwards = 0
        self.max_back_ns = 0
        self.reasons = dict.fromkeys(REASONS.values(), 0)
        self.skew_hist = np.zeros(_SKEW_EDGES.shape[0] + 1, dtype=np.int64)
        self.skew_max_ns = 0
        self.skew_over = 0
        self.run_value = math.nan
        self.run_len = 0
        self.longest_run = 0
        self.longest_value = math.nan
        self.stuck_runs = 0
        self.stuck_readings = 0

    def update(
        self,
        t: npt.NDArray[np.int64],
        rec: npt.NDArray[np.int64],
        d: npt.NDArray[np.float64],
        codes: npt.NDArray[np.int8],
        back_ns: npt.NDArray[np.int64],
    ) -> None:
        """Fold in this sensor's readings of one batch, in stream order; ``back_ns`` is how
        far each stamp lies below the sensor's running maximum (ingest's StampOrder)."""
        self.readings += int(t.shape[0])
        lo, hi = int(t.min()), int(t.max())
        self.t_min = lo if self.t_min is None else min(self.t_min, lo)
        self.t_max = hi if self.t_max is None else max(self.t_max, hi)
        back = back_ns > 0
        if back.any():
            self.backwards += int(back.sum())
            self.max_back_ns = max(self.max_back_ns, int(back_ns.max()))
        for name, n in count_reasons(codes).items():
            self.reasons[name] += n
        skew = np.abs(rec - t)
        self.skew_max_ns = max(self.skew_max_ns, int(skew.max()))
        self.skew_over += int((skew > SKEW_WARN_NS).sum())
        bins = np.searchsorted(_SKEW_EDGES, skew.astype(np.float64), side="right")
        self.skew_hist += np.bincount(bins, minlength=self.skew_hist.shape[0])
        self._update_runs(d[~np.isin(codes, _NOT_STUCK)])

    def _update_runs(self, v: npt.NDArray[np.float64]) -> None:
        if v.shape[0] == 0:
            return
        starts = np.flatnonzero(np.concatenate(([True], v[1:] != v[:-1])))
        lengths = np.diff(np.append(starts, v.shape[0]))
        values = v[starts]
        if self.run_len and values[0] == self.run_value:
            lengths[0] += self.run_len  # the run carried over from the last batch goes on
        else:
            self._close_run(self.run_value, self.run_len)
        # Every run but the last is complete; the last may go on in the next batch.
        done_v, done_n = values[:-1], lengths[:-1]
        if done_n.size:
            stuck = done_n >= STUCK_RUN
            self.stuck_runs += int(stuck.sum())
            self.stuck_readings += int(done_n[stuck].sum())
            i = int(np.argmax(done_n))  # the first longest run
            if done_n[i] > self.longest_run:
                self.longest_run, self.longest_value = int(done_n[i]), float(done_v[i])
        self.run_value, self.run_len = float(values[-1]), int(lengths[-1])

    def _close_run(self, value: float, n: int) -> None:
        if n > self.longest_run:
            self.longest_run, self.longest_value = n, value
        if n >= STUCK_RUN:
            self.stuck_runs += 1
            self.stuck_readings += n

    def finish(self) -> None:
        self._close_run(self.run_value, self.run_len)
        self.run_len = 0

    def skew_median_s(self) -> float:
        """Median |header stamp − record time|, s, to the histogram's resolution (±2.3 %)."""
        total = int(self.skew_hist.sum())
        k = int(np.searchsorted(np.cumsum(self.skew_hist), (total + 1) // 2))
        if k == 0:
            return 0.0
        if k >= _SKEW_EDGES.shape[0]:
            return self.skew_max_ns / 1e9
        return float(math.sqrt(_SKEW_EDGES[k - 1] * _SKEW_EDGES[k])) / 1e9


class _Coverage:
    """Readings outside the span of the poses, found in one pass.

    Stamps of readings outside the pose span seen *so far* are kept and pruned as later
    poses widen the span; what is left at the end lies before the first or after the
    last pose.
    """

    def __init__(self, offset_ns: int) -> None:
        self.offset_ns = offset_ns
        self.lo: int | None = None
        self.hi: int | None = None
        self.t: list[npt.NDArray[np.int64]] = []
        self.sid: list[npt.NDArray[np.int32]] = []

    def add_ranges(self, t: npt.NDArray[np.int64], sid: npt.NDArray[np.int32]) -> None:
        t = t + self.offset_ns
        if self.lo is None or self.hi is None:
            keep = np.ones(t.shape[0], dtype=bool)
        else:
            keep = (t < self.lo) | (t > self.hi)
        if keep.any():
            self.t.append(t[keep])
            self.sid.append(sid[keep])

    def add_poses(self, t: npt.NDArray[np.int64]) -> None:
        lo, hi = int(t.min()), int(t.max())
        if self.lo is not None and self.hi is not None and lo >= self.lo and hi <= self.hi:
            return
        self.lo = lo if self.lo is None else min(self.lo, lo)
        self.hi = hi if self.hi is None else max(self.hi, hi)
        if self.t:
            pt, ps = np.concatenate(self.t), np.concatenate(self.sid)
            keep = (pt < self.lo) | (pt > self.hi)
            self.t, self.sid = [pt[keep]], [ps[keep]]

    def outside(self, n_sensors: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """Per sensor id: readings before the first pose, after the last pose."""
        if not self.t or self.lo is None or self.hi is None:
            z = np.zeros(n_sensors, dtype=np.int64)
            return z, z.copy()
        t, sid = np.concatenate(self.t), np.concatenate(self.sid)
        before = np.bincount(sid[t < self.lo], minlength=n_sensors)
        after = np.bincount(sid[t > self.hi], minlength=n_sensors)
        return before.astype(np.int64), after.astype(np.int64)


# --------------------------------------------------------------------------- validation


def validate_log(reader: LogReader, config: Config) -> ValidationReport:
    """Stream ``reader`` once and report what would break or degrade a sonar map."""
    states: dict[int, _SensorState] = {}
    log_mounts: dict[str, SensorMount] = {}
    pose_t: dict[tuple[str, str], list[npt.NDArray[np.int64]]] = {}
    pose_xy: dict[tuple[str, str], list[npt.NDArray[np.float64]]] = {}
    stamps = StampOrder()
    beam_problems: dict[str, str] = {}
    coverage = _Coverage(round(config.pose_sync.time_offset_s * 1e9))
    table: SensorTable | None = None
    eps = config.mapper.eps_max

    # A log without a pose source or without range topics is a finding, not a crash:
    # stream only the kinds the log has (the readers raise TopicError for the others).
    info = reader.info()
    kinds: list[Kind] = ["mounts"]
    if info.pose_topic:
        kinds.append("poses")
    if info.range_topics:
        kinds.append("ranges")
    for batch in reader.batches(kinds):
        if isinstance(batch, MountBatch):
            log_mounts.update(batch.mounts)
        elif isinstance(batch, PoseBatch):
            if len(batch):
                frames = (batch.parent_frame, batch.child_frame)
                pose_t.setdefault(frames, []).append(np.asarray(batch.t_ns, dtype=np.int64))
                pose_xy.setdefault(frames, []).append(
                    np.column_stack([batch.x, batch.y]).astype(np.float64)
                )
                coverage.add_poses(batch.t_ns)
        elif isinstance(batch, RangeBatch) and len(batch):
            names = reader.sensor_names
            if table is None or len(table.names) != len(names):
                # Beam limits resolved exactly as the pipeline does (mounts don't matter here).
                table = resolve_sensors(names, {}, config, used=[False] * len(names))
            fov, lo, hi = table.apply_limits(batch)
            problem = beam_problem(table.names, batch.sensor_id, fov, lo, hi)
            if problem is not None:
                beam_problems.setdefault(problem.split(":", 1)[0], problem)
            codes = classify_readings(batch.range_m, lo, hi, eps)
            back_ns = stamps.steps_back(batch)
            coverage.add_ranges(batch.t_ns, batch.sensor_id)
            # One group per sensor (a stable sort keeps each sensor's stream order).
            order = np.argsort(batch.sensor_id, kind="stable")
            sid_sorted = batch.sensor_id[order]
            cuts = np.flatnonzero(np.diff(sid_sorted)) + 1
            for idx in np.split(order, cuts):
                sid = int(batch.sensor_id[idx[0]])
                state = states.setdefault(sid, _SensorState())
                state.update(
                    batch.t_ns[idx], batch.record_t_ns[idx], batch.range_m[idx], codes[idx],
                    back_ns[idx],
                )

    names = list(reader.sensor_names)
    for state in states.values():
        state.finish()
    findings: list[Finding] = []
    mounts = resolve_sensors(names, log_mounts, config, used=[False] * len(names)).source
    before, after = coverage.outside(len(names))
    summaries: list[SensorSummary] = []
    for sid in sorted(states, key=lambda i: natural_key(names[i])):
        st, name = states[sid], names[sid]
        findings += _sensor_findings(name, st, mounts[sid])
        summaries.append(
            SensorSummary(
                name,
                st.readings,
                st.t_min,
                st.t_max,
                dict(st.reasons),
                int(before[sid] + after[sid]),
                mounts[sid],
            )
        )

    all_pose_t = [t for ts in pose_t.values() for t in ts]
    n_poses = sum(int(t.shape[0]) for t in all_pose_t)
    if not states:
        findings.append(Finding("ERROR", "no_ranges", "the log has no range readings"))
    findings += [Finding("ERROR", "bad_beam", msg, key.removeprefix("sensor "))
                 for key, msg in sorted(beam_problems.items())]
    if not n_poses:
        findings.append(Finding("ERROR", "no_poses", "the log has no poses"))
    else:
        # The pose stream the pipeline maps with: the frame pair with the most poses.
        main = max(sorted(pose_t), key=lambda k: sum(int(t.shape[0]) for t in pose_t[k]))
        for frames, ts in sorted(pose_t.items()):
            t = np.concatenate(ts)
            order = np.argsort(t, kind="stable")
            xy = np.concatenate(pose_xy[frames])[order]
            total = sum(st.readings for st in states.values())
            findings += _pose_findings(
                frames, t, xy, config,
                reader if frames == main and total else None, total,
            )
        n_before, n_after = int(before.sum()), int(after.sum())
        if n_before or n_after:
            worst = sorted(
                ((int(before[i] + after[i]), names[i]) for i in states if before[i] + after[i]),
                key=lambda x: (-x[0], x[1]),
            )
            findings.append(
                Finding(
                    "WARNING",
                    "outside_pose_coverage",
                    f"{n_before + n_after} readings lie outside the poses' time span "
                    f"({n_before} before the first pose, {n_after} after the last); "
                    f"they cannot be placed (most: {worst[0][1]}, {worst[0][0]})",
                    counts={"before": n_before, "after": n_after, "total": n_before + n_after},
                )
            )

    info = reader.info()  # again: losses found while reading the chunks are in it now
    if info.losses:
        findings.append(
            Finding(
                "WARNING",
                "damaged_log",
                f"the log is damaged, {info.bytes_lost} bytes lost: {'; '.join(info.losses)}; "
                f"sonarmap maps the intact part ({info.message_count} messages)",
                counts={"bytes_lost": info.bytes_lost, "messages_recovered": info.message_count,
                        "losses": len(info.losses)},
            )
        )
    findings.sort(key=lambda f: (_SEVERITY_ORDER[f.severity], f.code, natural_key(f.sensor or "")))
    t_first = min((int(t.min()) for t in all_pose_t), default=None)
    t_last = max((int(t.max()) for t in all_pose_t), default=None)
    return ValidationReport(
        path=str(reader.path),
        format=reader.format_name,
        findings=findings,
        sensors=summaries,
        pose_count=n_poses,
        pose_first_ns=t_first,
        pose_last_ns=t_last,
    )


def _sensor_findings(name: str, st: _SensorState, mount: str) -> list[Finding]:
    out: list[Finding] = []
    r = st.reasons
    if st.backwards:
        out.append(
            Finding(
                "ERROR",
                "stamps_backwards",
                f"{name}: header stamps go backwards {st.backwards} times "
                f"(largest step back {st.max_back_ns / 1e9:.3f} s)",
                name,
                {"backwards": st.backwards, "max_step_back_s": st.max_back_ns / 1e9},
            )
        )
    if st.skew_max_ns > SKEW_WARN_NS:
        med = st.skew_median_s()
        out.append(
            Finding(
                "WARNING",
                "stamp_skew",
                f"{name}: header stamp and record time differ by up to {st.skew_max_ns / 1e9:.3f} s "
                f"(median ≈ {med:.3g} s); {st.skew_over} readings over 0.1 s",
                name,
                {"over_0_1s": st.skew_over, "max_s": st.skew_max_ns / 1e9, "median_s": med},
            )
        )
    for reason, code, severity, what in _QUALITY_FINDINGS:
        if r[reason]:
            share = 100.0 * r[reason] / st.readings
            out.append(
                Finding(
                    severity,
                    code,
                    f"{name}: {r[reason]} of {st.readings} readings are {what} ({share:.1f} %)",
                    name,
                    {reason: r[reason], "readings": st.readings},
                )
            )
    if mount == "missing":
        out.append(
            Finding(
                "ERROR",
                "unmounted_sensor",
                f"{name}: no mount in the log, [[sensors.mounts]] or the [sensors] preset; "
                "the map cannot be built",
                name,
                {"readings": st.readings},
            )
        )
    if st.stuck_runs:
        out.append(
            Finding(
                "WARNING",
                "stuck_sensor",
                f"{name}: the same value {st.longest_value!r} m {st.longest_run} times in a row "
                f"({st.stuck_runs} runs of >= {STUCK_RUN}; a stuck sensor, or the robot stood still)",
                name,
                {
                    "longest_run": st.longest_run,
                    "value_m": st.longest_value,
                    "runs": st.stuck_runs,
                    "readings_in_runs": st.stuck_readings,
                },
            )
        )
    return out


def _pose_findings(
    frames: tuple[str, str],
    t: npt.NDArray[np.int64],
    xy_sorted: npt.NDArray[np.float64],
    config: Config,
    reader: LogReader | None,
    total_readings: int,
) -> list[Finding]:
    """Pose stamps going backwards, gaps (with the readings they drop, counted in a second
    pass over ``reader`` when given) and impossible jumps of one pose stream."""
    out: list[Finding] = []
    label = f"{frames[0]}→{frames[1]}"
    back = int((np.diff(t) < 0).sum())
    if back:
        out.append(
            Finding(
                "WARNING",
                "pose_stamps_backwards",
                f"pose stamps ({label}) go backwards {back} times (the pipeline sorts them)",
                counts={"backwards": back},
            )
        )
    ts = np.sort(t, kind="stable")
    gaps = np.diff(ts)
    median_s = float(np.median(gaps)) / 1e9 if gaps.size else math.nan
    configured = config.pose_sync.max_pose_gap_s
    max_gap_s = pose_gap_limit_s(configured, median_s)
    limit = (f"[pose_sync] max_pose_gap_s = {max_gap_s:g} s" if configured > 0 else
             f"the automatic pose gap limit {max_gap_s:g} s (3 × the median pose interval "
             f"{median_s:.3g} s, within [0.5, 5] s; [pose_sync] max_pose_gap_s sets it)")
    big = np.flatnonzero(gaps > round(max_gap_s * 1e9))
    if big.size:
        # Largest first; ties broken by time so the list is deterministic.
        top = big[np.lexsort((ts[big], -gaps[big]))][:MAX_LISTED_GAPS]
        largest = [gaps[i] / 1e9 for i in top.tolist()]
        at = [(ts[i] - ts[0]) / 1e9 for i in top.tolist()]
        listed = ", ".join(f"{g:.3f} s at +{a:.3f} s" for g, a in zip(largest, at, strict=True))
        dropped = _readings_in_gaps(reader, ts, gaps, max_gap_s, config) if reader else None
        severity: Severity = "WARNING"
        what = "readings in them are dropped"
        if dropped is not None:
            share = dropped / total_readings
            what = (f"{dropped} of {total_readings} readings ({share:.1%}) are in them and "
                    "will be dropped; raise [pose_sync] max_pose_gap_s to keep them")
            if total_readings - dropped < MIN_MAPPED_FRACTION * total_readings:
                severity = "ERROR"  # sonarmap run would refuse to map this log
        out.append(
            Finding(
                severity,
                "pose_gap",
                f"{big.size} gaps in the poses ({label}) longer than {limit}; {what}; "
                f"largest: {listed}",
                counts={
                    "gaps": int(big.size),
                    "largest_s": largest,
                    "at_s": at,
                    "max_pose_gap_s": max_gap_s,
                    "median_pose_interval_s": median_s,
                    "readings_dropped": dropped,
                },
            )
        )
    out += _pose_jumps(label, ts, xy_sorted)
    return out


def _pose_jumps(
    label: str, ts: npt.NDArray[np.int64], xy: npt.NDArray[np.float64]
) -> list[Finding]:
    """Consecutive poses further apart than a robot moves (:func:`is_pose_jump`), and how
    many of them lead into and out of an isolated glitch pose (:func:`pose_spikes`)."""
    if ts.shape[0] < 2:
        return []
    dist = np.hypot(np.diff(xy[:, 0]), np.diff(xy[:, 1]))
    dt = np.diff(ts).astype(np.float64) / 1e9
    jump = np.flatnonzero(is_pose_jump(dist, dt))
    if not jump.size:
        return []
    spikes = int(np.count_nonzero(pose_spikes(ts, xy[:, 0], xy[:, 1])))
    i = int(jump[np.argmax(dist[jump])])
    return [
        Finding(
            "WARNING",
            "pose_jump",
            f"{jump.size} steps in the poses ({label}) faster than {MAX_POSE_SPEED_MPS:g} m/s "
            f"(largest {dist[i]:.1f} m in {dt[i]:.3f} s at +{(ts[i] - ts[0]) / 1e9:.3f} s): "
            f"odometry glitches; sonarmap run drops the {spikes} isolated glitch poses among "
            "them (poses_spikes), the readings between the other jumps (pose_jump), and leaves "
            "isolated outliers out of the grid (outside_grid)",
            counts={"jumps": int(jump.size), "spikes": spikes, "largest_m": float(dist[i]),
                    "max_speed_mps": MAX_POSE_SPEED_MPS},
        )
    ]


def _readings_in_gaps(
    reader: LogReader,
    ts: npt.NDArray[np.int64],
    gaps: npt.NDArray[np.int64],
    max_gap_s: float,
    config: Config,
) -> int:
    """Readings whose stamp falls strictly inside a pose gap longer than the limit (as
    pose sync drops them), from a second pass over the ranges."""
    offset = round(config.pose_sync.time_offset_s * 1e9)
    limit = round(max_gap_s * 1e9)
    n = 0
    for batch in reader.batches(("ranges",)):
        if not isinstance(batch, RangeBatch) or not len(batch):
            continue
        t = batch.t_ns + offset
        hi = np.searchsorted(ts, t, side="left")
        inside = (hi > 0) & (hi < ts.shape[0])
        h = hi[inside]
        exact = ts[h] == t[inside]
        n += int(((gaps[h - 1] > limit) & ~exact).sum())
    return n
