"""Bilabial closures: every /p b m/ of a unit-selection output closes, on the landmarks as on mouth_open."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ConfigError
from realtime_core.synthesis.closure import (
    CLOSED_IOD,
    ClosureConfig,
    bilabials_closed,
    close_bilabials,
    phone_frame_spans,
)
from realtime_core.synthesis.corpus import FPS
from realtime_core.synthesis.synthesizer import UnitSynthesizer
from realtime_core.synthesis.visemes import VISEME_ID

UPPER_INNER, LOWER_INNER = 13, 14  # MediaPipe's inner lip midpoints


@pytest.fixture(scope="module")
def shipped():
    from assets.unitcorpus import SHIPPED, load_unit_corpus

    return load_unit_corpus(SHIPPED)


def lip_gap(stored, frames: np.ndarray) -> np.ndarray:
    """(n,) inner lip gap (IOD) of the frames' landmark coefficients placed on the corpus's neutral face."""
    pos = {int(j): k for k, j in enumerate(stored.landmark_indices)}
    pts = stored.neutral[None] + stored.landmark_offsets(frames[:, : stored.corpus.n_coefficients])
    return np.linalg.norm(pts[:, pos[UPPER_INNER]] - pts[:, pos[LOWER_INNER]], axis=1)


# GRID s1 val sentences ("bin blue at f five again", "place red with d six please") with the talker's
# HMM phone timings: without its own recording, unit selection leaves their first /b/ and /p/ open
SENTENCES = ("bbaf5a", "prwd6p")


@pytest.mark.parametrize("sid", SENTENCES)
@pytest.mark.parametrize("n_best", [1, 10])
def test_every_pbm_closes_on_the_landmarks_too(shipped, sid, n_best):
    from training.grid_phones import HMM_PATH, read_grid_phones
    from training.unit_corpus import phone_rows

    rows = phone_rows(read_grid_phones(HMM_PATH)[sid])
    corpus = shipped.corpus
    mo = corpus.dim_names.index("mouth_open")
    plain = UnitSynthesizer(corpus, rest=shipped.rest_frame(), closure=None)
    closing = UnitSynthesizer(corpus, rest=shipped.rest_frame())
    before = plain.synthesize(rows, "arpabet", n_best=n_best, exclude=(sid,))
    after = closing.synthesize(rows, "arpabet", n_best=n_best, exclude=(sid,))
    t = after.target
    assert not bilabials_closed(before.frames[:, mo], t.visemes, t.starts_s, t.ends_s).all()
    assert bilabials_closed(after.frames[:, mo], t.visemes, t.starts_s, t.ends_s).all()

    # the landmarks: at every /p b m/ the inner lips come as close as the corpus's own closed frames do
    # (the 90th percentile of their gap over recorded frames whose mouth_open is <= 0.03 IOD)
    real = lip_gap(shipped, corpus.frames[corpus.frames[:, mo] <= CLOSED_IOD].astype(np.float64))
    limit = float(np.percentile(real, 90))
    opening = lip_gap(shipped, after.frames)
    spans = phone_frame_spans(t.starts_s, t.ends_s, len(after.frames))[t.visemes == VISEME_ID["PBM"]]
    assert all(opening[a:b].min() <= limit for a, b in spans)
    assert any(lip_gap(shipped, before.frames)[a:b].min() > limit for a, b in spans)

    # only the frames around the /p b m/ move
    near = np.zeros(len(after.frames), bool)
    for a, b in spans:
        near[max(a - 2, 0) : b + 2] = True  # the default fade: one frame each side
    np.testing.assert_array_equal(after.frames[~near], before.frames[~near])


def test_the_pull_reaches_the_target_fades_smoothly_and_leaves_closed_phones_alone():
    n, d = 40, 3
    k = np.arange(n)
    frames = np.zeros((n, d))
    frames[:, 0] = 0.1 + 0.02 * np.sin(k / 3)  # mouth_open, open throughout
    frames[:, 1] = 2.0 * frames[:, 0]  # a landmark channel that follows it
    frames[30:33, 0] = 0.0  # a /p/ that already closes
    frames[30:33, 1] = 0.0
    closed = np.array([-0.01, -0.02, 0.5])
    visemes = np.array([VISEME_ID["AA"], VISEME_ID["PBM"], VISEME_ID["AA"], VISEME_ID["PBM"], VISEME_ID["AA"]])
    edges = np.array([0, 10, 14, 30, 33, 40]) / FPS
    cfg = ClosureConfig(mouth_open_iod=0.02, hold_frames=1, ramp_frames=2)
    out = close_bilabials(frames, visemes, edges[:-1], edges[1:], closed, mouth_open_dim=0, config=cfg)
    inside = out[10:14, 0]
    c = 10 + int(np.argmin(frames[10:14, 0]))
    # the most closed frame and its held neighbours reach the target (at most), inside the phone only
    assert np.all(out[max(c - 1, 10) : min(c + 2, 14), 0] <= 0.02 + 1e-12)
    assert inside.min() == pytest.approx(0.02, abs=1e-12) or inside.min() < 0.02
    # a linear blend towards the closed pose: the landmark channel keeps following mouth_open
    w = (frames[:, 0] - out[:, 0]) / (frames[:, 0] - closed[0])
    np.testing.assert_allclose(out[:, 1], frames[:, 1] + w * (closed[1] - frames[:, 1]), atol=1e-12)
    np.testing.assert_allclose(out[:, 2], w * closed[2], atol=1e-12)
    # fades in and out: weights within [0, 1], no step larger than the ramp allows, zero far away
    assert np.all((w >= -1e-12) & (w <= 1 + 1e-12))
    assert np.max(np.abs(np.diff(w))) <= 0.5 + 1e-9
    np.testing.assert_array_equal(out[: max(c - 1, 10) - 3], frames[: max(c - 1, 10) - 3])
    # the /p/ that closes by itself is untouched
    np.testing.assert_array_equal(out[20:], frames[20:])


def test_closure_config_is_validated():
    for bad in ({"mouth_open_iod": 0.05}, {"hold_frames": -1}, {"ramp_frames": 0}, {"ramp_frames": 2.5}):
        with pytest.raises(ConfigError):
            ClosureConfig(**bad)
