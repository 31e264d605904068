"""Motion Units (paper 002, Hong, Wen, Huang 2002): PCA of facial deformation, expression units, and
the least-squares conversion between MU parameters and any keyframe (blendshape) set.

    units      Utterance MUs (Sec. IV-A), Expression MUs (eq. 1), eq. 2 composition and analysis
    keyframes  MUPs <-> keyframe weights (eq. 3-4), keyframes in the MU subspace, round-trip error
"""

from realtime_core.motion_units.keyframes import (
    KeyframeSet,
    in_mu_space,
    keyframes_to_mups,
    mups_to_keyframes,
    round_trip_error,
)
from realtime_core.motion_units.units import (
    ExpressionUnits,
    MotionUnits,
    analyse,
    compose,
    fit_expression_units,
    fit_motion_units,
)

__all__ = [
    "ExpressionUnits",
    "KeyframeSet",
    "MotionUnits",
    "analyse",
    "compose",
    "fit_expression_units",
    "fit_motion_units",
    "in_mu_space",
    "keyframes_to_mups",
    "mups_to_keyframes",
    "round_trip_error",
]
