"""Phone labels for the GRID s1 corpus: ARPAbet phone boundaries inside the corpus's word spans.

How each sentence is labelled
-----------------------------
GRID ships word alignments (``assets.grid.read_words``). Its vocabulary is closed (51 words),
so every word has one pronunciation, fixed here in :data:`PRONUNCIATIONS` (CMUdict as shipped
with pocketsphinx, except the letters A = ``EY`` and Z = ``Z EH D``, as the British talker says
them). Then:

1. ``pocketsphinx``: the sentence's speech region (GRID's first word start - 0.15 s to last word
   end + 0.15 s, 16 kHz) is force-aligned with those pronunciations by pocketsphinx's US-English
   acoustic model (10 ms frames, at least 3 frames per phone; the front end is reset for every
   sentence so results do not depend on the order). Each word's phones are then placed inside
   its **GRID** word span (:func:`_place_word`): the aligner's word span is mapped linearly onto
   the GRID span, so the phones tile the GRID words exactly. Next to a pause, silence of 60 ms or
   more that the aligner finds inside GRID's span becomes a SIL phone (GRID's own spans
   sometimes start in the leading silence), and a first phone stretched into the silence is cut
   at GRID's edge. Each sentence records the largest remaining word-edge disagreement.
2. ``spread`` (fallback per word): a word whose aligned edges still differ from GRID's by more
   than 0.1 s, or every word of a sentence the aligner cannot align, gets its pronunciation
   spread over its span with fixed relative durations (vowels twice a consonant). The fallback
   uses the dictionary pronunciation rather than espeak-ng's phonemes so that the whole corpus
   keeps one phone set (espeak's inventory would need a lossy mapping to ARPAbet).

``sil``/``sp`` words become ``SIL`` phones over their span. Each sentence records its method:
``pocketsphinx`` (every word aligned), ``pocketsphinx+spread`` (some words spread; they are
listed) or ``spread`` (no audio, pocketsphinx unavailable or failed).

Phone set: ARPAbet as in CMUdict without stress digits, upper case, plus ``SIL``: the
``arpabet`` inventory of :mod:`training.articulatory` (which lower-cases and strips stress).

File: ``assets/data/grid_s1_phones.json`` (written by ``facecast phones``), read with
:func:`read_grid_phones`. The GRID corpus is CC BY 4.0 (Cooke, Barker, Cunningham, Shao 2006);
the file carries that credit.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from assets.files import atomic_write_bytes
from assets.grid import SILENCE_WORDS, GridSentence, read_words
from training.alignments import Alignment, Phone
from training.errors import AlignmentFormatError, ConfigError, MissingDependencyError

FORMAT = "facecast-grid-phones/1"
PHONE_SET = "arpabet"
SILENCE = "SIL"
ALIGN_RATE_HZ = 16000
FRAME_S = 0.01
"""pocketsphinx's frame period (10 ms)."""
EDGE_SILENCE_MIN_S = 0.06
"""Silence the aligner finds at a word's edge next to a pause is labelled SIL from this length on."""
MAX_WORD_OFFSET_S = 0.1
"""A word whose aligned edges differ from GRID's by more than this (after edge silence) is spread."""
PAUSE_MIN_S = 0.1
"""A GRID 'sp' this long or longer counts as a pause for the edge-silence rule."""
MIN_PHONE_S = 0.02
"""Cutting a phone at GRID's word edge must leave it at least this long."""
ALIGN_PAD_S = 0.15
"""Audio aligned around the speech: GRID's first word start - pad .. last word end + pad."""

HMM_METHOD_TEXT = (
    "hmm: monophone HMMs (3 states, diagonal Gaussians) trained on this talker's own MFCCs (train+val "
    "sentences) by embedded Baum-Welch from a flat start inside GRID's word spans, then Viterbi-aligned "
    "over each whole sentence (optional short pauses between words, word edges within 0.1 s of GRID's; "
    "silence where the aligner finds it). See training/phone_hmm.py."
)

CREDIT = (
    "GRID audio-visual sentence corpus, talker s1: M. Cooke, J. Barker, S. Cunningham, X. Shao, "
    "'An audio-visual corpus for speech perception and automatic speech recognition', "
    "J. Acoust. Soc. Am. 120(5), 2006, 2421-2424. CC BY 4.0."
)

