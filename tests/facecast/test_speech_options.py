"""--expression on a file: changes anywhere in the file, the live limits otherwise."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from facecast.commands.speech_options import expression_intensities
from realtime_core.expressions import EXPRESSIONS, ExpressionError


def _args(*specs: str) -> argparse.Namespace:
    return argparse.Namespace(expression=list(specs), expression_ease=0.0)


def test_an_expression_late_in_a_long_file_is_scheduled():
    # 13 minutes of speech: a smile at 700 s was refused as "more than 600 s ahead of the media time 0 s"
    n = 13 * 60 * 30
    alpha = expression_intensities(_args("smile:0.5@700"), n)
    smile = alpha[:, EXPRESSIONS.index("smile")]
    assert np.all(smile[: 700 * 30] == 0) and np.all(smile[700 * 30 + 1 :] == 0.5)
    with pytest.raises(ExpressionError, match="ahead"):  # beyond the file's end: still refused
        expression_intensities(_args("smile@900"), n)


def test_animate_warns_of_speech_far_under_the_training_level_in_one_line(tmp_path, capsys):
    """The shipped model reads loudness as mouth opening: speech 20 dB under its training level opened the mouth about
    half as far, silently. The same speech at that level, and silence, give no warning; the file is written anyway."""
    from assets.audio import write_wav
    from facecast.cli import main
    from realtime_core.features.gain import S1_SPEECH_LEVEL_DBFS, speech_level_db
    from tests.speech import speechlike

    x = speechlike(1.5, 16000, seed=3)
    x = np.concatenate([np.zeros(8000), x, np.zeros(8000)])
    at_level = x * 10.0 ** ((S1_SPEECH_LEVEL_DBFS - speech_level_db(x, 16000)) / 20.0)
    for name, samples, warned in [
        ("level", at_level, False),
        ("quiet", at_level * 0.1, True),
        ("silent", np.zeros(16000), False),
    ]:
        wav = tmp_path / f"{name}.wav"
        write_wav(wav, samples, 16000)
        assert main(["animate", str(wav), "-o", str(tmp_path / f"{name}.csv")]) == 0
        err = capsys.readouterr().err
        assert (f"{wav}: speech at {S1_SPEECH_LEVEL_DBFS - 20:.1f} dBFS, 20 dB under" in err) == warned, err
        assert len(err.splitlines()) == int(warned), err
        assert (tmp_path / f"{name}.csv").is_file()


def test_animate_writes_curves_and_glb_keys_at_the_asked_frame_rate(tmp_path):
    """A game at 60 fps or a film at 24 asked for `animate --fps` (render had it, animate wrote 30 fps only): the
    curves are the 30 fps output interpolated onto k / fps (held after its last frame: as long as it, as render),
    and the glb's keys sit on the same times."""
    import pygltflib

    from assets.audio import write_wav
    from assets.tracks import read_csv
    from facecast.cli import main
    from tests.speech import speechlike

    wav = write_wav(tmp_path / "s.wav", speechlike(1.5, 16000, seed=5), 16000)
    assert main(["animate", str(wav), "-o", str(tmp_path / "s30.csv")]) == 0
    base = read_csv(tmp_path / "s30.csv")
    for fps in (24, 60):
        csv, glb = tmp_path / f"s{fps}.csv", tmp_path / f"s{fps}.glb"
        assert main(["animate", str(wav), "--fps", str(fps), "-o", str(csv), "-o", str(glb)]) == 0
        got = read_csv(csv, fps=fps)
        n = int(np.ceil(len(base.values) / 30 * fps - 1e-4))  # every frame starting within the 30 fps frames' span
        assert got.fps == fps and got.values.shape == (n, 4)
        want = np.stack([np.interp(np.arange(n) / fps, base.times(), base.values[:, j]) for j in range(4)], axis=1)
        np.testing.assert_allclose(got.values, want, atol=1e-8)
        g = pygltflib.GLTF2().load(str(glb))
        keys = g.accessors[g.animations[0].samplers[0].input]
        assert keys.count == n and keys.max[0] == pytest.approx((n - 1) / fps, abs=1e-6)


