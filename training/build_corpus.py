"""Build a training corpus: synthesise with espeak-ng, label by the articulatory rules,
augment like a microphone, and write the corpus layout (:mod:`training.corpus`).

Reproducibility: every random draw of utterance ``i`` comes from
``numpy.random.default_rng([seed, i])`` (sentence order from ``[seed, language]``), and the
writers format numbers with fixed precision. espeak-ng is deterministic only from a freshly
loaded library (it keeps phoneme-list and wave-generator state across calls and draws noise from
libc ``rand()``): each synthesis runs in a child forked from a process that never synthesised
(:mod:`assets.espeak`), and ``rand()`` is seeded per utterance. The same :class:`BuildConfig`
thus writes byte-identical files, also when built twice in one process (since stop 47 every
utterance from a fresh state: corpora built before differ from today's after each worker's first).

Real speech (``real_dirs``): every (WAV, phone alignment) pair found under each folder (and,
with ``force_align``, every transcribed WAV aligned by pocketsphinx) is labelled by the same rules
and written with ``source = "real"`` and ``speaker_group`` = ``real:<folder name>``; it is never
augmented, so evaluation can use it as it was recorded.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from assets.audio import read_wav
from assets.errors import FileProblem
from assets.espeak import LANGUAGES, RATE_RANGE_WPM, VARIANTS, Voice, synthesizer
from training.alignments import find_aligned_audio
from training.articulatory import ArticulatoryConfig, render_params
from training.augment import AugmentConfig, augment
from training.corpus import write_manifest, write_utterance
from training.errors import ConfigError
from training.params import n_frames_for

SENTENCES_DIR = Path(__file__).parent / "sentences"


def load_sentences(language: str) -> list[str]:
    """The project's sentence list for ``language`` (``training/sentences/<lang>.txt``)."""
    path = SENTENCES_DIR / f"{language}.txt"
    if not path.is_file():
        raise ConfigError(f"no sentence list for language {language!r} ({path})")
    return [ln.strip() for ln in path.read_text(encoding="utf-8").splitlines() if ln.strip() and not ln.startswith("#")]


@dataclass(frozen=True)
class VoiceSampling:
    """How a voice is drawn per utterance (uniform over each list/range, inclusive)."""

    variants: tuple[str | None, ...] = (None, *VARIANTS)
    rate_wpm: tuple[int, int] = (130, 220)
    pitch: tuple[int, int] = (25, 75)
    pitch_range: tuple[int, int] = (30, 80)

    def __post_init__(self) -> None:
        if not self.variants:
            raise ConfigError("variants must name at least one variant (None = the base voice)")
        unknown = [v for v in self.variants if v is not None and v not in VARIANTS]
        if unknown:
            raise ConfigError(f"unknown espeak variants {unknown}; known: {VARIANTS} (or the base voice)")
        for name, lo_hi, allowed in (
            ("rate_wpm", self.rate_wpm, RATE_RANGE_WPM),
            ("pitch", self.pitch, (0, 100)),
            ("pitch_range", self.pitch_range, (0, 100)),
        ):
            if not allowed[0] <= lo_hi[0] <= lo_hi[1] <= allowed[1]:
                raise ConfigError(f"{name} range {lo_hi} must be (low, high) within {allowed}")

    def draw(self, language: str, rng: np.random.Generator) -> Voice:
        bases = LANGUAGES[language]
        return Voice(
            language=language,
            base=bases[int(rng.integers(len(bases)))],
            variant=self.variants[int(rng.integers(len(self.variants)))],
            rate_wpm=int(rng.integers(self.rate_wpm[0], self.rate_wpm[1] + 1)),
            pitch=int(rng.integers(self.pitch[0], self.pitch[1] + 1)),
            pitch_range=int(rng.integers(self.pitch_range[0], self.pitch_range[1] + 1)),
        )


