"""A second speech engine for training corpora: Festival (Debian packages), with phone timings.

Why: espeak-ng is a formant synthesiser; a model trained on it alone learns its spectra and
transfers poorly to human voices. Festival's diphone voices (``kal``, ``ked``: concatenated
recordings of real speakers) and its HTS voice (``cmu_us_slt_arctic_hts``, a statistical model
of a real speaker) sound much closer to human speech, which is the acoustic variety the model
needs. Festival reports every phone's end time (``utt.save.segs``), so the same articulatory
rules label it (ARPAbet-like "radio" phone set, inventory ``arpabet``).

Festival runs as a subprocess on a generated Scheme script, one process per batch of
sentences (its start-up costs about a second). English only.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from assets.audio import read_wav
from realtime_core.phones import PhonemeSegment
from training.articulatory import ArticulatoryConfig, render_params
from training.augment import AugmentConfig, augment
from training.corpus import write_manifest, write_utterance
from training.errors import ConfigError, SynthesisError
from training.params import n_frames_for

VOICES: tuple[str, ...] = ("kal_diphone", "ked_diphone", "cmu_us_slt_arctic_hts")
"""Festival voices of Debian's festvox-kallpc16k, festvox-kdlpc16k and festvox-us-slt-hts."""


@dataclass(frozen=True, kw_only=True)
class FestivalVoice:
    """name: one of :data:`VOICES`; stretch: duration factor (>1 = slower speech)."""

    name: str
    stretch: float = 1.0

    def __post_init__(self) -> None:
        if self.name not in VOICES:
            raise ConfigError(f"unknown Festival voice {self.name!r}; known: {VOICES}")
        if not 0.6 <= self.stretch <= 1.6:
            raise ConfigError(f"stretch must be in 0.6..1.6, got {self.stretch}")

    @property
    def label(self) -> str:
        return f"festival:{self.name}@x{self.stretch:.2f}"


def _scheme_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def read_segs(path: Path) -> list[PhonemeSegment]:
    """An ESPS label file from ``utt.save.segs`` -> phones with start/end seconds."""
    phones: list[PhonemeSegment] = []
    start = 0.0
    body = False
    for line in path.read_text().splitlines():
        if not body:
            body = line.strip() == "#"
            continue
        parts = line.split()
        if len(parts) < 3:
            continue
        end = float(parts[0])
        phones.append(PhonemeSegment(parts[2], start, end))
        start = end
    return phones


def synthesize_batch(texts: Sequence[str], voice: FestivalVoice) -> list[tuple[np.ndarray, int, list[PhonemeSegment]]]:
    """Speak each text: ``[(samples (n,) float32 in [-1, 1], rate_hz, phones)]`` in order."""
    exe = shutil.which("festival")
    if exe is None:
        raise SynthesisError("festival is not installed (apt-get install festival festvox-kallpc16k ...)")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        lines = [f"(voice_{voice.name})", f"(Parameter.set 'Duration_Stretch {voice.stretch:.3f})"]
        for i, text in enumerate(texts):
            lines.append(f"(set! utt (utt.synth (Utterance Text {_scheme_string(text)})))")
            lines.append(f'(utt.save.wave utt "{d}/{i}.wav" \'riff)')
            lines.append(f'(utt.save.segs utt "{d}/{i}.segs")')
        script = d / "batch.scm"
        script.write_text("\n".join(lines) + "\n")
        proc = subprocess.run([exe, "--batch", str(script)], capture_output=True, text=True, check=False)
        out = []
        for i in range(len(texts)):
            wav, segs = d / f"{i}.wav", d / f"{i}.segs"
            if not wav.is_file() or not segs.is_file():
                raise SynthesisError(
                    f"festival produced no audio for voice {voice.name} ({proc.stderr.strip()[-300:]})"
                )
            samples, rate = read_wav(wav)
            out.append((samples, rate, read_segs(segs)))
        return out


def build_festival_corpus(
    out_dir: Path,
    sentences: Sequence[str],
    *,
    seed: int,
    voices: Sequence[FestivalVoice],
    augment_audio: bool,
    articulatory: ArticulatoryConfig = ArticulatoryConfig(),
    augmentation: AugmentConfig = AugmentConfig(),
    progress: Callable | None = None,
) -> Path:
    """Every sentence spoken by one voice drawn per sentence (seeded); writes a corpus folder."""
    rng = np.random.default_rng(seed)
    picks = rng.integers(len(voices), size=len(sentences))
    entries = []
    jobs = [(v, [i for i in range(len(sentences)) if picks[i] == k]) for k, v in enumerate(voices)]
    bar = progress(total=len(sentences), desc="festival", unit="utt") if progress else None
    for voice, idx in jobs:
        for i, (samples, rate, phones) in zip(idx, synthesize_batch([sentences[i] for i in idx], voice)):
            x = samples
            info: dict = {}
            if augment_audio:
                a = augment(samples, rate, np.random.default_rng([seed, i]), augmentation)
                x, rate, info = a.samples, a.sample_rate_hz, a.info
            params = render_params(phones, n_frames_for(len(x) / rate), inventory="arpabet", config=articulatory)
            entries.append(
                (
                    i,
                    write_utterance(
                        out_dir,
                        utt_id=f"fest-{i:05d}",
                        samples=x,
                        sample_rate_hz=rate,
                        params=params,
                        phonemes=phones,
                        language="en",
                        voice=voice.label,
                        source="festival",
                        speaker_group=voice.name,
                        extra={"engine": "festival", "text": sentences[i], "augmentation": info}
                        if info
                        else {"engine": "festival", "text": sentences[i]},
                    ),
                )
            )
            if bar:
                bar.update(1)
    if bar:
        bar.close()
    return write_manifest(out_dir, [e for _, e in sorted(entries, key=lambda t: t[0])], seed=seed)
