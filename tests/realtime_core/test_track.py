"""The domain Track: validated once, immutable; frames_from_samples puts samples on a frame grid."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import VISUAL_PARAMS, ConfigError
from realtime_core.track import Track, frames_from_samples


def test_track_validates_once():
    with pytest.raises(ConfigError, match=r"\(n_frames, 4\)"):
        Track(values=np.zeros((5, 3)))
    with pytest.raises(ConfigError, match="NaN"):
        Track(values=np.full((2, 4), np.nan))
    with pytest.raises(ConfigError, match="fps"):
        Track(values=np.zeros((2, 4)), fps=0)
    with pytest.raises(ConfigError, match="start_s"):
        Track(values=np.zeros((2, 4)), start_s=-1.0)
    with pytest.raises(ConfigError, match="distinct"):
        Track(values=np.zeros((2, 2)), names=("a", "a"))
    src = np.zeros((3, 4))
    t = Track(values=src)
    src[0, 0] = 5.0  # the track holds its own copy ...
    assert t.values[0, 0] == 0.0
    with pytest.raises(ValueError):
        t.values[0, 0] = 1.0  # ... and it is read-only
    assert (t.n_frames, t.n_channels, t.names, t.fps) == (3, 4, VISUAL_PARAMS, 30.0)


def test_times_duration_and_channels():
    v = np.arange(12.0).reshape(6, 2)
    t = Track(values=v, names=("a", "b"), fps=25, start_s=1.0)
    np.testing.assert_allclose(t.times(), 1.0 + np.arange(6) / 25)
    assert t.duration_s == pytest.approx(6 / 25)
    np.testing.assert_array_equal(t.channel("b"), v[:, 1])
    with pytest.raises(ConfigError, match="no channel 'c'"):
        t.channel("c")


def test_frames_from_samples_by_hand():
    t = np.array([0.0, 1.0])
    p = np.array([[0, 0, 0, 0], [1, 2, 3, 4.0]])
    f = frames_from_samples(t, p, 4.0)
    assert f.values.shape == (5, 4) and f.fps == 4.0 and f.start_s == 0.0
    np.testing.assert_allclose(f.values[:, 3], [0, 1, 2, 3, 4])


def test_frames_from_samples_agrees_with_scipy_interp1d_and_refuses_bad_times():
    from scipy.interpolate import interp1d

    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.005, 0.05, 200))  # irregular, first sample after 0 s
    v = rng.standard_normal((200, 4))
    f = frames_from_samples(t, v, 30.0)
    ft = np.arange(f.n_frames) / 30.0
    ref = interp1d(t, v, axis=0, bounds_error=False, fill_value=(v[0], v[-1]))(ft)
    np.testing.assert_allclose(f.values, ref, atol=1e-12)
    assert f.n_frames == int(np.floor(t[-1] * 30)) + 1
    with pytest.raises(ConfigError, match="strictly increasing"):
        frames_from_samples(np.array([0.0, 0.0]), np.zeros((2, 4)), 30.0)


def test_a_track_at_another_rate_covers_as_long_as_it_does():
    """93 frames at 30 fps cover 3.1 s; on the grid only up to the last frame's time (3.0667 s) they became 92 frames
    at 29.97 fps, 3.0697 s (a video 25 ms shorter than its speech). Every frame starting before the end, interpolated
    between rows and held after the last (np.interp computed here), and the same track at its own rate."""
    rng = np.random.default_rng(1)
    tr = Track(values=rng.standard_normal((93, 4)))
    for fps, n in ((29.97, 93), (24.0, 75), (60.0, 186), (25.0, 78)):
        got = tr.at_fps(fps)
        assert got.n_frames == n and got.fps == fps and got.duration_s >= tr.duration_s > (n - 1) / fps
        want = np.stack([np.interp(np.arange(n) / fps, tr.times(), tr.values[:, j]) for j in range(4)], axis=1)
        np.testing.assert_allclose(got.values, want, atol=1e-12)
    assert frames_from_samples(tr.times(), tr.values, 29.97).n_frames == 92  # through the last row's time only
    assert tr.at_fps(30.0) is tr
    one = Track(values=np.ones((1, 4)))
    assert one.at_fps(24.0).n_frames == 1 and one.at_fps(90.0).n_frames == 3  # 1/30 s: 3 frames at 90 fps
