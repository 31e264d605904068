"""The unit-selection motion corpus of GRID s1 (seed 001 Sec. 3.2-3.6): built once, cached.

From the shared real-lips extraction (:func:`training.video.load_face_track`: pose-free 3D
landmarks and the four mouth parameters at 30 fps, cached per video) and the shared GRID phone
boundaries (:mod:`training.grid_phones`), for the train + val sentences of the one split
(:func:`assets.grid.split_of`; test sentences are held out for the evaluation):

1. every sentence's lower-face landmarks (:data:`training.facetrack.LOWER_FACE`) as displacements
   from that clip's neutral face (IOD units, head pose removed), flattened per frame;
2. EM-PCA over all frames (:func:`realtime_core.synthesis.empca.fit_empca`), components chosen by
   explained variance; each frame becomes its coefficients (the paper's motion vector ``x_t``)
   followed by the four mouth parameters, carried along for the renderer and exports;
3. the phones of each sentence with their viseme classes.

The result is one compressed ``.npz`` (:mod:`assets.unitcorpus`), cached under
``$FACECAST_CACHE/unitsel/`` by a key over everything it derives from (extractor version, the
parameter definitions' version :data:`training.params.DEFINITION_VERSION`, sentence ids, phone boundaries,
settings), so it is rebuilt only when an input changes.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from assets.grid import GridSentence
from realtime_core import VISUAL_PARAMS
from realtime_core.motion_units.units import fit_motion_units
from realtime_core.synthesis.corpus import MotionCorpus, StoredCorpus
from realtime_core.synthesis.empca import EmPcaConfig, fit_empca
from realtime_core.synthesis.visemes import VISEME_ID, viseme_of
from training.alignments import Alignment
from training.errors import ConfigError, FileProblem
from training.facetrack import (
    EXTRACTOR_VERSION,
    LOWER_FACE,
    FaceTrack,
    cache_path,
    default_cache_dir,
)
from training.params import DEFINITION_VERSION

BUILD_VERSION = 2
"""Bumped whenever the corpus construction changes (part of the cache key). 2: Motion Units added."""

PhoneRows = Sequence[tuple[str, float, float]]
"""A phone timeline: (ARPAbet label, start_s, end_s) on the recording's clock."""

PhoneTimeline = Alignment | PhoneRows
"""A phone timeline as either an :class:`Alignment` (what ``read_grid_phones`` returns) or rows."""

GRID_CREDIT = (
    "GRID audio-visual sentence corpus, talker s1: M. Cooke, J. Barker, S. Cunningham, X. Shao, "
    "J. Acoust. Soc. Am. 120(5), 2006, 2421-2424. CC BY 4.0."
)


def track_motion(track: FaceTrack) -> np.ndarray:
    """(n_frames, 3 * len(LOWER_FACE)) float64 lower-face displacements from the clip's neutral face."""
    idx = list(LOWER_FACE)
    d = track.landmarks[:, idx, :].astype(np.float64) - track.neutral[idx].astype(np.float64)
    return d.reshape(len(d), -1)


def phone_rows(alignment: PhoneTimeline) -> list[tuple[str, float, float]]:
    """(label, start_s, end_s) rows from an Alignment (``.phones`` of PhonemeSegment) or rows."""
    # duck-typed beyond Alignment: any object with ``.phones`` (e.g. grid_phones.SentencePhones) works too
    phones: Sequence[Any] = (
        alignment.phones if isinstance(alignment, Alignment) else getattr(alignment, "phones", alignment)
    )
    out: list[tuple[str, float, float]] = []
    for p in phones:
        if hasattr(p, "phoneme"):
            out.append((str(p.phoneme), float(p.start_s), float(p.end_s)))
        else:
            lab, a, b = p
            out.append((str(lab), float(a), float(b)))
    return out


def corpus_key(sentences: Sequence[GridSentence], phones: Mapping[str, PhoneTimeline], config: EmPcaConfig) -> str:
    """Cache key: a hash of everything the corpus derives from."""
    h = hashlib.sha1()
    h.update(
        json.dumps(
            {
                "build": BUILD_VERSION,
                "extractor": EXTRACTOR_VERSION,
                "params": DEFINITION_VERSION,
                "empca": asdict(config),
            },
            sort_keys=True,
        ).encode()
    )
    for s in sorted(sentences, key=lambda s: s.sentence_id):
        h.update(s.sentence_id.encode())
        h.update(repr([(a, round(b, 6), round(c, 6)) for a, b, c in phone_rows(phones[s.sentence_id])]).encode())
    return h.hexdigest()[:16]


def default_corpus_path(key: str, cache_dir: str | Path | None = None) -> Path:
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return root / "unitsel" / f"grid_s1_units-{key}.npz"


def is_extracted(video: Path, cache_dir: str | Path | None = None, rate_hz: int = 16000) -> bool:
    """Whether the shared extraction already cached ``video`` (no MediaPipe needed to load it)."""
    from training.video import file_sha1

    return cache_path(Path(cache_dir) if cache_dir is not None else None, file_sha1(video), rate_hz).is_file()