def test_the_quiet_warning_does_not_call_room_noise_speech(tmp_path, ffmpeg, capsys):
    """5 s of white noise at -54 dBFS faded in over 0.1 s (ffmpeg): `animate` warned of "speech at -54.0 dBFS",
    while the output noise gate rested the face for 45 % of the file. The line now gives that share (the rows the gate
    brought to the neutral face: zero with the gate and not without it, on the live path computed here) and does
    not call the file speech (`render` prints the same line, from the same function)."""
    import subprocess

    from assets.audio import read_audio
    from assets.modelfile import load_model
    from facecast.cli import main
    from realtime_core.pipeline import speech_to_params

    wav = tmp_path / "room.wav"
    noise = "anoisesrc=color=white:amplitude=0.00346:duration=5:sample_rate=16000:seed=7,afade=t=in:d=0.1"
    subprocess.run([ffmpeg, "-v", "error", "-f", "lavfi", "-i", noise, "-c:a", "pcm_s16le", str(wav)], check=True)
    x, rate = read_audio(wav)
    model = load_model()
    gated, ungated = speech_to_params(model, x, rate), speech_to_params(model, x, rate, noise_gate=None)
    rested = np.all(gated == 0, axis=1) & np.any(ungated != 0, axis=1)
    assert 0.2 < rested.mean() < 0.9, rested.mean()  # the gate rests part of it, the rest is animated
    assert main(["animate", str(wav), "-o", str(tmp_path / "room.csv")]) == 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "speech at" not in err, err
    assert f"{wav}: the noise gate took {100 * rested.mean():.0f} % of it for room noise" in err, err
    assert "dB under the level the model was trained at" in err and "if it is speech" in err, err


def test_animate_auto_gain_brings_a_quiet_take_to_the_models_level_without_a_warning(tmp_path, capsys, shared_data):
    """The warning for quiet speech had only ffmpeg to offer: `--auto-gain` runs the live sessions' gain stage, so the
    quiet take's curves are the gain stage's (the offline path computed here) and near the take at its own level."""
    from assets.audio import read_audio, write_wav
    from assets.modelfile import load_model
    from assets.tracks import read_csv
    from facecast.cli import main
    from realtime_core.pipeline import speech_to_params, with_auto_gain

    x, _ = read_audio(shared_data / "speech" / "arctic" / "arctic_a0009.wav", rate_hz=16000)  # real read speech
    loud, quiet = write_wav(tmp_path / "loud.wav", x, 16000), write_wav(tmp_path / "quiet.wav", 0.1 * x, 16000)
    for wav, extra in [(loud, []), (quiet, []), (quiet, ["--auto-gain"])]:
        assert main(["animate", str(wav), *extra, "-o", str(tmp_path / f"{wav.stem}{len(extra)}.csv")]) == 0
    err = capsys.readouterr().err
    assert err.count("warning") == 1 and "give --auto-gain" in err, err  # the plain quiet run only
    at_level, plain, gained = (read_csv(tmp_path / n).values[:, 2] for n in ("loud0.csv", "quiet0.csv", "quiet1.csv"))
    samples, _ = read_audio(quiet)
    ref = speech_to_params(with_auto_gain(load_model()), samples, 16000)[:, 2]
    np.testing.assert_allclose(gained, ref, atol=1e-6)
    # measured: r 0.59 and 0.54 of the mean opening without, 0.92 and 0.95 with
    assert np.corrcoef(gained, at_level)[0, 1] > 0.85 > 0.7 > np.corrcoef(plain, at_level)[0, 1]
    assert 0.85 < gained.mean() / at_level.mean() < 1.15 and plain.mean() / at_level.mean() < 0.7


def test_animate_warns_of_clipped_speech_in_one_line(tmp_path, capsys):
    """A take driven into clipping (38 % of its samples at full scale: r 0.46 against the take unclipped) was
    animated without a word; the same speech unclipped gives no warning."""
    from assets.audio import write_wav
    from facecast.cli import main
    from tests.speech import speechlike

    x = speechlike(2.0, 16000, seed=4)
    x = 0.5 * x / np.abs(x).max()
    for name, samples, warned in [("clean", x, False), ("clipped", np.clip(x * 30.0, -1.0, 1.0), True)]:
        wav = write_wav(tmp_path / f"{name}.wav", samples, 16000)
        assert main(["animate", str(wav), "-o", str(tmp_path / f"{name}.csv")]) == 0
        err = capsys.readouterr().err
        assert ("of the samples are clipped (at full scale)" in err) == warned, err


def test_an_expression_set_after_the_speech_ends_is_warned_of_once(tmp_path, capsys):
    """`--expression surprise@9` on a 2 s take was dropped without a word; one set within the take is not warned of."""
    from assets.audio import write_wav
    from facecast.cli import main
    from tests.speech import speechlike

    wav = write_wav(tmp_path / "take.wav", 0.3 * speechlike(2.0, 16000, seed=4), 16000)
    for spec, warned in [("smile@1.5", False), ("surprise@9", True)]:
        assert main(["animate", str(wav), "-o", str(tmp_path / "x.csv"), "--expression", spec]) == 0
        err = capsys.readouterr().err
        want = f"facecast animate: warning: --expression {spec} starts at 9 s, after the speech ends (2.0"
        assert err.count(want) == warned, err
