"""sonarmap's staged mapping pipeline: ingest, pose sync, scan building, mapping, metrics.

Kept import-light: ``import pipeline`` pulls in nothing heavy, so that ``sonarmap --help``
is instant. The public entry point is :func:`pipeline.run.run`.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("sonarmap")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"
