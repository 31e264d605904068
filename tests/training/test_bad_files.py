"""Bad inputs give errors that name the file and the problem."""

from __future__ import annotations

import subprocess
import wave

import numpy as np
import pytest

from assets.audio import read_wav
from tests.prerequisites import missing, require_module
from training.corpus import load_corpus, write_manifest, write_utterance
from training.errors import (
    CorpusFormatError,
    NoFaceError,
    NotAudioError,
    NotVideoError,
    SilentAudioError,
    TruncatedFileError,
    WrongSampleRateError,
)

# ffmpeg, MediaPipe and CLI subprocesses on damaged files.
pytestmark = pytest.mark.system


@pytest.fixture
def mediapipe_installed() -> None:
    require_module("mediapipe", "optional extra: pip install 'facecast[video]'")


def _wav(path, samples, rate):
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(np.asarray(samples, dtype="<i2").tobytes())
    return path


def _tone(rate=16000, seconds=0.5):
    t = np.arange(int(rate * seconds)) / rate
    return (8000 * np.sin(2 * np.pi * 220 * t)).astype(np.int16)


def test_not_audio(tmp_path) -> None:
    p = tmp_path / "notes.wav"
    p.write_text("this is text, not a WAV file\n")
    with pytest.raises(NotAudioError, match=r"notes\.wav: not audio"):
        read_wav(p)


def test_silent(tmp_path) -> None:
    p = _wav(tmp_path / "quiet.wav", np.zeros(8000), 16000)
    with pytest.raises(SilentAudioError, match=r"quiet\.wav: silent"):
        read_wav(p)


def test_wrong_rate(tmp_path) -> None:
    p = _wav(tmp_path / "odd.wav", _tone(12345), 12345)
    with pytest.raises(WrongSampleRateError, match=r"odd\.wav: wrong sample rate: 12345 Hz"):
        read_wav(p)


def test_truncated_wav(tmp_path) -> None:
    p = _wav(tmp_path / "cut.wav", _tone(), 16000)
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(TruncatedFileError, match=r"cut\.wav: truncated WAV: header declares 8000 frames"):
        read_wav(p)


def _tiny_corpus(root):
    entry = write_utterance(
        root,
        utt_id="u1",
        samples=_tone(),
        sample_rate_hz=16000,
        params=np.zeros((15, 4)),
        phonemes=(),
        language="en",
        voice="test",
        source="espeak",
        speaker_group="test",
    )
    write_manifest(root, [entry], seed=0)
    return entry


def test_corpus_rate_mismatch_and_truncated_params(tmp_path) -> None:
    _tiny_corpus(tmp_path)
    assert len(load_corpus(tmp_path)) == 1
    _wav(tmp_path / "u1" / "audio.wav", _tone(22050), 22050)
    with pytest.raises(
        WrongSampleRateError, match=r"u1/audio\.wav: wrong sample rate: file has 22050 Hz, manifest says 16000"
    ):
        load_corpus(tmp_path)
    _tiny_corpus(tmp_path)
    csv = tmp_path / "u1" / "params.csv"
    csv.write_text("\n".join(csv.read_text().splitlines()[:10]) + "\n")
    with pytest.raises(TruncatedFileError, match=r"u1/params\.csv: truncated: 9 frames, expected 15"):
        load_corpus(tmp_path)
    (tmp_path / "manifest.json").write_text("{not json")
    with pytest.raises(CorpusFormatError, match=r"manifest\.json: not valid JSON"):
        load_corpus(tmp_path)


def _ffmpeg(*args):
    subprocess.run(["ffmpeg", "-v", "error", "-y", *map(str, args)], check=True)


def test_not_a_video(tmp_path, ffmpeg) -> None:
    from training.video import measure_video

    p = tmp_path / "clip.mp4"
    p.write_bytes(b"\x00garbage" * 100)
    with pytest.raises(NotVideoError, match=r"clip\.mp4: not a video"):
        measure_video(p)


