"""The model file format: round trip and validation that names each problem."""

from __future__ import annotations

import io

import numpy as np
import pytest

from realtime_core import ModelFormatError
from realtime_core.avmodel import AvModel, decode_model, encode_model
from realtime_core.features import FrontEndConfig, MfccConfig
from realtime_core.hmm.sampling import random_av_hmm
from realtime_core.pipeline import SpeechToParams, speech_to_params
from tests.chunking import assert_chunk_invariant


def small_model(seed: int = 0) -> AvModel:
    fe = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000, n_ceps=3), tc=1)
    hmm = random_av_hmm(np.random.default_rng(seed), n_states=3, n_mix=2, n_audio=9, n_visual=4)
    return AvModel(hmm=hmm, frontend=fe, cmvn_mean=np.zeros(3), cmvn_var=np.ones(3), metadata={"recipe": "test"})


def _tamper(data: bytes, **changes) -> bytes:
    npz = np.load(io.BytesIO(data), allow_pickle=False)
    arrays = {k: npz[k] for k in npz.files}
    arrays.update(changes)
    for k, v in list(arrays.items()):
        if v is None:
            del arrays[k]
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def test_round_trip_preserves_everything():
    m = small_model()
    back = decode_model(encode_model(m))
    for name in ("startprob", "transmat", "weights", "means", "covars"):
        np.testing.assert_array_equal(getattr(back.hmm, name), getattr(m.hmm, name))
    assert back.frontend == m.frontend and back.metadata == {"recipe": "test"}
    x = np.random.default_rng(0).standard_normal(8000).astype(np.float32) * 0.1
    np.testing.assert_array_equal(speech_to_params(back, x), speech_to_params(m, x))


def test_bad_files_name_the_problem():
    good = encode_model(small_model())
    bad_cov = np.load(io.BytesIO(good))["covars"].copy()
    bad_cov[2, 1] = -np.eye(13)
    cases = [
        (b"garbage", "not a facecast model archive"),
        (_tamper(good, covars=bad_cov), "state 2, mixture 1 is not positive definite"),
        (_tamper(good, transmat=np.eye(4)), "transmat must have shape"),
        (_tamper(good, means=np.full((3, 2, 13), np.nan)), "means contains NaN"),
        (_tamper(good, version=np.array(99)), "version 99"),
        (_tamper(good, format=np.array("other")), "format is 'other'"),
        (_tamper(good, quad=None), "lacks the array 'quad'"),
        (_tamper(good, quad=np.load(io.BytesIO(good))["quad"] * 1.01), "does not match"),
        (_tamper(good, cmvn_var=np.zeros(3)), "cmvn_var"),
    ]
    for data, match in cases:
        with pytest.raises(ModelFormatError, match=match):
            decode_model(data)


def test_pipeline_stream_equals_whole_and_batch_runs():
    m = small_model(1)
    rng = np.random.default_rng(5)
    x = (rng.standard_normal(16000) * 0.1).astype(np.float32)
    whole = speech_to_params(m, x)
    assert whole.shape == (30, 4)
    chunked = assert_chunk_invariant(lambda: SpeechToParams(m), x, atol=1e-9, max_examples=10)
    np.testing.assert_allclose(chunked, whole, atol=1e-9)
    # At another input rate the chain resamples itself: still chunk-invariant.
    x44 = (rng.standard_normal(22050) * 0.1).astype(np.float32)
    assert_chunk_invariant(lambda: SpeechToParams(m, rate_hz=44100), x44, atol=1e-9, max_examples=5, one_by_one=False)
    assert speech_to_params(m, x, mode="batch").shape == (30, 4)


def test_a_long_utterance_runs_in_bounded_memory_with_the_rows_of_one_push():
    # A 10-minute file pushed at once framed every hop together: 610 MB of arrays at the peak, growing
    # with the file's length (`facecast animate` on 10 min: 946 MB resident). Here 120 s: 17.8x the
    # audio's own bytes before, 3.3x in blocks.
    import tracemalloc

    m = small_model(2)
    x = (np.random.default_rng(6).standard_normal(16000 * 120) * 0.1).astype(np.float32)
    p = SpeechToParams(m)
    one_push = np.concatenate([p.push(x), p.flush()])
    tracemalloc.start()
    try:
        whole = speech_to_params(m, x)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    np.testing.assert_array_equal(whole, one_push)
    assert peak < 8 * x.nbytes, f"peak {peak / 2**20:.0f} MB for {x.nbytes / 2**20:.1f} MB of audio"


