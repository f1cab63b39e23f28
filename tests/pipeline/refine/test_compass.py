"""The walls as a compass (pipeline.refine.compass): a heading bias left after the
calibration shows as the walls' lattice turning along the run, and is taken out where it
stands clear of the walls' own spread; true poses and buildings off the lattice are left
as they are."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pipeline.drift import DriftModel, apply_drift
from pipeline.refine import compass
from pipeline.refine.compass import Lattice, fit_bias, lattice_angle, window_lattice

KW = dict(window_m=20.0, max_bias=math.radians(0.3), min_z=4.0)


def _correction(t, x, y, yaw, echoes, *, window_m, max_bias, min_z):
    """The compass on a track with its echoes, as refinement runs it."""
    lattice = window_lattice(compass.wall_chords(echoes, t, x, y, yaw), window_m)
    return compass.compass_correction(x, y, yaw, lattice, max_bias=max_bias, min_z=min_z)


def _spectrum(t, x, y, yaw, echoes, **kw):
    """The wall spectrum's turn of a track with its echoes, as refinement asks it."""
    return compass.spectrum_turn(compass.wall_chords(echoes, t, x, y, yaw), **kw)


def test_the_lattice_angle_of_turned_walls_among_clutter():
    rng = np.random.default_rng(3)
    walls = math.radians(25.0) + rng.integers(0, 4, 40) * math.pi / 2
    walls += rng.normal(0.0, math.radians(0.5), 40)
    clutter = rng.uniform(-math.pi, math.pi, 12)
    angle = np.concatenate([walls, clutter])
    length = np.concatenate([rng.uniform(0.5, 2.0, 40), rng.uniform(0.5, 2.0, 12)])
    phi, se, n = lattice_angle(angle, length)
    assert math.degrees(phi) % 90 == pytest.approx(25.0, abs=0.3)
    assert 0 < math.degrees(se) < 0.3
    assert 40 <= n < 52  # the walls, and clutter only where it happens to lie along them


def test_too_few_chords_give_no_lattice():
    phi, se, n = lattice_angle(np.zeros(compass.MIN_CHORDS - 1),
                               np.ones(compass.MIN_CHORDS - 1))
    assert math.isnan(phi) and math.isnan(se) and n == 0


def _windows(drift_deg_per_m: float, wing: slice | None = None, seed: int = 0) -> Lattice:
    """Forty windows along 800 m whose walls turn with a heading drift, walls spread 1°,
    a wing of the building turned 27° where ``wing`` says; modulo 90° like the chords'."""
    rng = np.random.default_rng(seed)
    s = 10.0 + 20.0 * np.arange(40)
    angle = math.radians(3.0) + math.radians(drift_deg_per_m) * s
    angle += rng.normal(0.0, math.radians(1.0), s.size)
    if wing is not None:
        angle[wing] += math.radians(27.0)
    angle = (angle + math.pi / 4) % (math.pi / 2) - math.pi / 4
    return Lattice(s, angle, np.full(s.size, math.radians(0.3)))


def test_a_drift_is_found_across_the_wrap_and_past_a_turned_wing():
    fit = fit_bias(_windows(-0.074, wing=slice(15, 19)), math.radians(0.3))
    assert fit is not None
    assert math.degrees(fit.bias) == pytest.approx(-0.074, abs=3 * math.degrees(fit.standard_error))
    assert math.degrees(fit.standard_error) < 0.003
    assert fit.z > 20
    assert math.degrees(fit.angle) % 90 == pytest.approx(3.0, abs=1.0)


