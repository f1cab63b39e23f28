"""Trajectory errors of an estimated trajectory against the true one: ATE and RPE.

The definitions are those of evo (M. Grupp, *evo: Python package for the evaluation of
odometry and SLAM*), ``evo_ape --align`` and ``evo_rpe``, restricted to SE(2):

* **Association.** Each estimated pose inside the truth's time span is paired with the
  true pose at its own stamp, interpolated between the bracketing true poses (linear in
  position, shortest arc in yaw — :func:`pipeline.stages.pose_sync.interpolate_poses`). evo pairs
  the nearest stamps within ``t_max_diff``; for trajectories logged on the same clock, as
  simulate and emulate write them, both give the same pairs, and interpolation needs no
  tolerance.
* **Alignment** (ATE only). The rigid motion ``(R, t)`` minimising
  ``Σ |R·p_i + t − q_i|²`` over the associated positions (Umeyama 1991 / Horn 1987 without
  scale; in 2-D ``θ = atan2(Σ p̃ × q̃, Σ p̃ · q̃)`` on the centred positions).
* **ATE** (evo APE, translation part): ``e_i = |R·p_i + t − q_i|``; reported as RMSE, mean,
  median and max, m.
* **RPE** (evo RPE, ``all_pairs = false``): pose pairs ``(i, j)`` chosen on the truth —
  with ``unit = "m"``, from pose 0, each next ``j`` is the first pose at which the true
  path length since ``i`` reaches ``delta``, then ``i = j``; with ``unit = "frames"``,
  ``j = i + delta``. The error of a pair is ``E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)`` (``Q`` truth,
  ``P`` estimate): its translation norm (m) and the absolute value of its angle (deg),
  each reported as RMSE and mean. RPE needs no alignment.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from formats.errors import ConfigError, InputError
from formats.writers.trajectory_tum import Trajectory
from pipeline.stages.pose_sync import POSE_OK, PoseTrack, interpolate_poses

RpeUnit = Literal["m", "frames"]


@dataclass(frozen=True)
class TrajectoryError:
    """ATE and RPE of one estimate against one truth; see the module docstring."""

    poses_compared: int
    alignment: tuple[float, float, float]  # (tx m, ty m, θ rad) applied to the estimate
    ate_rmse_m: float
    ate_mean_m: float
    ate_median_m: float
    ate_max_m: float
    rpe_delta: float
    rpe_unit: str
    rpe_pairs: int
    rpe_trans_rmse_m: float | None
    rpe_trans_mean_m: float | None
    rpe_rot_rmse_deg: float | None
    rpe_rot_mean_deg: float | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, floats rounded to 12 significant digits."""

        def r(v: Any) -> Any:
            if isinstance(v, float):
                return float(f"{v:.12g}")
            if isinstance(v, tuple):
                return [r(a) for a in v]
            return v

        return {k: r(v) for k, v in asdict(self).items()}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"

    def table_rows(self) -> list[tuple[str, str]]:
        """Rows for a two-column text table."""

        def num(v: float | None, fmt: str) -> str:
            return "n/a" if v is None else format(v, fmt)

        tx, ty, th = self.alignment
        unit = "m" if self.rpe_unit == "m" else "frames"
        return [
            ("ATE (aligned)", f"rmse {self.ate_rmse_m:.4f} m, mean {self.ate_mean_m:.4f} m, "
                              f"median {self.ate_median_m:.4f} m, max {self.ate_max_m:.4f} m "
                              f"({self.poses_compared} poses)"),
            ("alignment", f"({tx:.3f} m, {ty:.3f} m, {math.degrees(th):.2f}°)"),
            (f"RPE per {self.rpe_delta:g} {unit}",
             f"translation rmse {num(self.rpe_trans_rmse_m, '.4f')} m, mean "
             f"{num(self.rpe_trans_mean_m, '.4f')} m; rotation rmse "
             f"{num(self.rpe_rot_rmse_deg, '.3f')}°, mean {num(self.rpe_rot_mean_deg, '.3f')}° "
             f"({self.rpe_pairs} pairs)"),
        ]


def associate(estimate: Trajectory, truth: Trajectory) -> tuple[Trajectory, Trajectory]:
    """The estimate's poses inside the truth's span and the truth interpolated at them."""
    track = PoseTrack(truth.t_ns, truth.x, truth.y, truth.yaw, "", "")
    look = interpolate_poses(track, estimate.t_ns, max_gap_ns=np.iinfo(np.int64).max)
    ok = look.reason == POSE_OK
    est = Trajectory(estimate.t_ns[ok], estimate.x[ok], estimate.y[ok], estimate.yaw[ok])
    ref = Trajectory(estimate.t_ns[ok], look.x[ok], look.y[ok], look.yaw[ok])
    return est, ref


