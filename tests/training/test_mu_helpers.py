"""Paper 002's training helpers: the speaker -> built-in head correspondence (checked with the
MediaPipe canonical face, whose vertices are the face-mesh landmarks), closure windows and rates,
viseme keyframes from word alignments, and the score of eq. 6-8 against a hand computation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import assets
from training.motion_units import Clip, score
from training.mu_expressions import BILABIAL_WORDS, closure_rate, closure_windows, head_correspondence
from training.mu_keyframes import viseme_keyframes


def test_head_correspondence_lands_on_the_heads_own_landmarks(shared_data: Path, builtin_head) -> None:
    from assets.heads.landmarks import read_landmarks
    from assets.heads.mesh import load_mesh
    from realtime_core.face import MouthLandmarks, face_frame

    canon = load_mesh(shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj").vertices
    mp = {
        k: int(v)
        for k, v in read_landmarks(
            Path(assets.__file__).parent / "heads" / "landmarks" / "mediapipe_canonical.json"
        ).items()
    }
    head = builtin_head
    idx = [mp["corner_left"], mp["corner_right"], mp["upper_lip"], mp["lower_lip"], mp["chin"]]
    verts, sim = head_correspondence(canon, idx, head, mp)
    lm = MouthLandmarks(**{k: head.landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    iod = face_frame(head.mesh.vertices, lm).iod
    want = [head.landmarks[n] for n in ("corner_left", "corner_right", "upper_lip", "lower_lip", "chin")]
    gap = np.linalg.norm(head.mesh.vertices[verts] - head.mesh.vertices[want], axis=1) / iod
    assert gap.max() < 0.05, gap  # within 5 % of the IOD of the head's own landmark vertex
    assert sim.scale > 0


def test_closure_windows_and_rate() -> None:
    words = [(0.0, 0.5, "sil"), (0.5, 0.8, "bin"), (0.8, 1.0, "red"), (1.0, 1.3, "please")]
    w = closure_windows(words)
    assert len(w) == 2 and w[0][0] == int(np.floor((0.5 - 0.06) * 30))
    assert {"bin", "blue", "by", "place", "please"} <= BILABIAL_WORDS
    t = np.zeros((45, 4))
    t[:, 2] = 0.2
    t[16, 2] = 0.0  # closed in the first window only
    assert closure_rate([t], [w], 0.03) == pytest.approx(0.5)


def test_viseme_keyframes_take_the_named_word_parts() -> None:
    d = np.zeros((60, 6), dtype=np.float32)
    d[30:33] = 1.0  # the end of "three" spans 1.0..1.2 s -> frames 30..36
    clip = Clip("x", "train", np.zeros(16000, np.float32), 16000, d, np.zeros((60, 4)), np.zeros((468, 3)))
    vis = viseme_keyframes([clip], {"x": [(0.8, 1.1, "three"), (1.5, 1.9, "at")]})
    np.testing.assert_allclose(vis["i"], 1.0)
    np.testing.assert_allclose(vis["a"], 0.0)
    assert "u" not in vis


def test_score_matches_a_hand_computation() -> None:
    rng = np.random.default_rng(0)
    t = rng.standard_normal((200, 6))
    e = t + 0.3 * rng.standard_normal((200, 6))
    scale = np.abs(t).max(0)
    s = score(t, e, scale, t[:, :4], e[:, :4])
    tn, en = t / scale, e / scale
    tc, ec = tn - tn.mean(0), en - en.mean(0)
    assert s.r == pytest.approx((tc * ec).sum() / np.sqrt((tc**2).sum() * (ec**2).sum()))
    assert s.mse == pytest.approx(np.mean((tn - en) ** 2))
    assert s.nu_true == pytest.approx(np.mean(tn.std(0)))
