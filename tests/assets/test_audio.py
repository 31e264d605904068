"""``read_audio`` on the WAVs recorders, DAWs and Python tools actually write: float, 24-bit and
multichannel (WAVE_FORMAT_EXTENSIBLE), mu-law, 96 kHz. The PCM reader refuses them; ffmpeg decodes them,
to the same samples as the 16-bit original."""

from __future__ import annotations

import subprocess
import wave

import numpy as np
import pytest

from assets.audio import read_audio, write_wav
from assets.errors import NotAudioError
from tests.speech import speechlike

pytestmark = pytest.mark.system  # ffmpeg


@pytest.mark.parametrize(
    ("name", "codec", "extra", "rate", "atol"),
    [
        ("float.wav", "pcm_f32le", [], 16000, 1e-6),
        ("24bit.wav", "pcm_s24le", [], 16000, 1e-6),
        ("six.wav", "pcm_s16le", ["-ac", "6"], 16000, 0.0),  # 5.1: ffmpeg's downmix matrix, not the channel mean
        ("mulaw.wav", "pcm_mulaw", [], 16000, 0.02),  # 8-bit companding
        ("hi_rate.wav", "pcm_s16le", ["-ar", "96000"], 96000, None),
    ],
)
def test_wav_encodings_the_pcm_reader_refuses_are_decoded_by_ffmpeg(tmp_path, ffmpeg, name, codec, extra, rate, atol):
    src = write_wav(tmp_path / "src.wav", speechlike(1.0, 16000), 16000)
    ref, _ = read_audio(src)
    out = tmp_path / name
    subprocess.run([ffmpeg, "-v", "error", "-y", "-i", str(src), "-c:a", codec, *extra, str(out)], check=True)
    x, got_rate = read_audio(out)
    assert got_rate == rate and x.dtype == np.float32
    if atol is None:  # resampled: the same duration and loudness
        assert abs(len(x) / rate - len(ref) / 16000) < 1e-3
        assert abs(np.sqrt(np.mean(x**2)) / np.sqrt(np.mean(ref**2)) - 1) < 0.02
    elif atol == 0.0:  # the same waveform up to a gain
        assert len(x) == len(ref) and np.corrcoef(x, ref)[0, 1] > 0.999
    else:
        np.testing.assert_allclose(x, ref, atol=atol)


def test_a_corrupt_wav_is_still_one_error_naming_the_file(tmp_path, ffmpeg):
    bad = tmp_path / "bad.wav"
    bad.write_bytes(b"RIFF\x24\x00\x00\x00WAVEfmt \x10\x00\x00\x00" + b"\xff" * 40)
    with pytest.raises(NotAudioError, match=r"bad\.wav: "):
        read_audio(bad)


def test_a_wav_whose_chunk_runs_past_the_riff_size_is_one_error_naming_the_file(tmp_path, ffmpeg):
    # A chunk declaring more bytes than its RIFF container holds (a cut download, a mangled header):
    # Python's wave module raises a bare RuntimeError for it, which reached the user as a traceback.
    good = write_wav(tmp_path / "good.wav", speechlike(0.5, 16000), 16000).read_bytes()
    bad = tmp_path / "bad.wav"
    junk = b"junk" + (10**6).to_bytes(4, "little")
    bad.write_bytes(good[:4] + (20).to_bytes(4, "little") + good[8:12] + junk + good[12:])
    with pytest.raises(NotAudioError, match=r"bad\.wav: "):
        read_audio(bad)


def test_a_folder_or_a_missing_file_is_named_as_such(tmp_path):
    """A folder given as speech (a user pointing at a folder of takes) is told it is a folder, not that nothing
    is there; a missing path says it is missing."""
    with pytest.raises(NotAudioError, match="is a folder, not an audio file"):
        read_audio(tmp_path)
    with pytest.raises(NotAudioError, match=r"nope\.wav: file not found"):
        read_audio(tmp_path / "nope.wav")