@dataclass(frozen=True)
class BuildConfig:
    """What :func:`build_corpus` makes.

    out_dir:       corpus folder (created; existing utterance folders are overwritten).
    sentences:     synthetic utterances per language (sentences are reused, with other
                   voices, when this exceeds the list's length).
    languages:     language codes among ``LANGUAGES``.
    seed:          the one seed of every draw.
    augment:       apply :mod:`training.augment` to the synthetic utterances.
    real_dirs:     folders searched for real aligned speech (source "real").
    force_align:   also force-align transcribed WAVs without a phone alignment in
                   ``real_dirs`` with pocketsphinx (optional extra "align").
    """

    out_dir: Path
    sentences: int = 300
    languages: tuple[str, ...] = ("en", "es")
    seed: int = 0
    augment: bool = False
    real_dirs: tuple[Path, ...] = ()
    force_align: bool = False
    voices: VoiceSampling = field(default_factory=VoiceSampling)
    augmentation: AugmentConfig = field(default_factory=AugmentConfig)
    articulatory: ArticulatoryConfig = field(default_factory=ArticulatoryConfig)

    def __post_init__(self) -> None:
        if self.sentences < 0:
            raise ConfigError(f"sentences must be >= 0, got {self.sentences}")
        if not self.languages and not self.real_dirs:
            raise ConfigError("nothing to build: no languages and no real speech folders")
        for lang in self.languages:
            if lang not in LANGUAGES:
                raise ConfigError(f"unknown language {lang!r}; known: {sorted(LANGUAGES)}")
        for d in self.real_dirs:
            if not Path(d).is_dir():
                raise ConfigError(f"real speech folder {d} does not exist")
        if not 0 <= self.seed < 2**63:
            raise ConfigError(f"seed must be a non-negative integer, got {self.seed}")


@dataclass(frozen=True)
class BuildReport:
    manifest: Path
    n_utterances: int
    audio_s: float
    by_source: dict
    skipped: tuple[tuple[str, str], ...] = ()
    """(file, reason) of real recordings that could not be used."""


def _plan(cfg: BuildConfig) -> list[tuple[str, str]]:
    """(language, sentence) per synthetic utterance, in a seeded order per language."""
    plan: list[tuple[str, str]] = []
    for li, lang in enumerate(cfg.languages):
        lines = load_sentences(lang)
        order = np.random.default_rng([cfg.seed, 1000 + li]).permutation(len(lines))
        plan += [(lang, lines[order[k % len(lines)]]) for k in range(cfg.sentences)]
    return plan


def _synth_job(job: tuple[str, Voice, int]) -> tuple[np.ndarray, int, tuple]:
    """Worker-process side: (text, voice, noise seed) -> (int16 samples, rate, phonemes)."""
    text, voice, noise_seed = job
    syn = synthesizer().synthesize(text, voice, noise_seed=noise_seed)
    return syn.samples, syn.sample_rate_hz, syn.phonemes


def _write_synthetic(
    cfg: BuildConfig,
    out: Path,
    i: int,
    lang: str,
    text: str,
    voice: Voice,
    rng: np.random.Generator,
    pcm: np.ndarray,
    rate: int,
    phonemes: tuple,
) -> dict:
    """Label, optionally augment, and write synthetic utterance ``i``; returns its entry."""
    samples = pcm.astype(np.float32) / 32768.0
    extra: dict = {"text": text}
    if cfg.augment:
        aug = augment(samples, rate, rng, cfg.augmentation)
        samples, rate = aug.samples, aug.sample_rate_hz
        extra["augmentation"] = aug.info
    n = n_frames_for(len(samples) / rate)
    params = render_params(phonemes, n, inventory=f"espeak-{lang}", config=cfg.articulatory)
    return write_utterance(
        out,
        utt_id=f"{lang}-{i:05d}",
        samples=samples,
        sample_rate_hz=rate,
        params=params,
        phonemes=phonemes,
        language=lang,
        voice=voice.label,
        source="espeak",
        speaker_group=voice.espeak_name,
        extra=extra,
    )


