"""pocketsphinx forced alignment of transcribed real speech (optional extra "align")."""

from __future__ import annotations

import numpy as np
import pytest

from assets.audio import read_wav
from tests.prerequisites import require_module
from training.build_corpus import BuildConfig, build_corpus
from training.corpus import load_corpus

# pocketsphinx forced alignment on real speech.
pytestmark = [pytest.mark.system, pytest.mark.slow]


@pytest.fixture(autouse=True)
def _pocketsphinx_installed() -> None:
    require_module("pocketsphinx", "optional extra: pip install 'facecast[align]'")


def test_reproduces_the_shipped_librivox_alignment(shared_data) -> None:
    """The LibriVox clips' *.phone.json came from pocketsphinx: aligning the .txt again gives
    the same phones within 20 ms on average."""
    from training.alignments import read_phone_json
    from training.force_align import force_align

    stem = shared_data / "speech" / "librivox" / "sense_and_sensibility_01_austen_64kb-0880"
    samples, rate = read_wav(stem.with_suffix(".wav"))
    got = force_align(samples, rate, stem.with_suffix(".txt").read_text(), source=stem.with_suffix(".wav"))
    ref = read_phone_json(stem.with_name(stem.name + ".phone.json"))
    assert [p.phoneme for p in got.phones] == [p.phoneme for p in ref.phones]
    assert np.mean([abs(a.start_s - b.start_s) for a, b in zip(got.phones, ref.phones)]) < 0.02


def test_builder_aligns_transcribed_speech_and_names_what_it_skips(shared_data, tmp_path) -> None:
    rep = build_corpus(
        BuildConfig(
            out_dir=tmp_path,
            sentences=0,
            languages=(),
            real_dirs=(shared_data / "speech" / "ljspeech",),
            force_align=True,
        )
    )
    utts = load_corpus(tmp_path)
    assert len(utts) >= 5 and all(u.source == "real" and u.speaker_group == "real:ljspeech" for u in utts)
    for u in utts:  # phones cover the speech and the rules open and close the mouth
        assert u.phonemes[-1].end_s <= u.duration_s + 0.02 and u.params[:, 2].max() > 0.1
        assert (u.params[:, 2] == 0.0).any()
    # LJ001-0003 says "woodcutters", which the dictionary lacks: it was skipped; espeak-ng pronounces it now
    assert not any("LJ001-0003.wav" in f for f, _ in rep.skipped), rep.skipped


def test_fast_synthetic_speech_aligns(espeak, tmp_path) -> None:
    """`facecast say TEXT -o say.wav`, then `say TEXT --audio say.wav`: pocketsphinx's phone pass found no path
    through espeak-ng's speech at its default rate ("Failed to set up sub-word alignment": a /b/ of 20 ms is shorter
    than three 10 ms frames). It now aligns on 5 ms frames; every word's phones in order, within the audio, and
    each /p b m/ where espeak-ng itself says it is (its phoneme events)."""
    from assets.tts import speak
    from training.force_align import force_align

    speech = speak("Please bring me my big map.", language="en").padded()
    got = force_align(speech.samples, speech.sample_rate_hz, "Please bring me my big map.", source="say.wav")
    names = [p.phoneme for p in got.phones if p.phoneme != "SIL"]
    assert names == ["P", "L", "IY", "Z", "B", "R", "IH", "NG", "M", "IY", "M", "AY", "B", "IH", "G", "M", "AE", "P"]
    assert all(0 <= p.start_s < p.end_s <= len(speech.samples) / speech.sample_rate_hz + 1e-9 for p in got.phones)
    said = [(s, e) for ph, s, e in speech.phones if ph in ("p", "b", "m")]
    aligned = [(p.start_s, p.end_s) for p in got.phones if p.phoneme in ("P", "B", "M")]
    assert len(said) == len(aligned) == 7
    # espeak-ng's events put a stop's closure in the vowel before it at the end of a phrase (the last /p/)
    off = [abs(0.5 * (s0 + e0) - 0.5 * (s1 + e1)) for (s0, e0), (s1, e1) in zip(said, aligned, strict=True)]
    assert max(off[:-1]) < 0.03 and off[-1] < 0.15, off