DEFAULT_PATH = Path(__file__).resolve().parents[1] / "assets" / "data" / "grid_s1_phones.json"
HMM_PATH = DEFAULT_PATH.with_name("grid_s1_phones_hmm.json")
"""The same sentences labelled by this talker's own HMMs (``facecast phones --method hmm``,
:mod:`training.phone_hmm`): what the unit-selection corpus and its evaluation use by default
(chosen on the val split, docs/unit_selection.md); every other consumer reads DEFAULT_PATH."""


def default_path(method: str) -> Path:
    """The shipped labels file of a labelling ``method`` ("pocketsphinx" or "hmm"), which ``facecast phones``
    writes without ``-o``: the HMM labels have a file of their own, so relabelling one way never replaces the
    other's labels (whose readers differ: unit selection reads HMM_PATH, everything else DEFAULT_PATH)."""
    return HMM_PATH if method == "hmm" else DEFAULT_PATH


PRONUNCIATIONS: dict[str, tuple[str, ...]] = {
    w: tuple(p.split())
    for w, p in {
        # commands, colours, prepositions, adverbs
        "bin": "B IH N",
        "lay": "L EY",
        "place": "P L EY S",
        "set": "S EH T",
        "blue": "B L UW",
        "green": "G R IY N",
        "red": "R EH D",
        "white": "W AY T",
        "at": "AE T",
        "by": "B AY",
        "in": "IH N",
        "with": "W IH DH",
        "again": "AH G EH N",
        "now": "N AW",
        "please": "P L IY Z",
        "soon": "S UW N",
        # digits
        "zero": "Z IH R OW",
        "one": "W AH N",
        "two": "T UW",
        "three": "TH R IY",
        "four": "F AO R",
        "five": "F AY V",
        "six": "S IH K S",
        "seven": "S EH V AH N",
        "eight": "EY T",
        "nine": "N AY N",
        # letters (no W in GRID); A and Z as the British talker says them
        "a": "EY",
        "b": "B IY",
        "c": "S IY",
        "d": "D IY",
        "e": "IY",
        "f": "EH F",
        "g": "JH IY",
        "h": "EY CH",
        "i": "AY",
        "j": "JH EY",
        "k": "K EY",
        "l": "EH L",
        "m": "EH M",
        "n": "EH N",
        "o": "OW",
        "p": "P IY",
        "q": "K Y UW",
        "r": "AA R",
        "s": "EH S",
        "t": "T IY",
        "u": "Y UW",
        "v": "V IY",
        "x": "EH K S",
        "y": "W AY",
        "z": "Z EH D",
    }.items()
}
"""Every GRID word -> its ARPAbet phones (CMUdict via pocketsphinx; letters A and Z British)."""

VOWELS = frozenset(["AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW"])
BILABIALS = frozenset({"P", "B", "M"})
_SPREAD_WEIGHT_VOWEL = 2.0
"""In the spread fallback a vowel gets twice a consonant's share of the word (GRID s1's aligned
vowels are about twice as long as its consonants)."""


@dataclass(frozen=True, kw_only=True)
class SentencePhones:
    """Phones of one sentence: ``phones`` tile [first word start, last word end]."""

    sentence_id: str
    phones: tuple[Phone, ...]
    method: str
    spread_words: tuple[str, ...] = ()
    edge_silences: int = 0
    """How many SIL phones the aligner found inside word spans (at their edges)."""
    max_word_offset_s: float | None = None
    """Largest difference between a word edge of the aligner and of GRID (None: not aligned)."""


def pronunciation(word: str, *, source: str | Path = "<grid>") -> tuple[str, ...]:
    """ARPAbet phones of one GRID word; AlignmentFormatError naming ``source`` for other words."""
    try:
        return PRONUNCIATIONS[word.lower()]
    except KeyError:
        raise AlignmentFormatError(source, f"word {word!r} is not in the GRID vocabulary") from None


def spread(pron: Iterable[str], start_s: float, end_s: float) -> list[Phone]:
    """``pron`` over [start_s, end_s]: vowels weigh twice a consonant; the phones tile the span."""
    pron = list(pron)
    w = np.array([_SPREAD_WEIGHT_VOWEL if p in VOWELS else 1.0 for p in pron])
    edges = start_s + (end_s - start_s) * np.concatenate([[0.0], np.cumsum(w) / w.sum()])
    edges[-1] = end_s
    return [Phone(p, float(edges[i]), float(edges[i + 1])) for i, p in enumerate(pron)]


