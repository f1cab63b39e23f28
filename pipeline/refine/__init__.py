"""Pose refinement (``sonarmap run --refine-poses``): the odometry corrected from the sonar
echoes themselves — its calibration (scale error, heading bias), local corrections per
stretch of travel and, optionally, submap matching with a pose graph — before the final
mapping pass. Works on the pose track and the readings; the mapper is not involved."""

from pipeline.refine.echoes import Echoes, collect_echoes
from pipeline.refine.refine import Refinement, refine_track

__all__ = ["Echoes", "Refinement", "collect_echoes", "refine_track"]
