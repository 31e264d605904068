"""The compiled streaming kernels (realtime_core.inversion.compiled) against the numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import VISUAL_PARAMS, ConfigError, visual_floor
from realtime_core.hmm.sampling import random_av_hmm, sample
from realtime_core.inversion import ConditionalForm, StreamConfig, StreamingInverter, audio_posterior_estimate
from realtime_core.inversion.stream import SKIP_POSTERIOR
from realtime_core.output import OutputStage
from realtime_core.readout import Readout


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


def test_skipping_negligible_components_keeps_eq7_exact(paper_size):
    """The kernels leave components under SKIP_POSTERIOR out of eq. 7's sums. At the paper's size most
    posteriors are that small, and the lag-0 stream still equals batch forward filtering (computed over
    every component, independently of the streaming code) to float64 rounding."""
    form, data = paper_size
    oa = data[:, :77]
    _, post, _ = StreamingInverter(form, config=StreamConfig(kernel="numpy", dtype="float64")).trace(oa)
    assert (post < SKIP_POSTERIOR).mean() > 0.3  # the skip really happens on this data
    want = audio_posterior_estimate(form, oa, smoothing="forward")
    for kernel in ("numba", "numpy"):
        st = StreamingInverter(form, config=StreamConfig(kernel=kernel, dtype="float64"))
        np.testing.assert_allclose(np.concatenate([st.push(oa), st.flush()]), want, rtol=0, atol=1e-9)


@pytest.mark.parametrize("posteriors", ["state", "component"])
def test_fused_kernel_with_readout_and_output_stage_equals_the_reference_at_paper_size(paper_size, posteriors):
    """The compiled lag-0 kernel runs eq. 7, the readout (a 192-unit hidden layer, as shipped) and the
    output stage in one call; the numpy path runs them one by one. Equal to rounding, chunked unevenly,
    across a reset."""
    form, data = paper_size
    oa = data[:, :77]
    rng = np.random.default_rng(9)
    taps, hidden = 5, 192
    n_post = {"state": 28, "component": 140}[posteriors]
    f = taps * 4 + 77 + n_post
    ro = Readout(
        taps=taps,
        audio=True,
        posteriors=posteriors,
        n_states=28,
        n_mix=5,
        n_audio=77,
        n_visual=4,
        w1=rng.standard_normal((f, hidden)) * 0.1,
        b1=rng.standard_normal(hidden) * 0.1,
        w2=rng.standard_normal((hidden, 4)) * 0.1,
        b2=rng.standard_normal(4),
    )
    stage = OutputStage(visual_floor(VISUAL_PARAMS), 0.05)
    out = {}
    for kernel in ("numba", "numpy"):
        st = StreamingInverter(form, config=StreamConfig(kernel=kernel), output=stage, readout=ro)
        first = np.concatenate([st.push(oa[:1]), st.push(oa[1:90]), st.push(oa[90:0]), st.push(oa[90:150])])
        st.reset()
        out[kernel] = (first, np.concatenate([st.push(oa[150:151]), st.push(oa[151:]), st.flush()]))
    for a, b in zip(out["numba"], out["numpy"], strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    assert np.ptp(out["numpy"][0], axis=0).min() > 0.01  # a moving estimate
    closed = VISUAL_PARAMS.index("mouth_open")
    assert out["numba"][0][:, closed].min() >= 0.0  # the output stage ran in the kernel


def test_an_output_callable_of_another_kind_runs_after_the_compiled_kernel(paper_size):
    """Only an OutputStage runs inside the kernel; any other callable is applied to each frame after it."""
    form, data = paper_size
    oa = data[:60, :77]
    out = []
    for kernel in ("numba", "numpy"):
        calls: list[int] = []

        def double(x, calls=calls):
            calls.append(1)
            return 2.0 * x

        st = StreamingInverter(form, config=StreamConfig(kernel=kernel), output=double)
        out.append(np.concatenate([st.push(oa[:25]), st.push(oa[25:]), st.flush()]))
        assert len(calls) == 60
    plain = StreamingInverter(form, config=StreamConfig(kernel="numba"))
    np.testing.assert_allclose(out[0], out[1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[0], 2.0 * np.concatenate([plain.push(oa), plain.flush()]), rtol=0, atol=1e-12)
