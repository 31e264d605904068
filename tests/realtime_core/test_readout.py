"""The learned readout after the inversion: streaming == whole track, chunk invariance through the
inverter and the whole chain, both kernels, the model file, silence."""

from __future__ import annotations

import io
from dataclasses import replace

import numpy as np
import pytest

from realtime_core import ModelFormatError
from realtime_core.avmodel import AvModel, decode_model, encode_model
from realtime_core.features import FrontEndConfig, MfccConfig
from realtime_core.hmm.sampling import random_av_hmm
from realtime_core.inversion import StreamConfig
from realtime_core.pipeline import SpeechToParams, speech_to_params
from realtime_core.readout import Readout
from tests.chunking import assert_chunk_invariant

N, M, DA, DV = 3, 2, 9, 4


def small_model(seed: int = 0) -> AvModel:
    fe = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000, n_ceps=3), tc=1)
    hmm = random_av_hmm(np.random.default_rng(seed), n_states=N, n_mix=M, n_audio=DA, n_visual=DV)
    return AvModel(hmm=hmm, frontend=fe, cmvn_mean=np.zeros(3), cmvn_var=np.ones(3), closure_band=0.02)


def random_readout(*, taps: int, posteriors: str, hidden: int, audio: bool = True, seed: int = 0) -> Readout:
    rng = np.random.default_rng(seed)
    n_post = {"none": 0, "state": N, "component": N * M}[posteriors]
    f = taps * DV + (DA if audio else 0) + n_post
    w2_rows = hidden if hidden else f
    return Readout(
        taps=taps,
        audio=audio,
        posteriors=posteriors,
        n_states=N,
        n_mix=M,
        n_audio=DA,
        n_visual=DV,
        w1=rng.standard_normal((f, hidden)) * 0.3,
        b1=rng.standard_normal(hidden) * 0.1,
        w2=rng.standard_normal((w2_rows, DV)) * 0.3,
        b2=rng.standard_normal(DV) * 0.1,
        metadata={"fit": "test"},
    )


CASES = [
    {"taps": 1, "posteriors": "none", "hidden": 0, "audio": False},
    {"taps": 4, "posteriors": "state", "hidden": 0},
    {"taps": 3, "posteriors": "component", "hidden": 6},
    {"taps": 5, "posteriors": "state", "hidden": 8, "audio": False},
]


@pytest.mark.parametrize("kernel", ["numba", "numpy"])
@pytest.mark.parametrize("case", CASES)
def test_streaming_readout_equals_the_whole_track_and_known_values(case, kernel):
    ro = random_readout(**case)
    rng = np.random.default_rng(1)
    raw, audio = rng.standard_normal((30, DV)), rng.standard_normal((30, DA))
    post = rng.dirichlet(np.ones(N * M), 30)
    whole = ro.apply(raw, post, audio)
    st = ro.stream(kernel=kernel)
    stepped = np.array([st.step(raw[t], post[t], audio[t]) for t in range(30)])
    np.testing.assert_allclose(stepped, whole, atol=1e-12)
    # An independent evaluation of frame t: taps by hand (before frame 0: frame 0), then the map.
    for t in (0, 2, 29):
        taps = [raw[max(t - k, 0)] for k in range(ro.taps)]
        p = post[t].reshape(N, M).sum(1) if ro.posteriors == "state" else post[t]
        phi = np.concatenate([*taps, audio[t] if ro.audio else [], p if ro.posteriors != "none" else []])
        hid = np.maximum(phi @ ro.w1 + ro.b1, 0) @ ro.w2 + ro.b2 if ro.hidden else phi @ ro.w2 + ro.b2
        np.testing.assert_allclose(whole[t], hid, atol=1e-12)
    st.reset()  # a new utterance forgets the past taps
    np.testing.assert_allclose(
        st.step(raw[5], post[5], audio[5]), ro.apply(raw[5:6], post[5:6], audio[5:6])[0], atol=1e-12
    )


@pytest.mark.parametrize("kernel", ["numba", "numpy"])
@pytest.mark.parametrize("lag", [0, 2])
def test_inverter_with_readout_is_chunk_invariant_and_equals_the_readout_of_its_trace(kernel, lag):
    m = replace(small_model(1), readout=random_readout(taps=3, posteriors="component", hidden=6))
    oa = np.random.default_rng(2).standard_normal((60, DA))
    cfg = StreamConfig(lag=lag, kernel=kernel, dtype="float64")
    whole = assert_chunk_invariant(lambda: m.inverter(cfg), oa, atol=1e-12, max_examples=10)
    if lag == 0:
        # The live path = the readout (then the output stage) over the inverter's own trace.
        raw, post, audio = m.inverter(cfg).trace(oa)
        np.testing.assert_allclose(whole, m.output_stage(m.readout.apply(raw, post, audio)), atol=1e-12)
        no_readout = replace(m, readout=None).inverter(cfg)
        np.testing.assert_allclose(
            np.concatenate([no_readout.push(oa), no_readout.flush()]), m.output_stage(raw.copy()), atol=1e-12
        )


