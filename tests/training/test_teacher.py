"""Teacher labels (training/teacher.py): synthetic speech labelled with recorded lips by unit selection."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import VISUAL_PARAMS
from realtime_core.synthesis.rest import RestPauses
from realtime_core.synthesis.synthesizer import UnitSynthesizer
from training.teacher import (
    GRID_WORDS,
    TeacherClip,
    espeak_clips,
    festival_clips,
    grid_texts,
    load_clips,
    padded_phones,
    save_clips,
    set_level,
    teacher_params,
)


def _synth(stored) -> UnitSynthesizer:
    return UnitSynthesizer(stored.corpus, rest=stored.rest_frame())


def _independent(stored, clip: TeacherClip, n_best: int) -> np.ndarray:
    """The four parameters of a fresh synthesizer's own run on the clip's phones, picked by dim name."""
    frames = (
        _synth(stored)
        .synthesize(
            list(clip.phones), clip.inventory, n_frames=len(clip.params), n_best=n_best, rest_pauses=RestPauses()
        )
        .frames
    )
    names = list(stored.corpus.dim_names)
    return np.stack([frames[:, names.index(p)] for p in VISUAL_PARAMS], axis=1)


def test_grid_texts_follow_the_grammar():
    texts = grid_texts(50, np.random.default_rng(0))
    assert len(set(texts)) == 50
    for t in texts:
        words = t.split()
        assert len(words) == 6 and all(w in slot for w, slot in zip(words, GRID_WORDS, strict=True))


def test_espeak_labels_agree_with_an_independent_unit_selection_run_and_rest_in_silence(
    espeak, stored_corpus, tmp_path
):
    clips = espeak_clips(_synth(stored_corpus), 3, seed=4, n_best=2)
    assert len({name.split("-", 3)[3] for name, _, _ in clips}) > 1  # voices differ
    for _, clip, _ in clips:
        dur = len(clip.samples) / clip.sample_rate_hz
        assert len(clip.params) == int(np.ceil(dur * 30 - 1e-9))
        # the phones are espeak's own events on the samples' clock, padded with 0.2 s / 0.25 s of silence
        assert clip.phones[0] == ("_", 0.0, 0.2) and abs(clip.phones[-1][2] - dur) < 1e-9
        assert np.all(clip.samples[: int(0.2 * clip.sample_rate_hz)] == 0)
        np.testing.assert_allclose(clip.params, _independent(stored_corpus, clip, 2), atol=1e-12)
        # the padded silence is the rest pose (every parameter 0), the speech moves the mouth
        assert np.all(clip.params[0] == 0) and np.all(clip.params[-1] == 0)
        assert np.ptp(clip.params[:, VISUAL_PARAMS.index("mouth_open")]) > 0.01
        assert np.max(np.abs(clip.samples)) <= 1.0
    # one stream per utterance: a smaller set is the start of a larger one (same voices, sentences, phone labels;
    # the timings move by a few ms: espeak-ng's waveform state carries over from one call to the next)
    fewer = espeak_clips(_synth(stored_corpus), 2, seed=4, n_best=2)
    labels = [(n, [lab for lab, _, _ in c.phones]) for n, c, _ in clips[:2]]
    assert [(n, [lab for lab, _, _ in c.phones]) for n, c, _ in fewer] == labels
    # saved and loaded as they were
    back = load_clips(save_clips(tmp_path / "t.npz", clips))
    for (n0, c0, s0), (n1, c1, s1) in zip(clips, back, strict=True):
        assert n0 == n1 and c0.phones == c1.phones and c0.inventory == c1.inventory
        np.testing.assert_array_equal(c0.samples, c1.samples)
        np.testing.assert_allclose(c0.params, c1.params, atol=1e-6)
        assert [(a, b) for a, b, _ in s0] == [(a, b) for a, b, _ in s1]


def test_festival_labels_agree_with_an_independent_unit_selection_run(stored_corpus):
    from tests.prerequisites import require_tool

    require_tool("festival", "apt package festival")
    clips = festival_clips(_synth(stored_corpus), 2, seed=2, n_best=1, batch=2)
    for _, clip, _ in clips:
        dur = len(clip.samples) / clip.sample_rate_hz
        assert clip.phones[0][:2] == ("pau", 0.0) and clip.phones[-1][0] == "pau"
        assert abs(clip.phones[-1][2] - dur) < 1e-9 and clip.phones[1][1] >= 0.2 - 1e-9
        np.testing.assert_allclose(clip.params, _independent(stored_corpus, clip, 1), atol=1e-12)
        assert np.all(clip.params[0] == 0) and np.all(clip.params[-1] == 0)


def test_padded_phones_stretch_or_add_the_end_pauses():
    assert padded_phones([("pau", 0.2, 0.3), ("b", 0.3, 0.4), ("pau", 0.4, 0.5)], 0.75) == [
        ("pau", 0.0, 0.3),
        ("b", 0.3, 0.4),
        ("pau", 0.4, 0.75),
    ]
    assert padded_phones([("b", 0.2, 0.4)], 0.6) == [("pau", 0.0, 0.2), ("b", 0.2, 0.4), ("pau", 0.4, 0.6)]
    assert padded_phones([], 0.6) == [("pau", 0.0, 0.6)]


def test_a_silent_timeline_gives_the_rest_pose_throughout(stored_corpus):
    params = teacher_params(_synth(stored_corpus), [("sil", 0.0, 0.4), ("sil", 0.4, 1.0)], "arpabet", 30)
    assert params.shape == (30, 4) and np.all(params == 0)


def test_set_level_sets_the_mean_speech_block_level():
    rate, n = 16000, 512  # 32 ms blocks
    t = np.arange(32 * n) / rate
    x = np.concatenate([np.zeros(16 * n), 0.3 * np.sin(2 * np.pi * 200 * t) * np.linspace(0.5, 1.0, len(t))])
    y = set_level(x, rate, -20.0)
    blocks = y[16 * n :].reshape(32, n).astype(np.float64)  # the speech blocks; the silent ones are > 30 dB under
    assert np.mean(10 * np.log10(np.mean(blocks**2, axis=1))) == pytest.approx(-20.0, abs=1e-3)
    assert y.dtype == np.float32 and np.all(y[: 16 * n] == 0)


def test_no_teacher_sentences_build_no_corpus(tmp_path):
    """The default (0 + 0 sentences) returns no clips without reading GRID s1 (the folder does not exist)."""
    from training.teacher import TeacherConfig, teacher_clips

    assert teacher_clips(TeacherConfig(), tmp_path / "nowhere", cache_dir=tmp_path) == []
    with pytest.raises(Exception, match="teacher config"):
        TeacherConfig(espeak=-1)


def test_readout_command_refuses_teacher_sentences_with_a_corpus_or_bad_counts(tmp_path, capsys):
    """The teacher labels with GRID s1's lips: beside --corpus (another talker) it is refused, one line, before any
    work; so is a negative count. No model is written."""
    from facecast.cli import main

    out, corpus = tmp_path / "m.npz", tmp_path / "mycorpus"
    rc = main(["readout", "default", "-o", str(out), "--corpus", str(corpus), "--teacher-espeak", "10"])
    err = capsys.readouterr().err
    assert rc == 2 and "--teacher-espeak" in err and str(corpus) in err and len(err.strip().splitlines()) == 1
    rc = main(["readout", "default", "-o", str(out), "--teacher-festival", "-3", "--grid-s1", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "teacher config" in err
    assert not out.exists()


def test_the_teacher_cache_key_follows_every_option_and_the_unit_corpus(tmp_path):
    """The clips are cached by what makes them: another seed, count, n_best or unit corpus is another file (a stale
    file is never read for other options); the same options are the same file, beside the corpus's ``unitsel``."""
    from training.teacher import TeacherConfig, teacher_cache_path

    corpus = tmp_path / "cache" / "unitsel" / "grid_s1_units-aaaa.npz"
    base = TeacherConfig(espeak=250, festival=250)
    path = teacher_cache_path(base, corpus)
    assert path.parent == tmp_path / "cache" / "teacher"
    assert teacher_cache_path(TeacherConfig(espeak=250, festival=250), corpus) == path
    others = [
        teacher_cache_path(TeacherConfig(espeak=250, festival=250, seed=1), corpus),
        teacher_cache_path(TeacherConfig(espeak=250, festival=250, n_best=4), corpus),
        teacher_cache_path(TeacherConfig(espeak=251, festival=250), corpus),
        teacher_cache_path(TeacherConfig(espeak=250, festival=249), corpus),
        teacher_cache_path(base, corpus.with_name("grid_s1_units-bbbb.npz")),
    ]
    assert len({path, *others}) == 6


