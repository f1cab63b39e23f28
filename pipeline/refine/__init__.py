"""Pose refinement (``sonarmap run --refine-poses``): the odometry corrected from the sonar
echoes themselves by one model — its calibration (scale error, heading bias) and a pose
graph over submaps with loop closures, the scale and bias its variables — before the final
mapping pass (``model = "chain"``: the chain it replaces, kept for comparison). Works on the
pose track and the readings; the mapper is not involved."""

from pipeline.refine.echoes import Echoes, collect_echoes
from pipeline.refine.refine import Refinement, refine_track

__all__ = ["Echoes", "Refinement", "collect_echoes", "refine_track"]