def test_both_kernels_agree_with_a_readout():
    m = replace(small_model(3), readout=random_readout(taps=5, posteriors="state", hidden=8))
    oa = np.random.default_rng(4).standard_normal((50, DA))
    outs = []
    for kernel in ("numba", "numpy"):
        inv = m.inverter(StreamConfig(kernel=kernel, dtype="float64"))
        outs.append(np.concatenate([inv.push(oa[:17]), inv.push(oa[17:]), inv.flush()]))
    np.testing.assert_allclose(outs[0], outs[1], atol=1e-10)


def test_the_chain_with_a_readout_is_chunk_invariant_and_never_below_the_closed_pose():
    m = replace(small_model(4), readout=random_readout(taps=4, posteriors="state", hidden=0))
    x = (np.random.default_rng(5).standard_normal(16000) * 0.1).astype(np.float32)
    out = assert_chunk_invariant(lambda: SpeechToParams(m), x, atol=1e-9, max_examples=8)
    assert out.shape == (30, DV) and out[:, 2].min() >= 0.0


def test_silence_gives_no_motion():
    """Digital silence: the readout adds no motion of its own (every frame the same as the first once
    the inverter without it is still), and the output stays at or above the closed pose."""
    m = replace(small_model(6), readout=random_readout(taps=5, posteriors="component", hidden=8))
    silence = np.zeros(32000, dtype=np.float32)
    # the readout alone: the output noise gate would fade both to the neutral face after its warm-up
    with_ro = speech_to_params(m, silence, noise_gate=None)
    without = speech_to_params(replace(m, readout=None), silence, noise_gate=None)
    still = np.flatnonzero(np.abs(np.diff(without, axis=0)).max(axis=1) == 0)
    assert len(still) > 40  # the inverter settles on silence
    first = still[0] + 1 + m.readout.taps  # the readout's taps then hold settled frames only
    assert np.ptp(with_ro[first:], axis=0).max() <= 1e-12
    assert with_ro[:, 2].min() >= 0.0


def test_readout_round_trips_through_the_model_file_and_bad_ones_are_named():
    m = replace(small_model(7), readout=random_readout(taps=3, posteriors="state", hidden=5))
    data = encode_model(m)
    back = decode_model(data)
    assert back.readout is not None and back.readout.metadata == {"fit": "test"}
    for k in ("w1", "b1", "w2", "b2"):
        np.testing.assert_array_equal(getattr(back.readout, k), getattr(m.readout, k))
    x = (np.random.default_rng(8).standard_normal(8000) * 0.1).astype(np.float32)
    np.testing.assert_array_equal(speech_to_params(back, x), speech_to_params(m, x))
    assert decode_model(encode_model(small_model(7))).readout is None

    npz = np.load(io.BytesIO(data), allow_pickle=False)
    arrays = {k: npz[k] for k in npz.files}

    def tampered(**changes) -> bytes:
        a = {**arrays, **changes}
        a = {k: v for k, v in a.items() if v is not None}
        buf = io.BytesIO()
        np.savez(buf, **a)
        return buf.getvalue()

    cases = [
        (tampered(readout_w2=np.zeros((4, 4))), "readout w2 must be finite with shape"),
        (tampered(readout_b2=np.full(4, np.nan)), "readout b2"),
        (tampered(readout_w1=None), "lacks the array 'readout_w1'"),
    ]
    for bad, match in cases:
        with pytest.raises(ModelFormatError, match=match):
            decode_model(bad)
    with pytest.raises(ModelFormatError, match="do not match the HMM"):
        replace(small_model(7), readout=replace(m.readout, n_mix=M + 1))


def test_subnormal_weights_are_stored_as_zeros_and_change_no_estimate():
    """A dead ReLU unit's weights decay to subnormal floats (slow arithmetic on x86): the readout stores them
    as 0, leaves every normal weight as it was, and its estimates equal those of the unflushed weights."""
    ro = random_readout(taps=3, posteriors="state", hidden=6, seed=5)
    w1 = ro.w1.copy()
    w1[:, 2] = 3e-318  # unit 2 dead: subnormal in
    w2 = ro.w2.copy()
    w2[2] = -4e-317  # and out
    flushed = replace(ro, w1=w1, w2=w2)
    assert np.all(flushed.w1[:, 2] == 0) and np.all(flushed.w2[2] == 0)
    np.testing.assert_array_equal(np.delete(flushed.w1, 2, axis=1), np.delete(ro.w1, 2, axis=1))
    rng = np.random.default_rng(6)
    raw, audio = rng.standard_normal((40, DV)), rng.standard_normal((40, DA))
    post = rng.dirichlet(np.ones(N * M), 40)
    phi = flushed.features(raw, post, audio)
    with_subnormals = np.maximum(phi @ w1 + ro.b1, 0.0) @ w2 + ro.b2
    np.testing.assert_array_equal(flushed.apply(raw, post, audio), with_subnormals)
