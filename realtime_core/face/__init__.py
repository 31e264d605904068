"""Face models and retargeting onto arbitrary heads (paper 000 Sec. 5; paper 001 Sec. 3.5, 3.9).

model          FaceModel (mesh + animation/shape units), mouth measurement and calibration
candide        Candide-3 .wfm text parser
registration   similarity (Umeyama) + shape-unit fit from landmarks
projection     control points: closest vertex, one-to-one, geodesic check (Sec. 5.1)
interpolation  eq. 8-10 weights as one sparse matrix (Sec. 5.2)
rbf            Gaussian RBF map with GCV-chosen ridge (paper 001 Sec. 3.5)
adaptation     per-vertex affine transfer of morph targets (paper 001 Sec. 3.9)
simple         a simple face model sampled from a head with morph targets
rig            Rig: params (4,) -> head displacement with one sparse product; head calibration
harmonic       a smooth (harmonic) deformation field from the control-point motion
keyframes      keyframe (morph-target) weights by bounded least squares; heads driven by their own targets
checks         rig checks at the poses speech produces (flips, stretch, interpenetration, closure)
"""

from realtime_core.face.candide import parse_wfm
from realtime_core.face.model import (
    FaceFrame,
    FaceModel,
    MouthCalibration,
    MouthLandmarks,
    calibrate_mouth,
    face_frame,
    face_frame_at,
    inner_lip_gap,
    measure_mouth,
)
from realtime_core.face.registration import Registration, Similarity, fit_similarity, register
from realtime_core.face.rig import Rig, RigConfig, build_rig

__all__ = [
    "FaceFrame",
    "FaceModel",
    "MouthCalibration",
    "MouthLandmarks",
    "Registration",
    "Rig",
    "RigConfig",
    "Similarity",
    "build_rig",
    "calibrate_mouth",
    "face_frame",
    "face_frame_at",
    "fit_similarity",
    "inner_lip_gap",
    "measure_mouth",
    "parse_wfm",
    "register",
]
