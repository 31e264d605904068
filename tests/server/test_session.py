"""The sans-I/O session: the live pipeline, controls and the wire codecs (the resampler is tested in
tests/realtime_core/features/test_resample.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from realtime_core.blendshapes import ARKIT_NAMES, OVR_NAMES, blendshape_weights
from realtime_core.pipeline import speech_to_params
from server.errors import AudioFormatError, ControlError, ServerConfigError
from server.session import Frame, Session, SessionConfig
from tests.speech import speechlike
from wire import protocol as P


def _session_params(model, pcm: bytes, rate: int, fmt: str = "pcm_s16le", channels: int = 1, seed: int = 0):
    s = Session(model, config=SessionConfig(sample_rate_hz=rate, sample_format=fmt, channels=channels))
    frame = P.SAMPLE_FORMATS[fmt].itemsize * channels
    rng = np.random.default_rng(seed)
    frames, audio, i = [], [], 0
    while i < len(pcm):
        n = int(rng.integers(1, 700)) * frame
        out = s.push_bytes(pcm[i : i + n])
        frames += out.frames
        audio += [out.audio] if out.audio else []
        i += n
    out = s.flush()
    frames += out.frames
    audio += [out.audio] if out.audio else []
    return s, frames, audio


def test_session_params_equal_speech_to_params(model):
    x = speechlike(1.3, 16000)
    pcm = np.rint(x * 32768).clip(-32768, 32767).astype("<i2")
    ref = speech_to_params(model, pcm.astype(np.float32) / 32768.0)
    _s, frames, audio = _session_params(model, pcm.tobytes(), 16000)
    assert [f.index for f in frames] == list(range(len(ref)))
    np.testing.assert_array_equal(np.array([f.raw_params for f in frames]), ref)
    np.testing.assert_array_equal(np.array([f.media_time for f in frames]), np.arange(len(ref)) / 30)
    # The relayed audio is the stream itself, contiguous, stamped by its first sample.
    np.testing.assert_array_equal(np.concatenate([a.samples for a in audio]), pcm / 32768.0)
    assert [a.start for a in audio] == list(np.cumsum([0] + [a.samples.size for a in audio])[:-1])


def test_an_idle_microphone_serves_the_rest_pose(model):
    """A live session at a microphone's 48 kHz fed only room hiss (-54 dBFS, int16, random pushes): after the noise
    gate's warm-up and fade every served frame is the neutral face; the same session ungated moves."""
    from realtime_core.features import NoiseGateConfig

    settled = NoiseGateConfig().warmup_frames + NoiseGateConfig().release_frames
    hiss = np.random.default_rng(4).standard_normal(3 * 48000) * 10 ** (-54 / 20)
    pcm = np.rint(hiss * 32768).astype("<i2").tobytes()
    _s, frames, _ = _session_params(model, pcm, 48000)
    assert len(frames) == 90
    np.testing.assert_array_equal(np.array([f.params for f in frames[settled:]]), 0.0)
    ungated = speech_to_params(model, np.frombuffer(pcm, "<i2") / 32768.0, 48000, noise_gate=None)
    assert np.abs(ungated[settled:]).max() > 0.01


def test_session_resamples_and_mixes_down(model):
    from realtime_core.features.resample import resample_audio

    x = speechlike(1.0, 48000, seed=3)
    stereo = np.stack([x, 0.5 * x], axis=1).astype("<f4")
    _s, frames, _ = _session_params(model, stereo.tobytes(), 48000, fmt="f32le", channels=2)
    mono = stereo.astype(np.float64).mean(axis=1)
    ref = speech_to_params(model, resample_audio(mono, 48000, 16000))
    assert len(frames) == len(ref)
    np.testing.assert_allclose(np.array([f.raw_params for f in frames]), ref, atol=1e-4)


def test_frames_come_out_when_their_audio_has_arrived(model):
    s = Session(model, config=SessionConfig(sample_rate_hz=16000))
    need = s.model_samples_needed(5)
    assert len(s.push(np.zeros(need - 1)).frames) == 5  # frames 0..4
    assert [f.index for f in s.push(np.zeros(1)).frames] == [5]
    assert s.algorithmic_delay_s == pytest.approx(3 / 30 + s.window_len / 16000)


