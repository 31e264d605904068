"""The upper lip's peak at /a/ on heads as facecast rigs them (automatic landmarks, the rig cache).

    python scripts/upper_lip_peak.py HEAD [HEAD ...]

HEAD: a mesh file or a rig .npz. Prints, per head, :func:`realtime_core.face.checks.upper_lip_peak` (IOD: how far
the upper lip's lower edge at /a/ rises in the middle above a smooth arc through its sides; the anny child's capped
rig 0.038, the old heavy man's 0.042 before its upper lip was eased, the rows that pass at their first rig -0.02 to
0.022), the edge's
heights at -0.3 .. +0.3 of the mouth's width (IOD, from the middle's), and how the rig was made (docs/animation.md,
"The upper lip drawn to a peak").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("heads", nargs="+", type=Path)
    args = ap.parse_args()
    from assets.heads.head import head_check_inputs, resolve_head
    from clients.render.landmarks import find_landmarks
    from realtime_core.face.checks import upper_lip_peak

    for spec in args.heads:
        head = resolve_head(spec, landmark_finder=find_landmarks)
        landmarks, inputs = head_check_inputs(head, landmark_finder=find_landmarks)
        peak, edge = upper_lip_peak(head.rig, landmarks, teeth=inputs["teeth"])
        meta = head.rig.meta
        how = [k for k in ("simple_gain_capped", "lips_touching_apart", "lower_inner_moved") if meta.get(k)]
        tries = len(meta.get("rig_attempts", [])) + 1
        rel = np.round(edge - edge[len(edge) // 2], 3).tolist()
        print(f"{spec.name}: peak {peak:+.3f} IOD; edge {rel}; attempt {tries}{'; ' + ', '.join(how) if how else ''}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
