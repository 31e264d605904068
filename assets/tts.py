"""Text -> speech with phone timings for unit selection (espeak-ng; the phones of its own voice).

One call: :func:`speak` cleans the text (:func:`realtime_core.synthesis.text.clean_text`),
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


@dataclass(frozen=True, kw_only=True)
class Speech:
    """samples: (n,) float32 in [-1, 1]; sample_rate_hz; phones: ((label, start_s, end_s), ...) on the
    samples' clock; inventory: the labels' phone set; text: what was spoken (cleaned)."""

    samples: np.ndarray
    sample_rate_hz: int
    phones: tuple[tuple[str, float, float], ...]
    inventory: str
    text: str

    @property
    def duration_s(self) -> float:
        return len(self.samples) / self.sample_rate_hz

    def followed_by_pause(self, seconds: float) -> Speech:
        """The same speech with ``seconds`` of silence after it, timed as espeak's pause phone ``_``.
        espeak-ng ends an utterance 7 ms after its last phone, so a face animated to it stops
        mid-phone (the mouth open after "there"); the pause lets it come back to rest."""
        if not seconds >= 0:
            raise ConfigError(f"pause must be >= 0 s, got {seconds}")
        n = int(round(seconds * self.sample_rate_hz))
        if n == 0:
            return self
        end = self.duration_s
        return Speech(
            samples=np.concatenate([self.samples, np.zeros(n, dtype=self.samples.dtype)]),
            sample_rate_hz=self.sample_rate_hz,
            phones=(*self.phones, ("_", end, end + n / self.sample_rate_hz)),
            inventory=self.inventory,
            text=self.text,
        )


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


def speak(text: str, *, language: str = "en", voice: str | None = None, rate_wpm: int = 175) -> Speech:
    """Speak ``text``; raises TextError (nothing to say) or ConfigError (language, voice)."""
    v = parse_voice(language, voice, rate_wpm=rate_wpm)
    cleaned = clean_text(text)
    syn = synthesizer().synthesize(cleaned, v, noise_seed=0)
    phones = tuple((p.phoneme, p.start_s, p.end_s) for p in syn.phonemes)
    if not any(lab not in ("_", "_:", "_!", "_^_", ";") for lab, _, _ in phones):
        raise TextError(f"no pronounceable word in {text[:40]!r}")
    samples = syn.samples.astype(np.float32) / 32768.0
    return Speech(
        samples=samples, sample_rate_hz=syn.sample_rate_hz, phones=phones, inventory=INVENTORY[language], text=cleaned
    )
