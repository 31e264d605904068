"""Context stacking, running CMVN and the composed front end."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import ConfigError, InvalidFeaturesError
from realtime_core.features import (
    CmvnConfig,
    ContextStacker,
    FrontEnd,
    FrontEndConfig,
    MfccConfig,
    RunningCmvn,
    extract_features,
    stack_context,
)
from tests.chunking import assert_chunk_invariant


def test_context_rows_are_the_neighbouring_frames_with_replicated_edges():
    a = np.arange(10 * 2, dtype=float).reshape(10, 2)
    o = stack_context(a, tc=3)
    assert o.shape == (10, 14)
    for t in range(10):
        expect = np.concatenate([a[min(max(s, 0), 9)] for s in range(t - 3, t + 4)])
        np.testing.assert_array_equal(o[t], expect)


def test_context_releases_row_t_when_frame_t_plus_tc_arrives():
    st = ContextStacker(dim=1, tc=3)
    released = [st.push(np.array([[float(i)]])).shape[0] for i in range(6)]
    assert released == [0, 0, 0, 1, 1, 1]
    assert st.flush().shape[0] == 3


def test_context_chunking_invariance():
    rng = np.random.default_rng(0)
    a = rng.standard_normal((57, 3))
    whole = assert_chunk_invariant(lambda: ContextStacker(dim=3, tc=3), a)
    np.testing.assert_array_equal(whole, stack_context(a, tc=3))


class _CmvnStage:
    """RunningCmvn as a push/flush stage (it releases every frame at once, so flush is empty)."""

    def __init__(self, d: int) -> None:
        self.cmvn = RunningCmvn(
            CmvnConfig(prior_frames=20, max_frames=60, gate_db=-50), mean=np.zeros(d), var=np.ones(d)
        )
        self.d = d

    def push(self, features: np.ndarray, level_db: np.ndarray) -> np.ndarray:
        return self.cmvn.push(features, level_db)

    def flush(self) -> np.ndarray:
        return np.empty((0, self.d))


def test_cmvn_chunking_invariance():
    """The running statistics (warm start, gate, window) update frame by frame whatever the chunking."""
    rng = np.random.default_rng(4)
    feats = 3.0 * rng.standard_normal((150, 4)) + 5.0
    level = np.where(rng.random(150) < 0.3, -80.0, -20.0)  # a third of the frames below the gate
    whole = assert_chunk_invariant(lambda: _CmvnStage(4), feats, level, atol=1e-12)
    assert np.abs(whole[-50:].mean(0)).max() < np.abs(feats[-50:].mean(0)).min()  # it did normalise


def test_cmvn_warm_start_gating_and_adaptation():
    rng = np.random.default_rng(0)
    d = 4
    cfg = CmvnConfig(prior_frames=50, max_frames=200, gate_db=-50)
    cm = RunningCmvn(cfg, mean=np.zeros(d), var=np.ones(d))
    # Warm start: a frame at the training mean maps to ~0 straight away.
    assert np.allclose(cm.push(np.zeros((1, d)), np.array([0.0])), 0.0)
    # Silence (below the gate) leaves the statistics alone, however long it lasts.
    before = cm.push(np.full((1, d), 0.5), np.array([-80.0]))
    cm.push(np.full((3000, d), -7.0), np.full(3000, -80.0))
    np.testing.assert_allclose(cm.push(np.full((1, d), 0.5), np.array([-80.0])), before)
    # A new microphone (gain and offset on the cepstra) is normalised away over time.
    x = rng.standard_normal((3000, d))
    ref = RunningCmvn(cfg, mean=np.zeros(d), var=np.ones(d)).push(x, np.zeros(3000))
    shifted = RunningCmvn(cfg, mean=np.zeros(d), var=np.ones(d)).push(3.0 * x + 5.0, np.zeros(3000))
    assert np.abs(shifted[-500:] - ref[-500:]).max() < 0.15
    assert np.abs(shifted[:5] - ref[:5]).max() > 1.0  # ...and at first it was not


def test_front_end_same_output_for_any_chunking():
    rng = np.random.default_rng(3)
    cfg = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=11025), tc=3)
    x = (rng.standard_normal(11025) * 0.1).astype(np.float32)
    x[3000:5000] = 0.0  # a silent stretch, exercising the CMVN gate
    stats = dict(cmvn_mean=np.zeros(11), cmvn_var=np.ones(11))
    whole = extract_features(x, cfg, **stats)
    assert whole.shape == (cfg.mfcc.n_frames_for(x.size), 77)
    streamed = assert_chunk_invariant(lambda: FrontEnd(cfg, **stats), x, atol=1e-10, max_examples=10)
    np.testing.assert_allclose(streamed, whole, rtol=0, atol=1e-10)


def test_front_end_config_errors():
    with pytest.raises(ConfigError, match="include_c0"):
        FrontEndConfig(mfcc=MfccConfig(include_c0=True))
    with pytest.raises(ConfigError, match="cmvn_mean"):
        FrontEnd(FrontEndConfig())
    with pytest.raises(InvalidFeaturesError):
        RunningCmvn(CmvnConfig(), mean=np.zeros(3), var=np.array([1.0, 0.0, 1.0]))


def test_quiet_input_below_the_silence_floor_looks_exactly_like_digital_silence():
    """Room hiss at -75 dBFS must give the features of the silent pauses the model was trained
    on (so the mouth stays closed); -40 dBFS noise must not be gated."""
    rng = np.random.default_rng(0)
    cfg = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000), energy=True)
    stats = dict(cmvn_mean=np.zeros(12), cmvn_var=np.ones(12))
    zeros = extract_features(np.zeros(16000, np.float32), cfg, **stats)
    hiss = extract_features((rng.standard_normal(16000) * 10 ** (-75 / 20)).astype(np.float32), cfg, **stats)
    loud = extract_features((rng.standard_normal(16000) * 10 ** (-40 / 20)).astype(np.float32), cfg, **stats)
    np.testing.assert_array_equal(hiss, zeros)
    assert np.abs(loud - zeros).max() > 1.0
    ungated = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000), energy=True, silence_floor_db=None)
    assert (
        np.abs(
            extract_features((rng.standard_normal(16000) * 10 ** (-75 / 20)).astype(np.float32), ungated, **stats)
            - zeros
        ).max()
        > 1.0
    )
