"""Teacher labels: synthetic speech in many voices labelled with GRID s1's real lips by unit selection.

Issue 10's hard problem is other voices, and the only real-lip training data is one talker (s1). Unit
selection over s1's recorded motion (:class:`realtime_core.synthesis.synthesizer.UnitSynthesizer`, the path
of ``facecast say`` and the server's text sessions) turns a phone sequence with exact timings into s1-like
real lips: a *teacher*. Synthetic speech comes with exact phone timings in as many voices, pitches and rates
as wanted (espeak-ng phoneme events, :mod:`assets.espeak`; Festival's segments, :mod:`training.festival`),
so each utterance gets the four mouth parameters of the s1 targets' definitions, and a readout fitted on it
sees many vocal tracts mapped to real-lip motion.

- :func:`train_synthesizer`: the unit synthesizer of the s1 **train** split only (the cached corpus of
  ``facecast units build`` holds train + val; val sentences must never be units of a label that a val score
  is compared with).
- :func:`teacher_params`: phones -> ``(n_frames, 4)`` through ``UnitSynthesizer.synthesize`` (the same call
  as ``facecast say``), with the pauses at rest for synthetic speech (no in-breath in it).
- :func:`espeak_clips`, :func:`festival_clips`: GRID-grammar sentences spoken by spread voices and rates,
  ``[(name, TeacherClip, bilabial spans)]`` as :func:`training.readout.trace_clips` takes them.
- :func:`teacher_clips`: a :class:`TeacherConfig`'s clips, made once and cached (``$FACECAST_CACHE/teacher``,
  keyed by the config, the unit corpus and :data:`TEACHER_VERSION`), for ``facecast readout`` and
  ``facecast train`` alike; :func:`teacher_utterances` turns them into HMM training utterances.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.synthesis.rest import RestPauses
from realtime_core.synthesis.synthesizer import UnitSynthesizer
from training.corpus import Utterance
from training.errors import ConfigError
from training.params import n_frames_for

TEACHER_VERSION = 1
"""Part of the teacher clips' cache key: bump it when the same config would make different clips (voices,
levels, padding, labelling), so cached clips are made again."""

GRID_WORDS: tuple[tuple[str, ...], ...] = (
    ("bin", "lay", "place", "set"),
    ("blue", "green", "red", "white"),
    ("at", "by", "in", "with"),
    tuple("abcdefghijklmnopqrstuvxyz"),  # GRID's letters: no "w"
    ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine"),
    ("again", "now", "please", "soon"),
)
"""GRID's six-slot command grammar (Cooke et al. 2006): the sentences s1's units were recorded in."""

ESPEAK_BASES: tuple[str, ...] = ("en-us", "en", "en-gb-scotland", "en-gb-x-rp", "en-029", "en-us-nyc")
ESPEAK_VARIANTS: tuple[str | None, ...] = (None, "m1", "m2", "m3", "m4", "m5", "m6", "m7", "f1", "f2", "f3", "f4", "f5")
ESPEAK_RATES_WPM = (130, 230)
ESPEAK_PITCH = (25, 80)
FESTIVAL_STRETCH = (0.8, 1.35)
LEVEL_DBFS = (-24.0, -15.0)
"""Speech level of a teacher clip (mean dB of its 32 ms speech blocks), drawn uniformly: around GRID s1's
-18.8 dBFS (:data:`realtime_core.features.gain.S1_SPEECH_LEVEL_DBFS`), so the clips do not teach a level."""


@dataclass(frozen=True)
class TeacherClip:
    """What :func:`training.readout.trace_clips` reads of a clip: samples ``(n,)`` float32 in [-1, 1] at
    ``sample_rate_hz``, params ``(T, 4)`` the teacher's mouth parameters at 30 fps (``VISUAL_PARAMS``); and
    what they were labelled from: phones ``((label, start_s, end_s), ...)`` of ``inventory`` on the samples'
    clock."""

    samples: np.ndarray
    sample_rate_hz: int
    params: np.ndarray
    phones: tuple[tuple[str, float, float], ...] = ()
    inventory: str = "arpabet"


@dataclass(frozen=True, kw_only=True)
class TeacherConfig:
    """Synthetic utterances for the readout's fit: espeak / festival (how many of each), seed (texts, voices,
    rates, levels), n_best (unit sequences averaged per label, :meth:`UnitSynthesizer.synthesize`)."""

    espeak: int = 0
    festival: int = 0
    seed: int = 0
    n_best: int = 5

    def __post_init__(self) -> None:
        if self.espeak < 0 or self.festival < 0 or self.n_best < 1:
            raise ConfigError(f"invalid teacher config {self}: counts >= 0, n_best >= 1")

    def as_json(self) -> dict:
        return {"espeak": self.espeak, "festival": self.festival, "seed": self.seed, "n_best": self.n_best}


def grid_texts(n: int, rng: np.random.Generator) -> list[str]:
    """``n`` GRID-grammar sentences, each word drawn uniformly from its slot."""
    return [" ".join(str(rng.choice(slot)) for slot in GRID_WORDS) for _ in range(n)]


def train_synthesizer(
    root: str | Path | None = None, *, cache_dir: str | Path | None = None, say: Callable[[str], None] = print
) -> UnitSynthesizer:
    """The unit synthesizer of the GRID s1 train split (the talker-specific HMM phone labels, as
    ``facecast units build``; built once, cached under ``$FACECAST_CACHE/unitsel``)."""
    return _train_synthesizer(root, cache_dir=cache_dir, say=say)[0]


def _train_synthesizer(
    root: str | Path | None, *, cache_dir: str | Path | None, say: Callable[[str], None]
) -> tuple[UnitSynthesizer, Path]:
    """:func:`train_synthesizer` and its unit corpus's cache file (whose name carries the corpus's key)."""
    from assets import grid
    from training.grid_phones import HMM_PATH, read_grid_phones
    from training.unit_corpus import build_grid_corpus

    sents = grid.sentences(root, split="train")
    stored, path = build_grid_corpus(sents, read_grid_phones(HMM_PATH), cache_dir=cache_dir, say=say)
    return UnitSynthesizer(stored.corpus, rest=stored.rest_frame()), path


def teacher_params(
    synth: UnitSynthesizer,
    phones: Sequence[tuple[str, float, float]],
    inventory: str,
    n_frames: int,
    *,
    n_best: int = 5,
    rest_pauses: RestPauses | None = RestPauses(),
) -> np.ndarray:
    """``(n_frames, 4)`` mouth parameters (``VISUAL_PARAMS``) of s1's recorded lips for ``phones``
    ``[(label, start_s, end_s)]`` of ``inventory``. rest_pauses: synthetic speech's pauses eased to the rest
    pose (as ``facecast say``); None for phones aligned on a real recording (its in-breath is real)."""
    res = synth.synthesize(list(phones), inventory, n_frames=n_frames, n_best=n_best, rest_pauses=rest_pauses)
    names = synth.corpus.dim_names
    return res.frames[:, [names.index(p) for p in VISUAL_PARAMS]]


def set_level(x: np.ndarray, rate_hz: int, level_dbfs: float) -> np.ndarray:
    """``x`` scaled so the mean dB of its speech blocks (32 ms blocks within 30 dB of the loudest) is
    ``level_dbfs``; float32, clipped to [-1, 1]."""
    x = np.asarray(x, dtype=np.float64)
    n = max(1, int(0.032 * rate_hz))
    blocks = x[: len(x) // n * n].reshape(-1, n)
    if not len(blocks):
        return x.astype(np.float32)
    db = 10 * np.log10(np.mean(blocks**2, axis=1) + 1e-12)
    speech = db[db > db.max() - 30]
    return np.clip(x * 10 ** ((level_dbfs - speech.mean()) / 20), -1, 1).astype(np.float32)


def _bilabials(phones: Sequence[tuple[str, float, float]]) -> list:
    from realtime_core.phones import PhonemeSegment
    from training.reallips import phone_bilabial_spans

    return phone_bilabial_spans([PhonemeSegment(lab, a, b) for lab, a, b in phones])


def espeak_clips(
    synth: UnitSynthesizer, n: int, *, seed: int = 0, n_best: int = 5, progress: Callable | None = None
) -> list:
    """``n`` GRID-grammar sentences spoken by espeak-ng voices (``ESPEAK_BASES`` x ``ESPEAK_VARIANTS``, rate,
    pitch and level drawn per utterance, padded as ``facecast say`` pads), labelled by the teacher:
    ``[(name, TeacherClip, bilabial spans)]``."""
    from assets.espeak import Voice
    from assets.espeak import synthesizer as espeak
    from assets.tts import INVENTORY, Speech

    wrap = progress or (lambda it, **_: it)
    out = []
    for i in wrap(range(n), desc="teacher espeak", unit="utt"):
        # one stream per utterance: the first k of an n-utterance set are the k-utterance set
        rng = np.random.default_rng([seed, i])
        text = grid_texts(1, rng)[0]
        voice = Voice(
            language="en",
            base=str(rng.choice(ESPEAK_BASES)),
            variant=ESPEAK_VARIANTS[int(rng.integers(len(ESPEAK_VARIANTS)))],
            rate_wpm=int(rng.integers(*ESPEAK_RATES_WPM)),
            pitch=int(rng.integers(*ESPEAK_PITCH)),
        )
        syn = espeak().synthesize(text, voice, noise_seed=seed + i)
        speech = Speech(
            samples=syn.samples.astype(np.float32) / 32768.0,
            sample_rate_hz=syn.sample_rate_hz,
            phones=tuple((p.phoneme, p.start_s, p.end_s) for p in syn.phonemes),
            inventory=INVENTORY["en"],
            text=text,
        ).padded()
        x = set_level(speech.samples, speech.sample_rate_hz, float(rng.uniform(*LEVEL_DBFS)))
        params = teacher_params(synth, speech.phones, speech.inventory, n_frames_for(speech.duration_s), n_best=n_best)
        name = f"teacher-espeak-{i:05d}-{voice.label}"
        clip = TeacherClip(x, speech.sample_rate_hz, params, speech.phones, speech.inventory)
        out.append((name, clip, _bilabials(speech.phones)))
    return out


def padded_phones(phones: Sequence[tuple[str, float, float]], end_s: float, pause: str = "pau") -> list:
    """Festival's phones shifted into padded audio ``[0, end_s)``: its own leading and trailing ``pause``
    stretched to take the added silence (one pause at each end, which the synthesizer eases to rest), or a
    pause added where it has none."""
    rows = list(phones)
    if rows and rows[0][0] == pause:
        rows[0] = (pause, 0.0, rows[0][2])
    elif rows:
        rows.insert(0, (pause, 0.0, rows[0][1]))
    else:
        return [(pause, 0.0, end_s)]
    if rows[-1][0] == pause:
        rows[-1] = (pause, rows[-1][1], end_s)
    else:
        rows.append((pause, rows[-1][2], end_s))
    return [(str(lab), float(a), float(b)) for lab, a, b in rows]


def festival_clips(
    synth: UnitSynthesizer,
    n: int,
    *,
    seed: int = 0,
    n_best: int = 5,
    batch: int = 50,
    progress: Callable | None = None,
) -> list:
    """``n`` GRID-grammar sentences spoken by Festival's voices (:data:`training.festival.VOICES`, a duration
    stretch and level drawn per batch of ``batch``; 0.2 s of silence before and 0.25 s after, as espeak's
    clips), labelled by the teacher: ``[(name, TeacherClip, bilabial spans)]``."""
    from assets.tts import END_PAUSE_S, LEAD_PAUSE_S
    from training.festival import VOICES, FestivalVoice, synthesize_batch

    wrap = progress or (lambda it, **_: it)
    out = []
    for b0 in wrap(range(0, n, batch), desc="teacher festival", unit="batch"):
        # one stream per batch: the first batches of a larger set are the smaller set
        rng = np.random.default_rng([seed, b0 // batch])
        voice = FestivalVoice(name=VOICES[(b0 // batch) % len(VOICES)], stretch=float(rng.uniform(*FESTIVAL_STRETCH)))
        texts = grid_texts(min(batch, n - b0), rng)
        for k, (samples, rate, segs) in enumerate(synthesize_batch(texts, voice)):
            n0, n1 = int(round(LEAD_PAUSE_S * rate)), int(round(END_PAUSE_S * rate))
            x = np.concatenate([np.zeros(n0), np.asarray(samples, np.float64), np.zeros(n1)])
            lead, end = n0 / rate, len(x) / rate
            phones = padded_phones([(p.phoneme, p.start_s + lead, p.end_s + lead) for p in segs], end)
            x = set_level(x, rate, float(rng.uniform(*LEVEL_DBFS)))
            params = teacher_params(synth, phones, "arpabet", n_frames_for(len(x) / rate), n_best=n_best)
            name = f"teacher-festival-{b0 + k:05d}-{voice.label}"
            out.append((name, TeacherClip(x, rate, params, tuple(phones), "arpabet"), _bilabials(phones)))
    return out


def teacher_clips(
    config: TeacherConfig,
    root: str | Path | None = None,
    *,
    cache_dir: str | Path | None = None,
    progress: Callable | None = None,
    say: Callable[[str], None] = print,
) -> list:
    """``config``'s teacher clips: ``config.espeak`` espeak-ng utterances (seed ``config.seed``) then
    ``config.festival`` Festival ones (seed ``config.seed + 1``), labelled over the GRID s1 train split under
    ``root`` (:func:`train_synthesizer`); [] when both counts are 0 (no corpus is built). Made once and
    cached beside the unit corpus (:func:`teacher_cache_path`), so ``facecast train`` and ``facecast
    readout`` with the same options read the same clips."""
    if not config.espeak and not config.festival:
        return []
    synth, corpus_path = _train_synthesizer(root, cache_dir=cache_dir, say=say)
    path = teacher_cache_path(config, corpus_path)
    if path.is_file():
        return load_clips(path)
    out = espeak_clips(synth, config.espeak, seed=config.seed, n_best=config.n_best, progress=progress)
    if config.festival:
        more = festival_clips(synth, config.festival, seed=config.seed + 1, n_best=config.n_best, progress=progress)
        out += more
    save_clips(path, out)
    say(f"teacher: {len(out)} clips, {sum(len(c[1].params) for c in out)} frames -> {path}")
    return out


def teacher_cache_path(config: TeacherConfig, corpus_path: Path) -> Path:
    """Where ``config``'s clips labelled over the unit corpus ``corpus_path`` are cached: ``teacher/`` beside
    the corpus's ``unitsel/`` folder, named by a hash of the config, the corpus file's name (which holds its
    key: the sentences, phones and extraction it was built from) and :data:`TEACHER_VERSION`."""
    import hashlib
    import json

    blob = json.dumps({"v": TEACHER_VERSION, "config": config.as_json(), "corpus": corpus_path.name}, sort_keys=True)
    key = hashlib.sha1(blob.encode()).hexdigest()[:16]
    return corpus_path.parent.parent / "teacher" / f"teacher-{config.espeak}e{config.festival}f-{key}.npz"


def teacher_utterances(clips: Sequence) -> list[Utterance]:
    """Teacher clips as HMM training utterances (source "teacher", one speaker group per engine): the audio as
    synthesised, the teacher's four parameters at 30 fps as the visual targets."""
    out = []
    for name, clip, _ in clips:
        engine = "festival" if name.startswith("teacher-festival") else "espeak"
        out.append(
            Utterance(
                id=name,
                samples=np.asarray(clip.samples, dtype=np.float32),
                sample_rate_hz=clip.sample_rate_hz,
                params=np.asarray(clip.params, dtype=np.float64),
                phonemes=(),
                voice=name,
                language="en",
                source="teacher",
                speaker_group=f"teacher:{engine}",
            )
        )
    return out


