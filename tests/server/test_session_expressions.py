"""Sessions with expressions and with the MLP mapper: controls with media timestamps, chunk
invariance under an expression, blendshape outputs carrying it, bad requests rejected while the
session keeps streaming, and an MLP-mapper session equal to the offline path."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.blendshapes import ARKIT_NAMES
from realtime_core.expressions import EXPRESSIONS, SPEECH_REACH, ExpressionTrack, apply_expression
from realtime_core.fitted_maps import EXPRESSION_PARAMS
from realtime_core.mapping import MlpBank, MlpSpeechModel, decode_speech_model, encode_speech_model
from realtime_core.pipeline import speech_to_params
from server.errors import ControlError, ServerConfigError
from server.session import Session, SessionConfig
from tests.server.conftest import small_model, speechlike
from wire import protocol as P


def _run(model, x: np.ndarray, controls: list[tuple[int, dict]], seed: int) -> list:
    """Push ``x`` in random chunks, applying each (sample index, control) once the stream reaches it."""
    s = Session(model, config=SessionConfig(sample_rate_hz=16000))
    rng = np.random.default_rng(seed)
    pending = sorted(controls, key=lambda c: c[0])
    frames, i = [], 0
    while i < len(x):
        while pending and pending[0][0] <= i:
            s.apply_control(pending.pop(0)[1])
        n = int(rng.integers(1, 1200))
        frames += s.push(x[i : i + n]).frames
        i += n
    frames += s.flush().frames
    return frames


def test_expression_control_is_chunk_invariant_and_eased() -> None:
    model = small_model()
    x = speechlike(3.0, 16000)
    ctl = [
        (0, {"type": "control", "expression": {"name": "smile", "intensity": 0.7, "at": 1.0}}),
        (0, {"type": "control", "expression": {"name": "neutral", "at": 2.2}, "expression_ease_s": 0.2}),
    ]
    a, b = _run(model, x, ctl, 1), _run(model, x, ctl, 2)
    pa, pb = np.array([f.params for f in a]), np.array([f.params for f in b])
    np.testing.assert_array_equal(pa, pb)
    speech = speech_to_params(model, x)
    track = ExpressionTrack()
    track = track.copy(type(track.config)(ease_s=0.2))
    track.schedule("smile", 0.7, 1.0)
    track.schedule("neutral", 1.0, 2.2)
    alpha = track.intensities(np.arange(len(speech)) / 30)
    np.testing.assert_allclose(pa, apply_expression(speech, alpha, EXPRESSION_PARAMS), atol=1e-12)
    t = np.arange(len(pa)) / 30
    np.testing.assert_array_equal(pa[t < 1.0], speech[t < 1.0])
    mid = (t > 1.3) & (t < 2.2)
    # lip_stretch widened by the smile's change (saturating at the smile alone where speech spreads the lips).
    d = 0.7 * EXPRESSION_PARAMS[EXPRESSIONS.index("smile"), 1]
    assert np.allclose(
        pa[mid, 1], np.minimum(speech[mid, 1] + d, np.maximum(d, speech[mid, 1]).clip(SPEECH_REACH[1][1]))
    )
    # ARKit carries the expression's own shapes; the speech weights underneath stay.
    f = a[int(np.flatnonzero(mid)[0])]
    w = dict(zip(ARKIT_NAMES, np.frombuffer(f.payload(P.KIND_ARKIT52, P.ENC_FLOAT32)[0], "<f4")))
    assert w["mouthSmileLeft"] >= 0.7 * 0.5 - 1e-6 and w["cheekSquintLeft"] == pytest.approx(0.35, abs=1e-6)


def test_bad_expression_controls_are_rejected_and_the_session_streams_on() -> None:
    model = small_model()
    s = Session(model, config=SessionConfig(sample_rate_hz=16000))
    x = speechlike(2.0, 16000)
    n1 = len(s.push(x[:16000]).frames)
    before = s.control_state()
    for msg, text in (
        ({"expression": {"name": "grin"}}, "unknown expression 'grin'"),
        ({"expression": {"name": "smile", "intensity": 1.5}}, r"\[0, 1\]"),
        ({"expression": {"name": "smile", "at": 0.0}}, "in the past"),
        ({"expression": {"name": "smile", "at": 1e7}}, "ahead"),
        ({"expression": {"name": "smile", "at": "soon"}}, "number of seconds"),
        ({"expression": "smile"}, "must be an object"),
        ({"expression": {"name": "smile", "colour": 1}}, "unknown field"),
        ({"expression_ease_s": 99}, "0..10"),
        ({"gain": {"mouth_open": 2}, "expression": {"name": "nope"}}, "unknown expression"),
    ):
        with pytest.raises(ControlError, match=text):
            s.apply_control({"type": "control", **msg})
        assert s.control_state() == before  # nothing applied, not even the valid gain
    rest = s.push(x[16000:]).frames + s.flush().frames
    assert n1 + len(rest) == len(speech_to_params(model, x))


def _mlp_model(fe, seed: int = 0) -> MlpSpeechModel:
    rng = np.random.default_rng(seed)
    k, h, da = 3, 15, fe.audio_dim
    bank = MlpBank(
        gmm_log_weights=np.log(np.full(k, 1 / k)),
        gmm_means=rng.standard_normal((k, fe.n_feat)),
        gmm_vars=np.ones((k, fe.n_feat)),
        class_slice=(fe.tc * fe.n_feat, (fe.tc + 1) * fe.n_feat),
        w1=rng.standard_normal((k, h, da)) * 0.1,
        b1=np.zeros((k, h)),
        w2=rng.standard_normal((k, 4, h)) * 0.05,
        b2=np.zeros((k, 4)),
        hidden=np.full(k, h),
        activation="tanh",
    )
    return MlpSpeechModel(bank=bank, frontend=fe, cmvn_mean=np.zeros(fe.n_feat), cmvn_var=np.ones(fe.n_feat))


def test_mlp_mapper_session_equals_the_offline_path() -> None:
    model = _mlp_model(small_model().frontend)
    x = speechlike(2.0, 16000)
    frames = _run(model, x, [], 3)
    np.testing.assert_array_equal(np.array([f.params for f in frames]), speech_to_params(model, x))
    assert Session(model, config=SessionConfig(sample_rate_hz=16000)).delay_frames == model.frontend.tc
    with pytest.raises(ServerConfigError, match="no smoothing lag"):
        Session(model, config=SessionConfig(sample_rate_hz=16000, lag=2))
    # Compute workers receive the model as bytes: either kind round-trips.
    back = decode_speech_model(encode_speech_model(model))
    np.testing.assert_array_equal(speech_to_params(back, x), speech_to_params(model, x))


def _mlp_model_with_stages(fe, seed: int = 0) -> MlpSpeechModel:
    """An MLP model emitting 5 MUPs read out to the 4 parameters, with random second stages for smile
    and sad (2 EMUPs each)."""
    from dataclasses import replace

    from realtime_core.mapping import ExpressionMapper, ExpressionStage

    rng = np.random.default_rng(seed)
    base = _mlp_model(fe, seed)
    k, h, a0 = base.bank.n_classes, 15, 5
    bank = replace(
        base.bank,
        w2=rng.standard_normal((k, a0, h)) * 0.05,
        b2=np.zeros((k, a0)),
        readout=rng.standard_normal((4, a0)) * 0.5,
        readout_bias=np.array([0.0, 0.0, 0.05, 0.0]),
    )
    stages = {
        name: ExpressionStage(
            name=name,
            w1=rng.standard_normal((30, a0)),
            b1=rng.standard_normal(30) * 0.1,
            w2=rng.standard_normal((a0 + 2, 30)) * 0.05,
            b2=rng.standard_normal(a0 + 2) * 0.02,
            emu_params=rng.standard_normal((4, 2)) * 0.1,
            emu_bias=rng.standard_normal(4) * 0.02,
        )
        for name in ("smile", "sad")
    }
    ex = ExpressionMapper(readout=bank.readout, readout_bias=bank.readout_bias, stages=stages)
    return replace(base, bank=bank, expressions=ex)


def test_mlp_session_uses_the_second_stage_mlps() -> None:
    """Paper 002 Sec. VI-B at run time: a session whose MLP mapper has expression stages changes the
    parameters by Upsilon_k of each frame's UMUPs (equal to the offline computation for any chunking),
    not by the fixed offsets; an expression without a stage (surprise) falls back to its offset."""
    from realtime_core.expressions import add_expression
    from realtime_core.pipeline import speech_to_params_and_mups

    model = _mlp_model_with_stages(small_model().frontend)
    back = decode_speech_model(encode_speech_model(model))
    assert isinstance(back, MlpSpeechModel) and back.expressions is not None
    assert sorted(back.expressions.stages) == ["sad", "smile"]
    x = speechlike(3.0, 16000)
    ctl = [
        (0, {"type": "control", "expression": {"name": "smile", "intensity": 1.0, "at": 0.5}, "expression_ease_s": 0}),
        (0, {"type": "control", "expression": {"name": "surprise", "intensity": 0.5, "at": 2.0}}),
    ]
    a, b = _run(back, x, ctl, 4), _run(back, x, ctl, 5)
    pa = np.array([f.params for f in a])
    np.testing.assert_array_equal(pa, np.array([f.params for f in b]))
    speech, mups = speech_to_params_and_mups(model, x)
    assert mups is not None and mups.shape == (len(speech), 5)
    np.testing.assert_array_equal(speech, speech_to_params(model, x))
    track = ExpressionTrack(type(ExpressionTrack().config)(ease_s=0.0))
    track.schedule("smile", 1.0, 0.5)
    track.schedule("surprise", 0.5, 2.0)
    alpha = track.intensities(np.arange(len(speech)) / 30)
    # Independent computation of the smile stage: tanh layer, readout of the changed UMUPs, EMUP readout.
    st, ex = model.expressions.stages["smile"], model.expressions
    y = np.tanh(mups @ st.w1.T + st.b1) @ st.w2.T + st.b2
    d_smile = (y[:, :5] - mups) @ ex.readout.T + y[:, 5:] @ st.emu_params.T + st.emu_bias
    d_surprise = EXPRESSION_PARAMS[EXPRESSIONS.index("surprise")]
    want = add_expression(speech, alpha[:, :1] * d_smile + alpha[:, 2:3] * d_surprise)
    np.testing.assert_allclose(pa, want, atol=1e-12)
    t = np.arange(len(pa)) / 30
    np.testing.assert_array_equal(pa[t < 0.5], speech[t < 0.5])
    smile = (t >= 0.5) & (t < 2.0)
    fixed = apply_expression(speech, alpha, EXPRESSION_PARAMS)
    assert np.abs(pa[smile] - fixed[smile]).max() > 1e-3  # not the fixed-offset rule
    # Frame by frame: the change follows the UMUPs (not a constant).
    assert np.std(pa[smile, 1] - speech[smile, 1]) > 1e-4


def test_an_mlp_session_smiling_at_room_noise_holds_still() -> None:
    """The shipped MLP mapper (second-stage expression MLPs) in a live session with a smile, fed only room hiss
    (-54 dBFS, random pushes): after the noise gate's warm-up and fade every served frame is the same pose, the smile
    on the silent face. The expression's change follows the MUPs, which the gate fades with the rows (it took the
    noise's MUPs before: the smile moved 0.0015-0.0032 IOD)."""
    from assets.modelfile import load_speech_model
    from realtime_core.features import NoiseGateConfig

    model = load_speech_model("mlp")
    settled = NoiseGateConfig().warmup_frames + NoiseGateConfig().release_frames
    hiss = np.random.default_rng(4).standard_normal(3 * 16000) * 10 ** (-54 / 20)
    smile = (0, {"type": "control", "expression": {"name": "smile", "intensity": 0.7, "at": 0.0}})
    frames = _run(model, hiss, [smile], 3)
    served = np.array([f.params for f in frames[settled:]])
    assert np.abs(served[0]).max() > 0.05  # the smile shows on the neutral face
    np.testing.assert_array_equal(served, np.broadcast_to(served[0], served.shape))


