"""Phone alignments for transcribed speech with pocketsphinx's English aligner (optional extra
``align``: the ``pocketsphinx`` wheel ships its US-English acoustic model and dictionary, so it
runs offline).

pocketsphinx aligns in two passes over the same audio: the first (with ``set_align_text``)
finds the words, the second (``set_alignment``) their phones and states; times are in its
10 ms frames. Audio is resampled to 16 kHz first.

The transcript is read as it is spoken (:func:`normalise_transcript`): accents are folded
("café" -> "cafe", not "caf"), and numbers, ordinals, currency, percentages, symbols, initials
and mid-sentence abbreviations ("20", "3rd", "$5", "50%", "&", "U.S.", "Dr. Smith") are kept as
written. Those, and any word the pocketsphinx dictionary lacks ("woodcutters"), are pronounced by
espeak-ng, whose text normalisation speaks numbers and whose letter-to-sound rules pronounce any
word; its phones (:data:`ESPEAK_EN_TO_ARPABET`) are added to the aligner's dictionary. "20"
was dropped before, so the mouth rested while "twenty" was said; one unknown word failed the run.
What espeak-ng reads badly is written out first as `facecast say` does
(:func:`realtime_core.synthesis.text.normalise_for_speech`: "$5.50" was "dollar five point five zero", "9:00"
"nine zero zero"; now "five dollars and fifty cents", "nine o'clock").

Without a transcript, :func:`recognise_phones` runs the same decoder in its **allphone** mode: the
phones themselves are recognised, with the acoustic model (trained on many US-English talkers) and
the phone bigram language model the wheel ships (``en-us-phone.lm.bin``), in one pass.

Transcripts are found next to the audio: ``<stem>.txt`` or an LJ Speech style
``metadata.csv`` (``id|text|normalised text``) in the same folder.
"""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import numpy as np

from assets.audio import to_int16
from realtime_core.features.mfcc import loudness_db
from realtime_core.features.resample import resample_audio
from realtime_core.synthesis.text import normalise_for_speech
from realtime_core.synthesis.visemes import viseme_of
from training.alignments import Alignment, Phone
from training.errors import AlignmentFormatError, MissingDependencyError

FRAME_S = 0.01
"""pocketsphinx's frame period: alignment times are multiples of 10 ms."""

FAST_FRAME_RATE_HZ = 200
"""Frames a second of the second try, when the phones of fast speech do not fit 10 ms frames (see force_align)."""

SPEECH_BELOW_PEAK_DB = 25.0
"""A frame is speech when its level is within this of the recording's loud frames (95th percentile)."""


ALLPHONE_LM_WEIGHT = 2.0
"""Weight of the phone bigram language model against the acoustic scores in :func:`recognise_phones`
(pocketsphinx's phoneme-recognition recipe: ``-lw 2.0`` with the wide beams below; its word-decoding
default, 6.5, lets the bigram override what is heard)."""

ALLPHONE_BEAM = 1e-20
"""Beam and phone beam of the allphone search (the recipe's: every phone hypothesis is kept)."""


def _decoder_class():
    try:
        from pocketsphinx import Decoder  # lazy: optional extra "align"
    except ImportError as exc:
        raise MissingDependencyError(
            "forced alignment and phone recognition need pocketsphinx: pip install 'facecast[align]'"
        ) from exc
    return Decoder


def _pcm16k(samples: np.ndarray, rate_hz: int) -> bytes:
    """``samples`` ((n,) float in [-1, 1] at ``rate_hz``) as pocketsphinx reads them: 16 kHz 16-bit little-endian."""
    return to_int16(resample_audio(np.asarray(samples, dtype=np.float64), rate_hz, 16000)).astype("<i2").tobytes()