@pytest.mark.parametrize(
    ("bad", "rate_hz"),
    [(np.nan, None), (np.inf, None), (np.nan, 8000), (-np.inf, 8000)],
    ids=["nan", "inf", "nan-resampled", "-inf-resampled"],
)
def test_a_float_wav_holding_nan_or_inf_is_refused_naming_the_file_and_where(tmp_path, ffmpeg, bad, rate_hz):
    """A 32-bit float WAV with NaN (a failed computation written out) was decoded to 16-bit, where ffmpeg makes a NaN
    -32768 (a full-scale click) and clips +-inf, and animated without a word, while a live session refuses such a
    block (1007). It is refused, naming the file and the first bad sample's time, also when read at another rate
    (a second decode, to float, for the files that may hold them: float output would change every stereo file's
    downmix)."""
    x = (0.3 * speechlike(1.0, 16000)).astype("<f4")
    x[8000:8010] = bad  # at 0.50 s
    wav = tmp_path / "broken.wav"
    raw = ["-f", "f32le", "-ar", "16000", "-ac", "1", "-i", "-"]
    subprocess.run([ffmpeg, "-v", "error", "-y", *raw, "-c:a", "pcm_f32le", str(wav)], input=x.tobytes(), check=True)
    assert np.isnan(np.frombuffer(wav.read_bytes()[-len(x) * 4 :], dtype="<f4")).any() == np.isnan(bad)  # as written
    with pytest.raises(NotAudioError, match=r"broken\.wav: holds NaN/inf samples at 0\.(49|50) s"):
        read_audio(wav, rate_hz=rate_hz)
    x[8000:8010] = 0.0
    subprocess.run([ffmpeg, "-v", "error", "-y", *raw, "-c:a", "pcm_f32le", str(wav)], input=x.tobytes(), check=True)
    got, rate = read_audio(wav)
    assert rate == 16000
    np.testing.assert_allclose(got, x, atol=0.5 / 32768)  # the file made whole reads as written (16-bit steps)


@pytest.mark.parametrize("suffix", [".wav", ".flac"])  # the PCM reader, and ffmpeg's decode
def test_channels_in_opposite_polarity_are_not_mixed_to_silence(tmp_path, suffix, caplog):
    """A stereo take with one channel inverted (a miswired microphone) was mixed to digital silence: the mouth never
    opened and nothing was said. The loudest channel is used instead, with one warning; a real stereo take (two
    channels that differ) is still mixed to their mean."""
    import logging

    x = (0.3 * speechlike(1.0, 16000, seed=3)).astype(np.float32)
    wav = tmp_path / "inverted.wav"
    pcm = np.rint(np.stack([x, -x], axis=1) * 32767).astype("<i2")
    with wave.open(str(wav), "wb") as w:
        w.setnchannels(2), w.setsampwidth(2), w.setframerate(16000), w.writeframes(pcm.tobytes())
    path = wav
    if suffix != ".wav":
        path = tmp_path / f"inverted{suffix}"
        subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(wav), str(path)], check=True)
    with caplog.at_level(logging.WARNING, logger="assets.audio"):
        got, rate = read_audio(path)
    assert rate == 16000
    np.testing.assert_allclose(got, x, atol=2 / 32767)  # the first channel, not silence
    assert sum("channels cancel when mixed to mono" in r.getMessage() for r in caplog.records) == 1
    caplog.clear()
    y = (0.3 * speechlike(1.0, 16000, seed=4)).astype(np.float32)  # another voice on the other channel
    pcm = np.rint(np.stack([x, y], axis=1) * 32767).astype("<i2")
    with wave.open(str(wav), "wb") as w:
        w.setnchannels(2), w.setsampwidth(2), w.setframerate(16000), w.writeframes(pcm.tobytes())
    got, _ = read_audio(wav)
    np.testing.assert_allclose(got, pcm.astype(np.float32).mean(axis=1) / 32768, atol=1e-6)
    assert not caplog.records


def test_is_silent_reads_the_peak_of_either_sign_in_int16_and_float() -> None:
    """The peak from the extremes (no float64 |x| copy): a lone negative sample counts as much as a positive one, int16
    against 32768, -32768 included (whose |x| does not fit int16)."""
    from assets.audio import SILENCE_PEAK, is_silent

    threshold = int(np.ceil(SILENCE_PEAK * 32768))  # the least int16 peak that is not silent
    for value, silent in ((threshold - 1, True), (threshold, False), (-threshold, False), (-32768, False)):
        x = np.zeros(16000, np.int16)
        x[123] = value
        assert is_silent(x) is silent, value
        assert is_silent(x / 32768.0) is silent, value  # the same samples as float
    assert is_silent(np.zeros(0, np.int16)) and is_silent(np.zeros(0))
    assert is_silent(np.full(10, -0.5 * SILENCE_PEAK)) and not is_silent(np.full(10, -2 * SILENCE_PEAK))