def test_controls_gain_smoothing_and_rejection(model):
    x = speechlike(0.8, 16000)
    s = Session(model, config=SessionConfig(sample_rate_hz=16000))
    state = s.apply_control({"type": "control", "gain": {"mouth_open": 2.0}})
    assert state["gain"]["mouth_open"] == 2.0
    frames = s.push(x).frames
    for f in frames:
        np.testing.assert_allclose(f.params, f.raw_params * [1, 1, 2, 1])
    s.apply_control({"smoothing_ms": 100})
    more = s.flush().frames
    a = math.exp(-1000 / (30 * 100))
    prev = frames[-1].params
    for f in more:
        np.testing.assert_allclose(f.params, a * prev + (1 - a) * f.raw_params * [1, 1, 2, 1])
        prev = f.params
    for bad, match in [
        ({"volume": 3}, "unknown control 'volume'"),
        ({"gain": {"jaw": 1}}, "unknown parameter 'jaw'"),
        ({"gain": {"mouth_open": -1}}, "0..10"),
        ({"smoothing_ms": "x"}, "smoothing_ms"),
    ]:
        with pytest.raises(ControlError, match=match):
            s.apply_control(bad)
    assert s.control_state()["smoothing_ms"] == 100  # a rejected control changes nothing


def test_bad_audio_and_config_are_named(model):
    s = Session(model, config=SessionConfig(sample_rate_hz=16000, sample_format="pcm_s16le", channels=2))
    with pytest.raises(AudioFormatError, match="not a whole number"):
        s.push_bytes(b"\x00" * 6)
    f = Session(model, config=SessionConfig(sample_rate_hz=16000))
    with pytest.raises(AudioFormatError, match="NaN"):
        f.push_bytes(np.array([0.1, np.nan], "<f4").tobytes())
    for kw in (
        {"sample_rate_hz": 10**9},
        {"sample_rate_hz": 0},
        {"sample_rate_hz": "16000"},
        {"sample_rate_hz": 16000, "channels": 0},
        {"sample_rate_hz": 16000, "sample_format": "mp3"},
    ):
        with pytest.raises(ServerConfigError):
            SessionConfig(**kw)


def test_wire_codecs_round_trip():
    rng = np.random.default_rng(0)
    d = rng.standard_normal((500, 3)).astype(np.float32) * 0.01
    for enc, tol in ((P.ENC_INT16, None), (P.ENC_FLOAT16, 2e-3), (P.ENC_FLOAT32, 0)):
        payload, scale = P.encode_payload(d, enc)
        msg = P.pack_header(P.KIND_DELTAS, enc, 7, d.size, scale, 7 / 30, 123.5) + payload
        m = P.decode_message(msg)
        assert (m.kind, m.index, m.media_time, m.send_time) == (P.KIND_DELTAS, 7, 7 / 30, 123.5)
        err = np.abs(m.values - d.reshape(-1)).max()
        assert err <= (scale / 2 * 1.001 if tol is None else tol * np.abs(d).max() + 1e-9)
    with pytest.raises(ValueError, match="shorter"):
        P.decode_message(b"\x01\x02")
    with pytest.raises(ValueError, match="payload"):
        P.decode_message(P.pack_header(P.KIND_PARAMS, P.ENC_FLOAT32, 0, 4, 1.0, 0, 0) + b"\x00" * 12)


def test_blendshape_maps():
    assert len(ARKIT_NAMES) == len(set(ARKIT_NAMES)) == 52 and len(OVR_NAMES) == 15
    rest = blendshape_weights(np.zeros(4), "ovr15")
    assert rest[0] == 1.0 and rest[1:].max() == 0.0  # neutral face: silence viseme only
    wide = dict(zip(ARKIT_NAMES, blendshape_weights(np.array([0, 0, 0.35, 0]), "arkit52")))
    # Fitted maps (realtime_core.fitted_maps): an open mouth opens the jaw, and does not smile.
    assert wide["jawOpen"] > 0.3 and wide["mouthSmileLeft"] == 0.0
    w = blendshape_weights(np.random.default_rng(0).standard_normal((10, 4)), "arkit52")
    assert w.shape == (10, 52) and w.min() >= 0 and w.max() <= 1