@pytest.mark.parametrize("stem", ["arctic/arctic_a0009", "librivox/sense_and_sensibility_01_austen_64kb-0870"])
def test_recognised_phones_agree_with_the_reference_alignment(shared_data, stem: str) -> None:
    """Allphone recognition without the transcript: a contiguous ARPAbet timeline over the whole clip whose
    visemes agree with the clip's reference phone alignment on most 10 ms frames (measured 0.65 and 0.70; the
    most common viseme class alone covers 0.25 and 0.19 of them, so a timeline that ignored the audio fails)."""
    from realtime_core.synthesis.visemes import viseme_of
    from training.alignments import find_aligned_audio
    from training.force_align import recognise_phones

    wav = shared_data / "speech" / f"{stem}.wav"
    ref = dict(find_aligned_audio(wav.parent))[wav]
    samples, rate = read_wav(wav)
    got = recognise_phones(samples, rate, source=wav)
    assert got.inventory == "arpabet" and got.phones[0].start_s == 0.0
    assert all(abs(a.end_s - b.start_s) < 1e-9 for a, b in zip(got.phones, got.phones[1:]))
    assert abs(got.phones[-1].end_s - len(samples) / rate) < 0.02
    assert all(viseme_of(p.phoneme, "arpabet", default="") for p in got.phones)  # every label known

    n = int(np.ceil(len(samples) / rate * 100))

    def frames(al) -> np.ndarray:
        out = np.full(n, "sil", dtype=object)
        for p in al.phones:
            out[int(round(p.start_s * 100)) : int(round(p.end_s * 100))] = viseme_of(
                p.phoneme, "arpabet", default="sil"
            )
        return out

    assert np.mean(frames(got) == frames(ref)) > 0.55


def test_the_transcript_keeps_every_spoken_word() -> None:
    # The regex [a-z']+ dropped numbers ("20" -> nothing) and cut accented words ("café" -> "caf").
    from training.force_align import normalise_transcript

    assert normalise_transcript("The café, naïve Zoë’s well-known “Dr. Smith” paid $5 (50%) for 3 U.S. maps.") == [
        *("the", "cafe", "naive", "zoe's", "well", "known", "dr.", "smith", "paid", "$5", "50%", "for", "3"),
        *("u.s.", "maps"),
    ]


def test_every_espeak_phone_has_arpabet_the_aligner_accepts() -> None:
    """Every espeak-ng English phone the viseme table knows (bar pauses and links) maps to phones that
    pocketsphinx's dictionary accepts (``add_word`` refuses a phone its acoustic model lacks)."""
    from pocketsphinx import Decoder

    from realtime_core.synthesis.visemes import PHONE_TO_VISEME
    from training.force_align import _SILENT_ESPEAK, ESPEAK_EN_TO_ARPABET

    assert set(PHONE_TO_VISEME["espeak-en"]) - _SILENT_ESPEAK <= set(ESPEAK_EN_TO_ARPABET)
    decoder = Decoder(samprate=16000, bestpath=False, loglevel="FATAL")
    for k, phones in enumerate(sorted(set(ESPEAK_EN_TO_ARPABET.values()))):
        decoder.add_word(f"probe{k}", phones, False)  # raises RuntimeError for an unknown phone


def _runs(names: list[str], run: list[str]) -> bool:
    return any(names[i : i + len(run)] == run for i in range(len(names)))


def test_numbers_are_aligned_as_spoken(espeak) -> None:
    """`say "I paid 20 dollars for 3 coffees at noon." --audio rec.wav` aligned "twenty" and "three" as silence
    (the numbers were dropped from the transcript): the mouth rested while they were said. espeak-ng reads them
    now, and their phones are aligned where espeak-ng's own events put them."""
    from assets.tts import speak
    from training.force_align import force_align

    text = "I paid 20 dollars for 3 coffees at noon."
    speech = speak(text).padded()
    got = force_align(speech.samples, speech.sample_rate_hz, text, source="rec.wav")
    names = [p.phoneme for p in got.phones if p.phoneme != "SIL"]
    assert names[:3] == ["AY", "P", "EY"] and names[-3:] == ["N", "UW", "N"], names
    assert _runs(names, ["D", "T", "W", "EH", "N", "T", "IY", "D", "AA", "L"]), names  # "paid twenty dollars"
    assert _runs(names, ["R", "TH", "R", "IY", "K"]), names  # "for three coffees"
    # the aligned /TH/ of "three" is where espeak-ng said its /T/
    said = [0.5 * (s + e) for ph, s, e in speech.phones if ph == "T"]
    th = [0.5 * (p.start_s + p.end_s) for p in got.phones if p.phoneme == "TH"]
    assert len(said) == len(th) == 1 and abs(said[0] - th[0]) < 0.05, (said, th)