def test_a_head_driven_by_its_own_targets_shows_the_expression_on_its_face_shapes() -> None:
    """The browser's default kind (morph weights) and vertex deltas of the built-in head carried an expression through
    the mouth only: a surprise raised no brows. Its own brow/eye targets now take the recipe, in both kinds alike."""
    from assets.heads.head import builtin_morph_head

    rig = builtin_morph_head().rig
    model = small_model()
    s = Session(model, config=SessionConfig(sample_rate_hz=16000), rig=rig)
    s.apply_control({"type": "control", "expression": {"name": "surprise", "intensity": 1.0, "at": 0.5}})
    frames = s.push(speechlike(2.0, 16000)).frames + s.flush().frames
    brow = next(i for i, n in enumerate(rig.names) if rig.meta["face_shapes"].get(n) == "browInnerUp")
    before, after = frames[5], frames[-1]
    for f in (before, after):
        w = np.frombuffer(f.payload(P.KIND_MORPH, P.ENC_FLOAT32)[0], "<f4")
        np.testing.assert_allclose(w, rig.weights(f.params, f.expression), atol=1e-6)
        d = np.frombuffer(f.payload(P.KIND_DELTAS, P.ENC_FLOAT32)[0], "<f4").reshape(-1, 3)
        np.testing.assert_allclose(d, rig.displacements(f.params, f.expression), atol=1e-5)
    w0 = np.frombuffer(before.payload(P.KIND_MORPH, P.ENC_FLOAT32)[0], "<f4")
    w1 = np.frombuffer(after.payload(P.KIND_MORPH, P.ENC_FLOAT32)[0], "<f4")
    assert w0[brow] == 0 and w1[brow] == pytest.approx(0.7, abs=1e-6)
