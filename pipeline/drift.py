"""Odometry drift: a documented, seeded model of wheel-odometry error.

``simulate`` and ``emulate`` use it to turn a true trajectory into the odometry a robot
would log, keeping the true trajectory as truth. The model works on the motion
increments between consecutive poses, expressed in the robot frame at the earlier pose
(``Δs`` = the true distance of the step, ``Δθ`` = its true rotation):

* **scale error** ``k``: the step's translation is reported ``(1 + k)`` times its true
  length (a wheel radius off by ``k``);
* **heading bias** ``b`` (deg/m): the step's rotation is reported ``Δθ + b·Δs``, so the
  heading error grows by ``b`` degrees per metre driven (a wheelbase or gyro bias;
  positive = counter-clockwise);
* **noise per step**: each translation axis gets ``N(0, noise_xy²·Δs)`` (position random
  walk, m per √m) and the rotation ``N(0, noise_yaw²·|Δθ|)`` (rad per √rad turned);
* **heading random walk** per metre: the rotation also gets ``N(0, heading_walk²·Δs)``
  (rad per √m), so the heading error grows as the square root of the distance driven and
  the position error faster than linearly (real wheel odometry's dominant error);
* **wheel slip**: slips start at a Poisson rate of ``slips_per_100m`` along the path; each
  one spreads a heading error ``N(0, slip_yaw_deg²)`` and a scale error ``N(0, slip_scale²)``
  over the next ``slip_length_m`` of travel (steps overlapping it share it pro rata).

The drifted increments are composed again from the first true pose, so the odometry
starts where the truth starts (REP 105: ``odom`` coincides with the world at the start).
Noise is drawn from the generator given (one ``standard_normal((3, n−1))`` call when
``noise_xy`` or ``noise_yaw`` is non-zero, then the heading walk's, then the slips', each
only when its term is non-zero), so the same seed gives the same bytes and a model without
the newer terms draws exactly what it drew before they existed.
:meth:`DriftModel.wheel_odometry` gives typical figures (docs/POSE_REFINEMENT.md cites them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.angles import wrap_angle
from formats.arrays import F64
from formats.errors import ConfigError


@dataclass(frozen=True)
class DriftModel:
    """The odometry error model (see the module docstring); all zero = no drift."""

    scale_error: float = 0.0  # fraction: 0.03 reports 3 % more distance than driven
    heading_bias_deg_per_m: float = 0.0  # deg of yaw error per metre driven (+ = CCW)
    noise_xy: float = 0.0  # m per √m, per translation axis
    noise_yaw: float = 0.0  # rad per √rad turned
    heading_walk: float = 0.0  # rad per √m driven: heading random walk
    slips_per_100m: float = 0.0  # wheel slips per 100 m of path (Poisson)
    slip_yaw_deg: float = 0.0  # std of one slip's heading error, deg
    slip_scale: float = 0.0  # std of one slip's scale error over its length, fraction
    slip_length_m: float = 0.5  # path over which one slip acts, m

    @staticmethod
    def wheel_odometry(scale_error: float = -0.02, heading_bias_deg_per_m: float = -0.5
                       ) -> DriftModel:
        """Typical uncalibrated differential-drive odometry (docs/POSE_REFINEMENT.md, "Drift
        model", for the sources): a systematic scale and heading bias, a heading random walk
        of 0.01 rad/√m, position noise 0.01 m/√m, 0.02 rad/√rad turned, one slip per 50 m."""
        return DriftModel(scale_error, heading_bias_deg_per_m, noise_xy=0.01, noise_yaw=0.02,
                          heading_walk=0.01, slips_per_100m=2.0, slip_yaw_deg=2.0,
                          slip_scale=0.2)

    @staticmethod
    def removing(scale_error: float, heading_bias: float) -> DriftModel:
        """The model that removes a systematic error of ``scale_error`` (fraction) and
        ``heading_bias`` (rad per metre driven): applied to odometry with that error, it
        gives the poses without it (pose refinement's calibration)."""
        return DriftModel(scale_error=1.0 / (1.0 + scale_error) - 1.0,
                          heading_bias_deg_per_m=-math.degrees(heading_bias) / (1.0 + scale_error))

    @property
    def is_zero(self) -> bool:
        return (self.scale_error, self.heading_bias_deg_per_m, self.noise_xy, self.noise_yaw,
                self.heading_walk, self.slip_rate) == (0.0,) * 6

    @property
    def slip_rate(self) -> float:
        """Slips per metre that change anything (0 when a slip has no error)."""
        return self.slips_per_100m / 100.0 if (self.slip_yaw_deg or self.slip_scale) else 0.0

    def or_typical(self) -> DriftModel:
        """This model with every term left at 0 set to :meth:`wheel_odometry`'s figure."""
        typical = DriftModel.wheel_odometry()
        return DriftModel(*(getattr(self, f) or getattr(typical, f)
                            for f in self.__dataclass_fields__))

    def describe_random_walk(self) -> str:
        """The heading walk and slip terms in words, each after ", " (empty when zero)."""
        parts = ""
        if self.heading_walk:
            parts += f", heading walk {self.heading_walk:g} rad/√m"
        if self.slip_rate:
            parts += (f", {self.slips_per_100m:g} slips/100 m ({self.slip_yaw_deg:g}°, "
                      f"{self.slip_scale:g} scale over {self.slip_length_m:g} m)")
        return parts

    def validate(self) -> DriftModel:
        """Raise ConfigError naming the parameter when a value is out of range."""
        checks = [
            (math.isfinite(self.scale_error) and -0.5 < self.scale_error < 0.5,
             "scale_error", "in (-0.5, 0.5)"),
            (math.isfinite(self.heading_bias_deg_per_m)
             and abs(self.heading_bias_deg_per_m) <= 45, "heading_bias_deg_per_m",
             "in [-45, 45]"),
            (math.isfinite(self.noise_xy) and self.noise_xy >= 0, "noise_xy", ">= 0"),
            (math.isfinite(self.noise_yaw) and self.noise_yaw >= 0, "noise_yaw", ">= 0"),
            (math.isfinite(self.heading_walk) and 0 <= self.heading_walk <= 1, "heading_walk",
             "in [0, 1]"),
            (math.isfinite(self.slips_per_100m) and 0 <= self.slips_per_100m <= 100,
             "slips_per_100m", "in [0, 100]"),
            (math.isfinite(self.slip_yaw_deg) and 0 <= self.slip_yaw_deg <= 90, "slip_yaw_deg",
             "in [0, 90]"),
            (math.isfinite(self.slip_scale) and 0 <= self.slip_scale <= 1, "slip_scale",
             "in [0, 1]"),
            (math.isfinite(self.slip_length_m) and self.slip_length_m > 0, "slip_length_m",
             "> 0"),
        ]
        for ok, key, rule in checks:
            if not ok:
                raise ConfigError(f"drift '{key}' must be {rule}, got {getattr(self, key)!r}")
        return self


def drift_model(model: DriftModel, wheel_odometry: bool) -> DriftModel:
    """``model`` (or with ``wheel_odometry`` :meth:`DriftModel.or_typical`), validated."""
    return (model.or_typical() if wheel_odometry else model).validate()


def apply_drift(
    x: F64, y: F64, yaw: F64, model: DriftModel, rng: np.random.Generator | None = None
) -> tuple[F64, F64, F64]:
    """Drifted odometry ``(x, y, yaw)`` of the true poses ``(x, y, yaw)`` (m, rad).

    ``rng`` is needed only when a noise term is non-zero. With a zero model the true poses
    are returned (as copies).
    """
    return Steps.of(x, y, yaw).drifted(model, rng)


def systematic_factors(models: list[DriftModel]) -> tuple[F64, F64, npt.NDArray[np.bool_]]:
    """Per model, the factor on each step's length (``1 + scale error``), the heading bias
    (rad per metre of step) and whether the model is zero (its poses are the odometry's)."""
    scale = 1.0 + np.array([v.scale_error for v in models], np.float64)
    bias = np.array([math.radians(v.heading_bias_deg_per_m) for v in models], np.float64)
    return scale, bias, np.array([v.is_zero for v in models], np.bool_)


@dataclass(frozen=True)
class Steps:
    """A trajectory's motion increments (the module docstring's ``Δs``, ``Δθ``, and the step
    in the robot frame at the earlier pose), kept so that many drift models can be applied
    to one trajectory without recomputing them (pose refinement's calibration search)."""

    x: F64
    y: F64
    yaw: F64
    lx: F64  # the step in the robot frame at the earlier pose, m
    ly: F64
    ds: F64  # its length, m
    dyaw: F64  # its rotation, rad (wrapped)

    @staticmethod
    def of(x: F64, y: F64, yaw: F64) -> Steps:
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        yaw = np.asarray(yaw, dtype=np.float64)
        dx, dy = np.diff(x), np.diff(y)
        c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
        return Steps(x, y, yaw, c * dx + s * dy, -s * dx + c * dy, np.hypot(dx, dy),
                     wrap_angle(np.diff(yaw)))

    def drifted_many(self, models: list[DriftModel]) -> tuple[F64, F64, F64]:
        """The poses under each of ``models`` (noise-free), one row per model: the same
        arithmetic as :meth:`drifted`, so the same bits, in one pass over the steps."""
        x, y, yaw = self.x, self.y, self.yaw
        m, n = len(models), x.shape[0]
        if n < 2 or m == 0:
            return (np.tile(x, (m, 1)), np.tile(y, (m, 1)), np.tile(yaw, (m, 1)))
        scale, bias, same = systematic_factors(models)
        ox, oy, oyaw = self._integrate(self.lx * scale[:, None], self.ly * scale[:, None],
                                       self.dyaw + bias[:, None] * self.ds)
        ox[same], oy[same], oyaw[same] = x, y, yaw  # as drifted(): the poses themselves
        return ox, oy, oyaw

    def drifted(self, model: DriftModel, rng: np.random.Generator | None = None
                ) -> tuple[F64, F64, F64]:
        """The poses with ``model``'s error (:func:`apply_drift`)."""
        x, y, yaw = self.x, self.y, self.yaw
        n = x.shape[0]
        if model.is_zero or n < 2:
            return x.copy(), y.copy(), yaw.copy()
        ds = self.ds
        lx = self.lx * (1.0 + model.scale_error)
        ly = self.ly * (1.0 + model.scale_error)
        dyaw = self.dyaw + math.radians(model.heading_bias_deg_per_m) * ds
        if model.noise_xy or model.noise_yaw:
            if rng is None:
                raise ValueError("apply_drift needs a random generator for a noisy drift model")
            noise = rng.standard_normal((3, n - 1))
            lx = lx + noise[0] * model.noise_xy * np.sqrt(ds)
            ly = ly + noise[1] * model.noise_xy * np.sqrt(ds)
            dyaw = dyaw + noise[2] * model.noise_yaw * np.sqrt(np.abs(self.dyaw))
        if model.heading_walk or model.slip_rate:
            if rng is None:
                raise ValueError("apply_drift needs a random generator for a noisy drift model")
            if model.heading_walk:
                dyaw = dyaw + rng.standard_normal(n - 1) * model.heading_walk * np.sqrt(ds)
            if model.slip_rate:
                slip_yaw, slip_scale = _slips(ds, model, rng)
                lx, ly = lx * (1.0 + slip_scale), ly * (1.0 + slip_scale)
                dyaw = dyaw + slip_yaw
        ox, oy, oyaw = self._integrate(lx[None], ly[None], dyaw[None])
        return ox[0], oy[0], oyaw[0]

    def _integrate(self, lx: F64, ly: F64, dyaw: F64) -> tuple[F64, F64, F64]:
        """Rows of steps (robot frame, rotations) composed again from the first pose."""
        zero = np.zeros((lx.shape[0], 1))
        heading = self.yaw[0] + np.concatenate([zero, np.cumsum(dyaw, axis=1)], axis=1)
        c, s = np.cos(heading[:, :-1]), np.sin(heading[:, :-1])
        ox = self.x[0] + np.concatenate([zero, np.cumsum(c * lx - s * ly, axis=1)], axis=1)
        oy = self.y[0] + np.concatenate([zero, np.cumsum(s * lx + c * ly, axis=1)], axis=1)
        return ox, oy, wrap_angle(heading)


def _slips(ds: F64, model: DriftModel, rng: np.random.Generator) -> tuple[F64, F64]:
    """Per step, the heading error (rad) and the scale error (fraction) the slips give it:
    slips start uniformly along the path (a Poisson count), each spreads its errors over
    ``slip_length_m``; a step gets the share of each slip that falls on it."""
    end = np.concatenate([[0.0], np.cumsum(ds)])
    length = float(end[-1])
    count = int(rng.poisson(model.slip_rate * length))
    starts = np.sort(rng.uniform(0.0, length, count))
    err = rng.standard_normal((2, count))
    yaw = np.zeros(ds.shape[0])
    scale = np.zeros(ds.shape[0])
    for k in range(count):
        a, b = starts[k], starts[k] + model.slip_length_m
        overlap = np.clip(np.minimum(end[1:], b) - np.maximum(end[:-1], a), 0.0, None)
        yaw += overlap / model.slip_length_m * math.radians(model.slip_yaw_deg) * err[0, k]
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = np.where(ds > 0, overlap / np.where(ds > 0, ds, 1.0), 0.0)
        scale += frac * model.slip_scale * err[1, k]
    return yaw, scale
