"""The on-disk corpus layout (the contract with ``facecast train``): writers and reader.

A corpus is a folder::

    manifest.json      {"version": 1, "seed": S, "params": [the 4 names],
                        "utterances": [{"id", "dir", "language", "voice", "source",
                                        "duration_s", "sample_rate_hz", "speaker_group", ...}]}
    <dir>/audio.wav    mono 16-bit PCM
    <dir>/params.csv   header "t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress";
                       row k at t = k/30 s exactly; n = ceil(duration_s * 30) rows
                       (the track codec of :mod:`assets.tracks`, read in its strict mode)
    <dir>/phonemes.json  [{"phoneme", "start_s", "end_s"}, ...] (empty list when unknown)

``source`` is "espeak" (synthetic), "real" (real speech labelled from phone alignments by the
articulatory rules) or "video" (parameters measured on a talking-face video). Keep "real" and
"video" utterances out of training when they are used for evaluation; ``speaker_group`` lets a
split keep whole voices/speakers out.

Every file is written atomically (temporary file in the same folder, then ``os.replace``) so an
interrupted build never leaves a half-written file under its final name. Only JSON, CSV and WAV.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from assets.audio import ACCEPTED_RATES_HZ, read_wav, write_wav
from assets.files import atomic_write_bytes
from assets.tracks import csv_header, read_csv, write_csv
from realtime_core.phones import PhonemeSegment
from realtime_core.track import Track
from training.errors import ConfigError, CorpusFormatError
from training.params import FPS, N_PARAMS, PARAM_NAMES, n_frames_for

MANIFEST = "manifest.json"
VERSION = 1
SOURCES = ("espeak", "festival", "real", "video")
CSV_HEADER = csv_header(PARAM_NAMES)


PhonemeRecord = PhonemeSegment  # the shared timeline type (training.params)


@dataclass(frozen=True)
class Utterance:
    """One loaded utterance.

    samples:        (n,) float32 in [-1, 1], mono.
    sample_rate_hz: rate of ``samples``.
    params:         (n_frames, 4) float64, IOD units, frame k at t = k/30 s,
                    n_frames = ceil(n / sample_rate_hz * 30).
    phonemes:       the phoneme timeline (empty when unknown, e.g. for video).
    """

    id: str
    samples: np.ndarray
    sample_rate_hz: int
    params: np.ndarray
    phonemes: tuple[PhonemeRecord, ...]
    voice: str
    language: str
    source: str
    speaker_group: str

    @property
    def duration_s(self) -> float:
        return len(self.samples) / self.sample_rate_hz


# --------------------------------------------------------------------------- atomic writes


def write_json(path: Path, obj) -> None:
    atomic_write_bytes(Path(path), (json.dumps(obj, indent=1, ensure_ascii=False) + "\n").encode("utf-8"))


def write_utterance(
    corpus_dir: Path,
    *,
    utt_id: str,
    samples: np.ndarray,
    sample_rate_hz: int,
    params: np.ndarray,
    phonemes: Iterable,
    language: str,
    voice: str,
    source: str,
    speaker_group: str,
    extra: dict | None = None,
) -> dict:
    """Write one utterance folder; returns its manifest entry.

    samples: (n,) float in [-1, 1] or int16; params: (ceil(n / rate * 30), 4) float64.
    phonemes: objects with phoneme/start_s/end_s (seconds). ``extra`` keys (JSON-ready) are
    added to the manifest entry (e.g. the augmentation drawn).
    """
    if source not in SOURCES:
        raise ConfigError(f"source must be one of {SOURCES}, got {source!r}")
    if sample_rate_hz not in ACCEPTED_RATES_HZ:
        raise ConfigError(f"sample rate {sample_rate_hz} Hz is not one of {ACCEPTED_RATES_HZ}")
    duration = len(samples) / sample_rate_hz
    want = n_frames_for(duration)
    if params.shape != (want, N_PARAMS):
        raise ConfigError(f"{utt_id}: params shape {params.shape}, expected ({want}, {N_PARAMS}) for {duration:.4f} s")
    folder = Path(corpus_dir) / utt_id
    write_wav(folder / "audio.wav", samples, sample_rate_hz)
    write_csv(folder / "params.csv", Track(values=params, names=PARAM_NAMES, fps=FPS))
    write_json(
        folder / "phonemes.json",
        [
            {"phoneme": p.phoneme, "start_s": round(float(p.start_s), 6), "end_s": round(float(p.end_s), 6)}
            for p in phonemes
        ],
    )
    entry = {
        "id": utt_id,
        "dir": utt_id,
        "language": language,
        "voice": voice,
        "source": source,
        "duration_s": round(duration, 6),
        "sample_rate_hz": int(sample_rate_hz),
        "speaker_group": speaker_group,
    }
    if extra:
        entry.update(extra)
    return entry


def write_manifest(corpus_dir: Path, entries: Sequence[dict], *, seed: int | None, extra: dict | None = None) -> Path:
    """Atomically write ``manifest.json`` (entries in the given order)."""
    doc = {"version": VERSION, "seed": seed, "params": list(PARAM_NAMES), "utterances": list(entries)}
    if extra:
        doc.update(extra)
    path = Path(corpus_dir) / MANIFEST
    write_json(path, doc)
    return path


# --------------------------------------------------------------------------- reading


def load_corpus(path: str | Path) -> list[Utterance]:
    """Load every utterance of a corpus folder (in manifest order), checking the layout."""
    root = Path(path)
    mpath = root / MANIFEST
    if not mpath.is_file():
        # A folder of videos given straight to `facecast train` is the likely case: name the commands that make one.
        raise CorpusFormatError(
            mpath,
            "missing: not a corpus folder (no manifest.json); make one with `facecast extract VIDEOS -o DIR` "
            "(talking-face video) or `facecast corpus DIR` (synthetic speech)",
        )
    try:
        doc = json.loads(mpath.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CorpusFormatError(mpath, f"not valid JSON ({exc})") from exc
    if doc.get("version") != VERSION:
        raise CorpusFormatError(mpath, f"version {doc.get('version')!r} is not {VERSION}")
    if list(doc.get("params", [])) != list(PARAM_NAMES):
        raise CorpusFormatError(mpath, f"params must be {list(PARAM_NAMES)}")
    out: list[Utterance] = []
    for entry in doc.get("utterances", []):
        try:
            uid, folder = entry["id"], root / entry["dir"]
            rate, source = int(entry["sample_rate_hz"]), entry["source"]
        except (KeyError, TypeError, ValueError) as exc:
            raise CorpusFormatError(mpath, f"utterance entry lacks {exc}: {entry!r}") from exc
        if source not in SOURCES:
            raise CorpusFormatError(mpath, f"{uid}: source {source!r} not one of {SOURCES}")
        samples, rate = read_wav(folder / "audio.wav", expected_rate_hz=rate)
        n = n_frames_for(len(samples) / rate)
        params = read_csv(folder / "params.csv", names=PARAM_NAMES, fps=FPS, n_frames=n, start_s=0.0).values
        ppath = folder / "phonemes.json"
        phon: tuple[PhonemeRecord, ...] = ()
        if ppath.is_file():
            try:
                phon = tuple(
                    PhonemeRecord(str(p["phoneme"]), float(p["start_s"]), float(p["end_s"]))
                    for p in json.loads(ppath.read_text(encoding="utf-8"))
                )
            except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
                raise CorpusFormatError(ppath, f"not a phoneme list ({exc})") from exc
        out.append(
            Utterance(
                id=uid,
                samples=samples,
                sample_rate_hz=rate,
                params=params,
                phonemes=phon,
                voice=str(entry.get("voice", "")),
                language=str(entry.get("language", "")),
                source=source,
                speaker_group=str(entry.get("speaker_group", "")),
            )
        )
    return out