class SentenceAligner:
    """pocketsphinx forced alignment of a whole GRID sentence with the fixed pronunciations."""

    def __init__(self) -> None:
        try:
            from pocketsphinx import Decoder  # lazy: optional extra "align"
        except ImportError as exc:
            raise MissingDependencyError(
                "GRID phone alignment needs pocketsphinx: pip install 'facecast[align]'"
            ) from exc
        self._decoder = Decoder(samprate=ALIGN_RATE_HZ, bestpath=False, loglevel="FATAL")
        # Private dictionary entries so the aligner uses exactly PRONUNCIATIONS (no alternates).
        last = len(PRONUNCIATIONS) - 1
        for i, (word, phones) in enumerate(PRONUNCIATIONS.items()):
            self._decoder.add_word(self._entry(word), " ".join(phones), i == last)  # last one updates the search

    @staticmethod
    def _entry(word: str) -> str:
        return f"grid_{word}"

    def align(self, pcm16: np.ndarray, words: list[str]) -> list[tuple[str, list[tuple[str, int, int]]]] | None:
        """[(word, [(phone, start frame, n frames)])] for ``words`` (silence dropped) in ``pcm16``
        ((n,) int16 at 16 kHz), or None when pocketsphinx finds no alignment."""
        d = self._decoder
        # The feature front end keeps its cepstral-mean state across utterances, which makes a
        # result depend on what was aligned before; a reset makes every sentence stand alone.
        d.reinit_feat()
        try:
            d.set_align_text(" ".join(self._entry(w) for w in words))
            for second_pass in (False, True):
                if second_pass:
                    d.set_alignment()
                d.start_utt()
                d.process_raw(pcm16.astype("<i2").tobytes(), full_utt=True)
                d.end_utt()
            got = [(w.name, [(ph.name, ph.start, ph.duration) for ph in w]) for w in d.get_alignment() or ()]
        except RuntimeError:
            return None
        got = [(name[len("grid_") :], phones) for name, phones in got if name.startswith("grid_")]
        if [w for w, _ in got] != list(words) or any(
            [p for p, _, _ in phones] != list(PRONUNCIATIONS[w]) for w, phones in got
        ):
            return None
        return got


def _place_word(
    aligned: list[tuple[str, int, int]], a0: float, a1: float, *, lead_silence: bool, trail_silence: bool
) -> tuple[list[Phone], float]:
    """One word's aligned phones (frames) placed to tile its GRID span [a0, a1] (seconds).

    At an edge next to a pause (sil/sp or the recording's edge):
    * the aligner's word starts (ends) EDGE_SILENCE_MIN_S or more inside the GRID span: that part
      is SIL (GRID's spans sometimes start in the leading silence: 'bbwt1a' has "bin" from
      0.03 s, speech from about 0.6 s);
    * the aligner's word starts before GRID's (it stretched the first phone into the silence):
      that phone is cut at GRID's edge.
    Then the aligner's word span is mapped linearly onto what remains of the GRID span, keeping
    the phones' proportions. Returns the phones and the larger edge disagreement left (s).
    """
    s0 = aligned[0][1] * FRAME_S
    s1 = (aligned[-1][1] + aligned[-1][2]) * FRAME_S
    inner = [st * FRAME_S for _, st, _ in aligned[1:]]
    t0, t1 = a0, a1
    lead = trail = False
    if lead_silence:
        if s0 - a0 >= EDGE_SILENCE_MIN_S:
            t0 = s0
            lead = True
        elif s0 < a0 and (not inner or inner[0] > a0 + MIN_PHONE_S):
            s0 = a0
    if trail_silence:
        if a1 - s1 >= EDGE_SILENCE_MIN_S:
            t1 = s1
            trail = True
        elif s1 > a1 and (not inner or inner[-1] < a1 - MIN_PHONE_S):
            s1 = a1
    scale = (t1 - t0) / (s1 - s0)
    edges = [t0] + [t0 + (b - s0) * scale for b in inner] + [t1]
    out = [Phone(p, edges[i], edges[i + 1]) for i, (p, _, _) in enumerate(aligned)]
    if lead:
        out.insert(0, Phone(SILENCE, a0, t0))
    if trail:
        out.append(Phone(SILENCE, t1, a1))
    return out, max(abs(s0 - t0), abs(s1 - t1))