@pytest.mark.parametrize("fmt", [{"a": 1}, ["pcm_s16le"], 16, None])
def test_a_non_string_sample_format_is_a_config_error_not_a_crash(fmt):
    """Found by tests/server/test_fuzz.py: an unhashable format (a JSON object) raised TypeError (1011)."""
    with pytest.raises(ServerConfigError, match="format must be one of"):
        SessionConfig(sample_rate_hz=16000, sample_format=fmt)


def test_compiled_int16_rows_equal_the_wire_encoding_byte_for_byte():
    # server.session.morph_delta_payloads quantises with the compiled kernel; viewers must get the bytes
    # wire.protocol.encode_payload (the reference) gives, ties and signs included.
    from realtime_core.face.compiled import quantize_int16_rows

    rng = np.random.default_rng(3)
    v = (rng.standard_normal((5, 3001)) * 0.01).astype(np.float32)
    v[1] = 0.0  # scale 1, all zeros
    v[2, :8] = [0.5, 1.5, 2.5, -0.5, -1.5, -2.5, 32766.5, -32767.0]  # ties at a scale of 1 (peak 32767)
    v[2, 8:] = np.clip(v[2, 8:] * 1e6, -32767, 32767)
    v[3] = -np.abs(v[3])  # the peak is negative
    v[4, 0] = -0.0
    scales = np.empty(5)
    q = quantize_int16_rows(v, np.empty(v.shape, dtype="<i2"), scales)
    for row, qrow, scale in zip(v, q, scales):
        data, want_scale = P.encode_payload(row, P.ENC_INT16)
        assert qrow.tobytes() == data and float(scale) == want_scale


def test_morph_delta_payloads_are_the_same_bytes_alone_or_batched_and_match_the_reference(model, builtin_head):
    # A loop turn's vertex frames are encoded together (server.live.TurnDeltas); one frame alone
    # (Frame.payload) must give the same bytes, and both the numpy rig's values to rounding.
    from assets.heads.head import builtin_morph_head
    from server.session import morph_delta_payloads

    head = builtin_morph_head()  # driven by its own morph targets, as facecast serve's default head

    x = speechlike(1.0, 16000)
    s = Session(model, config=SessionConfig(sample_rate_hz=16000), rig=head.rig)
    params = [f.params for f in s.push(x).frames + s.flush().frames]
    assert len(params) > 20

    def frames():
        return [Frame(k, k / 30, p, p, 0.0, 0.0, head.rig) for k, p in enumerate(params)]

    alone = {}
    for enc in (P.ENC_INT16, P.ENC_FLOAT16, P.ENC_FLOAT32):
        alone[enc] = [f.payload(P.KIND_DELTAS, enc) for f in frames()]
        for b in (2, 7, len(params)):
            fs = frames()
            for i in range(0, len(fs), b):
                morph_delta_payloads(fs[i : i + b][::-1], enc)
            assert [f.payload(P.KIND_DELTAS, enc) for f in fs] == alone[enc]
    for p, (data, count, _), (data16, _, scale) in zip(params, alone[P.ENC_FLOAT32], alone[P.ENC_INT16]):
        want = head.rig.displacements(p).reshape(-1)  # the numpy rig
        peak = max(float(np.abs(want).max()), 1e-9)
        assert count == want.size
        np.testing.assert_allclose(np.frombuffer(data, dtype="<f4"), want, rtol=0, atol=1e-6 * peak)
        got16 = np.frombuffer(data16, dtype="<i2") * scale
        np.testing.assert_allclose(got16, want, rtol=0, atol=scale * 0.501 + 1e-6 * peak)