def test_cached_clips_read_back_bit_for_bit(tmp_path):
    """The cache keeps the labels in float64: a readout fitted on cached clips is the one fitted on fresh ones."""
    rng = np.random.default_rng(3)
    params = rng.uniform(0, 0.3, (12, 4))
    clip = TeacherClip(rng.uniform(-0.5, 0.5, 6400).astype(np.float32), 16000, params, (("pau", 0.0, 0.4),))
    ((_, back, _),) = load_clips(save_clips(tmp_path / "c.npz", [("teacher-espeak-00000-x", clip, [])]))
    assert back.params.dtype == np.float64 and np.array_equal(back.params, params)
    np.testing.assert_array_equal(back.samples, clip.samples)


def test_train_command_refuses_teacher_sentences_without_grid_s1(tmp_path, capsys):
    from facecast.cli import main

    out = tmp_path / "m.npz"
    rc = main(["train", str(tmp_path / "corpus"), "-o", str(out), "--teacher-espeak", "3"])
    err = capsys.readouterr().err
    assert rc == 2 and "--grid-s1" in err and len(err.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.slow
def test_train_on_grid_s1_with_teacher_clips_grows_by_exactly_the_clips(grid_copy, tmp_path, espeak, ffmpeg):
    """`facecast train --grid-s1 ROOT --teacher-espeak 3` on a three-sentence GRID copy (train split): the model
    is trained on the GRID utterances and their speed copies plus the 3 teacher clips, once each (no speed copies),
    every teacher frame a Baum-Welch frame: the utterance and frame counts grow by exactly the clips' (their
    audio's 30 fps frame count, computed here from the cached clips' samples), and the metadata records them. The
    clips are the cache's (the file the readout reads with the same options)."""
    from tests.prerequisites import require_module

    require_module("mediapipe", "optional extra: pip install 'facecast[video]'")

    from assets.modelfile import load_model
    from facecast.cli import main
    from training.params import n_frames_for

    root = grid_copy(("bbaf2n", "bbal6n", "bbbf6n"))
    cache = tmp_path / "cache"
    argv = ["train", "--grid-s1", str(root), "--speed", "1.1", "--cache-dir", str(cache)]
    argv += ["--states", "2", "--mix", "1", "--iters", "1"]
    assert main([*argv, "-o", str(tmp_path / "plain.npz")]) == 0
    assert main([*argv, "-o", str(tmp_path / "taught.npz"), "--teacher-espeak", "3", "--teacher-seed", "5"]) == 0
    plain, taught = load_model(tmp_path / "plain.npz"), load_model(tmp_path / "taught.npz")
    (cached,) = (cache / "teacher").glob("teacher-3e0f-*.npz")
    clips = load_clips(cached)
    frames = sum(n_frames_for(len(c.samples) / c.sample_rate_hz) for _, c, _ in clips)
    assert len(clips) == 3 and all(
        len(c.params) == n_frames_for(len(c.samples) / c.sample_rate_hz) for _, c, _ in clips
    )
    assert taught.metadata["train_utterances"] == plain.metadata["train_utterances"] + 3
    assert taught.metadata["train_frames"] == plain.metadata["train_frames"] + frames
    assert taught.metadata["teacher"] == {
        "espeak": 3,
        "festival": 0,
        "seed": 5,
        "n_best": 5,
        "utterances": 3,
        "frames": frames,
    }
    assert "teacher" not in plain.metadata and plain.metadata["grid_s1"] == taught.metadata["grid_s1"]
    # the teacher's audio moved the CMVN warm-start statistics (they are over all the training audio)
    assert not np.allclose(plain.cmvn_mean, taught.cmvn_mean)
