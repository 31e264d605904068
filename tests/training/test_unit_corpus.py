"""The unit corpus: built from face tracks by EM-PCA, stored as .npz (no pickle), read back equal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from assets.unitcorpus import UnitCorpusFileError, load_unit_corpus
from realtime_core.synthesis.visemes import VISEME_ID, viseme_of
from training.facetrack import LOWER_FACE


def test_corpus_frames_are_pca_coefficients_then_params(stored_corpus, corpus_rows):
    c = stored_corpus.corpus
    k = c.n_coefficients
    assert k == 3  # three latent gestures make all the motion: explained >= 0.99 keeps exactly them
    assert c.dim_names[k:] == ("upper_lip_raise", "lip_stretch", "mouth_open", "lip_corner_depress")
    _, track, phones = corpus_rows[4]
    frames = c.sentence_frames(4)
    idx = list(LOWER_FACE)
    want = track.landmarks[:, idx].astype(np.float64) - track.neutral[idx]
    np.testing.assert_allclose(stored_corpus.landmark_offsets(frames[:, :k]), want, atol=1e-4)  # float32 tracks
    np.testing.assert_allclose(frames[:, k:], track.params, atol=1e-6)
    a, b = c.phone_offsets[4], c.phone_offsets[5]
    assert c.phone_labels[a:b] == tuple(p[0] for p in phones)
    assert all(c.phone_visemes[i] == VISEME_ID[viseme_of(lab, "arpabet")] for i, lab in enumerate(c.phone_labels))


def test_file_round_trip_and_bad_files(stored_corpus, corpus_file, tmp_path):
    back = load_unit_corpus(corpus_file)
    np.testing.assert_array_equal(back.corpus.frames, stored_corpus.corpus.frames.astype(np.float32))
    np.testing.assert_array_equal(back.corpus.phone_visemes, stored_corpus.corpus.phone_visemes)
    assert back.corpus.phone_labels == stored_corpus.corpus.phone_labels
    np.testing.assert_allclose(back.pca_components, stored_corpus.pca_components)
    assert back.meta["test"] is True
    with np.load(corpus_file, allow_pickle=False) as z:  # plain arrays only
        assert "frames" in z.files
    cut = tmp_path / "cut.npz"
    cut.write_bytes(corpus_file.read_bytes()[:1000])
    with pytest.raises(UnitCorpusFileError, match=r"cut.npz"):
        load_unit_corpus(cut)
    with pytest.raises(UnitCorpusFileError, match="not found"):
        load_unit_corpus(tmp_path / "missing.npz")


def test_rest_frame_is_the_neutral_face_as_closely_as_the_pca_can_show_it(stored_corpus):
    k = stored_corpus.corpus.n_coefficients
    rest = stored_corpus.rest_frame()
    assert rest.shape == (stored_corpus.corpus.n_dims,) and np.all(rest[k:] == 0.0)
    offsets = stored_corpus.landmark_offsets(rest[None, :k]).reshape(-1)
    # least squares: what is left of the zero displacement is orthogonal to every component
    np.testing.assert_allclose(stored_corpus.pca_components @ offsets, 0.0, atol=1e-9)
    # and no other coefficient vector comes closer to zero displacement
    other = stored_corpus.landmark_offsets(rest[None, :k] + 0.01).reshape(-1)
    assert np.linalg.norm(offsets) < np.linalg.norm(other)


def test_leave_one_out_evaluation_never_uses_the_sentence_itself(stored_corpus, corpus_rows):
    from realtime_core.synthesis.synthesizer import UnitSynthesizer
    from training.unitsel_eval import evaluate

    # closure=None: a sentence selecting itself reproduces its lips exactly only without the /p b m/ rule
    synth = UnitSynthesizer(stored_corpus.corpus, rest=stored_corpus.rest_frame(), closure=None)
    tests = list(corpus_rows[:4])
    inside = evaluate(stored_corpus, tests, n_best=(1,), synthesizer=synth)[0][0]
    loo = evaluate(stored_corpus, tests, n_best=(1,), synthesizer=synth, leave_one_out=True)[0][0]
    assert inside["system"] == loo["system"] == "unit selection, n_best=1"
    # in the corpus, each sentence selects itself and reproduces its own lips; left out, it cannot
    assert inside["r"]["mouth_open"] > 0.999
    assert loo["r"]["mouth_open"] < 0.99


@pytest.mark.slow  # runs the audio-driven model six times
def test_text_and_recording_rows_span_the_text_rows_and_the_audio_driven_model(stored_corpus, corpus_rows):
    """The text + recording rows are the pure text rows at weight 0 and the audio-driven model's
    row at weight 1; the pure text rows do not depend on whether a model is given."""
    import dataclasses

    from assets.modelfile import load_model
    from realtime_core.synthesis.recording import RecordingBlend
    from realtime_core.synthesis.synthesizer import UnitSynthesizer
    from training.unitsel_eval import evaluate

    rng = np.random.default_rng(3)
    tests = [  # audible noise in place of the synthetic tracks' silence, so the model's output moves
        (sid, dataclasses.replace(track, samples=rng.normal(0, 0.1, track.samples.shape).astype(np.float32)), ph)
        for sid, track, ph in corpus_rows[:3]
    ]
    # closure=None: the /p b m/ rule closes the lips after the mix, so at weight 1 it is not the model's alone
    synth = UnitSynthesizer(stored_corpus.corpus, rest=stored_corpus.rest_frame(), closure=None)
    model = load_model(None)
    rows = {}
    for w in (0.0, 1.0):
        blend = RecordingBlend(lead=w, speech=w, trail=w, ramp_s=0.0)
        out = evaluate(stored_corpus, tests, model=model, n_best=(1,), synthesizer=synth, recording=blend)[0]
        rows[w] = {r["system"].split(",")[0].split(":")[0]: r for r in out}
    text_only = evaluate(stored_corpus, tests, n_best=(1,), synthesizer=synth)[0][0]
    systems = {"unit selection", "text + recording", "audio-driven HMM", "articulatory rules (same phones)"}
    assert set(rows[0.0]) == systems
    assert rows[0.0]["unit selection"]["r"] == rows[1.0]["unit selection"]["r"] == text_only["r"]
    assert rows[0.0]["text + recording"]["r"] == pytest.approx(text_only["r"], abs=1e-9)
    assert rows[1.0]["text + recording"]["r"] == pytest.approx(rows[1.0]["audio-driven HMM"]["r"], abs=1e-9)


def test_cache_key_changes_with_the_parameter_definitions_and_every_other_input(monkeypatch, tmp_path):
    """A changed definition of the mouth parameters (training.params.DEFINITION_VERSION) must rebuild the
    cached corpus, which stores them, instead of handing back values measured the old way."""
    from pathlib import Path

    import training.unit_corpus as uc
    from assets.grid import GridSentence
    from realtime_core.synthesis.empca import EmPcaConfig
    from training.params import DEFINITION_VERSION

    s = [GridSentence(sentence_id="bbaf2n", video=Path("bbaf2n.mp4"), align=Path("bbaf2n.align"))]
    phones = {"bbaf2n": [("sil", 0.0, 0.5), ("b", 0.5, 0.6)]}
    key = uc.corpus_key(s, phones, EmPcaConfig())
    assert uc.corpus_key(s, phones, EmPcaConfig()) == key  # a pure function of its inputs
    assert uc.corpus_key(s, {"bbaf2n": [("sil", 0.0, 0.5), ("b", 0.5, 0.65)]}, EmPcaConfig()) != key
    monkeypatch.setattr(uc, "DEFINITION_VERSION", DEFINITION_VERSION + 1)
    assert uc.corpus_key(s, phones, EmPcaConfig()) != key


def test_units_eval_writes_its_figure_beside_its_output_never_into_the_checkouts_docs(tmp_path):
    """`units eval`'s Fig. 8 went to the relative docs/img/unitsel_fig8.png whatever --output said: run from the
    checkout it replaced the committed test figure (with the val one for --split val); run elsewhere it made a
    docs/img there. It goes to img/ beside the markdown now, the link relative to it."""
    from facecast.commands.units import figure_path

    out = tmp_path / "report" / "sec.md"
    assert figure_path(None, out, "test") == (tmp_path / "report" / "img" / "unitsel_fig8.png", "img/unitsel_fig8.png")
    assert figure_path(None, out, "val") == (
        tmp_path / "report" / "img" / "unitsel_fig8_val.png",
        "img/unitsel_fig8_val.png",
    )
    assert figure_path(tmp_path / "f.png", out, "test") == (tmp_path / "f.png", "../f.png")
    assert figure_path(None, None, "val") == (Path("unitsel_fig8_val.png"), "unitsel_fig8_val.png")
