"""The compiled streaming kernels (realtime_core.inversion.compiled) against the numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import ConfigError
from realtime_core.hmm.sampling import random_av_hmm, sample
from realtime_core.inversion import ConditionalForm, StreamConfig, StreamingInverter


@pytest.fixture(scope="module")
def paper_size():
    """The paper's live size: 28 states x 5 mixtures, 77 audio and 4 visual dims."""
    rng = np.random.default_rng(5)
    hmm = random_av_hmm(rng, n_states=28, n_mix=5, n_audio=77, n_visual=4)
    return ConditionalForm.from_model(hmm), sample(hmm, rng, 300)[0]


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize("lag", [0, 2])
def test_compiled_equals_numpy_reference(paper_size, dtype, lag):
    form, data = paper_size
    oa = data[:, :77]
    out = {}
    for kernel in ("numba", "numpy"):
        st = StreamingInverter(form, config=StreamConfig(lag=lag, dtype=dtype, kernel=kernel))
        # Uneven chunks: the compiled path keeps its state across pushes like the reference.
        out[kernel] = np.concatenate([st.push(oa[:1]), st.push(oa[1:37]), st.push(oa[37:]), st.flush()])
    assert out["numba"].shape == (300, 4)
    # Same arithmetic in the same order and dtypes: equal to rounding (the visual values are O(1..10)).
    np.testing.assert_allclose(out["numba"], out["numpy"], rtol=0, atol=1e-10)
    assert np.ptp(out["numpy"], axis=0).min() > 0.1  # a moving estimate, not a constant both agree on


def test_compiled_restarts_the_filter_like_the_reference_after_an_impossible_frame(paper_size):
    """A frame far outside every component underflows all likelihoods; both paths restart the
    filter from the frame's own state likelihoods and agree afterwards."""
    form, data = paper_size
    oa = data[:40, :77].copy()
    oa[20] = 1e4
    out = [
        np.concatenate([st.push(oa), st.flush()])
        for st in (StreamingInverter(form, config=StreamConfig(kernel=k, dtype="float64")) for k in ("numba", "numpy"))
    ]
    assert np.all(np.isfinite(out[0]))
    np.testing.assert_allclose(out[0], out[1], rtol=0, atol=1e-10)


def test_unknown_kernel_is_refused():
    with pytest.raises(ConfigError, match="kernel"):
        StreamConfig(kernel="cuda")