def save_clips(path: str | Path, clips: Sequence) -> Path:
    """Teacher clips to one ``.npz`` (no pickle; written atomically): audio, rate, labels and phones per clip."""
    from assets.heads.cache import atomic_savez

    arrays: dict[str, np.ndarray] = {"names": np.array([c[0] for c in clips])}
    for i, (_, clip, spans) in enumerate(clips):
        arrays[f"x{i}"] = clip.samples
        # float64 as made: clips read from the cache fit exactly as freshly made ones
        arrays[f"p{i}"] = np.asarray(clip.params, dtype=np.float64)
        arrays[f"r{i}"] = np.array([clip.sample_rate_hz])
        arrays[f"l{i}"] = np.array([clip.inventory] + [lab for lab, _, _ in clip.phones])
        arrays[f"t{i}"] = np.array([(a, b) for _, a, b in clip.phones], dtype=np.float64).reshape(-1, 2)
        arrays[f"s{i}"] = np.array([(a, b) for a, b, _ in spans], dtype=np.float64).reshape(-1, 2)
    return atomic_savez(path, **arrays)


def load_clips(path: str | Path) -> list:
    """The clips of :func:`save_clips` (the bilabial spans' labels are not kept: "p")."""
    out = []
    with np.load(path, allow_pickle=False) as z:
        for i, name in enumerate(str(n) for n in z["names"]):
            labels = [str(v) for v in z[f"l{i}"]]
            phones = tuple((lab, float(a), float(b)) for lab, (a, b) in zip(labels[1:], z[f"t{i}"], strict=True))
            clip = TeacherClip(z[f"x{i}"], int(z[f"r{i}"][0]), z[f"p{i}"].astype(np.float64), phones, labels[0])
            out.append((name, clip, [(float(a), float(b), "p") for a, b in z[f"s{i}"]]))
    return out