ESPEAK_EN_TO_ARPABET: dict[str, str] = {
    # consonants (espeak's t#/d#/t2/t[ are its variants of /t d/; x only in loans: "loch")
    "p": "P", "b": "B", "m": "M", "f": "F", "v": "V", "T": "TH", "D": "DH",
    "t": "T", "t#": "T", "t2": "T", "t[": "T", "d": "D", "d#": "D", "d[": "D",
    "n": "N", "l": "L", "l/": "L", "s": "S", "z": "Z", "S": "SH", "Z": "ZH", "tS": "CH", "dZ": "JH",
    "k": "K", "g": "G", "N": "NG", "x": "K", "h": "HH", "r": "R", "r-": "R", "w": "W", "w#": "W", "j": "Y",
    # syllabic consonants: the dictionary writes a schwa before them ("button" B AH T AH N)
    "n-": "AH N", "@L": "AH L",
    # vowels; r-coloured ones as the dictionary writes them ("near" N IH R, "sure" SH UH R)
    "i:": "IY", "i": "IY", "I": "IH", "I2": "IH", "I#": "IH", "i@": "IH R", "i@3": "IH R", "IR": "IH R",
    "e": "EH", "E": "EH", "e@": "EH R", "a": "AE", "aa": "AE", "a#": "AH",
    "A:": "AA", "A@": "AA R", "0": "AA", "VR": "ER",
    "@": "AH", "@2": "AH", "@5": "AH", "@-": "AH", "V": "AH", "3": "ER", "3:": "ER",
    "O:": "AO", "O2": "AO", "O@": "AO R", "o@": "AO R",
    "u:": "UW", "U": "UH", "U@": "UH R",
    "eI": "EY", "aI": "AY", "aI2": "AY", "aI@": "AY ER", "aI3": "AY ER", "aU": "AW", "oU": "OW", "@U": "OW",
    "OI": "OY",
}  # fmt: skip
"""espeak-ng's US-English phones (its ``en-us`` voice's phoneme events) as pocketsphinx's ARPAbet:
one phone or a space-separated few. espeak's pauses (``_``, ``_:``), links (``;``) and glottal stop
(``?``, which the dictionary never writes) carry no phone of their own and are left out."""

_SILENT_ESPEAK = frozenset({"_", "_:", "_!", "_^_", ";", "?"})

_WORD = re.compile(r"[a-z']+")
_ABBREVIATION = re.compile(r"[A-Z][a-z]{0,3}\.")
"""A capitalised short word with a full stop ("Dr.", "Mr.", "St."): followed by more words, an
abbreviation, which espeak-ng reads ("Dr. Smith": "doctor"; the dictionary's "dr" is "drive")."""


def _fold(text: str) -> str:
    """Accents folded (NFKD without its combining marks: "naïve" -> "naive", "ﬁ" -> "fi"), quotes plain."""
    decomposed = unicodedata.normalize("NFKD", text.replace("’", "'").replace("‘", "'"))
    return "".join(c for c in decomposed if not unicodedata.combining(c))


def normalise_transcript(text: str) -> list[str]:
    """The transcript's spoken tokens, lower case: words without punctuation (apostrophes kept:
    "don't"; accents folded: "café" -> "cafe"; "well-known" -> "well", "known"), and as written
    what espeak-ng must read ("20", "3rd", "$5", "50%", "1,000", "&", "u.s.", a mid-sentence "dr.")."""
    raw = _fold(text).split()
    tokens: list[str] = []
    for k, chunk in enumerate(raw):
        bare = re.sub(r"^\W+", "", chunk)  # opening quotes and brackets
        if _ABBREVIATION.fullmatch(bare) and k + 1 < len(raw):
            tokens.append(bare.lower())
            continue
        for part in re.split(r"[-\u2013\u2014/]+", chunk.lower()):
            # keep what is spoken of the edges: currency before a number, % after, a dot inside "u.s."
            part = re.sub(r"^[^\w$£€¥&+#@]+|[^\w%&+]+$", "", part).strip("'")
            if not part:
                continue
            if _WORD.fullmatch(part):
                tokens.append(part)
            elif re.fullmatch(r"(?:[a-z]\.)+[a-z]?", part):  # initials: "u.s", "e.g"
                tokens.append(part + ".")
            elif re.search(r"[\w$£€¥&+#@%]", part):
                tokens.append(part)
    return tokens