def align_se2(px: F64, py: F64, qx: F64, qy: F64) -> tuple[float, float, float]:
    """``(tx, ty, θ)`` of the rigid motion taking points ``p`` onto ``q`` in least squares."""
    mpx, mpy, mqx, mqy = px.mean(), py.mean(), qx.mean(), qy.mean()
    ax, ay, bx, by = px - mpx, py - mpy, qx - mqx, qy - mqy
    theta = math.atan2(float(np.sum(ax * by - ay * bx)), float(np.sum(ax * bx + ay * by)))
    c, s = math.cos(theta), math.sin(theta)
    return float(mqx - (c * mpx - s * mpy)), float(mqy - (s * mpx + c * mpy)), theta


def rpe_pairs(truth: Trajectory, delta: float, unit: RpeUnit) -> tuple[I64, I64]:
    """Index pairs ``(i, j)`` of the relative pose error (see the module docstring)."""
    n = len(truth)
    if unit == "frames":
        step = int(delta)
        ids = np.arange(0, n, step, dtype=np.int64)
    else:
        seg = np.hypot(np.diff(truth.x), np.diff(truth.y))
        picked = [0]
        run = 0.0
        for k, d in enumerate(seg.tolist(), start=1):
            run += d
            if run >= delta:
                picked.append(k)
                run = 0.0
        ids = np.asarray(picked, dtype=np.int64)
    return ids[:-1], ids[1:]


def trajectory_error(
    estimate: Trajectory, truth: Trajectory, *, rpe_delta: float = 1.0, rpe_unit: RpeUnit = "m"
) -> TrajectoryError:
    """ATE and RPE of ``estimate`` against ``truth``. InputError when fewer than two
    estimated poses fall inside the truth's time span."""
    if rpe_unit not in ("m", "frames"):
        raise ConfigError(f"RPE unit must be 'm' or 'frames', got {rpe_unit!r}")
    if not (math.isfinite(rpe_delta) and rpe_delta > 0) or (
        rpe_unit == "frames" and rpe_delta != int(rpe_delta)
    ):
        raise ConfigError(f"RPE delta must be > 0 (a whole number of frames), got {rpe_delta!r}")
    est, ref = associate(estimate, truth)
    if len(est) < 2:
        raise InputError(
            f"only {len(est)} estimated pose(s) lie inside the true trajectory's time span; "
            "are both on the same clock?"
        )
    tx, ty, th = align_se2(est.x, est.y, ref.x, ref.y)
    c, s = math.cos(th), math.sin(th)
    ex = c * est.x - s * est.y + tx - ref.x
    ey = s * est.x + c * est.y + ty - ref.y
    e = np.hypot(ex, ey)
    i, j = rpe_pairs(ref, rpe_delta, rpe_unit)
    trans: F64 | None = None
    rot: F64 | None = None
    if i.shape[0]:
        # Relative motions in the frame of pose i, for the truth (Q) and the estimate (P).
        def rel(p: Trajectory) -> tuple[F64, F64, F64]:
            dx, dy = p.x[j] - p.x[i], p.y[j] - p.y[i]
            ci, si = np.cos(p.yaw[i]), np.sin(p.yaw[i])
            return ci * dx + si * dy, -si * dx + ci * dy, wrap_angle(p.yaw[j] - p.yaw[i])

        qx, qy, qa = rel(ref)
        px, py, pa = rel(est)
        trans = np.hypot(px - qx, py - qy)  # |R(−qa)(t_P − t_Q)| = |t_P − t_Q|
        rot = np.degrees(np.abs(wrap_angle(pa - qa)))

    def rms(v: F64 | None) -> float | None:
        return None if v is None else float(np.sqrt(np.mean(v * v)))

    def mean(v: F64 | None) -> float | None:
        return None if v is None else float(np.mean(v))

    return TrajectoryError(
        poses_compared=len(est),
        alignment=(tx, ty, th),
        ate_rmse_m=float(np.sqrt(np.mean(e * e))),
        ate_mean_m=float(np.mean(e)),
        ate_median_m=float(np.median(e)),
        ate_max_m=float(np.max(e)),
        rpe_delta=float(rpe_delta),
        rpe_unit=rpe_unit,
        rpe_pairs=int(i.shape[0]),
        rpe_trans_rmse_m=rms(trans),
        rpe_trans_mean_m=mean(trans),
        rpe_rot_rmse_deg=rms(rot),
        rpe_rot_mean_deg=mean(rot),
    )
