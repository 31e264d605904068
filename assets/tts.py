"""Text -> speech with phone timings for unit selection (espeak-ng; the phones of its own voice).

One call: :func:`speak` cleans the text (:func:`realtime_core.synthesis.text.clean_text`: what espeak-ng reads
badly, URLs, dates, times, amounts, written out as said in the language),
synthesises it with an espeak-ng voice of the language and returns the samples and the phone
timeline in the inventory the viseme table knows (``espeak-en``, ``espeak-es``). espeak-ng
pronounces any word, known or not (it spells letters and applies its letter-to-sound rules), which
is the spoken fallback for words outside its dictionary.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from assets.espeak import LANGUAGES, VARIANTS, Voice, synthesizer
from realtime_core.errors import ConfigError
from realtime_core.synthesis.text import TextError, clean_text

INVENTORY = {"en": "espeak-en", "es": "espeak-es"}
"""Phone inventory of each language's espeak voices (keys: the supported languages)."""

LEAD_PAUSE_S = 0.2
"""Silence put before synthesised speech (:meth:`Speech.padded`): the face opens from rest into the
first phone over it (0.2 s, the ramp of :class:`realtime_core.synthesis.rest.RestPauses`)."""

END_PAUSE_S = 0.25
"""Silence put after synthesised speech, so the face ends at rest (the mouth is back within 2-3
frames of the pause's start: "Hello there." ended at mouth_open 0.095 without it, 0.004 with it)."""


@dataclass(frozen=True, kw_only=True)
class Speech:
    """samples: (n,) float32 in [-1, 1]; sample_rate_hz; phones: ((label, start_s, end_s), ...) on the
    samples' clock; inventory: the labels' phone set; text: what was spoken (cleaned, and written out as said:
    "see example dot com", :func:`realtime_core.synthesis.text.clean_text`)."""

    samples: np.ndarray
    sample_rate_hz: int
    phones: tuple[tuple[str, float, float], ...]
    inventory: str
    text: str

    @property
    def duration_s(self) -> float:
        return len(self.samples) / self.sample_rate_hz

    def padded(self, *, before_s: float = LEAD_PAUSE_S, after_s: float = END_PAUSE_S) -> Speech:
        """The same speech with ``before_s`` seconds of silence before it and ``after_s`` after it,
        timed as espeak's pause phone ``_`` (the phones shifted by the leading pause). espeak-ng starts
        speaking within ~12 ms and ends 7 ms after its last phone, so a face animated to it would
        start and stop mid-phone; the pauses give it time to leave the rest pose and come back to it
        (:mod:`realtime_core.synthesis.rest`)."""
        if not (before_s >= 0 and after_s >= 0):
            raise ConfigError(f"pauses must be >= 0 s, got {before_s} and {after_s}")
        rate = self.sample_rate_hz
        n0, n1 = int(round(before_s * rate)), int(round(after_s * rate))
        if n0 == 0 and n1 == 0:
            return self
        lead, end = n0 / rate, n0 / rate + self.duration_s
        phones = tuple((lab, a + lead, b + lead) for lab, a, b in self.phones)
        return Speech(
            samples=np.concatenate([np.zeros(n0, self.samples.dtype), self.samples, np.zeros(n1, self.samples.dtype)]),
            sample_rate_hz=rate,
            phones=(("_", 0.0, lead),) * (n0 > 0) + phones + (("_", end, end + n1 / rate),) * (n1 > 0),
            inventory=self.inventory,
            text=self.text,
        )


def language_of_voice(voice: str | None, default: str = "en") -> str:
    """The language whose espeak voices include ``voice``'s base ("es", "es-419+f2" -> "es"); ``default``
    for None, a bare variant ("f3") or an unknown voice (which :func:`parse_voice` then names)."""
    base = (voice or "").partition("+")[0]
    return next((lang for lang, bases in LANGUAGES.items() if base in bases), default)


def parse_voice(language: str, voice: str | None = None, *, rate_wpm: int = 175) -> Voice:
    """An espeak voice for ``language`` ("en", "es"): ``voice`` like "en-us", "en-gb-x-rp+f3", "es"
    or just a variant "f3"; None = the language's first voice."""
    if language not in INVENTORY:
        raise ConfigError(f"unsupported language {language!r}; supported: {sorted(INVENTORY)}")
    base, variant = LANGUAGES[language][0], None
    if voice:
        head, _, tail = voice.partition("+")
        if head in VARIANTS and not tail:
            variant = head
        else:
            base, variant = head, tail or None
    # Voice's own errors name the offending value ("voice 'xx' is not one of ...", "unknown variant 'zz'",
    # "rate_wpm must be in (80, 450), got 0"); a "voice None: ..." prefix on a bad rate only confused.
    return Voice(language=language, base=base, variant=variant, rate_wpm=rate_wpm)


def day_first(voice: Voice) -> bool | None:
    """How ``voice`` reads an ambiguous numeric date ("07/12/2026", :func:`clean_text`): a US English voice month
    first, a British (or other) English one day first; None = the language's custom (Spanish day first)."""
    return None if voice.language != "en" else not voice.base.startswith("en-us")


def speak(text: str, *, language: str = "en", voice: str | None = None, rate_wpm: int = 175) -> Speech:
    """Speak ``text``; raises TextError (nothing to say) or ConfigError (language, voice)."""
    v = parse_voice(language, voice, rate_wpm=rate_wpm)
    # URLs, dates, times, amounts written out as said in the language; "07/12/2026" is July 12 to a US voice
    cleaned = clean_text(text, language=language, day_first=day_first(v))
    syn = synthesizer().synthesize(cleaned, v, noise_seed=0)
    phones = tuple((p.phoneme, p.start_s, p.end_s) for p in syn.phonemes)
    if not any(lab not in ("_", "_:", "_!", "_^_", ";") for lab, _, _ in phones):
        raise TextError(f"no pronounceable word in {text[:40]!r}")
    samples = syn.samples.astype(np.float32) / 32768.0
    return Speech(
        samples=samples, sample_rate_hz=syn.sample_rate_hz, phones=phones, inventory=INVENTORY[language], text=cleaned
    )