def espeak_pronunciation(token: str) -> str | None:
    """ARPAbet phones (space-separated) of ``token`` as espeak-ng's US-English voice says it (numbers,
    symbols and abbreviations read out, unknown words by its letter-to-sound rules); None when it says
    nothing or a phone :data:`ESPEAK_EN_TO_ARPABET` lacks."""
    from assets.espeak import Voice, synthesizer

    phones: list[str] = []
    for seg in synthesizer().synthesize(token, Voice(language="en", base="en-us"), noise_seed=0).phonemes:
        if seg.phoneme in _SILENT_ESPEAK:
            continue
        if seg.phoneme not in ESPEAK_EN_TO_ARPABET:
            return None
        for phone in ESPEAK_EN_TO_ARPABET[seg.phoneme].split():
            # an r-coloured vowel before espeak's linking /r/ ("zero" z'i@roU): one R, as the dictionary has it
            if not (phone == "R" and phones[-1:] == ["R"]):
                phones.append(phone)
    return " ".join(phones) or None


def force_align(
    samples: np.ndarray, rate_hz: int, text: str, *, source: str | Path = "<audio>", day_first: bool | None = None
) -> Alignment:
    """ARPAbet phones of ``text`` in ``samples`` ((n,) float in [-1, 1] at ``rate_hz``).

    Words outside the dictionary, numbers and symbols are pronounced by espeak-ng (module doc). ``day_first``: how
    the transcript's "07/12/2026" was read (:func:`realtime_core.synthesis.text.normalise_for_speech`; None: month
    first, as a US English talker, whom pocketsphinx's model is of).
    Raises MissingDependencyError without pocketsphinx, AlignmentFormatError (naming
    ``source``) when a token has no pronunciation or the alignment fails.
    """
    Decoder = _decoder_class()
    # what `facecast say` writes out before espeak-ng reads it ("$5.50" "5 dollars and 50 cents", "9:00" "9 o'clock"),
    # so a take of `say`'s own speech aligns with its transcript, and a person's reading is matched as said
    words = normalise_transcript(normalise_for_speech(text, language="en", day_first=day_first))
    if not words:
        raise AlignmentFormatError(source, "empty transcript")
    pcm = _pcm16k(samples, rate_hz)
    decoder = Decoder(samprate=16000, bestpath=False, loglevel="FATAL")
    # Words the dictionary lacks, and what only espeak-ng reads (numbers, symbols, abbreviations), get its phones.
    spoken = {
        w: espeak_pronunciation(w) for w in sorted(set(words)) if not _WORD.fullmatch(w) or not decoder.lookup_word(w)
    }
    unpronounced = sorted(w for w, ph in spoken.items() if ph is None)
    if unpronounced:
        raise AlignmentFormatError(
            source, f"cannot align: no pronunciation for {unpronounced}: spell them out in the transcript"
        )
    guessed = f" (pronounced by espeak-ng: {sorted(spoken)})" if spoken else ""
    # Each phone takes at least its three HMM states, a frame each: 30 ms at pocketsphinx's 100 frames a second.
    # Fast speech (espeak-ng at its default 175 words a minute: /b/ 20 ms) has no such path, and the phone pass
    # fails ("Failed to set up sub-word alignment"); at FAST_FRAME_RATE_HZ (5 ms frames) it aligns, the acoustic
    # model's features taken at twice their rate (the shared LibriVox / LJ Speech clips align at 100 as before).
    for frame_rate in (round(1 / FRAME_S), FAST_FRAME_RATE_HZ):
        try:
            if frame_rate == FAST_FRAME_RATE_HZ:
                decoder = Decoder(samprate=16000, bestpath=False, loglevel="FATAL", frate=frame_rate)
            for word, phones_of_word in spoken.items():
                decoder.add_word(word, phones_of_word, True)
            decoder.set_align_text(" ".join(words))
            for second_pass in (False, True):
                if second_pass:
                    decoder.set_alignment()
                decoder.start_utt()
                decoder.process_raw(pcm, full_utt=True)
                decoder.end_utt()
            break
        except RuntimeError as exc:  # pocketsphinx found no path through the transcript
            if frame_rate == FAST_FRAME_RATE_HZ:
                raise AlignmentFormatError(
                    source, f"the transcript could not be aligned to the audio ({exc}){guessed}"
                ) from None
    phones: list[Phone] = []
    for word in decoder.get_alignment():
        for ph in word:
            start = ph.start / frame_rate
            phones.append(Phone(ph.name, start, start + ph.duration / frame_rate))
    if not phones:
        raise AlignmentFormatError(source, "pocketsphinx found no alignment for the transcript")
    return Alignment(tuple(phones), "arpabet", Path(source))