def build_corpus(cfg: BuildConfig, *, progress: Callable | None = None) -> BuildReport:
    """Write the corpus described by ``cfg``; ``progress(iterable, total=, desc=)`` wraps loops
    (pass ``assets.progress.Progress`` for a bar). Returns counts for the caller to print."""
    wrap = progress or (lambda it, **_: it)
    out = Path(cfg.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    entries: list[dict] = []
    plan = _plan(cfg)
    rngs = [np.random.default_rng([cfg.seed, i]) for i in range(len(plan))]
    voices = [cfg.voices.draw(lang, rng) for (lang, _), rng in zip(plan, rngs)]
    jobs = [(text, v, int(rng.integers(2**31))) for (_, text), v, rng in zip(plan, voices, rngs)]
    with ExitStack() as stack:
        results: Iterable = ()
        if jobs:
            # A fresh espeak-ng per build (see the module doc); one worker: espeak is global.
            pool = stack.enter_context(ProcessPoolExecutor(max_workers=1, mp_context=get_context("spawn")))
            results = pool.map(_synth_job, jobs, chunksize=8)
        for i, ((lang, text), voice, rng, (pcm, rate, phonemes)) in enumerate(
            wrap(zip(plan, voices, rngs, results), total=len(plan), desc="synthesising", unit="utt")
        ):
            entries.append(_write_synthetic(cfg, out, i, lang, text, voice, rng, pcm, rate, phonemes))

    real: list[tuple[Path, Path, object]] = []
    transcribed: list[tuple[Path, Path, str]] = []
    unaligned: list[tuple[Path, str]] = []
    for d in cfg.real_dirs:
        pairs = find_aligned_audio(d, skipped=unaligned)
        real += [(Path(d), wav, al) for wav, al in pairs]
        if cfg.force_align:
            from training.force_align import find_transcripts

            have = {wav for wav, _ in pairs}
            transcribed += [(Path(d), wav, text) for wav, text in find_transcripts(d).items() if wav not in have]
    skipped: list[tuple[str, str]] = [(str(wav), why) for wav, why in unaligned]
    for root, wav, text in (
        wrap(transcribed, total=len(transcribed), desc="aligning", unit="utt") if transcribed else ()
    ):
        from training.force_align import force_align

        try:
            samples, rate = read_wav(wav)
            real.append((root, wav, force_align(samples, rate, text, source=wav)))
        except FileProblem as exc:  # an unreadable WAV, or no alignment
            skipped.append((str(wav), exc.problem))
    real.sort(key=lambda item: str(item[1]))
    n_real = 0  # utterance ids count the recordings used, so a skipped one leaves no gap
    # no bar for no real speech: `facecast corpus` without --real printed "aligning: 0utt" and "real speech: 0utt"
    for root, wav, al in wrap(real, total=len(real), desc="real speech", unit="utt") if real else ():
        try:
            samples, rate = read_wav(wav)
        except FileProblem as exc:  # one bad recording never aborts a build of hundreds
            skipped.append((str(wav), exc.problem))
            continue
        group = wav.relative_to(root).parts[0] if len(wav.relative_to(root).parts) > 1 else root.name
        params = render_params(
            al.phones, n_frames_for(len(samples) / rate), inventory=al.inventory, config=cfg.articulatory
        )
        entries.append(
            write_utterance(
                out,
                utt_id=f"real-{n_real:04d}-{wav.stem}",
                samples=samples,
                sample_rate_hz=rate,
                params=params,
                phonemes=al.phones,
                language="en",
                voice=f"real:{group}",
                source="real",
                speaker_group=f"real:{group}",
                extra={
                    "origin": str(wav.relative_to(root)),
                    "alignment": al.path.name if al.path != wav else "pocketsphinx forced alignment",
                },
            )
        )
        n_real += 1

    manifest = write_manifest(
        out,
        entries,
        seed=cfg.seed,
        extra={
            "builder": {
                "sentences": cfg.sentences,
                "languages": list(cfg.languages),
                "augment": cfg.augment,
                "lead_s": cfg.articulatory.lead_s,
            },
        },
    )
    by_source: dict = {}
    for e in entries:
        by_source[e["source"]] = by_source.get(e["source"], 0) + 1
    return BuildReport(manifest, len(entries), float(sum(e["duration_s"] for e in entries)), by_source, tuple(skipped))