def test_a_small_drift_is_found_over_a_long_run():
    """Eight kilometres, 400 windows: the coarse-to-fine search still lands on the drift
    (0.03°/m: 240° over the run, wrapping the lattice's 90° many times)."""
    rng = np.random.default_rng(0)
    s = 10.0 + 20.0 * np.arange(400)
    angle = math.radians(0.03) * s + rng.normal(0.0, math.radians(1.0), s.size)
    angle = (angle + math.pi / 4) % (math.pi / 2) - math.pi / 4
    fit = fit_bias(Lattice(s, angle, np.full(s.size, math.radians(0.3))), math.radians(0.15))
    assert fit is not None
    assert math.degrees(fit.bias) == pytest.approx(0.03, abs=3 * math.degrees(fit.standard_error))
    assert math.degrees(fit.standard_error) < 1e-4


def test_no_drift_is_not_established():
    for seed in range(5):
        fit = fit_bias(_windows(0.0, wing=slice(15, 19), seed=seed), math.radians(0.3))
        assert fit is not None and fit.z < 3


def test_windows_that_agree_better_than_real_walls_do_not_establish_a_drift():
    """A simulated floor's straight walls scatter the windows by hundredths of a degree;
    the walls' floor (WALL_FLOOR_DEG) keeps a trend of tenths of a degree unproven."""
    s = np.array([2.0, 7.0, 12.0, 17.0, 22.0, 25.0])
    angle = math.radians(0.3) / 25.0 * s  # 0.3° over the run, nothing else
    fit = fit_bias(Lattice(s, angle, np.full(6, math.radians(0.02))), math.radians(0.3))
    assert fit is not None and fit.z < 1


def test_few_windows_must_stand_further_from_zero():
    """The standard error is estimated from the windows themselves: with few, Student's t
    asks more of ``z`` than ``min_z`` (the drifted Freiburg 101, six windows: a drift 0.08°/m
    off at z 3.1 that applied would have turned its map)."""
    fit = fit_bias(_windows(-0.074), math.radians(0.3))
    assert fit is not None and 35 < fit.dof <= 38
    assert 4.0 < fit.z_needed(4.0) < 4.6
    few = dataclasses.replace(fit, dof=4.0)
    assert few.z_needed(4.0) == pytest.approx(17.45, abs=0.01)
    assert dataclasses.replace(fit, dof=1e6).z_needed(4.0) == pytest.approx(4.0, abs=1e-3)


def test_windows_without_a_lattice_are_not_a_compass(intel, monkeypatch):
    """Chords in every direction (a track curled by a wrong bias): whatever drift fits
    their windows is not applied."""
    (t, x, y, yaw), echoes = intel
    real = compass.wall_chords(echoes, t, x, y, yaw)
    rng = np.random.default_rng(1)
    scattered = compass.Chords(rng.uniform(-math.pi, math.pi, real.angle.size), real.length,
                               real.travel)
    monkeypatch.setattr(compass, "wall_chords", lambda *args: scattered)
    out = _correction(t, x, y, yaw, echoes, **KW)
    assert out.metrics["applied"] is False and out.x is x
    assert out.metrics["wall_sigma_deg"] > compass.MAX_WALL_SIGMA_DEG == pytest.approx(12.99,
                                                                                      abs=0.01)
    assert out.metrics["note"].startswith("not applied: the windows share no lattice")


def test_fewer_than_three_windows_fit_nothing():
    assert fit_bias(Lattice(np.array([10.0, 30.0]), np.zeros(2), np.full(2, 0.01)), 0.01) is None


@pytest.fixture(scope="module")
def intel():
    from pathlib import Path

    from tests.pipeline.refine.conftest import log_echoes

    log = Path(__file__).resolve().parents[3] / "sample_logs" / "intel-lab" / "intel.mcap"
    return log_echoes(log, 3.0)


def test_a_heading_bias_left_on_the_intel_lab_is_taken_out(intel):
    (t, x, y, yaw), echoes = intel
    dx, dy, dyaw = apply_drift(x, y, yaw, DriftModel(heading_bias_deg_per_m=0.03))
    out = _correction(t, dx, dy, dyaw, echoes.on_track(t, dx, dy, dyaw), **KW)
    m = out.metrics
    assert m["applied"] is True
    assert m["bias_left_deg_per_m"] == pytest.approx(0.03, abs=0.005)
    assert m["z"] > 8 and m["windows"] >= 20 and 4.5 < m["z_needed"] < 6
    before = float(np.sqrt(np.mean((dx - x) ** 2 + (dy - y) ** 2)))
    after = float(np.sqrt(np.mean((out.x - x) ** 2 + (out.y - y) ** 2)))
    assert before > 1.0 and after < before / 10
    assert out.x[0] == dx[0] and out.yaw[0] == dyaw[0]  # the start pose is the frame