def recognise_phones(
    samples: np.ndarray,
    rate_hz: int,
    *,
    lm_weight: float = ALLPHONE_LM_WEIGHT,
    source: str | Path = "<audio>",
) -> Alignment:
    """ARPAbet phones recognised in ``samples`` ((n,) float in [-1, 1] at ``rate_hz``) without a transcript:
    pocketsphinx's allphone search (the shipped US-English acoustic model and phone bigram, ``lm_weight``
    its language-model weight). A timeline of contiguous phones from 0 s to the last 10 ms frame, pauses
    ``SIL``; its noise fillers (``+NSN+`` and the like, when they appear) are pauses too, since they carry no
    articulation. Raises MissingDependencyError without pocketsphinx, AlignmentFormatError (naming
    ``source``) when nothing was recognised (e.g. no audio)."""
    import os

    Decoder = _decoder_class()  # first: without pocketsphinx, the error that says how to install it
    import pocketsphinx

    phone_lm = os.path.join(pocketsphinx.get_model_path(), "en-us", "en-us-phone.lm.bin")
    decoder = Decoder(
        samprate=16000,
        allphone=phone_lm,
        lw=lm_weight,
        beam=ALLPHONE_BEAM,
        pbeam=ALLPHONE_BEAM,
        bestpath=False,
        loglevel="FATAL",
    )
    decoder.start_utt()
    decoder.process_raw(_pcm16k(samples, rate_hz), full_utt=True)
    decoder.end_utt()
    phones: list[Phone] = []
    for seg in decoder.seg():  # end_frame is the segment's last frame, inclusive
        name = "SIL" if seg.word.startswith(("+", "<")) else seg.word
        start, end = seg.start_frame * FRAME_S, (seg.end_frame + 1) * FRAME_S
        if phones and phones[-1].phoneme == name == "SIL":  # two fillers in a row: one pause
            phones[-1] = Phone("SIL", phones[-1].start_s, end)
        else:
            phones.append(Phone(name, start, end))
    if not phones:
        raise AlignmentFormatError(source, "pocketsphinx recognised no phones in the audio")
    return Alignment(tuple(phones), "arpabet", Path(source))


def find_transcripts(root: str | Path) -> dict[Path, str]:
    """{wav: transcript} for the WAVs under ``root`` that have a transcript (``<stem>.txt`` or
    a ``metadata.csv`` entry in their folder)."""
    out: dict[Path, str] = {}
    root = Path(root)
    for meta in sorted(root.rglob("metadata.csv")):
        for line in meta.read_text(encoding="utf-8", errors="replace").splitlines():
            parts = line.split("|")
            if len(parts) >= 2:
                wav = meta.with_name(parts[0] + ".wav")
                if wav.is_file():
                    out[wav] = parts[-1]
    for txt in sorted(root.rglob("*.txt")):
        wav = txt.with_suffix(".wav")
        if wav.is_file() and wav not in out:
            out[wav] = txt.read_text(encoding="utf-8", errors="replace").strip()
    return out


def speech_in_pauses_s(samples: np.ndarray, rate_hz: int, alignment: Alignment) -> tuple[float, float]:
    """``(speech_s, in_pauses_s)``: seconds of speech in the recording (30 fps frames within
    :data:`SPEECH_BELOW_PEAK_DB` of its 95th-percentile level, :func:`loudness_db`) and how many of them the
    alignment puts in its pauses. pocketsphinx aligns any transcript, matching or not, and pads the rest
    with silence: on the shared LibriVox and LJ Speech clips with their own transcripts 0.0-0.3 s (0-11 %)
    of the speech fell in pauses; with another clip's transcript, or one word, 3.5-6.0 s (55-93 %)."""
    n = int(len(samples) * 30 / rate_hz)
    if n == 0:
        return 0.0, 0.0
    level = loudness_db(samples, rate_hz, n)
    speech = level > np.percentile(level, 95) - SPEECH_BELOW_PEAK_DB
    pause = np.zeros(n, dtype=bool)
    for ph in alignment.phones:
        if viseme_of(ph.phoneme, alignment.inventory, default="sil") == "sil":
            pause[int(round(ph.start_s * 30)) : int(round(ph.end_s * 30))] = True
    return float(speech.sum() / 30), float((speech & pause).sum() / 30)
