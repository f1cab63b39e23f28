"""The parameters of the sonar physics model, each with its unit and source.

An echo is heard when its level, in dB above the receiver's detection threshold, is ≥ 0:

    E = margin − beam(φ) − incidence(θ; θc) − 2·α·path + N(0, level_noise)

``beam(φ) = 6 dB·(φ/φ6)²`` is the two-way Gaussian main lobe of a piston transducer (φ the
angle off the beam axis, φ6 where it is 6 dB down); ``incidence`` is 0 dB up to the
surface's critical angle θc (the specular return) and ``diffuse_loss − 20·log10(cos θ)``
beyond (Lambertian backscatter of the roughness); θc is drawn per surface from a
log-normal (median, spread); α is the air's absorption. docs/SONAR_PHYSICS.md gives the
values and their sources (Kuc & Siegel 1987; Leonard & Durrant-Whyte 1992; the Polaroid
6500 ranging module and Pioneer 3 manuals).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields

from formats.errors import ConfigError

SONAR_MODELS = ("realistic", "ideal")


@dataclass(frozen=True)
class SonarPhysics:
    """Physical parameters of the realistic sonar (units in the names' comments)."""

    margin_db: float = 34.0  # head-on smooth-wall echo above threshold at 0 m, dB
    beam_half_width_deg: float = 10.0  # off-axis angle where the two-way lobe is −6 dB, deg
    absorption_db_per_m: float = 1.6  # air absorption at 50 kHz, one way, dB/m
    critical_angle_median_deg: float = 10.0  # median specular cut-off of a surface, deg
    critical_angle_spread: float = 0.7  # log-normal σ of the cut-off across surfaces, 1
    diffuse_loss_db: float = 40.0  # rough backscatter below a specular echo at normal, dB
    level_noise_db: float = 3.0  # echo level fluctuation (speckle), std, dB
    surface_patch_m: float = 1.0  # extent of one surface finish in emulated buildings, m
    p_miss: float = 0.03  # readings that drop their echo (electronics), 1
    p_crosstalk: float = 0.02  # readings that hear another sonar's pulse first, 1
    sigma_d0: float = 0.01  # range noise at 0 m, m
    k_d: float = 0.01  # range noise growth with range, 1

    def audible_half_angle(self) -> float:
        """Off-axis angle (rad) beyond which no echo can be heard: beam loss = margin."""
        return min(math.pi / 2, math.radians(self.beam_half_width_deg) * math.sqrt(self.margin_db / 6.0))

    def validate(self) -> SonarPhysics:
        """Raise ConfigError naming the parameter when a value is out of range."""
        rules = {
            "margin_db": (0, 200),
            "beam_half_width_deg": (0.1, 90),
            "absorption_db_per_m": (0, 100),
            "critical_angle_median_deg": (0.1, 90),
            "critical_angle_spread": (0, 5),
            "diffuse_loss_db": (0, 200),
            "level_noise_db": (0, 50),
            "surface_patch_m": (0.01, 1000),
            "p_miss": (0, 1),
            "p_crosstalk": (0, 1),
            "sigma_d0": (0, 10),
            "k_d": (0, 1),
        }
        for key, (lo, hi) in rules.items():
            v = getattr(self, key)
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ConfigError(f"sonar model parameter '{key}' must be in [{lo}, {hi}], got {v!r}")
        return self

    def with_overrides(self, pairs: list[str] | tuple[str, ...]) -> SonarPhysics:
        """These parameters with ``key=value`` overrides (``--sonar-param``), validated."""
        known = {f.name for f in fields(self)}
        changes: dict[str, float] = {}
        for pair in pairs:
            key, sep, value = pair.partition("=")
            key = key.strip()
            if not sep or key not in known:
                raise ConfigError(
                    f"sonar parameter '{pair}' must be KEY=VALUE with KEY one of "
                    f"{', '.join(sorted(known))}"
                )
            try:
                changes[key] = float(value)
            except ValueError:
                raise ConfigError(f"sonar parameter '{key}' must be a number, got {value!r}") from None
        return dataclasses.replace(self, **changes).validate()


def check_model_name(name: str) -> str:
    """``name`` when it is a sonar model (realistic, ideal), else ConfigError."""
    if name not in SONAR_MODELS:
        raise ConfigError(f"unknown sonar model '{name}' (known: {', '.join(SONAR_MODELS)})")
    return name