def label_sentence(
    sentence_id: str,
    words: list[tuple[float, float, str]],
    samples_16k: np.ndarray | None,
    aligner: SentenceAligner | None,
    *,
    source: str | Path = "<grid>",
) -> SentencePhones:
    """Phones of one sentence from its word alignment and (optional) 16 kHz audio ((n,) float in [-1, 1]).

    Without audio or aligner, or when the alignment fails, every word is spread. Raises
    AlignmentFormatError for an unknown word or a word alignment that is not contiguous.
    """
    if not words:
        raise AlignmentFormatError(source, "empty word alignment")
    for (a0, a1, w), nxt in zip(words, [*words[1:], None]):
        if not a1 > a0:
            raise AlignmentFormatError(source, f"word {w!r} has end {a1:.3f} s <= start {a0:.3f} s")
        if nxt is not None and abs(nxt[0] - a1) > 1e-6:
            raise AlignmentFormatError(source, f"gap or overlap between {w!r} and {nxt[2]!r} at {a1:.3f} s")
    speech = [w.lower() for _, _, w in words if w not in SILENCE_WORDS]
    for w in speech:
        pronunciation(w, source=source)
    aligned = None
    if samples_16k is not None and aligner is not None and speech:
        # Align the speech region only (GRID's first/last word edges +- ALIGN_PAD_S): with seconds of
        # leading silence the aligner sometimes skips its optional silence and stretches the first
        # phone over it ('bbaf4p': a 0.7 s /B/).
        first = next(a for a, _, w in words if w not in SILENCE_WORDS)
        last = max(b for _, b, w in words if w not in SILENCE_WORDS)
        f0 = max(0, round((first - ALIGN_PAD_S) / FRAME_S))
        f1 = round((last + ALIGN_PAD_S) / FRAME_S)
        x = np.asarray(samples_16k, np.float64)[f0 * ALIGN_RATE_HZ // 100 : f1 * ALIGN_RATE_HZ // 100]
        pcm = np.clip(np.round(x * 32767.0), -32768, 32767).astype(np.int16)
        got = aligner.align(pcm, speech)
        if got is not None:
            aligned = [(w, [(p, st + f0, n) for p, st, n in phones]) for w, phones in got]
    # pause[i + 1]: word i is a real pause: 'sil', or an 'sp' of PAUSE_MIN_S or more (GRID's short 'sp'
    # of 10-30 ms mostly mark a stop's closure, e.g. "eight sp please", not a pause)
    pause = [True] + [w == "sil" or (w in SILENCE_WORDS and b - a >= PAUSE_MIN_S) for a, b, w in words] + [True]
    phones: list[Phone] = []
    disagreement: list[float] = []
    spread_words: list[str] = []
    k = 0
    for i, (a0, a1, w) in enumerate(words):
        if w in SILENCE_WORDS:
            phones.append(Phone(SILENCE, a0, a1))
            continue
        placed = None
        if aligned is not None:
            placed, off = _place_word(aligned[k][1], a0, a1, lead_silence=pause[i], trail_silence=pause[i + 2])
            if off > MAX_WORD_OFFSET_S:
                placed = None  # the aligner put this word elsewhere: its phone proportions are not trusted
            else:
                disagreement.append(off)
        if placed is None:
            placed = spread(PRONUNCIATIONS[w.lower()], a0, a1)
            spread_words.append(w)
        phones += placed
        k += 1
    n_sil_words = sum(w in SILENCE_WORDS for _, _, w in words)
    method = "spread" if not disagreement else "pocketsphinx+spread" if spread_words else "pocketsphinx"
    return SentencePhones(
        sentence_id=sentence_id,
        phones=tuple(phones),
        method=method,
        spread_words=tuple(spread_words),
        edge_silences=sum(p.phoneme == SILENCE for p in phones) - n_sil_words,
        max_word_offset_s=round(max(disagreement), 3) if disagreement else None,
    )


# ----------------------------------------------------------------------------- corpus build
_WORKER: SentenceAligner | None = None


def _init_worker(use_aligner: bool) -> None:
    global _WORKER
    _WORKER = SentenceAligner() if use_aligner else None


def _label_one(s: GridSentence) -> SentencePhones | tuple[str, str]:
    from training.errors import FileProblem
    from training.video import decode_audio

    try:
        words = read_words(s.align)
        samples = decode_audio(s.video, ALIGN_RATE_HZ) if _WORKER is not None else None
        return label_sentence(s.sentence_id, words, samples, _WORKER, source=s.align)
    except (FileProblem, OSError, ValueError) as exc:
        return (str(s.align), str(exc))


METHODS = ("pocketsphinx", "hmm")
"""How :func:`label_corpus` labels: ``pocketsphinx`` (above) or ``hmm``: this talker's own monophone
HMMs by embedded re-estimation (:mod:`training.phone_hmm`; word edges free within 0.1 s of GRID's,
silence where the aligner finds it)."""


def label_corpus(
    sents: list[GridSentence],
    *,
    workers: int = 2,
    align: bool = True,
    progress: Callable | None = None,
    method: str = "pocketsphinx",
    say: Callable[[str], None] = lambda _: None,
) -> tuple[list[SentencePhones], list[tuple[str, str]]]:
    """Label every sentence (``workers`` processes). Returns (labelled, skipped [(file, reason)]).

    method: one of :data:`METHODS` (``align=False`` spreads every word whatever the method)."""
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    if method not in METHODS:
        raise ConfigError(f"method must be one of {METHODS}, got {method!r}")
    if method == "hmm" and align:
        from training.phone_hmm import PhoneHmmConfig, grid_features, label_grid_corpus

        config = PhoneHmmConfig()
        data, unread = grid_features(sents, config=config, workers=workers, progress=progress)
        labelled, failed, _ = label_grid_corpus(data, config=config, progress=progress, say=say)
        return labelled, unread + failed
    if align:
        SentenceAligner()  # fail early and clearly when pocketsphinx is missing
    wrap = progress or (lambda it, **_: it)
    done: list[SentencePhones] = []
    skipped: list[tuple[str, str]] = []
    with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker, initargs=(align,)) as pool:
        for res in wrap(pool.map(_label_one, sents, chunksize=8), total=len(sents), desc="phones", unit="sentence"):
            (skipped.append(res) if isinstance(res, tuple) else done.append(res))
    return done, skipped


