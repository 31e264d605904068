"""The compiled front-end kernels (realtime_core.features.compiled) against the numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import ConfigError
from realtime_core.features import CmvnConfig, FrontEnd, FrontEndConfig, MfccConfig, MfccStream, RunningCmvn


def _speechy(rng: np.random.Generator, seconds: float) -> np.ndarray:
    t = np.arange(int(16000 * seconds)) / 16000
    x = 0.1 * np.clip(np.sin(2 * np.pi * 3 * t), 0, None) ** 2 * rng.standard_normal(t.size)
    x[8000:16000] *= 1e-6  # a quiet stretch: the silence gate and the CMVN gate both act
    return x


@pytest.mark.parametrize("energy", [False, True])
def test_front_end_compiled_equals_numpy_reference_for_live_pushes(energy):
    rng = np.random.default_rng(3)
    cfg = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000), energy=energy)
    d = cfg.n_feat
    mean, var = rng.standard_normal(d), rng.uniform(0.5, 2.0, d)
    x = _speechy(rng, 4.0)
    cuts = np.cumsum(rng.integers(1, 900, 200))
    cuts = cuts[cuts < x.size]
    out = {}
    for kernel in ("numba", "numpy"):
        fe = FrontEnd(cfg, cmvn_mean=mean, cmvn_var=var, kernel=kernel)
        out[kernel] = np.concatenate([*(fe.push(b) for b in np.split(x, cuts)), fe.flush()])
    assert out["numba"].shape == (120, cfg.audio_dim)
    np.testing.assert_allclose(out["numba"], out["numpy"], rtol=0, atol=1e-11)


def test_mfcc_and_cmvn_kernels_equal_the_reference_on_many_frames_at_once():
    rng = np.random.default_rng(4)
    x = _speechy(rng, 2.0)
    cfg = MfccConfig(sample_rate_hz=16000, include_c0=True)
    a, b = (np.concatenate([s.push(x), s.flush()]) for s in (MfccStream(cfg), MfccStream(cfg, kernel="numpy")))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-11)
    level = rng.uniform(-90, 0, a.shape[0])
    c1 = RunningCmvn(CmvnConfig(), mean=np.zeros(12), var=np.ones(12))
    c2 = RunningCmvn(CmvnConfig(), mean=np.zeros(12), var=np.ones(12), kernel="numpy")
    np.testing.assert_allclose(c1.push(a, level), c2.push(a, level), rtol=0, atol=1e-12)
    np.testing.assert_allclose(c1.push(a[:5], level[:5]), c2.push(a[:5], level[:5]), rtol=0, atol=1e-12)


def test_unknown_kernel_is_refused():
    with pytest.raises(ConfigError, match="kernel"):
        MfccStream(MfccConfig(), kernel="fortran")


@pytest.mark.parametrize(
    "cfg",
    [
        FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000), cmvn=None, silence_floor_db=None, tc=0),
        FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=8000, n_ceps=5), tc=1, energy=True),
        FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=22050), tc=5, silence_floor_db=-30.0),
    ],
    ids=["no-cmvn-no-gate-tc0", "8k-tc1-energy", "22k-tc5-gate"],
)
@pytest.mark.parametrize("seconds", [0.07, 0.2, 1.5])
def test_compiled_framing_and_tail_equal_the_reference_with_flush_edges(cfg, seconds):
    """The compiled framing (pre-emphasis, buffer, window) and the compiled level gate, CMVN and context
    stacking against the numpy stages, on utterances shorter than the context (every row then comes from
    the flush, with both edges replicated) and longer, pushed in uneven chunks, twice across a reset."""
    rng = np.random.default_rng(7)
    d = cfg.n_feat
    mean, var = rng.standard_normal(d), rng.uniform(0.5, 2.0, d)
    rate = int(cfg.mfcc.sample_rate_hz)
    x = _speechy(rng, 2.0)[: int(seconds * rate)]
    cuts = np.cumsum(rng.integers(0, 700, 40))
    cuts = cuts[cuts < x.size]
    out = {}
    for kernel in ("numba", "numpy"):
        fe = FrontEnd(cfg, cmvn_mean=mean, cmvn_var=var, kernel=kernel)
        runs = []
        for _ in range(2):
            runs.append(np.concatenate([*(fe.push(b) for b in np.split(x, cuts)), fe.flush()]))
            assert fe.frames_out == len(runs[-1])
            fe.reset()
        out[kernel] = runs
    n = cfg.mfcc.n_frames_for(x.size)
    for a, b in zip(out["numba"], out["numpy"], strict=True):
        assert a.shape == b.shape == (n, cfg.audio_dim)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-11)
    np.testing.assert_array_equal(out["numba"][0], out["numba"][1])  # reset forgets everything
