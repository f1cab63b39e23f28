"""One sonar physics model for ``simulate`` and ``emulate`` (docs/SONAR_PHYSICS.md).

:mod:`.model` holds the physical parameters, :mod:`.surfaces` the per-surface specular
cut-offs, :mod:`.echo` the echo levels and errors that turn the surfaces a beam meets into
a reading; the scenes say which surfaces a beam meets: :mod:`.scan_scene` from a laser
scan (``emulate``), :mod:`.world_scene` from a world's segments and circles (``simulate``).
"""

from __future__ import annotations

from pipeline.tools.sonar.echo import Echoes, Fan, readings
from pipeline.tools.sonar.model import SONAR_MODELS, SonarPhysics, check_model_name

__all__ = ["SONAR_MODELS", "Echoes", "Fan", "SonarPhysics", "check_model_name", "readings"]
