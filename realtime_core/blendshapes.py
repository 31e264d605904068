"""Blendshape weights from the four mouth parameters: ARKit's 52 and the 15 OVR visemes.

Many engines drive faces by named blendshape weights instead of vertex positions. facecast's model
estimates four mouth parameters (``realtime_core.VISUAL_PARAMS``, in inter-ocular distances, IOD);
this module maps them to weights with one documented affine map per set, clipped to ``[0, 1]``:

    w = clip(A p + b, 0, 1),      p = (upper_lip_raise, lip_stretch, mouth_open, lip_corner_depress)

The maps are hand-set from the parameters' typical ranges (``training.params.TYPICAL_RANGES``): a
weight reaches 1 at the end of its parameter's typical range. They are a starting point that
engines can rescale, not a learned retargeting; shapes the four parameters do not observe (eyes,
brows, cheeks, tongue, jaw sideways) stay 0.

ARKit (Apple ``ARFaceAnchor.BlendShapeLocation``), per row ``name: expression``:

    jawOpen                 = mouth_open / 0.35
    mouthLowerDown{L,R}     = mouth_open / 0.60
    mouthUpperUp{L,R}       = upper_lip_raise / 0.06
    mouthPress{L,R}         = -upper_lip_raise / 0.03
    mouthStretch{L,R}       = lip_stretch / 0.10
    mouthPucker             = -lip_stretch / 0.12
    mouthFunnel             = -lip_stretch / 0.24 + mouth_open / 0.90
    mouthFrown{L,R}         = lip_corner_depress / 0.05
    mouthSmile{L,R}         = -lip_corner_depress / 0.05

OVR visemes (Oculus/Meta Lipsync order: sil PP FF TH DD kk CH SS nn RR aa E I O U):

    sil = 1 - mouth_open / 0.10          PP = -upper_lip_raise / 0.02
    FF  = upper_lip_raise / 0.04 - mouth_open / 0.30
    TH  = mouth_open / 0.30 - 0.20        DD = mouth_open / 0.40 - 0.10
    kk  = mouth_open / 0.40 - 0.15        CH = -lip_stretch / 0.16 + lip_corner_depress / 0.10
    SS  = lip_stretch / 0.12 - mouth_open / 0.50
    nn  = mouth_open / 0.50 - 0.05        RR = -lip_stretch / 0.20
    aa  = mouth_open / 0.35 - 0.30        E  = lip_stretch / 0.10 + mouth_open / 0.60 - 0.20
    I   = lip_stretch / 0.08 - mouth_open / 0.60
    O   = -lip_stretch / 0.12 + mouth_open / 0.50 - 0.20
    U   = -lip_stretch / 0.08 - mouth_open / 0.40
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from realtime_core import VISUAL_PARAMS

ARKIT_NAMES: tuple[str, ...] = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft",
    "eyeSquintLeft", "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight",
    "eyeLookOutRight", "eyeLookUpRight", "eyeSquintRight", "eyeWideRight", "jawForward",
    "jawLeft", "jawRight", "jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthLeft",
    "mouthRight", "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight",
    "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper", "mouthPressLeft",
    "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft",
    "browOuterUpRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft",
    "noseSneerRight", "tongueOut",
)
"""ARKit's 52 blendshape names in Apple's documented order (the order of the weights on the wire)."""

OVR_NAMES: tuple[str, ...] = ("sil", "PP", "FF", "TH", "DD", "kk", "CH", "SS", "nn", "RR", "aa", "E", "I", "O", "U")
"""The 15 OVR (Oculus Lipsync) visemes in their documented order."""

_P = {name: i for i, name in enumerate(VISUAL_PARAMS)}

# name -> ({parameter: coefficient (1/IOD)}, offset); see the module docstring.
_ARKIT_ROWS: dict[str, tuple[dict[str, float], float]] = {
    "jawOpen": ({"mouth_open": 1 / 0.35}, 0.0),
    "mouthLowerDownLeft": ({"mouth_open": 1 / 0.60}, 0.0),
    "mouthLowerDownRight": ({"mouth_open": 1 / 0.60}, 0.0),
    "mouthUpperUpLeft": ({"upper_lip_raise": 1 / 0.06}, 0.0),
    "mouthUpperUpRight": ({"upper_lip_raise": 1 / 0.06}, 0.0),
    "mouthPressLeft": ({"upper_lip_raise": -1 / 0.03}, 0.0),
    "mouthPressRight": ({"upper_lip_raise": -1 / 0.03}, 0.0),
    "mouthStretchLeft": ({"lip_stretch": 1 / 0.10}, 0.0),
    "mouthStretchRight": ({"lip_stretch": 1 / 0.10}, 0.0),
    "mouthPucker": ({"lip_stretch": -1 / 0.12}, 0.0),
    "mouthFunnel": ({"lip_stretch": -1 / 0.24, "mouth_open": 1 / 0.90}, 0.0),
    "mouthFrownLeft": ({"lip_corner_depress": 1 / 0.05}, 0.0),
    "mouthFrownRight": ({"lip_corner_depress": 1 / 0.05}, 0.0),
    "mouthSmileLeft": ({"lip_corner_depress": -1 / 0.05}, 0.0),
    "mouthSmileRight": ({"lip_corner_depress": -1 / 0.05}, 0.0),
}

_OVR_ROWS: dict[str, tuple[dict[str, float], float]] = {
    "sil": ({"mouth_open": -1 / 0.10}, 1.0),
    "PP": ({"upper_lip_raise": -1 / 0.02}, 0.0),
    "FF": ({"upper_lip_raise": 1 / 0.04, "mouth_open": -1 / 0.30}, 0.0),
    "TH": ({"mouth_open": 1 / 0.30}, -0.20),
    "DD": ({"mouth_open": 1 / 0.40}, -0.10),
    "kk": ({"mouth_open": 1 / 0.40}, -0.15),
    "CH": ({"lip_stretch": -1 / 0.16, "lip_corner_depress": 1 / 0.10}, 0.0),
    "SS": ({"lip_stretch": 1 / 0.12, "mouth_open": -1 / 0.50}, 0.0),
    "nn": ({"mouth_open": 1 / 0.50}, -0.05),
    "RR": ({"lip_stretch": -1 / 0.20}, 0.0),
    "aa": ({"mouth_open": 1 / 0.35}, -0.30),
    "E": ({"lip_stretch": 1 / 0.10, "mouth_open": 1 / 0.60}, -0.20),
    "I": ({"lip_stretch": 1 / 0.08, "mouth_open": -1 / 0.60}, 0.0),
    "O": ({"lip_stretch": -1 / 0.12, "mouth_open": 1 / 0.50}, -0.20),
    "U": ({"lip_stretch": -1 / 0.08, "mouth_open": -1 / 0.40}, 0.0),
}


def _matrix(names: tuple[str, ...], rows: dict[str, tuple[dict[str, float], float]]) -> tuple[np.ndarray, np.ndarray]:
    a = np.zeros((len(names), len(VISUAL_PARAMS)))
    b = np.zeros(len(names))
    index = {n: i for i, n in enumerate(names)}
    for name, (coefs, offset) in rows.items():
        for param, c in coefs.items():
            a[index[name], _P[param]] = c
        b[index[name]] = offset
    a.setflags(write=False)
    b.setflags(write=False)
    return a, b


_MAPS = MappingProxyType({
    "arkit52": (ARKIT_NAMES, *_matrix(ARKIT_NAMES, _ARKIT_ROWS)),
    "ovr15": (OVR_NAMES, *_matrix(OVR_NAMES, _OVR_ROWS)),
})

BLENDSHAPE_SETS: tuple[str, ...] = tuple(_MAPS)
"""Known weight sets: "arkit52", "ovr15"."""


def blendshape_names(which: str) -> tuple[str, ...]:
    """Names of a set, in wire order. Raises KeyError for an unknown set."""
    return _MAPS[which][0]


def blendshape_map(which: str) -> tuple[np.ndarray, np.ndarray]:
    """The affine map of a set: A (n_names, 4) in 1/IOD and b (n_names,), read-only."""
    _, a, b = _MAPS[which]
    return a, b


def blendshape_weights(params: np.ndarray, which: str) -> np.ndarray:
    """params (..., 4) mouth parameters (IOD) -> (..., n_names) float32 weights in [0, 1]."""
    a, b = blendshape_map(which)
    p = np.asarray(params, dtype=np.float64)
    return np.clip(p @ a.T + b, 0.0, 1.0).astype(np.float32)