def test_sessions_of_a_model_share_one_plan_and_match_an_unshared_inverter():
    from realtime_core.inversion import StreamConfig, StreamingInverter

    m = small_model(2)
    a, b = m.inverter(), m.inverter()
    assert a.plan is b.plan  # one copy of the matrices for every live session
    assert m.inverter(StreamConfig(dtype="float64")).plan is not a.plan
    oa = np.random.default_rng(1).standard_normal((40, 9))
    own = StreamingInverter(m.form, config=StreamConfig(likelihood_scale=m.likelihood_scale), output=m.output_stage)
    np.testing.assert_array_equal(np.concatenate([a.push(oa), a.flush()]), np.concatenate([own.push(oa), own.flush()]))
    # Sharing does not couple the sessions' states: interleaved pushes give each its own result.
    ref = StreamingInverter(
        m.form, config=StreamConfig(likelihood_scale=m.likelihood_scale), output=m.output_stage
    ).push(oa)
    c = m.inverter()
    out_b = [b.push(oa[:20])]
    c.push(oa[::-1])
    out_b.append(b.push(oa[20:]))
    np.testing.assert_array_equal(np.concatenate(out_b), ref)


def test_output_stage_clamps_at_the_closed_pose():
    """A model's inverter never emits mouth_open below the closed pose (0); other parameters are
    untouched: its output equals the unclamped inverter's with mouth_open floored at 0."""
    from realtime_core import VISUAL_PARAMS
    from realtime_core.inversion import StreamConfig, StreamingInverter

    m = small_model(2)
    j = VISUAL_PARAMS.index("mouth_open")
    assert m.visual_floor[j] == 0.0 and np.isneginf(np.delete(m.visual_floor, j)).all()
    oa = np.random.default_rng(3).standard_normal((200, 9)) * 3
    free = StreamingInverter(m.form, config=StreamConfig(likelihood_scale=m.likelihood_scale))
    raw = np.concatenate([free.push(oa), free.flush()])
    inv = m.inverter()
    out = np.concatenate([inv.push(oa), inv.flush()])
    np.testing.assert_array_equal(out, np.maximum(raw, m.visual_floor))


def test_closure_band_draws_near_closures_shut_and_round_trips():
    """With a closure band b the output stage maps mouth_open in [0, b] to 0, stretches [b, 3b] onto
    [0, 3b] linearly, leaves values >= 3b alone (monotone, continuous); the band survives the file."""
    from dataclasses import replace

    from realtime_core.output import OutputStage

    stage = OutputStage(np.array([-np.inf, -np.inf, 0.0, -np.inf]), band=0.02)
    x = np.zeros((7, 4))
    x[:, 2] = [-0.01, 0.0, 0.02, 0.03, 0.05, 0.06, 0.2]
    x[:, 0] = -1.0
    y = stage(x.copy())
    np.testing.assert_allclose(y[:, 2], [0.0, 0.0, 0.0, 0.015, 0.045, 0.06, 0.2])
    np.testing.assert_array_equal(y[:, 0], x[:, 0])
    grid = np.zeros((1000, 4))
    grid[:, 2] = np.linspace(-0.1, 0.3, 1000)
    assert np.all(np.diff(stage(grid)[:, 2]) >= 0)
    m = replace(small_model(2), closure_band=0.02)
    back = decode_model(encode_model(m))
    assert back.closure_band == 0.02 and decode_model(encode_model(small_model(2))).closure_band == 0.0


def test_filterbank_warp_round_trips_and_unwarped_files_read_as_before():
    """MfccConfig.warp is written only when it is not 1 (files of unwarped models are as before it
    existed) and read back; AvModel.front_end(warp=...) warps one stream without changing the model."""
    from dataclasses import replace as dc_replace

    from realtime_core.avmodel import frontend_from_json, frontend_to_json
    from realtime_core.features import FrontEndConfig, MfccConfig

    plain = FrontEndConfig(mfcc=MfccConfig(n_ceps=11))
    assert "warp" not in frontend_to_json(plain)["mfcc"]
    warped = dc_replace(plain, mfcc=dc_replace(plain.mfcc, warp=1.1))
    assert frontend_to_json(warped)["mfcc"]["warp"] == 1.1
    assert frontend_from_json(frontend_to_json(warped)) == warped
    assert frontend_from_json(frontend_to_json(plain)) == plain
