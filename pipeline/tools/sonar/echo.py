"""From the surfaces a beam meets to one reading: echo levels, first echo, errors.

A reading is a fan of R rays (N readings × R rays, padded with ``d1 = +inf``). Each ray
meets a first surface at ``d1`` with incidence cos ``cos1`` and critical angle ``crit1``,
and, along the mirror direction from there, a second surface ``d2`` farther on
(``cos2``, ``crit2``). It gives two candidate echoes:

- direct, range ``d1``: level ``margin − beam(φ) − incidence(θ1) − 2α·d1``;
- a ghost through the first surface's mirror (multipath, only when the first surface
  reflects specularly, θ1 > θc1): range ``d1 + d2``, level with ``incidence(θ2)`` and
  ``2α·(d1 + d2)``. Its range is longer than the surface the ray met.

Each level gets N(0, level_noise) dB; the reading is the shortest candidate at ≥ 0 dB, or
no echo (max range). Then range noise N(0, σ0 + k·d), misses (``p_miss``: max range) and
crosstalk (``p_crosstalk``: another sonar's pulse heard at a uniform time before the own
echo). Below the minimum range: −inf (REP 117). Draws come from ``rng`` in a fixed order
(levels, noise, misses, crosstalk), one block per array, so results are deterministic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from formats.arrays import F64
from pipeline.tools.sonar.model import SonarPhysics

_LN10_20 = 20.0 / math.log(10.0)
Bools = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Fan:
    """(N, R) rays of N readings; see the module docstring (m, rad; +inf = nothing)."""

    off_axis: F64
    d1: F64
    cos1: F64
    crit1: F64
    d2: F64
    cos2: F64
    crit2: F64


@dataclass(frozen=True)
class Echoes:
    """Per reading: the range logged, and which candidate answered (for tests/notes)."""

    range_m: F64  # what the sonar reports (max range: no echo; −inf too close)
    first_echo_m: F64  # the detected echo before errors (+inf: none)
    ghost: Bools  # the detected echo is a multipath ghost
    missed: Bools  # dropped by p_miss
    crosstalk: Bools  # replaced by another sonar's pulse


def incidence_loss_db(cos_inc: F64, crit: F64, physics: SonarPhysics) -> F64:
    """0 dB up to the critical angle, diffuse backscatter (Lambert, cos²) beyond."""
    c = np.clip(cos_inc, 1e-6, 1.0)
    specular = c >= np.cos(crit)
    diffuse = physics.diffuse_loss_db - _LN10_20 * np.log(c)
    return np.where(specular, 0.0, diffuse)


def beam_loss_db(off_axis: F64, physics: SonarPhysics) -> F64:
    """Two-way Gaussian main lobe: 6 dB at the half width."""
    return 6.0 * (off_axis / math.radians(physics.beam_half_width_deg)) ** 2


def echo_levels(fan: Fan, physics: SonarPhysics) -> tuple[F64, F64]:
    """(direct, ghost) levels in dB above threshold, before noise (−inf: no surface)."""
    beam = beam_loss_db(fan.off_axis, physics)
    a2 = 2.0 * physics.absorption_db_per_m
    with np.errstate(invalid="ignore"):
        direct = physics.margin_db - beam - incidence_loss_db(fan.cos1, fan.crit1, physics) - a2 * fan.d1
        mirror = np.cos(fan.crit1) > fan.cos1  # the first surface reflects specularly
        ghost = (physics.margin_db - beam - incidence_loss_db(fan.cos2, fan.crit2, physics)
                 - a2 * (fan.d1 + fan.d2))
    direct = np.where(np.isfinite(fan.d1), direct, -np.inf)
    ghost = np.where(mirror & np.isfinite(fan.d1) & np.isfinite(fan.d2), ghost, -np.inf)
    return direct, ghost


def readings(
    fan: Fan, min_range: F64, max_range: F64, physics: SonarPhysics, rng: np.random.Generator
) -> Echoes:
    """One reading per fan row (see the module docstring)."""
    n, r = fan.d1.shape
    direct, ghost = echo_levels(fan, physics)
    noise = rng.standard_normal((2, n, r)) * physics.level_noise_db
    heard_d = direct + noise[0] >= 0.0
    heard_g = ghost + noise[1] >= 0.0
    rd = np.where(heard_d, fan.d1, np.inf).min(axis=1) if r else np.full(n, np.inf)
    rg = np.where(heard_g, fan.d1 + fan.d2, np.inf).min(axis=1) if r else np.full(n, np.inf)
    first = np.minimum(rd, rg)
    is_ghost = rg < rd
    z = rng.standard_normal(n)
    u_miss = rng.random(n)
    u_cross = rng.random(n)
    u_val = rng.random(n)
    echo = first < max_range
    d_safe = np.where(echo, first, 0.0)
    noisy = np.clip(d_safe + z * (physics.sigma_d0 + physics.k_d * d_safe), min_range, max_range)
    d = np.where(echo, noisy, max_range)
    missed = np.less(u_miss, physics.p_miss)
    d = np.where(missed, max_range, d)
    # Another sonar's pulse arrives at a time unrelated to this firing: uniform over the
    # listening window up to this reading's own echo (or its max range).
    cross = np.less(u_cross, physics.p_crosstalk)
    d = np.where(cross, min_range + u_val * (d - min_range), d)
    d = np.where(d < min_range, -np.inf, d)
    d = np.where(echo & ~missed & ~cross & (first < min_range), -np.inf, d)
    return Echoes(
        range_m=d.astype(np.float32).astype(np.float64),
        first_echo_m=first,
        ghost=is_ghost & echo,
        missed=missed,
        crosstalk=cross,
    )