def test_true_poses_are_left_exactly_as_they_are(intel):
    (t, x, y, yaw), echoes = intel
    out = _correction(t, x, y, yaw, echoes, **KW)
    assert out.metrics["applied"] is False
    assert "not established" in out.metrics["note"] and out.metrics["z"] < 2
    assert out.x is x and out.y is y and out.yaw is yaw


def test_a_run_too_short_for_three_windows_is_left_alone(sample_echoes):
    (t, x, y, yaw), echoes = sample_echoes("corridor", 3.0)
    out = _correction(t, x, y, yaw, echoes, **KW)  # 26 m: two windows
    assert out.metrics == {"windows": 2, "applied": False,
                           "note": "not applied: fewer than 3 windows of travel show a wall "
                                   "lattice"}
    assert out.x is x
    none = _correction(t, x, y, yaw, echoes.take(np.arange(0)), **KW)
    assert none.metrics["windows"] == 0 and none.metrics["applied"] is False
    turn, m = _spectrum(t, x, y, yaw, echoes.take(np.arange(0)),
                                    max_bias=math.radians(0.15), reach=math.radians(6.0),
                                    window_m=20.0)
    assert turn is None and m == {"applied": False, "note": "no wall chords"}


def test_chords_follow_the_walls_of_the_simulated_corridor(sample_echoes):
    (t, x, y, yaw), echoes = sample_echoes("corridor", 3.0)
    chords = compass.wall_chords(echoes, t, x, y, yaw)
    assert chords.angle.size > 100
    assert np.all((chords.length >= compass.CHORD_MIN_M) & (chords.length <= compass.CHORD_MAX_M))
    off = np.degrees(np.abs((chords.angle + math.pi / 4) % (math.pi / 2) - math.pi / 4))
    assert np.median(off) < 3.0  # the corridor's walls run along the axes
    lattice = window_lattice(chords, 5.0)
    assert lattice.travel.size >= 5
    assert np.all(np.abs(np.degrees(lattice.angle)) % 90 < 1.0)


def test_a_round_hall_is_no_compass(tmp_path):
    """A ring corridor (walls of a 48-gon, radii 5 and 9 m) driven four times round: its
    walls turn with the travel as a drift would, but they share no lattice."""
    from pipeline.tools.simulate import SimOptions, simulate, write_simulation
    from pipeline.tools.simulate.world import world_from_dict
    from tests.pipeline.refine.conftest import log_echoes

    def ring(radius: float, n: int) -> list[list[float]]:
        return [[radius * math.cos(2 * math.pi * k / n), radius * math.sin(2 * math.pi * k / n)]
                for k in range(n)]

    world = world_from_dict({"polygon": [{"points": ring(9.0, 48)}, {"points": ring(5.0, 48)}]})
    waypoints = ring(7.0, 24) * 4
    log = tmp_path / "round.mcap"
    write_simulation(simulate(world, [*waypoints, waypoints[0]],
                              SimOptions(sonar_model="ideal", seed=3, speed=0.5, ring_rate_hz=5.0)), log, "mcap")
    (t, x, y, yaw), echoes = log_echoes(log, 3.0)
    dx, dy, dyaw = apply_drift(x, y, yaw, DriftModel(heading_bias_deg_per_m=0.05))
    out = _correction(t, dx, dy, dyaw, echoes.on_track(t, dx, dy, dyaw),
                                     **{**KW, "max_bias": math.radians(0.15)})
    assert out.metrics["windows"] >= 8 and out.metrics["applied"] is False
    assert out.x is dx
    assert out.metrics["wall_sigma_deg"] > compass.MAX_WALL_SIGMA_DEG
    assert out.metrics["note"].startswith("not applied: the windows share no lattice")
    turn, m = _spectrum(t, dx, dy, dyaw, echoes.on_track(t, dx, dy, dyaw),
                                    max_bias=math.radians(0.15), reach=math.radians(6.0),
                                    window_m=20.0)
    assert turn is None and m["applied"] is False  # nor does the spectrum find a lattice


