"""The rig checks' pose set and what the checks catch."""

from __future__ import annotations

import numpy as np

from realtime_core.face.checks import (
    SINGLE_POSES,
    SPEECH_POSES,
    SPEECH_SCALE,
    check_rig,
)
from realtime_core.face.model import MouthLandmarks
from training.articulatory import CLASSES


def test_speech_poses_are_the_articulatory_targets_scaled() -> None:
    # The table in checks.py (realtime_core cannot import training) must follow the classes.
    want = sorted(
        tuple(round(float(x) * SPEECH_SCALE, 3) + 0.0 for x in c.target) for c in CLASSES.values() if not c.silence
    )
    assert sorted(SPEECH_POSES) == want
    span = np.array(SPEECH_POSES)
    lo, hi = span.min(0), span.max(0)
    singles = np.array(SINGLE_POSES)
    # Each single pose moves one parameter to an end of the span (pressed lips: mouthPress = 1).
    assert np.all((singles != 0).sum(1) == 1)
    for j in range(4):
        ends = singles[:, j][singles[:, j] != 0]
        assert ends.max() >= hi[j] - 1e-9
        assert lo[j] == 0 or ends.min() <= lo[j] + 1e-9
    assert np.isclose(hi[2], 0.45)


class _Fold:
    """A flat 2x2 grid of quads whose centre vertex moves through its neighbours with mouth_open."""

    def __init__(self) -> None:
        g = np.array([[x, y, 0.0] for y in range(3) for x in range(3)], dtype=np.float64)
        self.neutral = g
        t = []
        for y in range(2):
            for x in range(2):
                a = y * 3 + x
                t += [[a, a + 1, a + 4], [a, a + 4, a + 3]]
        self.triangles = np.array(t)

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = self.neutral.copy()
        v[4, 0] += 10.0 * p[2]  # 0.45 -> 4.5: far past the right column, folding its triangles
        return v


def test_check_catches_a_fold() -> None:
    rig = _Fold()
    lm = MouthLandmarks(
        eye_outer_left=2,
        eye_inner_left=5,
        eye_inner_right=3,
        eye_outer_right=0,
        corner_left=8,
        corner_right=6,
        upper_lip=7,
        lower_lip=7,
        upper_inner=7,
        lower_inner=7,
    )
    rep = check_rig(rig, lm)
    assert rep.flipped_triangles > 0 and not rep.passed
