"""Head files made for tests and the held-out head script: the built-in head's targets as other tools name them."""

from __future__ import annotations

import re

import numpy as np


def cc4_targets(builtin) -> dict[str, np.ndarray]:
    """The built-in head's 52 ARKit targets (``builtin``: :func:`assets.heads.builtin.load_builtin_head`; name -> (n, 3)
    displacements) as Character Creator 4's facial profile names them: its own words for sided targets
    (Mouth_Up_Upper_L, Brow_Raise_Outer_L, Cheek_Raise_L), ARKit's unsided mouth targets and its inner brow raise split
    into halves (Mouth_Roll_In_Upper_L/R, Brow_Raise_Inner_L/R) or quarters (Mouth_Funnel_Up_L ... Down_R) by smooth
    masks across the face's midline (0.05 IOD) and the mouth line (0.03 IOD) that sum to one, the rest in snake case
    (Jaw_Open, Mouth_Smile_L)."""
    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face import face_frame

    lm = builtin.landmarks
    v = np.asarray(builtin.mesh.vertices, dtype=np.float64)
    fr = face_frame(v, mouth_landmarks(lm))
    x = (v - v[lm["upper_inner"]]) @ fr.axes[0] / fr.iod
    y = (v - 0.5 * (v[lm["upper_inner"]] + v[lm["lower_inner"]])) @ fr.axes[1] / fr.iod
    left, up = 0.5 * (1 + np.tanh(x / 0.05)), 0.5 * (1 + np.tanh(y / 0.03))
    sides = {"L": left, "R": 1 - left}
    halves = {"Up": up, "Down": 1 - up}
    words = {
        "mouthUpperUp": "Mouth_Up_Upper",
        "mouthLowerDown": "Mouth_Down_Lower",
        "browDown": "Brow_Drop",
        "browOuterUp": "Brow_Raise_Outer",
        "cheekSquint": "Cheek_Raise",
    }
    cc: dict[str, np.ndarray] = {}
    for name, d in builtin.targets.items():
        d = np.asarray(d, dtype=np.float64)
        if name in ("mouthRollUpper", "mouthRollLower"):
            for s, m in sides.items():
                cc[f"Mouth_Roll_In_{name[9:]}_{s}"] = d * m[:, None]
        elif name == "browInnerUp":
            for s, m in sides.items():
                cc[f"Brow_Raise_Inner_{s}"] = d * m[:, None]
        elif name in ("mouthFunnel", "mouthPucker"):
            for h, mh in halves.items():
                for s, m in sides.items():
                    cc[f"Mouth_{name[5:]}_{h}_{s}"] = d * (mh * m)[:, None]
        else:
            side = "L" if name.endswith("Left") else "R" if name.endswith("Right") else ""
            stem = name.removesuffix("Left").removesuffix("Right")
            stem = words.get(stem, stem)
            cc["_".join(w.capitalize() for w in re.findall(r"[A-Z]?[a-z]+", stem)) + ("_" + side if side else "")] = d
    return cc