def write_grid_phones(path: str | Path, labelled: list[SentencePhones]) -> Path:
    """One JSON file: a header (format, phone set, method, credit) and per sentence its method
    and ``[[start_s, end_s, phone], ...]`` (times rounded to 0.1 ms). Written atomically."""
    hmm = bool(labelled) and all(s.method == "hmm" for s in labelled)
    header = {
        "format": FORMAT,
        "phone_set": "ARPAbet (CMUdict, no stress digits, upper case) plus SIL for silence",
        "method": HMM_METHOD_TEXT
        if hmm
        else "pocketsphinx 5.1.1 forced alignment (en-us model) of the sentence with the fixed "
        "pronunciations; each word's phones mapped linearly onto its GRID word span, so phones tile the "
        "GRID word spans exactly; next to a pause, aligned silence of 60 ms or more inside a GRID span is "
        "SIL. Fallback 'spread' (per word whose aligned edges differ from GRID's by > 0.1 s, or per "
        "sentence when alignment fails): the pronunciation spread over the span (vowel 2 : consonant 1). "
        "See training/grid_phones.py.",
        "times": "seconds from the start of the recording",
        "credit": CREDIT,
        "pronunciations": {w: " ".join(p) for w, p in sorted(PRONUNCIATIONS.items())},
    }
    lines = ["{", f'"header": {json.dumps(header)},', '"sentences": {']
    items = sorted(labelled, key=lambda s: s.sentence_id)
    for i, s in enumerate(items):
        entry: dict[str, object] = {
            "method": s.method,
            "phones": [[round(p.start_s, 4), round(p.end_s, 4), p.phoneme] for p in s.phones],
        }
        if s.spread_words:
            entry["spread_words"] = list(s.spread_words)
        if s.max_word_offset_s is not None:
            entry["max_word_offset_s"] = s.max_word_offset_s
        if s.edge_silences:
            entry["edge_silences"] = s.edge_silences
        lines.append(
            f"{json.dumps(s.sentence_id)}: {json.dumps(entry, separators=(',', ':'))}"
            + ("," if i < len(items) - 1 else "")
        )
    lines += ["}", "}", ""]
    return atomic_write_bytes(path, "\n".join(lines).encode("utf-8"))


