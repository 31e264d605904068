"""espeak-ng through ctypes: phoneme events line up with the synthesised audio."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from assets.espeak import LANGUAGES, VARIANTS, Voice
from training.errors import ConfigError

# Real espeak-ng speech.
pytestmark = pytest.mark.system


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x.astype(np.float64) ** 2))) if len(x) else 0.0


def _core(syn, seg, frac: float = 0.5) -> np.ndarray:
    """Samples of the central ``frac`` of a segment (where a stop's closure is)."""
    rate = syn.sample_rate_hz
    mid, half = 0.5 * (seg.start_s + seg.end_s), 0.5 * frac * (seg.end_s - seg.start_s)
    return syn.samples[int((mid - half) * rate) : int((mid + half) * rate)]


@pytest.mark.parametrize(
    "voice,text,vowels",
    [
        (
            Voice(language="en", base="en-us"),
            "a papa, a puppy, a happy pup",
            {"a", "A:", "V", "aa", "a#", "@", "i", "I"},
        ),
        (
            Voice(language="es", base="es", variant="f2", rate_wpm=150),
            "papá pone la pipa en el tapete",
            {"a", "e", "i", "o"},
        ),
    ],
)
def test_bilabial_closure_is_quiet(espeak, voice, text, vowels) -> None:
    """A /p/'s closure (centre of its event span) is >= 12 dB quieter than the vowels.

    If the event sample positions were off by more than a few tens of ms the /p/ span would
    overlap a vowel and the ratio would fail.
    """
    syn = espeak.synthesize(text, voice)
    ps = [s for s in syn.phonemes if s.phoneme == "p"]
    vs = [s for s in syn.phonemes if s.phoneme in vowels]
    assert len(ps) >= 3 and len(vs) >= 3, [s.phoneme for s in syn.phonemes]
    vowel_rms = np.median([_rms(_core(syn, s)) for s in vs])
    for p in ps:
        ratio_db = 20 * np.log10((_rms(_core(syn, p)) + 1.0) / vowel_rms)
        assert ratio_db < -12.0, f"/p/ at {p.start_s:.3f}-{p.end_s:.3f}s only {ratio_db:.1f} dB below vowels"


def test_events_are_ordered_and_inside_audio(espeak) -> None:
    syn = espeak.synthesize("Bob moved five blue boxes.", Voice(language="en", base="en", variant="m3", pitch=30))
    assert syn.sample_rate_hz == 22050
    assert syn.samples.dtype == np.int16 and syn.samples.ndim == 1
    starts = [s.start_s for s in syn.phonemes]
    assert starts == sorted(starts)
    assert all(0 <= s.start_s < s.end_s <= syn.duration_s + 1e-9 for s in syn.phonemes)
    names = [s.phoneme for s in syn.phonemes]
    for expected in ("b", "m", "u:", "f", "v"):
        assert expected in names, names


@pytest.mark.parametrize(
    "voice,text,n_m",
    [
        (Voice(language="en", base="en-us"), "Hello there. My friend is here.", 1),
        (Voice(language="es", base="es"), "Hola, ¿cómo estás? Mañana vamos.", 3),
    ],
)
def test_a_sentence_initial_m_keeps_its_own_span(espeak, voice, text, n_m) -> None:
    # espeak-ng marks a pause at the /m/'s own sample ("_", a clause end, then "m"): both phones were
    # given the /m/'s span, and unit selection, reading the pause first, dropped the /m/ (say "... Mañana"
    # kept the lips 0.16 IOD apart through it).
    phones = espeak.synthesize(text, voice).phonemes
    assert all(b.start_s >= a.end_s - 1e-9 for a, b in itertools.pairwise(phones)), phones
    m = [p for p in phones if p.phoneme == "m"]
    assert len(m) == n_m and all(p.end_s - p.start_s > 0.03 for p in m), m


def test_a_phoneme_sharing_its_sample_with_the_next_has_no_length() -> None:
    from assets.espeak import _timeline

    events = [(0, "_:"), (100, "_"), (100, ""), (100, "m"), (150, "a"), (150, ""), (200, "")]
    got = [(s.phoneme, s.start_s, s.end_s) for s in _timeline(events, 250, 100)]
    assert got == [("_:", 0.0, 1.0), ("m", 1.0, 1.5), ("a", 1.5, 2.0)]


def test_rate_changes_duration(espeak) -> None:
    text = "Peter bought a bag of apples."
    slow = espeak.synthesize(text, Voice(language="en", base="en-us", rate_wpm=120))
    fast = espeak.synthesize(text, Voice(language="en", base="en-us", rate_wpm=260))
    assert slow.duration_s > 1.5 * fast.duration_s


def test_all_voices_and_variants_speak_and_sound_different(espeak) -> None:
    """Every base voice and every variant synthesises audible speech with an /m/ and a vowel event,
    and each variant changes the sound (a variant espeak silently ignored would equal the base)."""
    for lang, bases in LANGUAGES.items():
        for base in bases:
            syn = espeak.synthesize("ma", Voice(language=lang, base=base))
            assert _rms(syn.samples) > 100, f"{lang}/{base} is (near) silent"
            assert "m" in [s.phoneme for s in syn.phonemes], f"{lang}/{base}: {syn.phonemes}"
    base = espeak.synthesize("ma", Voice(language="es", base="es")).samples
    for v in VARIANTS:
        syn = espeak.synthesize("ma", Voice(language="es", base="es", variant=v))
        assert _rms(syn.samples) > 100, f"variant {v} is (near) silent"
        same = len(syn.samples) == len(base) and np.array_equal(syn.samples, base)
        assert not same, f"variant {v} sounds exactly like the base voice"


def test_bad_voice_config() -> None:
    with pytest.raises(ConfigError, match="unknown variant"):
        Voice(language="en", base="en-us", variant="zz9")
    with pytest.raises(ConfigError, match="rate_wpm"):
        Voice(language="en", base="en-us", rate_wpm=20)
    with pytest.raises(ConfigError, match="unknown language 'xx'"):
        Voice(language="xx", base="en-us")
    with pytest.raises(ConfigError, match="is not one of"):
        Voice(language="es", base="en-us")


def test_empty_text_is_refused(espeak) -> None:
    with pytest.raises(ConfigError, match="empty text"):
        espeak.synthesize("", Voice(language="en", base="en-us"))


def test_the_same_text_gives_the_same_samples_whatever_came_before(espeak) -> None:
    # espeak-ng 1.51 reads the phoneme list past a clause's end, where the previous text's last clause
    # lies: in one process "Sure!" gave 8900 samples, 10843 after "Dr." (its vowel 0.331 s, not 0.292 s)
    # for the rest of the process, and a few samples more or less call to call (wave generator phase).
    voice = Voice(language="en", base="en-us")
    first = espeak.synthesize("Sure!", voice, noise_seed=0)
    espeak.synthesize("Hello there, how are you?", voice, noise_seed=0)
    again = espeak.synthesize("Sure!", voice, noise_seed=0)
    espeak.synthesize("Dr.", voice, noise_seed=0)
    after_dr = espeak.synthesize("Sure!", voice, noise_seed=0)
    espeak.synthesize("Hola, ¿cómo estás?", Voice(language="es", base="es"), noise_seed=0)
    after_spanish = espeak.synthesize("Sure!", voice, noise_seed=0)
    for other in (again, after_dr, after_spanish):
        assert np.array_equal(other.samples, first.samples), (len(first.samples), len(other.samples))
        assert other.phonemes == first.phonemes


def test_a_sentence_after_dr_equals_it_in_a_new_process(espeak) -> None:
    """What the server says mid-session is what `facecast say` says in a fresh process (an independent
    espeak-ng, loaded by another interpreter)."""
    import subprocess
    import sys

    text, voice = "My friend is here.", Voice(language="en", base="en-us", variant="f3")
    espeak.synthesize("Dr.", voice, noise_seed=7)
    here = espeak.synthesize(text, voice, noise_seed=7)
    code = (
        "import sys; from assets.espeak import Voice, synthesizer; "
        "s = synthesizer().synthesize(sys.argv[1], Voice(language='en', base='en-us', variant='f3'), noise_seed=7); "
        "sys.stdout.buffer.write(s.samples.tobytes())"
    )
    repo = Path(__file__).resolve().parents[2]  # this checkout's assets, not an installed copy
    out = subprocess.run([sys.executable, "-c", code, text], capture_output=True, check=True, cwd=repo).stdout
    assert np.array_equal(np.frombuffer(out, dtype=np.int16), here.samples)