def test_a_transcript_is_read_as_facecast_say_reads_it(espeak) -> None:
    """`say "I paid $5.50 at 9:00 on Dec 7." -o say.wav` now speaks "5 dollars and 50 cents at 9 o'clock on December
    7th"; the aligner read the same transcript as espeak-ng did before ("dollar five point five zero ... nine zero
    zero ... deck seven"), so `say TEXT --audio say.wav` looked for words that were not said. It reads it as said."""
    from assets.tts import speak
    from training.force_align import force_align

    text = "I paid $5.50 at 9:00 on Dec 7."
    speech = speak(text).padded()
    assert speech.text == "I paid 5 dollars and 50 cents at 9 o'clock on December 7th."
    got = force_align(speech.samples, speech.sample_rate_hz, text, source="say.wav")
    said = " ".join(p.phoneme for p in got.phones if p.phoneme != "SIL")
    assert "F AY V D AO L ER Z AH N D F IH F T IY S EH N T S" in said, said  # not "dollar five point five zero"
    assert "N AY N AH K L AA K" in said, said  # "nine o'clock", not "nine zero zero"
    assert "D IH S EH M B ER S EH V AH N TH" in said, said  # "December seventh", not "deck seven"


def test_a_word_outside_the_dictionary_aligns(shared_data) -> None:
    """LJ001-0003 says "woodcutters", which the pocketsphinx dictionary lacks: it failed the run (exit 2, no hint).
    espeak-ng's letter-to-sound rules pronounce it now, and the clip aligns with those phones in their place."""
    from training.force_align import force_align, speech_in_pauses_s

    wav = shared_data / "speech" / "ljspeech" / "LJ001-0003.wav"
    text = next(
        line.split("|")[2]
        for line in (wav.parent / "metadata.csv").read_text().splitlines()
        if line.startswith("LJ001-0003|")
    )
    samples, rate = read_wav(wav)
    got = force_align(samples, rate, text, source=wav)
    names = [p.phoneme for p in got.phones if p.phoneme != "SIL"]
    assert _runs(names, ["DH", "AH", "W", "UH", "D", "K", "AH", "T", "ER", "Z", "AH", "V"]), names
    speech_s, in_pauses_s = speech_in_pauses_s(samples, rate, got)
    assert in_pauses_s < 0.15 * speech_s, (speech_s, in_pauses_s)  # the words cover the speech


def test_a_transcripts_numeric_date_is_read_as_the_voice_reads_it(espeak) -> None:
    """`say "It is due 07/12/2026." --voice en-gb-x-rp --audio rec.wav`: the British voice says "December 7th" (day
    first), but the aligner read the transcript month first whatever the voice ("July 12th") and failed ("Failed to
    set up sub-word alignment"). It takes the voice's reading, as `say` without --audio does."""
    from assets.tts import day_first, parse_voice, speak
    from training.force_align import force_align

    text = "It is due 07/12/2026."
    speech = speak(text, voice="en-gb-x-rp").padded()
    assert speech.text == "It is due December 7th, 2026."
    first = day_first(parse_voice("en", "en-gb-x-rp"))
    assert first is True and day_first(parse_voice("en", None)) is False and day_first(parse_voice("es")) is None
    got = force_align(speech.samples, speech.sample_rate_hz, text, source="rec.wav", day_first=first)
    said = " ".join(p.phoneme for p in got.phones if p.phoneme != "SIL")
    assert "D IH S EH M B ER" in said and "JH UW L AY" not in said, said  # "December", not "July"