def read_grid_phones_file(path: str | Path | None = None) -> dict[str, SentencePhones]:
    """Every sentence of a GRID phones file (default: the shipped one) with its method."""
    path = Path(path) if path is not None else DEFAULT_PATH
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise AlignmentFormatError(path, f"cannot be read ({exc.strerror or exc})") from exc
    except json.JSONDecodeError as exc:
        raise AlignmentFormatError(path, f"not valid JSON ({exc})") from exc
    if not isinstance(doc, dict) or doc.get("header", {}).get("format") != FORMAT:
        raise AlignmentFormatError(path, f"not a GRID phones file (expected header.format {FORMAT!r})")
    out: dict[str, SentencePhones] = {}
    try:
        for sid, entry in doc["sentences"].items():
            phones = tuple(Phone(str(p), float(a), float(b)) for a, b, p in entry["phones"])
            out[sid] = SentencePhones(
                sentence_id=sid,
                phones=phones,
                method=str(entry["method"]),
                spread_words=tuple(entry.get("spread_words", ())),
                edge_silences=int(entry.get("edge_silences", 0)),
                max_word_offset_s=entry.get("max_word_offset_s"),
            )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise AlignmentFormatError(path, f"malformed sentence entry ({exc})") from exc
    return out


def read_grid_phones(path: str | Path | None = None) -> dict[str, Alignment]:
    """{sentence id: Alignment} (ARPAbet ``PhonemeSegment`` timelines, inventory "arpabet")."""
    path = Path(path) if path is not None else DEFAULT_PATH
    return {sid: Alignment(s.phones, PHONE_SET, path) for sid, s in read_grid_phones_file(path).items()}


# ----------------------------------------------------------------------------- validation
@dataclass(frozen=True, kw_only=True)
class PhoneCheck:
    """What :func:`check_sentence` found: problems (empty = fine) and per-phone durations."""

    problems: tuple[str, ...]
    durations: tuple[tuple[str, float], ...]


def check_sentence(
    phones: tuple[Phone, ...], words: list[tuple[float, float, str]], *, tol_s: float = 1e-3
) -> PhoneCheck:
    """Phones tile every word span exactly (within ``tol_s``), in the word's pronunciation order
    (so /P B M/ are where the words have them; SIL allowed at a word's edges), and no phone is
    shorter than 5 ms."""
    problems: list[str] = []
    durations: list[tuple[str, float]] = []
    for a0, a1, w in words:
        inside = [p for p in phones if p.start_s >= a0 - tol_s and p.end_s <= a1 + tol_s]
        want = [SILENCE] if w in SILENCE_WORDS else list(PRONUNCIATIONS.get(w.lower(), ()))
        labels = [p.phoneme for p in inside]
        if w not in SILENCE_WORDS:  # silence found at a word's edge is allowed (see _place_word)
            labels = labels[1:] if labels[:1] == [SILENCE] else labels
            labels = labels[:-1] if labels[-1:] == [SILENCE] else labels
        if labels != want:
            problems.append(f"{w} [{a0:.3f}, {a1:.3f}]: phones {[p.phoneme for p in inside]} != {want}")
            continue
        if abs(inside[0].start_s - a0) > tol_s or abs(inside[-1].end_s - a1) > tol_s:
            problems.append(f"{w}: phones do not start/end at the word's edges")
        for p, q in itertools.pairwise(inside):
            if abs(p.end_s - q.start_s) > tol_s:
                problems.append(f"{w}: gap between {p.phoneme} and {q.phoneme}")
        for p in inside:
            if p.end_s - p.start_s < 0.005:
                problems.append(f"{w}: {p.phoneme} lasts {1000 * (p.end_s - p.start_s):.1f} ms")
            if p.phoneme != SILENCE:
                durations.append((p.phoneme, p.end_s - p.start_s))
    return PhoneCheck(problems=tuple(problems), durations=tuple(durations))


