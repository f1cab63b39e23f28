"""The building's walls as a compass (``[pose_refinement] compass``): the heading bias
left after the calibration, measured against the directions the walls run in.

The calibration finds the heading bias from how well the echoes agree, and that is
precise where the robot revisits places. A long tour that rarely does can leave it off
(Acapulco's convention centre, 837 m: 0.07°/m while the calibration's bias grid was capped
at 401 steps, the end of the run 60° turned; uncapped, its grid finds 0.80°/m and the
compass nothing left). But
indoor walls mostly run along two perpendicular directions (a Manhattan world), and a
sonar passing a wall draws it: where the track's heading is wrong by ``e`` at travel
``s``, every wall drawn from there is turned by ``e``. The walls are a reference the
whole run shares without a single revisit, so the lever arm is the run's length.

* **Chords**: per sensor, its first echo in each ``CHORD_STEP_M`` of travel joined to the
  next (the echo's axis point, placed with the current poses): ``CHORD_MIN_M`` …
  ``CHORD_MAX_M`` long, over at most ``CHORD_MAX_TRAVEL_M`` of travel and
  ``CHORD_MAX_TURN_DEG`` of turn, the range changing by under ``CHORD_MAX_DRANGE_M`` (one
  wall, not a corner or a door).
* **The lattice angle** ``φ_w`` per window of ``window_m`` of travel: the chords'
  directions modulo 90°, averaged as ``4θ`` unit vectors weighted by length², refined
  over the chords within ``INLIER_DEG`` (walls, not clutter); its standard error from
  their scatter. A window needs ``MIN_CHORDS`` of them, the run three windows.
* **The drift** ``c`` (``φ_w = φ₀ + c·s_w``, ``|c| ≤ max_bias``): first the ``c`` on which
  the most pairs of windows agree once ``c·Δs`` is taken out (a kernel over their
  offsets modulo 90°; windows of a wing turned off the lattice agree with none, MIT
  CSAIL's 27° wing), then iteratively reweighted least squares on the windows unwrapped
  onto that lattice (Cauchy weights, scale ``CAUCHY`` × the residuals' MAD σ). The
  residuals' σ has a floor, ``WALL_FLOOR_DEG``: on true poses real buildings' windows
  scatter 0.45-1.8° about their lattice (eight Radish buildings), a simulated floor's
  straight walls 0.02-0.05°, where a chord's lean of a few hundredths of a degree that
  changes along the run would stand 14 errors from 0 (the sample corridor, 5 m windows).
  ``c``'s standard error is the larger of the weighted model's and a sandwich over the
  residuals with neighbouring windows correlated (Newey-West, ``HAC_LAG``).

Design notes and the measurements behind them: docs/research/pose_refinement.md, "How it works", item 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from formats.angles import wrap_angle
from formats.arrays import F64, I64
from pipeline.drift import DriftModel, apply_drift
from pipeline.refine.echoes import Echoes
from pipeline.refine.stretches import Corrected
from pipeline.refine.submaps import path_length_at
from pipeline.refine.surfaces import CAUCHY, MAD_SIGMA
from pipeline.se2 import transform_points

CHORD_STEP_M = 0.5
CHORD_MIN_M = 0.3
CHORD_MAX_M = 3.0
CHORD_MAX_TRAVEL_M = 2.0
CHORD_MAX_TURN_DEG = 5.0
CHORD_MAX_DRANGE_M = 0.3
INLIER_DEG = 8.0
MIN_CHORDS = 5
IRLS_STEPS = 8
HAC_LAG = 2
COARSE_STEPS = 16  # the drift search's first level: max_bias / this apart
WALL_FLOOR_DEG = 0.5
# directions with no lattice at all scatter 90°/√12 = 26° modulo 90°; windows that scatter
# half that about the lattice fitted share none (a track curled by a wrong bias: 35°)
MAX_WALL_SIGMA_DEG = 0.5 * 90.0 / math.sqrt(12.0)
SPECTRUM_BIN_M = 0.25  # the wall spectrum's travel bins (phase error under 2·c·bin, 0.05 rad at 6°/m)
SPECTRUM_PAD = 4  # its FFT padded to this many times the run: candidates a quarter lobe apart
SPECTRUM_MAX_RATIO = 0.5  # the track's own lattice at most half as strong as the turned one's
SPECTRUM_ALPHA = 1e-6  # the turned lattice's Rayleigh test over all candidates (Bonferroni)
# ... and the turned lattice holds half the chords' weight (real buildings at their right
# heading: 0.65-0.97; a ring corridor 30 m across driven three times, turned onto a
# "lattice" the Rayleigh test still passes at 40,000 echoes: 0.18)
SPECTRUM_MIN_STRENGTH = 0.5


@dataclass(frozen=True)
class Chords:
    """Wall chords in the world: direction (rad), length (m), travel at their middle (m)."""

    angle: F64
    length: F64
    travel: F64


@dataclass(frozen=True)
class Lattice:
    """Per window of travel: its middle (m), the lattice angle (rad, modulo 90°) and its
    standard error (rad)."""

    travel: F64
    angle: F64
    standard_error: F64


@dataclass(frozen=True)
class BiasFit:
    """The lattice's drift along the run: ``c`` (rad/m) and its standard error, the
    lattice's angle ``φ₀`` (rad), the residuals' robust σ (rad), the windows used."""

    bias: float
    standard_error: float
    angle: float
    wall_sigma: float
    windows: int
    dof: float  # the fit's degrees of freedom: the windows its robust weights keep, less 2

    @property
    def z(self) -> float:
        return abs(self.bias) / self.standard_error if self.standard_error > 0 else math.inf

    def z_needed(self, min_z: float) -> float:
        """The ``z`` that is as unlikely under no drift, with the standard error estimated
        from :attr:`dof` degrees of freedom (Student's t), as ``min_z`` with it known: a
        fit of six windows needs 17, of twenty 5.2, for ``min_z`` 4."""
        from scipy.special import ndtr, stdtrit  # not scipy.stats: 0.5 s of imports

        return float(-stdtrit(max(self.dof, 1.0), ndtr(-min_z)))


@dataclass(frozen=True)
class Turn:
    """The wall spectrum's strongest drift: ``c`` (rad/m), the lattice's strength ``R`` there
    and at no drift (0 … 1), the chords' effective number, the candidates searched, and
    the windows' own strength (:func:`window_strength`) without and with the turn."""

    bias: float
    strength: float
    strength_at_zero: float
    chords: float
    candidates: int
    windows_at_zero: float  # window_strength without the turn, and with it
    windows: float
    window_m: float

    @property
    def rayleigh(self) -> float:
        """The peak's Rayleigh statistic, ``n·R²``: ``P(R ≥ r) ≈ e^{−n r²}`` for directions
        with no lattice."""
        return self.chords * self.strength**2

    @property
    def windows_gain_needed(self) -> float:
        """Half what taking out a drift ``c`` tightens a window of ``window_m`` whose
        chords it spreads evenly: its strength times ``1 − sinc(2c·window_m)``."""
        half_turn = abs(self.bias) * self.window_m * 2.0  # the 4θ spread, halved
        return 0.5 * self.windows * (1.0 - math.sin(half_turn) / half_turn) if half_turn else 0.0

    def decisive(self) -> bool:
        """Whether the turn is established (module docstring, *the wall spectrum*): the
        turned lattice passes the Rayleigh test at ``SPECTRUM_ALPHA`` over every candidate
        searched and holds ``SPECTRUM_MIN_STRENGTH`` of the chords' weight, the track's own
        lattice is at most ``SPECTRUM_MAX_RATIO`` of it, and the turn tightens the windows'
        own lattices as a drift would (:attr:`windows_gain_needed`): parts of a building on
        two lattices 40-45° apart, visited one after the other, align under a drift that
        spreads each window instead."""
        return (self.rayleigh >= math.log(self.candidates / SPECTRUM_ALPHA)
                and self.strength >= SPECTRUM_MIN_STRENGTH
                and self.strength_at_zero <= SPECTRUM_MAX_RATIO * self.strength
                and self.windows - self.windows_at_zero >= self.windows_gain_needed)


def lattice_strength(chords: Chords, bias: F64) -> F64:
    """Per drift ``c`` in ``bias`` (rad/m): ``|Σ w·e^{4i(θ − c·s)}| / Σ w``, how well the
    chords share one lattice once the heading drift ``c`` is taken out (1: every chord on
    it; weights ``w`` = length²)."""
    w = chords.length**2
    phasor = w * np.exp(4j * chords.angle)
    out = np.empty(bias.size)
    for i in range(0, bias.size, 256):  # bounded memory: 256 × chords
        c = bias[i:i + 256]
        out[i:i + 256] = np.abs(np.exp(-4j * np.outer(c, chords.travel)) @ phasor)
    return out / max(float(w.sum()), 1e-300)


def window_strength(chords: Chords, window_m: float, bias: float = 0.0) -> float:
    """How well each window of ``window_m`` of travel shares a lattice of its own with the
    drift ``bias`` (rad/m) taken out: ``Σ_windows |Σ w·e^{4i(θ − c·s)}| / Σ w`` (1: every
    window's chords on one lattice, whatever the others')."""
    if chords.angle.size == 0:
        return 0.0
    w = chords.length**2
    phasor = w * np.exp(4j * (chords.angle - bias * chords.travel))
    _, win = np.unique(np.floor(chords.travel / window_m), return_inverse=True)
    per = np.bincount(win, phasor.real) + 1j * np.bincount(win, phasor.imag)
    return float(np.abs(per).sum() / w.sum())


def wall_spectrum(chords: Chords, reach: float, window_m: float = 20.0) -> Turn | None:
    """The drift ``|c| ≤ reach`` (rad/m) under which the whole run's chords share one lattice
    best: the strength over travel binned by ``SPECTRUM_BIN_M`` and Fourier transformed
    (frequency ``4c``), then the best candidate refined on the chords themselves; None
    without chords."""
    if chords.angle.size == 0:
        return None
    w = chords.length**2
    s0 = float(chords.travel.min())
    b = np.floor((chords.travel - s0) / SPECTRUM_BIN_M).astype(np.int64)
    phasor = w * np.exp(4j * chords.angle)
    binned = np.bincount(b, phasor.real) + 1j * np.bincount(b, phasor.imag)
    n = 1 << max(math.ceil(math.log2(SPECTRUM_PAD * binned.size)), 4)
    spectrum = np.abs(np.fft.fft(binned, n))  # Σ Z_b e^{−iωs_b}, ω = 2πk / (n·bin)
    omega = 2.0 * math.pi * np.fft.fftfreq(n, SPECTRUM_BIN_M)
    c = omega / 4.0
    inside = np.abs(c) <= reach  # 0 among them
    step = float(2.0 * math.pi / (n * SPECTRUM_BIN_M) / 4.0)
    best = float(c[inside][int(np.argmax(spectrum[inside]))])
    fine = np.clip(best + step * np.linspace(-1.0, 1.0, 41), -reach, reach)
    strength = lattice_strength(chords, fine)
    i = int(np.argmax(strength))
    zero = float(lattice_strength(chords, np.zeros(1))[0])
    return Turn(float(fine[i]), float(strength[i]), zero,
                float(w.sum() ** 2 / (w**2).sum()), int(inside.sum()),
                window_strength(chords, window_m), window_strength(chords, window_m, float(fine[i])),
                window_m)


def wall_chords(echoes: Echoes, t_ns: I64, x: F64, y: F64, yaw: F64) -> Chords:
    """The chords along each sensor's echoes on the track ``(x, y, yaw)`` (module
    docstring): per sensor, its first echo in each ``CHORD_STEP_M`` of travel, joined to
    the next such echo (however fast the sensor fires, a chord spans some travel)."""
    pose = echoes.on_track(t_ns, x, y, yaw).odo
    mid = echoes.bx.shape[1] // 2  # the arc's middle point: the beam's axis
    wx, wy = transform_points(pose, echoes.bx[:, mid], echoes.by[:, mid])
    travel = path_length_at(t_ns, x, y, echoes.t_ns)
    sid = echoes.mounts()
    step = np.floor(travel / CHORD_STEP_M).astype(np.int64)
    order = np.lexsort((np.arange(len(sid)), step, sid))  # by sensor, step, then time
    first = np.ones(order.size, bool)
    first[1:] = (sid[order][1:] != sid[order][:-1]) | (step[order][1:] != step[order][:-1])
    pick = order[first]  # each sensor's first echo per step of travel, in travel order
    a, b = pick[:-1], pick[1:]
    dx, dy = wx[b] - wx[a], wy[b] - wy[a]
    length = np.hypot(dx, dy)
    ok = ((sid[a] == sid[b]) & (length >= CHORD_MIN_M) & (length <= CHORD_MAX_M)
          & (np.abs(travel[b] - travel[a]) <= CHORD_MAX_TRAVEL_M)
          & (np.abs(wrap_angle(pose[b, 2] - pose[a, 2])) <= math.radians(CHORD_MAX_TURN_DEG))
          & (np.abs(echoes.range_m[b] - echoes.range_m[a]) < CHORD_MAX_DRANGE_M))
    return Chords(np.arctan2(dy, dx)[ok], length[ok], 0.5 * (travel[a] + travel[b])[ok])


def _off_lattice(angle: F64, phi: float) -> F64:
    """Each direction's offset (rad) from the nearest of the lattice ``phi``'s four."""
    return np.asarray((angle - phi + math.pi / 4) % (math.pi / 2) - math.pi / 4)


def lattice_angle(angle: F64, length: F64) -> tuple[float, float, int]:
    """(the lattice angle modulo 90°, its standard error, the inlier chords) of one
    window's chords; NaN where fewer than :data:`MIN_CHORDS` agree."""
    if angle.size < MIN_CHORDS:
        return math.nan, math.nan, 0
    w = length**2
    phi = float(np.angle((w * np.exp(4j * angle)).sum())) / 4
    band = math.radians(INLIER_DEG)
    for _ in range(4):
        d = _off_lattice(angle, phi)
        keep = np.abs(d) < band
        if keep.sum() < MIN_CHORDS:
            return math.nan, math.nan, int(keep.sum())
        phi += float((w[keep] * d[keep]).sum() / w[keep].sum())
    d = _off_lattice(angle, phi)
    keep = np.abs(d) < band
    n = int(keep.sum())
    if n < MIN_CHORDS:
        return math.nan, math.nan, n
    wk = w[keep]
    spread = math.sqrt(float((wk * d[keep] ** 2).sum() / wk.sum()))
    n_eff = float(wk.sum() ** 2 / (wk**2).sum())
    return phi, spread / math.sqrt(max(n_eff - 1.0, 1.0)), n


def window_lattice(chords: Chords, window_m: float) -> Lattice:
    """The lattice angle (modulo 90°) of each window of ``window_m`` of travel that has
    one."""
    win = np.floor(chords.travel / window_m).astype(np.int64)
    mids, angles, errors = [], [], []
    for k in np.unique(win):
        i = win == k
        phi, se, _ = lattice_angle(chords.angle[i], chords.length[i])
        if math.isfinite(phi):
            mids.append(float(chords.travel[i].mean()))
            angles.append(phi)
            errors.append(se)
    return Lattice(np.array(mids), np.array(angles), np.array(errors))


def _best_drift(lattice: Lattice, max_bias: float, wall_sigma: float) -> float:
    """The drift ``c`` (``|c| ≤ max_bias``, rad/m) on which the most pairs of windows agree on
    one lattice once ``c·Δs`` is taken out (a Gaussian kernel of their offset modulo 90° in
    their errors and the walls' spread; pairs on different lattices add ~0). Searched
    coarse to fine: each level's candidates ``step`` apart, every pair's kernel widened
    by the drift a step leaves unresolved over its separation, ``step·Δs/2``, so that no
    level steps over the peak; then a quarter of the step around the best, down to
    ``wall_sigma / 4`` over the run. The pairs are the cost: ``n²/2`` per candidate, and a
    flat grid at the final step over a run of 8 km took 16 s."""
    s = lattice.travel
    i, j = np.triu_indices(s.size, k=1)
    ds, dphi = s[j] - s[i], lattice.angle[j] - lattice.angle[i]
    var = lattice.standard_error[i] ** 2 + lattice.standard_error[j] ** 2 + 2 * wall_sigma**2
    final = 0.25 * wall_sigma / max(float(s.max() - s.min()), 1.0)
    step, centre, reach = max_bias / COARSE_STEPS, 0.0, max_bias
    while True:
        k = math.ceil(reach / step - 1e-9)
        candidates = np.clip(centre + step * np.arange(-k, k + 1), -max_bias, max_bias)
        wide = var + (0.5 * step * ds) ** 2
        score = [float(np.exp(-0.5 * _off_lattice(dphi - c * ds, 0.0) ** 2 / wide).sum())
                 for c in candidates]
        centre = float(candidates[int(np.argmax(score))])
        if step <= final:
            return centre
        reach, step = 2.0 * step, max(0.25 * step, final)


def fit_bias(lattice: Lattice, max_bias: float, wall_sigma: float = math.radians(1.0)
             ) -> BiasFit | None:
    """The heading drift ``c`` on which the windows agree best (searched over
    ``|c| ≤ max_bias``, rad/m, then fitted: module docstring) and its standard error, from
    the windows unwrapped onto the lattice it finds; None under three windows."""
    s, n = lattice.travel, lattice.travel.size
    if n < 3:
        return None
    c = _best_drift(lattice, max_bias, wall_sigma)
    # the lattice: the window angles, drift taken out, nearest the densest of them
    psi = lattice.angle - c * s
    agree = np.array([np.exp(-0.5 * (_off_lattice(psi, float(p)) / wall_sigma) ** 2).sum()
                      for p in psi])
    phi0 = float(psi[int(np.argmax(agree))])
    # the windows unwrapped onto that lattice, for the fit
    y = phi0 + _off_lattice(psi, phi0) + c * s
    design = np.column_stack([np.ones_like(s), s])
    sol = np.array([phi0, c])
    sigma = max(wall_sigma, math.radians(WALL_FLOOR_DEG))
    for _ in range(IRLS_STEPS):
        res = y - design @ sol
        robust = 1.0 / (1.0 + (res / (CAUCHY * sigma)) ** 2)
        ww = robust / (sigma**2 + lattice.standard_error**2)
        normal = design.T @ (design * ww[:, None])
        sol = np.linalg.solve(normal, design.T @ (ww * y))
        sigma = max(MAD_SIGMA * float(np.median(np.abs(res))), math.radians(WALL_FLOOR_DEG))
    res = y - design @ sol
    inv = np.linalg.inv(normal)
    # sandwich covariance with the windows' scores correlated over HAC_LAG neighbours
    # (Newey-West: a corridor's walls, off the lattice by the same amount, span windows)
    score = design * (ww * res)[:, None]
    meat = score.T @ score
    for lag in range(1, HAC_LAG + 1):
        cross = score[lag:].T @ score[:-lag]
        meat += (1.0 - lag / (HAC_LAG + 1)) * (cross + cross.T)
    sandwich = float((inv @ meat @ inv)[1, 1]) * n / (n - 2)
    # never below the model's own: windows that agree better than the walls' floor (a
    # simulated floor's straight walls) do not make a drift of a few tenths of a degree real
    variance = max(sandwich, float(inv[1, 1]))
    kept = float(robust.sum() ** 2 / (robust**2).sum())  # windows the weights keep
    return BiasFit(float(sol[1]), math.sqrt(variance), float(sol[0]), sigma, int(n), kept - 2.0)


def metrics_of(fit: BiasFit | None, lattice: Lattice) -> dict[str, Any]:
    """What the compass measured, for ``metrics.json``."""
    out: dict[str, Any] = {"windows": int(lattice.travel.size)}
    if fit is not None:
        out.update(bias_left_deg_per_m=math.degrees(fit.bias),
                   bias_left_standard_error=math.degrees(fit.standard_error),
                   z=fit.z, lattice_deg=math.degrees(fit.angle) % 90.0,
                   wall_sigma_deg=math.degrees(fit.wall_sigma))
    return out


def spectrum_metrics(turn: Turn, applied: bool) -> dict[str, Any]:
    """What the wall spectrum measured, for ``metrics.json``."""
    return {"bias_deg_per_m": math.degrees(turn.bias), "strength": turn.strength,
            "strength_at_zero": turn.strength_at_zero, "rayleigh": turn.rayleigh,
            "rayleigh_needed": math.log(turn.candidates / SPECTRUM_ALPHA),
            "windows_at_zero": turn.windows_at_zero, "windows": turn.windows,
            "windows_gain_needed": turn.windows_gain_needed, "applied": applied}


def spectrum_turn(chords: Chords, *, max_bias: float, reach: float, window_m: float
                  ) -> tuple[Turn | None, dict[str, Any]]:
    """The wall spectrum's turn of the track whose ``chords`` (:func:`wall_chords`) are
    given, where it is established and beyond ``max_bias`` (the windows' reach; searched up
    to ``reach``, rad/m), else None; and what was measured, for ``metrics.json``."""
    turn = wall_spectrum(chords, reach, window_m)
    if turn is None:
        return None, {"applied": False, "note": "no wall chords"}
    applied = abs(turn.bias) > max_bias and turn.decisive()
    return (turn if applied else None), spectrum_metrics(turn, applied)


def compass_correction(x: F64, y: F64, yaw: F64, lattice: Lattice, *, max_bias: float,
                       min_z: float) -> Corrected:
    """The track ``(x, y, yaw)`` with the heading bias its walls establish taken out, or as
    given (module docstring); ``lattice``: its windows' (:func:`window_lattice` of its
    :func:`wall_chords`)."""
    fit = fit_bias(lattice, max_bias)
    metrics = metrics_of(fit, lattice)
    metrics["applied"] = False
    if fit is None:
        metrics["note"] = "not applied: fewer than 3 windows of travel show a wall lattice"
        return Corrected(x, y, yaw, metrics)
    if fit.wall_sigma > math.radians(MAX_WALL_SIGMA_DEG):
        metrics["note"] = (f"not applied: the windows share no lattice (they scatter "
                           f"{math.degrees(fit.wall_sigma):.1f}° about it, > "
                           f"{MAX_WALL_SIGMA_DEG:.0f}°)")
        return Corrected(x, y, yaw, metrics)
    if abs(fit.bias) > max_bias:
        metrics["note"] = (f"not applied: the walls' drift, {math.degrees(fit.bias):+.3f}°/m, "
                           f"leaves the ± {math.degrees(max_bias):g}°/m searched")
        return Corrected(x, y, yaw, metrics)
    # Student's t only asks more than min_z (and its import costs a run 50 ms)
    needed = min_z if fit.z < min_z else fit.z_needed(min_z)
    if fit.z < needed:
        metrics["note"] = (f"not applied: the heading drift against the walls, "
                           f"{math.degrees(fit.bias):+.4f}°/m, is not established "
                           f"(z {fit.z:.1f} < {needed:.1f} for {fit.windows} windows)")
        return Corrected(x, y, yaw, metrics)
    metrics["z_needed"] = needed
    metrics["applied"] = True
    turned = apply_drift(x, y, yaw, DriftModel(heading_bias_deg_per_m=-math.degrees(fit.bias)))
    return Corrected(*turned, metrics)