def test_truncated_video(tmp_path, ffmpeg, shared_data) -> None:
    from training.video import measure_video

    src = shared_data / "video" / "grid" / "lbax4n.mpg"
    if not src.is_file():
        missing(f"GRID clip not found: {src}")
    cut = tmp_path / "cut.mpg"
    cut.write_bytes(src.read_bytes()[:150_000])
    with pytest.raises(TruncatedFileError, match=r"cut\.mpg: truncated"):
        measure_video(cut)
    mp4 = tmp_path / "full.mp4"
    _ffmpeg("-i", src, "-c:v", "libx264", "-preset", "ultrafast", "-c:a", "aac", mp4)
    cut_mp4 = tmp_path / "cut.mp4"
    cut_mp4.write_bytes(mp4.read_bytes()[: mp4.stat().st_size // 2])
    with pytest.raises(TruncatedFileError, match=r"cut\.mp4: truncated video"):
        measure_video(cut_mp4)


def test_no_face(mediapipe_installed, tmp_path, ffmpeg) -> None:
    from training.video import measure_video

    p = tmp_path / "wall.mp4"
    _ffmpeg(
        "-f",
        "lavfi",
        "-i",
        "testsrc=size=320x240:rate=25:duration=1",
        "-f",
        "lavfi",
        "-i",
        "sine=frequency=300:duration=1",
        "-shortest",
        "-pix_fmt",
        "yuv420p",
        p,
    )
    with pytest.raises(NoFaceError, match=r"wall\.mp4: no face found in 25 of 25 frames"):
        measure_video(p)


def test_silent_video_and_no_audio_track(tmp_path, ffmpeg, shared_data) -> None:
    from training.video import measure_video

    src = shared_data / "video" / "grid" / "lbax4n.mpg"
    if not src.is_file():
        missing(f"GRID clip not found: {src}")
    mute = tmp_path / "mute.mp4"
    _ffmpeg(
        "-i",
        src,
        "-f",
        "lavfi",
        "-i",
        "anullsrc=r=16000:cl=mono",
        "-map",
        "0:v",
        "-map",
        "1:a",
        "-shortest",
        "-c:v",
        "libx264",
        "-preset",
        "ultrafast",
        "-c:a",
        "aac",
        mute,
    )
    with pytest.raises(SilentAudioError, match=r"mute\.mp4: silent"):
        measure_video(mute)
    noaudio = tmp_path / "noaudio.mp4"
    _ffmpeg("-i", src, "-an", "-c:v", "libx264", "-preset", "ultrafast", noaudio)
    with pytest.raises(NotAudioError, match=r"noaudio\.mp4: not audio: the video has no audio track"):
        measure_video(noaudio)


def test_cli_prints_one_line_error(tmp_path, capsys, ffmpeg) -> None:
    from facecast.cli import main

    p = tmp_path / "notavideo.webm"
    p.write_text("hello")
    assert main(["extract", str(p), "-o", str(tmp_path / "out")]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "facecast extract: error:" in ln]
    assert len(lines) == 1 and lines[0].endswith("\r") is False
    assert f"facecast extract: error: {p}: not a video: ffprobe cannot read it" in lines[0]


def test_a_folder_of_camera_files_is_found_and_other_files_are_named(tmp_path, capsys) -> None:
    """A camera's AVCHD .MTS files were passed over without a word: `extract` said only "no video found"."""
    from facecast.cli import main
    from training.video import find_videos, passed_over

    for name in ("a/take1.MTS", "a/take2.m2ts", "clip.MP4", "notes.txt", "still.jpg", ".DS_Store"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("x")
    assert [p.name for p in find_videos([tmp_path])] == ["take1.MTS", "take2.m2ts", "clip.MP4"]
    assert [p.name for p in passed_over([tmp_path])] == ["notes.txt", "still.jpg"]
    assert main(["extract", str(tmp_path)]) == 2  # three text files named as video: skipped, none ok
    err = capsys.readouterr().err
    assert "passed over 2 file(s) not named as video (.jpg, .txt)" in err, err
