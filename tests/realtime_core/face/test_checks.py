"""The rig checks' pose set and what the checks catch."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from realtime_core.face.checks import (
    EXTREME_POSES,
    MEASURED_POSES,
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
    assert np.isclose(np.array(SPEECH_POSES)[:, 2].max(), 0.45)


def test_single_poses_reach_the_ends_of_every_other_pose() -> None:
    span = np.array(SPEECH_POSES + MEASURED_POSES)
    lo, hi = span.min(0), span.max(0)
    singles = np.array(SINGLE_POSES)
    # Each single pose moves one parameter to an end of the span, both ends of each (mouth_open: 0 is rest).
    assert np.all((singles != 0).sum(1) == 1)
    for j in range(4):
        ends = singles[:, j][singles[:, j] != 0]
        assert ends.max() >= hi[j] - 1e-9
        assert lo[j] == 0 or ends.min() <= lo[j] + 1e-9


# The box the checks tested before they were measured on the shipped models (the articulatory
# targets' span): the frames below lie outside it.
ARTICULATORY_BOX = ((-0.014, 0.034), (-0.123, 0.089), (0.0, 0.45), (-0.027, 0.034))


@pytest.mark.parametrize("model_name", ["default", "low-latency"])
def test_checked_poses_hold_every_frame_a_shipped_model_produces(shared_data: Path, model_name: str) -> None:
    # Real speech of a voice no model was trained on, through the live path: every frame lies in the
    # convex hull of the checked poses (within the 0.002 IOD the table was chosen to), so a rig that
    # passes the checks is checked where this speech takes it (scripts/measure_param_box.py).
    from scipy.spatial import ConvexHull

    from assets.audio import read_audio
    from assets.modelfile import load_speech_model
    from realtime_core.pipeline import speech_to_params

    samples, rate = read_audio(shared_data / "speech" / "praatio" / "bobby.wav")
    x = np.asarray(speech_to_params(load_speech_model("hmm", model_name), samples, rate), dtype=np.float64)[:, :4]
    x[:, 2] = np.maximum(x[:, 2], 0.0)
    lo, hi = np.array(ARTICULATORY_BOX).T
    assert np.any((x < lo - 0.01) | (x > hi + 0.01)), "the speech no longer leaves the old box: pick another file"
    eq = ConvexHull(np.array(EXTREME_POSES)).equations
    outside = (x @ eq[:, :4].T + eq[:, 4]).max(axis=1)
    assert outside.max() <= 0.002 + 1e-6, x[int(np.argmax(outside))]


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
