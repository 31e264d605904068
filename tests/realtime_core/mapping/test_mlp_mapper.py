"""The GMM-selected MLP mapper: numpy inference vs scikit-learn, streaming == batch for any
chunking (features and raw audio through SpeechToParams), the file format and its errors."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.avmodel import AvModel, encode_model
from realtime_core.errors import ConfigError, InvalidFeaturesError, ModelFormatError, StreamStateError
from realtime_core.features import FrontEndConfig, MfccConfig, extract_features
from realtime_core.mapping import (
    MlpSpeechModel,
    SpeechModel,
    VisualMapper,
    decode_mlp_model,
    encode_mlp_model,
)
from realtime_core.pipeline import SpeechToParams, speech_to_params
from training.mapper import MapperRecipe, fit_bank, fit_readout, fit_selector

FE = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000, n_ceps=11), cmvn=None, tc=3)


def _data(n: int = 3000, seed: int = 0):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, FE.audio_dim))
    mid = slice(3 * FE.n_feat, 4 * FE.n_feat)
    y = np.column_stack(
        [np.tanh(x[:, mid] @ rng.standard_normal(FE.n_feat)), x[:, mid][:, 0] * x[:, mid][:, 1], np.sin(x[:, 0])]
    )
    return x, y


@pytest.fixture(scope="module")
def bank_and_data():
    x, y = _data()
    recipe = MapperRecipe(n_classes=4, hidden=15, max_iter=60, min_frames=200)
    lo, hi = 3 * FE.n_feat, 4 * FE.n_feat
    readout = fit_readout(y, y[:, :2] * 2 + 1)
    return fit_bank(x, y, recipe, class_slice=(lo, hi), readout=readout), x, y, recipe


def test_numpy_inference_matches_sklearn(bank_and_data) -> None:
    bank, x, y, recipe = bank_and_data
    from realtime_core.mapping import MlpMapper

    m64 = MlpMapper(bank, dtype="float64")
    # The selector: sklearn's GaussianMixture predict on the same (refitted, deterministic) mixture.
    gmm = fit_selector(x[:, bank.class_slice[0] : bank.class_slice[1]], recipe)
    np.testing.assert_array_equal(m64.classify(x), gmm.predict(x[:, bank.class_slice[0] : bank.class_slice[1]]))
    # Each expert: the exported weights reproduce an independent forward pass of the stored weights.
    cls = m64.classify(x)
    ref = np.array([bank.w2[c] @ np.tanh(bank.w1[c] @ row + bank.b1[c]) + bank.b2[c] for c, row in zip(cls, x)])
    np.testing.assert_allclose(m64.mups(x), ref, atol=1e-10)
    # float32 live path stays close to float64.
    m32 = MlpMapper(bank)
    np.testing.assert_allclose(m32.mups(x), ref, atol=2e-4)
    # It learned something: better than predicting the mean.
    assert np.mean((m64.mups(x) - y) ** 2) < 0.7 * np.mean((y - y.mean(0)) ** 2)


def test_export_matches_sklearn_predict() -> None:
    from sklearn.neural_network import MLPRegressor

    from training.mapper import export_mlp

    rng = np.random.default_rng(2)
    x = rng.standard_normal((500, 7)) * 3 + 1
    y = np.column_stack([x[:, 0] ** 2, x[:, 1]]) * 10
    xm, xsd, ym, ysd = x.mean(0), x.std(0), y.mean(0), y.std(0)
    mlp = MLPRegressor(hidden_layer_sizes=(20,), activation="tanh", max_iter=50, random_state=0).fit(
        (x - xm) / xsd, (y - ym) / ysd
    )
    w1, b1, w2, b2 = export_mlp(mlp, xm, xsd, ym, ysd)
    ours = (w2 @ np.tanh(w1 @ x.T + b1[:, None])).T + b2
    np.testing.assert_allclose(ours, mlp.predict((x - xm) / xsd) * ysd + ym, rtol=1e-9, atol=1e-9)


def test_streaming_equals_batch_for_any_chunking(bank_and_data) -> None:
    bank, x, _, _ = bank_and_data
    model = MlpSpeechModel(
        bank=bank, frontend=FE, cmvn_mean=np.zeros(FE.n_feat), cmvn_var=np.ones(FE.n_feat), visual_names=("a", "b")
    )
    assert isinstance(model, SpeechModel)
    batch = model.mapper().predict(x[:500])
    rng = np.random.default_rng(1)
    for _ in range(3):
        s = model.visual_mapper()
        assert isinstance(s, VisualMapper)
        cuts = np.sort(rng.choice(np.arange(1, 500), 30, replace=False))
        out = np.concatenate([s.push(c) for c in np.split(x[:500], cuts)] + [s.flush()])
        np.testing.assert_array_equal(out, batch)
    # Raw audio through the speech pipeline: sample by sample chunks vs whole.
    audio = 0.1 * np.sin(np.arange(16000) * 0.05) * rng.standard_normal(16000)
    whole = speech_to_params(model, audio)
    p = SpeechToParams(model)
    pieces, i = [], 0
    while i < audio.size:
        n = int(rng.integers(1, 900))
        pieces.append(p.push(audio[i : i + n]))
        i += n
    pieces.append(p.flush())
    np.testing.assert_array_equal(np.concatenate(pieces), whole)
    assert len(whole) == len(extract_features(audio, FE))
    assert p.delay_frames == FE.tc


def test_file_round_trip_and_errors(bank_and_data, tmp_path) -> None:
    bank, x, _, _ = bank_and_data
    model = MlpSpeechModel(
        bank=bank,
        frontend=FE,
        cmvn_mean=np.zeros(FE.n_feat),
        cmvn_var=np.ones(FE.n_feat),
        visual_names=("a", "b"),
        metadata={"k": 4},
    )
    back = decode_mlp_model(encode_mlp_model(model))
    np.testing.assert_array_equal(back.mapper().predict(x[:50]), model.mapper().predict(x[:50]))
    assert back.metadata == {"k": 4} and back.closure_band == 0.0
    import dataclasses

    banded = decode_mlp_model(encode_mlp_model(dataclasses.replace(model, closure_band=0.03)))
    assert banded.closure_band == 0.03
    with pytest.raises(ModelFormatError, match="closure_band"):
        dataclasses.replace(model, closure_band=0.5)
    with pytest.raises(ModelFormatError, match="not a facecast mapper archive"):
        decode_mlp_model(b"not a zip")
    import io

    def tampered(**changes) -> bytes:
        z = dict(np.load(io.BytesIO(encode_mlp_model(model))))
        z.update(changes)
        buf = io.BytesIO()
        np.savez(buf, **z)
        return buf.getvalue()

    with pytest.raises(ModelFormatError, match="version 99 is not supported"):
        decode_mlp_model(tampered(version=np.array(99)))
    with pytest.raises(ModelFormatError, match="format is 'something'"):
        decode_mlp_model(tampered(format=np.array("something")))
    with pytest.raises(ModelFormatError, match="w1 contains NaN"):
        w1 = bank.w1.copy()
        w1[0, 0, 0] = np.nan
        decode_mlp_model(tampered(w1=w1))
    with pytest.raises(ModelFormatError, match="w2 must be"):
        decode_mlp_model(tampered(w2=bank.w2[:, :, :3]))


def test_hmm_file_given_as_mlp_mapper_is_named() -> None:
    from realtime_core.hmm import AvHmm

    rng = np.random.default_rng(0)
    d = FE.audio_dim + 4
    hmm = AvHmm(
        startprob=np.ones(2) / 2,
        transmat=np.ones((2, 2)) / 2,
        weights=np.ones((2, 1)),
        means=rng.standard_normal((2, 1, d)),
        covars=np.tile(np.eye(d), (2, 1, 1, 1)),
        covariance_type="full",
        n_audio=FE.audio_dim,
    )
    av = AvModel(hmm=hmm, frontend=FE, cmvn_mean=np.zeros(FE.n_feat), cmvn_var=np.ones(FE.n_feat))
    with pytest.raises(ModelFormatError, match=r"this is an HMM model .* use --mapper hmm"):
        decode_mlp_model(encode_model(av))
    # The HMM path satisfies the same interface.
    assert isinstance(av, SpeechModel) and isinstance(av.visual_mapper(), VisualMapper)


def test_mlp_mapper_given_as_hmm_model_is_named(bank_and_data) -> None:
    # The reverse of the above was refused for "lacking the array 'startprob'".
    from realtime_core.avmodel import decode_model

    model = MlpSpeechModel(
        bank=bank_and_data[0],
        frontend=FE,
        cmvn_mean=np.zeros(FE.n_feat),
        cmvn_var=np.ones(FE.n_feat),
        visual_names=("a", "b"),
    )
    with pytest.raises(ModelFormatError, match=r"this is an MLP mapper .* use --mapper mlp"):
        decode_model(encode_mlp_model(model))


def test_stream_misuse_and_bad_features(bank_and_data) -> None:
    bank, x, _, _ = bank_and_data
    model = MlpSpeechModel(
        bank=bank, frontend=FE, cmvn_mean=np.zeros(FE.n_feat), cmvn_var=np.ones(FE.n_feat), visual_names=("a", "b")
    )
    s = model.visual_mapper()
    with pytest.raises(InvalidFeaturesError, match=r"\(k, 77\)"):
        s.push(x[:3, :10])
    bad = x[:3].copy()
    bad[1, 5] = np.inf
    with pytest.raises(InvalidFeaturesError, match="NaN or inf"):
        s.push(bad)
    s.flush()
    with pytest.raises(StreamStateError):
        s.push(x[:1])
    with pytest.raises(ConfigError, match="no smoothing lag"):
        model.visual_mapper(lag=2)
    with pytest.raises(ConfigError, match="batch"):
        speech_to_params(model, np.zeros(4000), mode="batch")


def test_readout_is_the_affine_map_of_the_mups(bank_and_data) -> None:
    bank, x, _, _ = bank_and_data
    from realtime_core.mapping import MlpMapper

    m = MlpMapper(bank, dtype="float64")
    np.testing.assert_allclose(m.predict(x[:100]), m.mups(x[:100]) @ bank.readout.T + bank.readout_bias, atol=1e-10)
