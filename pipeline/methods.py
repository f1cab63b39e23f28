"""The mapping methods, one definition for ``[mapper] method``, ``run --method`` and the
mapper factory (kept import-light: the CLI builds its ``--method`` choice from it)."""

from __future__ import annotations

from enum import StrEnum


class Method(StrEnum):
    """A mapping method; its value is the name the configuration, the command line and
    ``metrics.json`` (``run.method``) use."""

    SPECULAR = "specular"  # echo attribution with specular surfaces, §10
    FORWARD = "forward"  # §10 with the detection by incidence measured on the log, §11 (the default)
    ATTRIBUTION = "attribution"  # echo attribution, ALGORITHM.md §9
    ANDERSONE = "andersone"  # the paper's method as published, §1-5
    CLASSIC = "classic"  # log-odds occupancy grid with an inverse sensor model, §8