def build_stored_corpus(
    tracks: Sequence[tuple[str, FaceTrack, PhoneRows]], *, config: EmPcaConfig | None = None, meta: dict | None = None
) -> StoredCorpus:
    """The corpus of ``[(sentence id, face track, ARPAbet phones)]`` (sans file I/O)."""
    config = config or EmPcaConfig()
    if not tracks:
        raise ConfigError("no sentences to build a unit corpus from")
    motions = [track_motion(t) for _, t, _ in tracks]
    pca = fit_empca(np.concatenate(motions), config)
    # The Utterance Motion Units of paper 002 (PCA by covariance eigenvectors, 97 % of the variance)
    # on the same lower-face displacements, so synthesised motion can also be given as MUPs.
    units = fit_motion_units(np.concatenate(motions))
    sentences, neutral = [], []
    for (sid, track, rows), m in zip(tracks, motions):
        end_s = len(m) / 30.0
        phones = []
        for lab, a, b in sorted(phone_rows(rows), key=lambda r: r[1]):
            a, b = max(a, 0.0), min(b, end_s)
            if b - a > 1e-6:
                phones.append((lab, VISEME_ID[viseme_of(lab, "arpabet")], a, b))
        if not phones:
            raise ConfigError(f"sentence {sid}: no phone inside its {end_s:.2f} s of motion")
        sentences.append((sid, np.concatenate([pca.transform(m), track.params], axis=1).astype(np.float32), phones))
        neutral.append(track.neutral[list(LOWER_FACE)])
    k = pca.n_components
    corpus = MotionCorpus.of_sentences(
        sentences, n_coefficients=k, dim_names=tuple(f"pc{i + 1}" for i in range(k)) + VISUAL_PARAMS
    )
    info = {
        "n_sentences": corpus.n_sentences,
        "n_frames": len(corpus.frames),
        "n_phones": corpus.n_phones,
        "n_components": k,
        "explained": float(pca.explained_ratio[-1]),
        "empca_iterations": pca.iterations,
        "empca": asdict(config),
        "extractor": EXTRACTOR_VERSION,
        "params": DEFINITION_VERSION,
        "build": BUILD_VERSION,
        "credit": GRID_CREDIT,
    }
    return StoredCorpus(
        corpus=corpus,
        pca_mean=pca.mean,
        pca_components=pca.components,
        pca_variances=pca.variances,
        pca_total_variance=pca.total_variance,
        landmark_indices=np.array(LOWER_FACE),
        neutral=np.mean(neutral, axis=0).astype(np.float64),
        meta={**info, "motion_units": units.n_units, **(meta or {})},
        motion_units=units,
    )


def build_grid_corpus(
    sentences: Sequence[GridSentence],
    phones: Mapping[str, PhoneTimeline],
    *,
    cache_dir: str | Path | None = None,
    config: EmPcaConfig | None = None,
    only_extracted: bool = False,
    progress: Callable | None = None,
    say: Callable[[str], None] = lambda _: None,
) -> tuple[StoredCorpus, Path]:
    """The unit corpus of ``sentences`` (their face tracks and phones), from the cache if built before.

    only_extracted: skip sentences the shared extraction has not cached yet (instead of running
    MediaPipe on them); they are counted in ``meta["skipped"]``. Returns (corpus, its file).
    """
    from assets.unitcorpus import load_unit_corpus, save_unit_corpus
    from training.video import load_face_track

    config = config or EmPcaConfig()
    missing_phones = [s.sentence_id for s in sentences if s.sentence_id not in phones]
    if missing_phones:
        say(f"unit corpus: {len(missing_phones)} sentences have no phone boundaries, skipped")
    use = [s for s in sentences if s.sentence_id in phones]
    skipped: list[str] = []
    if only_extracted:
        skipped = [s.sentence_id for s in use if not is_extracted(s.video, cache_dir)]
        use = [s for s in use if s.sentence_id not in set(skipped)]
    key = corpus_key(use, phones, config)
    path = default_corpus_path(key, cache_dir)
    if path.is_file():
        return load_unit_corpus(path), path
    rows, bad = [], []
    wrap = progress or (lambda it, **_: it)
    for s in wrap(use, desc="unit corpus", unit="sentence"):
        try:
            track = load_face_track(s.video, cache_dir=cache_dir)
        except FileProblem as exc:  # a clip the extraction refuses (face lost, truncated): skipped, counted
            bad.append(f"{s.sentence_id}: {exc.problem}")
            continue
        rows.append((s.sentence_id, track, phone_rows(phones[s.sentence_id])))
    if bad:
        say(f"unit corpus: {len(bad)} clips refused by the extraction, skipped (first: {bad[0]})")
    stored = build_stored_corpus(
        rows,
        config=config,
        meta={
            "skipped_not_extracted": skipped,
            "skipped_no_phones": missing_phones,
            "skipped_bad_clips": bad,
            "key": key,
        },
    )
    save_unit_corpus(path, stored)
    say(
        f"unit corpus: {stored.corpus.n_sentences} sentences, {stored.corpus.n_phones} phones, "
        f"{stored.corpus.n_coefficients} PCA components -> {path}"
    )
    return stored, path