def test_a_drift_beyond_the_range_searched_is_not_applied(intel):
    """The range is what a calibration leaves (0.07-0.09°/m measured); beyond it, a turning
    the walls show is more likely the building's (a round one) than the odometry's."""
    (t, x, y, yaw), echoes = intel
    dx, dy, dyaw = apply_drift(x, y, yaw, DriftModel(heading_bias_deg_per_m=0.2))
    out = _correction(t, dx, dy, dyaw, echoes.on_track(t, dx, dy, dyaw),
                                     **{**KW, "max_bias": math.radians(0.15)})
    assert out.metrics["applied"] is False and out.x is dx
    assert out.metrics["bias_left_deg_per_m"] == pytest.approx(0.2, abs=0.01)
    assert out.metrics["note"] == ("not applied: the walls' drift, +0.202°/m, leaves the "
                                   "± 0.15°/m searched")


def test_the_lattice_strength_peaks_at_the_drift_that_turns_the_walls():
    """Chords on one lattice whose direction turns 1.2°/m along 300 m of travel: only that
    drift taken out puts them back on it."""
    rng = np.random.default_rng(5)
    s = np.sort(rng.uniform(0.0, 300.0, 600))
    angle = rng.integers(0, 4, s.size) * math.pi / 2 + math.radians(1.2) * s
    chords = compass.Chords(angle + rng.normal(0.0, math.radians(1.0), s.size),
                            rng.uniform(0.5, 2.0, s.size), s)
    strength = compass.lattice_strength(chords, np.radians([0.0, 1.2, -1.2]))
    assert strength[1] > 0.99 and strength[0] < 0.1 and strength[2] < 0.1
    turn = compass.wall_spectrum(chords, math.radians(6.0))
    assert turn is not None
    assert math.degrees(turn.bias) == pytest.approx(1.2, abs=0.002)
    assert turn.strength > 0.99 and turn.strength_at_zero < 0.1 and turn.decisive()
    assert compass.wall_spectrum(compass.Chords(*(np.empty(0),) * 3), 0.1) is None


def test_a_wall_spectrum_without_a_lattice_is_not_decisive():
    """Directions with no lattice: some drift always scores best, by chance; the Rayleigh
    test over every candidate searched refuses it (five seeds)."""
    for seed in range(5):
        rng = np.random.default_rng(seed)
        s = np.sort(rng.uniform(0.0, 300.0, 400))
        chords = compass.Chords(rng.uniform(-math.pi, math.pi, s.size),
                                rng.uniform(0.5, 2.0, s.size), s)
        turn = compass.wall_spectrum(chords, math.radians(6.0))
        assert turn is not None and not turn.decisive()
        assert turn.rayleigh < math.log(turn.candidates / compass.SPECTRUM_ALPHA)


