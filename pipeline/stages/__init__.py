"""The stages a run goes through: ingest, pose sync, scans, metrics and the run's report.

A run (:mod:`pipeline.run`) reads readings and poses (:mod:`.ingest`), gives every reading
the robot's pose at its stamp (:mod:`.pose_sync`), groups readings into scans
(:mod:`.scans`), maps them (:mod:`pipeline.mapper`, after :mod:`pipeline.refine` when poses
are refined) and writes what it measured (:mod:`.metrics`, :mod:`.run_report`). Stages never
import :mod:`pipeline.tools`.
"""