def check_free_sentence(
    phones: tuple[Phone, ...], words: list[tuple[float, float, str]], *, slack_s: float = 0.1, tol_s: float = 1e-6
) -> PhoneCheck:
    """For labels whose word edges are free (method ``hmm``): the speech phones are the words'
    pronunciations in order (SIL anywhere between words), contiguous from 0 s, each word within
    ``slack_s`` of its GRID span, and no phone shorter than 5 ms."""
    problems: list[str] = []
    durations: list[tuple[str, float]] = []
    spoken = [(a, b, w) for a, b, w in words if w not in SILENCE_WORDS]
    want = [p for _, _, w in spoken for p in PRONUNCIATIONS.get(w.lower(), ())]
    speech = [p for p in phones if p.phoneme != SILENCE]
    if [p.phoneme for p in speech] != want:
        problems.append(f"phones {[p.phoneme for p in speech]} != {want}")
        return PhoneCheck(problems=tuple(problems), durations=())
    if phones and abs(phones[0].start_s) > tol_s:
        problems.append(f"first phone starts at {phones[0].start_s:.3f} s, not 0")
    for p, q in itertools.pairwise(phones):
        if abs(p.end_s - q.start_s) > tol_s:
            problems.append(f"gap between {p.phoneme} and {q.phoneme} at {p.end_s:.3f} s")
    k = 0
    for a0, a1, w in spoken:
        n = len(PRONUNCIATIONS[w.lower()])
        mine = speech[k : k + n]
        k += n
        if mine[0].start_s < a0 - slack_s - tol_s or mine[-1].end_s > a1 + slack_s + tol_s:
            problems.append(
                f"{w}: [{mine[0].start_s:.3f}, {mine[-1].end_s:.3f}] outside GRID's [{a0:.3f}, {a1:.3f}] +- {slack_s} s"
            )
    for p in phones:
        if p.end_s - p.start_s < 0.005:
            problems.append(f"{p.phoneme} at {p.start_s:.3f} s lasts {1000 * (p.end_s - p.start_s):.1f} ms")
        if p.phoneme != SILENCE:
            durations.append((p.phoneme, p.end_s - p.start_s))
    return PhoneCheck(problems=tuple(problems), durations=tuple(durations))


def save_phone_plot(
    samples: np.ndarray,
    rate_hz: int,
    words: list[tuple[float, float, str]],
    phones: tuple[Phone, ...],
    png: str | Path,
    *,
    title: str = "",
) -> Path:
    """PNG: waveform with the word spans above and the phones below (bilabials in red)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    png = Path(png)
    t = np.arange(len(samples)) / rate_hz
    fig, (ax, axw, axp) = plt.subplots(3, 1, figsize=(12, 5), sharex=True, gridspec_kw={"height_ratios": [3, 0.6, 0.6]})
    ax.plot(t, samples, lw=0.4, color="k")
    ax.set_ylabel("waveform")
    ax.set_title(title)
    for axis, items in (
        (axw, [(a, b, w) for a, b, w in words]),
        (axp, [(p.start_s, p.end_s, p.phoneme) for p in phones]),
    ):
        for a, b, label in items:
            bil = label in BILABIALS
            axis.axvspan(
                a,
                b,
                color="tab:red" if bil else ("0.92" if label in (SILENCE, "sil", "sp") else "0.8"),
                alpha=0.5 if bil else 1.0,
                ec="k",
                lw=0.5,
            )
            axis.text(
                0.5 * (a + b),
                0.5,
                label,
                ha="center",
                va="center",
                fontsize=8 if axis is axp else 10,
                color="darkred" if bil else "k",
                clip_on=True,
            )
            ax.axvline(a, color="tab:blue" if axis is axw else "0.7", lw=0.8 if axis is axw else 0.4, ls=":")
        axis.set_yticks([])
    axw.set_ylabel("words", rotation=0, ha="right")
    axp.set_ylabel("phones", rotation=0, ha="right")
    axp.set_xlabel("time (s)")
    speech = [w for w in words if w[2] not in SILENCE_WORDS]
    if speech:
        ax.set_xlim(speech[0][0] - 0.15, speech[-1][1] + 0.15)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return png
