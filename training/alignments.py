"""Readers for real speech with phone alignments, and discovery of (audio, alignment) pairs.

Formats (all return a list of :class:`Phone` in seconds, sorted, with the inventory of their
labels, so :mod:`training.articulatory` can label them by the same rules as espeak speech):

* HTS / ARCTIC ``.lab``: ``start end label`` per line, times in 100 ns units; the label is a
  full-context string ``a^b-PHONE+c=d@...`` (the current phone sits between ``-`` and ``+``)
  or a plain phone. ARPAbet, lower case (``pau``/``sil`` = silence).
* Praat TextGrid (long or short text format, UTF-8 or UTF-16): the first interval tier whose
  name contains "phone" (else the only interval tier). Labels are ARPAbet (``AA1``) or IPA
  (``ə``): the inventory is detected from the labels.
* pocketsphinx / LibriVox ``*.phone.json``: ``{"b": begin_s, "d": duration_s, "t": text,
  "w": [...]}`` nested utterance -> words -> phones; ARPAbet upper case, ``SIL`` silence.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

from realtime_core.phones import PhonemeSegment
from training.errors import AlignmentFormatError

HTS_UNIT_S = 1e-7
"""HTS label time unit: 100 ns."""


Phone = PhonemeSegment  # the shared timeline type (training.params)


@dataclass(frozen=True)
class Alignment:
    """Phones of one recording; ``inventory`` is "arpabet" or "ipa"."""

    phones: tuple[Phone, ...]
    inventory: str
    path: Path


_HTS_CENTRE = re.compile(r"-([^+]+)\+")


def read_hts_lab(path: str | Path) -> Alignment:
    """ARCTIC/HTS phone labels (times in 100 ns units)."""
    path = Path(path)
    phones: list[Phone] = []
    for n, line in enumerate(_read_text(path).splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) < 3 or not (parts[0].isdigit() and parts[1].isdigit()):
            raise AlignmentFormatError(
                path, f"line {n}: expected 'start end label' with integer 100 ns times, got {line!r}"
            )
        m = _HTS_CENTRE.search(parts[2])
        label = m.group(1) if m else parts[2]
        phones.append(Phone(label, int(parts[0]) * HTS_UNIT_S, int(parts[1]) * HTS_UNIT_S))
    if not phones:
        raise AlignmentFormatError(path, "no phone labels")
    return Alignment(tuple(phones), "arpabet", path)


def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise AlignmentFormatError(path, f"cannot be read ({exc.strerror or exc})") from exc
    for enc in ("utf-8-sig", "utf-16"):
        try:
            return data.decode(enc)
        except UnicodeDecodeError:
            continue
    raise AlignmentFormatError(path, "not UTF-8/UTF-16 text")


_TG_TOKEN = re.compile(r'"((?:[^"]|"")*)"|([-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)|<exists>')


def read_textgrid(path: str | Path) -> Alignment:
    """The phone tier of a Praat TextGrid (long or short format)."""
    path = Path(path)
    text = _read_text(path)
    # Both formats are the same token stream once the "key =" decorations are dropped:
    # strings and numbers in order. Parse that stream.
    body = re.sub(r"^\s*[A-Za-z_\[\] 0-9?]*=\s*", "", text, flags=re.M)  # long format: keys
    body = re.sub(r"^\s*(item|intervals|points) \[\d*\]:\s*$", "", body, flags=re.M)
    tokens: list[str | float] = []
    for m in _TG_TOKEN.finditer(body):
        if m.group(1) is not None:
            tokens.append(m.group(1).replace('""', '"'))
        elif m.group(2) is not None:
            tokens.append(float(m.group(2)))
    try:
        if tokens[:2] != ["ooTextFile", "TextGrid"]:
            raise AlignmentFormatError(path, "not a TextGrid (missing 'ooTextFile' / 'TextGrid' header)")
        i = 4  # skip header strings, xmin, xmax
        n_tiers = int(tokens[i])
        i += 1
        tiers: list[tuple[str, str, list[Phone]]] = []
        for _ in range(n_tiers):
            cls, name = str(tokens[i]), str(tokens[i + 1])
            count = int(tokens[i + 4])
            i += 5
            items: list[Phone] = []
            if cls == "IntervalTier":
                for _ in range(count):
                    items.append(Phone(str(tokens[i + 2]).strip(), float(tokens[i]), float(tokens[i + 1])))
                    i += 3
            else:
                i += 2 * count
            tiers.append((cls, name, items))
    except (IndexError, ValueError, TypeError) as exc:
        raise AlignmentFormatError(path, f"malformed TextGrid ({exc})") from exc
    intervals = [t for t in tiers if t[0] == "IntervalTier"]
    chosen = [t for t in intervals if "phone" in t[1].lower()] or (intervals if len(intervals) == 1 else [])
    if not chosen:
        raise AlignmentFormatError(path, f"no phone tier (tiers: {[t[1] for t in tiers]})")
    phones = chosen[0][2]
    labels = [p.phoneme for p in phones if p.phoneme]
    if not labels:
        raise AlignmentFormatError(path, "the phone tier has no labels")
    arpabet = all(re.fullmatch(r"[A-Za-z]{1,3}[0-2]?|sil|sp|spn|<sil>", lab) for lab in labels) and any(
        lab.isupper() for lab in labels
    )
    return Alignment(tuple(phones), "arpabet" if arpabet else "ipa", path)


def read_phone_json(path: str | Path) -> Alignment:
    """pocketsphinx-style nested alignment JSON (utterance -> words -> phones)."""
    path = Path(path)
    try:
        doc = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise AlignmentFormatError(path, f"not valid JSON ({exc})") from exc
    phones: list[Phone] = []
    try:
        for word in doc["w"]:
            for ph in word.get("w", []):
                b, d = float(ph["b"]), float(ph["d"])
                phones.append(Phone(str(ph["t"]), b, b + d))
    except (KeyError, TypeError, ValueError) as exc:
        raise AlignmentFormatError(path, f"expected nested {{'b','d','t','w'}} words and phones ({exc})") from exc
    if not phones:
        raise AlignmentFormatError(path, "no phones")
    return Alignment(tuple(phones), "arpabet", path)


def read_alignment(path: str | Path) -> Alignment:
    """Dispatch on the file name: ``.lab``, ``.TextGrid``, ``.phone.json``."""
    p = Path(path)
    name = p.name.lower()
    if name.endswith(".phone.json"):
        return read_phone_json(p)
    if name.endswith(".textgrid"):
        return read_textgrid(p)
    if name.endswith(".lab"):
        return read_hts_lab(p)
    raise AlignmentFormatError(p, "unknown alignment format (want .lab, .TextGrid or .phone.json)")


def _audio_for(align: Path) -> Path | None:
    """The WAV an alignment file belongs to: same stem, minus ``_phone(s)``/``.phone``."""
    name = align.name
    for suffix in (".phone.json", ".TextGrid", ".textgrid", ".lab"):
        if name.endswith(suffix):
            stem = name[: -len(suffix)]
            break
    else:
        return None
    for cand in (stem, re.sub(r"_(phone|phones)$", "", stem)):
        wav = align.with_name(cand + ".wav")
        if wav.is_file():
            return wav
    return None


def find_aligned_audio(
    root: str | Path, *, skipped: list[tuple[Path, str]] | None = None
) -> list[tuple[Path, Alignment]]:
    """All (wav, phone alignment) pairs under ``root``, sorted by wav path.

    Files that are not phone alignments (word-only TextGrids, voice-activity .lab files) are
    skipped; a WAV with several usable alignments uses the first by name. ``skipped``, when given,
    receives ``(wav, "ALIGNMENT: problem")`` for each WAV none of whose alignment files could be read.
    """
    root = Path(root)
    pairs: dict[Path, Alignment] = {}
    problems: dict[Path, str] = {}  # wav -> the first alignment problem, reported if no alignment works
    for f in sorted(p for p in root.rglob("*") if p.is_file()):
        n = f.name.lower()
        if not (n.endswith(".lab") or n.endswith(".textgrid") or n.endswith(".phone.json")):
            continue
        wav = _audio_for(f)
        if wav is None or wav in pairs:
            continue
        try:
            pairs[wav] = read_alignment(f)
        except AlignmentFormatError as exc:  # e.g. a word tier or a VAD label file next to the phone alignment
            problems.setdefault(wav, f"{f.name}: {exc.problem}")
    if skipped is not None:
        skipped += [(wav, why) for wav, why in sorted(problems.items()) if wav not in pairs]
    return sorted(pairs.items(), key=lambda kv: str(kv[0]))


def phones_from_words(words, *, voice, spellings: dict[str, str] | None = None) -> tuple[Phone, ...]:
    """An approximate phone alignment from a word alignment: espeak-ng's phonemes of each word
    (its own pauses dropped) stretched linearly over the word's interval.

    words: [(start_s, end_s, word)]; "sil"/"sp"/"" words become a "_" pause.
    voice: a :class:`assets.espeak.Voice` (its language picks the espeak inventory).
    spellings: how to say a word (e.g. GRID's letter "p" -> "pee").
    Returns espeak-inventory phones (``inventory = f"espeak-{voice.language}"``).
    """
    from assets.espeak import synthesizer

    synth = synthesizer()
    out: list[Phone] = []
    for a, b, w in words:
        if w.lower() in ("sil", "sp", "") or b <= a:
            out.append(Phone("_", a, b))
            continue
        text = (spellings or {}).get(w, w)
        ph = [p for p in synth.synthesize(text, voice).phonemes if not p.phoneme.startswith("_")]
        if not ph:
            out.append(Phone("_", a, b))
            continue
        t0, t1 = ph[0].start_s, ph[-1].end_s
        scale = (b - a) / (t1 - t0)
        out += [Phone(p.phoneme, a + (p.start_s - t0) * scale, a + (p.end_s - t0) * scale) for p in ph]
    return tuple(out)
