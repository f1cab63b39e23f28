"""The ``--drift-*`` options that ``simulate`` and ``emulate`` share (pipeline/drift.py's
model of wheel-odometry error), declared once."""

from __future__ import annotations

from typing import Annotated

import typer

DriftScale = Annotated[
    float, typer.Option("--drift-scale", help="Odometry scale error, fraction (0.03: 3 % too long).")
]
DriftHeadingBias = Annotated[
    float, typer.Option("--drift-heading-bias", help="Odometry heading bias, degrees per metre driven.")
]
DriftXY = Annotated[float, typer.Option("--drift-xy", help="Odometry position noise, m per √m.")]
DriftYaw = Annotated[float, typer.Option("--drift-yaw", help="Odometry yaw noise, rad per √rad.")]
DriftHeadingWalk = Annotated[
    float,
    typer.Option("--drift-heading-walk", help="Odometry heading random walk, rad per √m driven."),
]
DriftSlips = Annotated[
    float, typer.Option("--drift-slips", help="Wheel slips per 100 m driven (Poisson).")
]
DriftSlipYaw = Annotated[
    float, typer.Option("--drift-slip-yaw", help="Std of one slip's heading error, degrees.")
]
DriftSlipScale = Annotated[
    float,
    typer.Option("--drift-slip-scale", help="Std of one slip's scale error over 0.5 m, fraction."),
]
DriftWheelOdometry = Annotated[
    bool,
    typer.Option("--drift-wheel-odometry", help="Set every --drift-* term left at 0 to typical "
                 "wheel-odometry figures (docs/POSE_REFINEMENT.md)."),
]