@pytest.mark.parametrize(("wing_deg", "first_m"), [(45.0, 100.0), (45.0, 200.0), (40.0, 150.0)])
def test_two_lattices_visited_one_after_the_other_are_no_drift(wing_deg, first_m):
    """A building whose second part stands 40-45° off the first's lattice, visited after
    it: a drift that turns one onto the other aligns the whole run (the spectrum's
    strength 0.01-0.2 → 0.7) but spreads every window's own lattice, which a drift the
    odometry had would have tightened: not decisive."""
    rng = np.random.default_rng(0)
    s = np.sort(rng.uniform(0.0, 2 * first_m, 800))
    lattice = np.where(s < first_m, 0.0, math.radians(wing_deg))
    angle = (lattice + rng.integers(0, 4, s.size) * math.pi / 2
             + rng.normal(0.0, math.radians(1.5), s.size))
    chords = compass.Chords(angle, rng.uniform(0.5, 2.0, s.size), s)
    turn = compass.wall_spectrum(chords, math.radians(6.0), 20.0)
    assert turn is not None and abs(math.degrees(turn.bias)) > 0.15
    assert turn.strength > 2 * turn.strength_at_zero  # the whole run aligns ...
    assert turn.windows - turn.windows_at_zero < turn.windows_gain_needed  # ... its windows not
    assert not turn.decisive()


@pytest.mark.parametrize("drift_deg_per_m", [0.2, 0.5, 3.6])
def test_a_drift_tightens_the_windows_as_well(drift_deg_per_m):
    rng = np.random.default_rng(1)
    s = np.sort(rng.uniform(0.0, 300.0, 800))
    angle = (rng.integers(0, 4, s.size) * math.pi / 2 + math.radians(drift_deg_per_m) * s
             + rng.normal(0.0, math.radians(1.5), s.size))
    turn = compass.wall_spectrum(compass.Chords(angle, rng.uniform(0.5, 2.0, s.size), s),
                                 math.radians(6.0), 20.0)
    assert turn is not None and turn.decisive()
    assert math.degrees(turn.bias) == pytest.approx(drift_deg_per_m, abs=0.005)
    assert turn.windows - turn.windows_at_zero > 1.5 * turn.windows_gain_needed


def test_the_spectrum_finds_a_heading_the_windows_cannot_reach(intel):
    """The Intel lab's true poses turned by 1.5°/m (30° per 20 m window, beyond the
    windows' fit): the spectrum finds the turn; on the true poses it finds none to make."""
    (t, x, y, yaw), echoes = intel
    dx, dy, dyaw = apply_drift(x, y, yaw, DriftModel(heading_bias_deg_per_m=1.5))
    turn, m = _spectrum(t, dx, dy, dyaw, echoes.on_track(t, dx, dy, dyaw),
                                    max_bias=math.radians(0.15), reach=math.radians(6.0),
                                    window_m=20.0)
    assert turn is not None and m["applied"] is True
    assert m["bias_deg_per_m"] == pytest.approx(1.5, abs=0.02)
    assert m["strength"] > 2 * m["strength_at_zero"] and m["rayleigh"] > m["rayleigh_needed"]
    none, m0 = _spectrum(t, x, y, yaw, echoes, max_bias=math.radians(0.15),
                                     reach=math.radians(6.0), window_m=20.0)
    assert none is None and m0["applied"] is False
    assert abs(m0["bias_deg_per_m"]) < 0.15  # the peak is where the walls already are


def test_a_weak_lattice_is_not_a_building_however_many_chords_show_it():
    """A fifth of 20,000 chords on a turning lattice, the rest in every direction: the
    Rayleigh test passes (the directions are not uniform), but a lattice holding 0.2 of
    their weight is not a Manhattan building's (0.65-0.97 measured)."""
    rng = np.random.default_rng(2)
    s = np.sort(rng.uniform(0.0, 400.0, 20_000))
    on = rng.random(s.size) < 0.2
    angle = np.where(on, rng.integers(0, 4, s.size) * math.pi / 2 + math.radians(1.0) * s,
                     rng.uniform(-math.pi, math.pi, s.size))
    turn = compass.wall_spectrum(compass.Chords(angle, np.ones(s.size), s), math.radians(6.0),
                                 20.0)
    assert turn is not None and math.degrees(turn.bias) == pytest.approx(1.0, abs=0.01)
    assert turn.rayleigh > 10 * math.log(turn.candidates / compass.SPECTRUM_ALPHA)
    assert turn.strength < compass.SPECTRUM_MIN_STRENGTH and not turn.decisive()
