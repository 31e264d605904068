"""The phone-labelled motion corpus (seed 001 Sec. 3.2-3.3) as plain arrays.

Every recorded sentence contributes its motion frames (30 fps, frame ``k`` at ``k / 30`` s of the
sentence) and its phones with their boundaries in seconds on the same clock. Frames of all
sentences are stored end to end in one ``(n_frames_total, n_dims)`` array, phones in flat arrays;
``*_offsets`` arrays delimit the sentences. Frame dimensions are the motion features: first the
``n_coefficients`` PCA coefficients of the pose-free landmarks (the paper's motion vectors
``x_t``, used by the smoothness cost), then any further channels carried along unchanged (the
four mouth parameters). Sans-I/O: :mod:`training.unit_corpus` builds and stores it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from realtime_core.errors import ConfigError, InvalidFeaturesError
from realtime_core.motion_units.units import MotionUnits
from realtime_core.synthesis.visemes import VISEME_ID, VISEMES

FPS = 30.0
"""Frame rate of corpus motion and of synthesised output, frames per second."""


@dataclass(frozen=True, kw_only=True)
class MotionCorpus:
    """sentence_ids: (S,) names; frames: (F, D) float32 motion features of all sentences end to end;
    frame_offsets: (S + 1,) int64, sentence s owns frames ``frame_offsets[s]:frame_offsets[s+1]``;
    phone_labels: (N,) str (for reports); phone_visemes: (N,) int16 class ids (:data:`VISEMES`);
    phone_start_s, phone_end_s: (N,) float64 seconds on the sentence's clock (start < end);
    phone_offsets: (S + 1,) int64, sentence s owns phones ``phone_offsets[s]:phone_offsets[s+1]``;
    n_coefficients: leading dims of ``frames`` that are motion vectors (smoothness cost);
    dim_names: (D,) names of the frame dims."""

    sentence_ids: tuple[str, ...]
    frames: np.ndarray
    frame_offsets: np.ndarray
    phone_labels: tuple[str, ...]
    phone_visemes: np.ndarray
    phone_start_s: np.ndarray
    phone_end_s: np.ndarray
    phone_offsets: np.ndarray
    n_coefficients: int
    dim_names: tuple[str, ...]

    def __post_init__(self) -> None:
        s = len(self.sentence_ids)
        f = np.asarray(self.frames)
        if f.ndim != 2 or not np.all(np.isfinite(f)):
            raise InvalidFeaturesError(f"corpus frames must be finite (F, D), got shape {f.shape}")
        fo, po = np.asarray(self.frame_offsets), np.asarray(self.phone_offsets)
        if fo.shape != (s + 1,) or po.shape != (s + 1,) or fo[0] != 0 or po[0] != 0:
            raise ConfigError("frame_offsets and phone_offsets must be (S + 1,) starting at 0")
        if fo[-1] != len(f) or np.any(np.diff(fo) < 2) or np.any(np.diff(po) < 1):
            raise ConfigError("every sentence needs >= 2 frames and >= 1 phone; offsets must end at the totals")
        n = int(po[-1])
        for name in ("phone_visemes", "phone_start_s", "phone_end_s"):
            if np.asarray(getattr(self, name)).shape != (n,):
                raise ConfigError(f"{name} must be ({n},)")
        if len(self.phone_labels) != n:
            raise ConfigError(f"phone_labels must have {n} entries")
        if np.any(np.asarray(self.phone_end_s) <= np.asarray(self.phone_start_s)):
            raise ConfigError("every phone must end after it starts")
        v = np.asarray(self.phone_visemes)
        if n and (v.min() < 0 or v.max() >= len(VISEMES)):
            raise ConfigError("phone_visemes must be viseme class ids")
        if not 0 < self.n_coefficients <= f.shape[1] or len(self.dim_names) != f.shape[1]:
            raise ConfigError("n_coefficients must be in 1..D and dim_names must name every frame dim")

    @classmethod
    def of_sentences(
        cls,
        sentences: Sequence[tuple[str, np.ndarray, Sequence[tuple[str, int, float, float]]]],
        *,
        n_coefficients: int,
        dim_names: tuple[str, ...],
    ) -> MotionCorpus:
        """The corpus of ``sentences`` laid end to end, each (id, frames (n, D), its phones as (label, viseme
        class id, start s, end s) on its clock); the offsets are counted here."""
        phones = [p for _, _, ph in sentences for p in ph]
        return cls(
            sentence_ids=tuple(sid for sid, _, _ in sentences),
            frames=np.concatenate([f for _, f, _ in sentences]),
            frame_offsets=np.cumsum([0, *(len(f) for _, f, _ in sentences)], dtype=np.int64),
            phone_labels=tuple(p[0] for p in phones),
            phone_visemes=np.array([p[1] for p in phones], dtype=np.int16),
            phone_start_s=np.array([p[2] for p in phones], dtype=np.float64),
            phone_end_s=np.array([p[3] for p in phones], dtype=np.float64),
            phone_offsets=np.cumsum([0, *(len(ph) for _, _, ph in sentences)], dtype=np.int64),
            n_coefficients=n_coefficients,
            dim_names=dim_names,
        )

    @property
    def n_sentences(self) -> int:
        return len(self.sentence_ids)

    @property
    def n_phones(self) -> int:
        return int(self.phone_offsets[-1])

    @property
    def n_dims(self) -> int:
        return int(self.frames.shape[1])

    def sentence_frames(self, s: int) -> np.ndarray:
        """(n_frames_s, D) motion of sentence s."""
        return self.frames[self.frame_offsets[s] : self.frame_offsets[s + 1]]

    def phone_sentence(self) -> np.ndarray:
        """(N,) int64 sentence index of every phone."""
        return np.repeat(np.arange(self.n_sentences), np.diff(self.phone_offsets))

    def visemes_present(self) -> frozenset[str]:
        return frozenset(VISEMES[i] for i in np.unique(self.phone_visemes))

    def subset(self, keep: list[int]) -> MotionCorpus:
        """The corpus of sentences ``keep`` (indices, in that order)."""
        fo, po = self.frame_offsets, self.phone_offsets
        fr = [np.arange(fo[s], fo[s + 1]) for s in keep]
        ph = [np.arange(po[s], po[s + 1]) for s in keep]
        fi, pi = np.concatenate(fr), np.concatenate(ph)
        return MotionCorpus(
            sentence_ids=tuple(self.sentence_ids[s] for s in keep),
            frames=self.frames[fi],
            frame_offsets=np.concatenate([[0], np.cumsum([len(a) for a in fr])]).astype(np.int64),
            phone_labels=tuple(self.phone_labels[i] for i in pi),
            phone_visemes=self.phone_visemes[pi],
            phone_start_s=self.phone_start_s[pi],
            phone_end_s=self.phone_end_s[pi],
            phone_offsets=np.concatenate([[0], np.cumsum([len(a) for a in ph])]).astype(np.int64),
            n_coefficients=self.n_coefficients,
            dim_names=self.dim_names,
        )


def viseme_ids(visemes: list[str] | tuple[str, ...]) -> np.ndarray:
    """Class names -> (n,) int16 ids."""
    try:
        return np.array([VISEME_ID[v] for v in visemes], dtype=np.int16)
    except KeyError as exc:
        raise ConfigError(f"unknown viseme class {exc.args[0]!r}") from exc


def sample_motion(corpus: MotionCorpus, sentence: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """Motion of sentences ``sentence`` (n,) at times ``times_s`` (n,) on their clocks -> (n, D),
    linear interpolation between frames (frame k at k / 30 s), edges held."""
    fo = corpus.frame_offsets
    n_fr = (fo[sentence + 1] - fo[sentence]).astype(np.float64)
    pos = np.clip(np.asarray(times_s, dtype=np.float64) * FPS, 0.0, n_fr - 1.0)
    k0 = np.minimum(np.floor(pos).astype(np.int64), (n_fr - 2).astype(np.int64))
    frac = (pos - k0)[:, None]
    base = fo[sentence] + k0
    f = corpus.frames
    return (1.0 - frac) * f[base] + frac * f[base + 1]


# ----------------------------------------------------------------------------- the .npz codec
CORPUS_FORMAT = "facecast-unit-corpus"
CORPUS_VERSION = 1


@dataclass(frozen=True, kw_only=True)
class StoredCorpus:
    """What a unit-corpus file holds: the corpus; the landmark PCA that made its coefficients
    (``pca_mean`` (P,), ``pca_components`` (K, P) orthonormal, ``pca_variances`` (K,),
    ``pca_total_variance``), the landmark indices the PCA covers (``landmark_indices`` (P/3,)) and
    the mean neutral positions of those landmarks (``neutral`` (P/3, 3), IOD units, face frame);
    ``meta``: JSON-able provenance (sources, credit, build settings); ``motion_units``: the
    Utterance Motion Units (paper 002) of the same lower-face deformations, fitted on the corpus's
    frames (None in files written before they were added), which turn synthesised coefficients
    into MU parameters (:meth:`mups`)."""

    corpus: MotionCorpus
    pca_mean: np.ndarray
    pca_components: np.ndarray
    pca_variances: np.ndarray
    pca_total_variance: float
    landmark_indices: np.ndarray
    neutral: np.ndarray
    meta: dict[str, Any]
    motion_units: MotionUnits | None = None

    def landmark_offsets(self, coefficients: np.ndarray) -> np.ndarray:
        """(n, K) coefficients -> (n, P/3, 3) landmark displacements from the neutral face (IOD)."""
        flat = np.asarray(coefficients, dtype=np.float64) @ self.pca_components + self.pca_mean
        return flat.reshape(len(flat), -1, 3)

    def rest_frame(self) -> np.ndarray:
        """(D,) the frame vector of the neutral face: the PCA coefficients of zero displacement
        (``-components @ mean``) followed by zero for every further dim (the mouth parameters)."""
        out = np.zeros(self.corpus.n_dims)
        out[: self.corpus.n_coefficients] = -(self.pca_components @ self.pca_mean)
        return out

    def mups(self, coefficients: np.ndarray) -> np.ndarray:
        """(n, K) coefficients -> (n, A) Utterance MU parameters (paper 002 eq. 1: ``M_0^T (d - m_00)``
        of the landmark displacements the coefficients stand for). Raises ConfigError if the corpus
        carries no Motion Units (a file from before they were added: rebuild it)."""
        if self.motion_units is None:
            raise ConfigError("this unit corpus carries no Motion Units (built before v2: rebuild it)")
        d = self.landmark_offsets(coefficients)
        return self.motion_units.project(d.reshape(len(d), -1))


def encode_corpus(stored: StoredCorpus) -> bytes:
    """Serialise to compressed ``.npz`` bytes (no pickle)."""
    import io
    import json

    c = stored.corpus
    header = {
        "sentence_ids": list(c.sentence_ids),
        "phone_labels": list(c.phone_labels),
        "n_coefficients": c.n_coefficients,
        "dim_names": list(c.dim_names),
        "meta": stored.meta,
        "pca_total_variance": stored.pca_total_variance,
    }
    arrays: dict[str, np.ndarray] = {
        "format": np.array(CORPUS_FORMAT),
        "version": np.array(CORPUS_VERSION),
        "header_json": np.array(json.dumps(header)),
        "frames": np.asarray(c.frames, dtype=np.float32),
        "frame_offsets": np.asarray(c.frame_offsets, dtype=np.int64),
        "phone_visemes": np.asarray(c.phone_visemes, dtype=np.int16),
        "phone_start_s": c.phone_start_s,
        "phone_end_s": c.phone_end_s,
        "phone_offsets": np.asarray(c.phone_offsets, dtype=np.int64),
        "pca_mean": stored.pca_mean,
        "pca_components": stored.pca_components,
        "pca_variances": stored.pca_variances,
        "landmark_indices": np.asarray(stored.landmark_indices, dtype=np.int64),
        "neutral": stored.neutral,
    }
    if stored.motion_units is not None:  # optional arrays: files without them still read (no Motion Units)
        arrays.update(
            mu_mean=stored.motion_units.mean,
            mu_units=stored.motion_units.units,
            mu_eigenvalues=stored.motion_units.eigenvalues,
        )
    buf = io.BytesIO()
    np.savez_compressed(buf, allow_pickle=False, **arrays)
    return buf.getvalue()


def decode_corpus(data: bytes) -> StoredCorpus:
    """Parse and validate ``.npz`` bytes; raises ModelFormatError naming the problem."""
    import json

    from realtime_core.archive import npz_arrays
    from realtime_core.errors import ModelFormatError

    a = npz_arrays(data, "unit-corpus")
    need = (
        "format",
        "version",
        "header_json",
        "frames",
        "frame_offsets",
        "phone_visemes",
        "phone_start_s",
        "phone_end_s",
        "phone_offsets",
        "pca_mean",
        "pca_components",
        "pca_variances",
        "landmark_indices",
        "neutral",
    )
    missing = [k for k in need if k not in a]
    if missing:
        raise ModelFormatError(f"unit-corpus archive lacks {missing}")
    if str(a["format"]) != CORPUS_FORMAT or int(a["version"]) != CORPUS_VERSION:
        raise ModelFormatError(
            f"format {str(a['format'])!r} v{int(a['version'])} is not {CORPUS_FORMAT!r} v{CORPUS_VERSION}"
        )
    try:
        h = json.loads(str(a["header_json"]))
        corpus = MotionCorpus(
            sentence_ids=tuple(h["sentence_ids"]),
            frames=a["frames"],
            frame_offsets=a["frame_offsets"],
            phone_labels=tuple(h["phone_labels"]),
            phone_visemes=a["phone_visemes"],
            phone_start_s=a["phone_start_s"],
            phone_end_s=a["phone_end_s"],
            phone_offsets=a["phone_offsets"],
            n_coefficients=int(h["n_coefficients"]),
            dim_names=tuple(h["dim_names"]),
        )
        stored = StoredCorpus(
            corpus=corpus,
            pca_mean=a["pca_mean"],
            pca_components=a["pca_components"],
            pca_variances=a["pca_variances"],
            pca_total_variance=float(h["pca_total_variance"]),
            landmark_indices=a["landmark_indices"],
            neutral=a["neutral"],
            meta=dict(h["meta"]),
            motion_units=(
                MotionUnits(mean=a["mu_mean"], units=a["mu_units"], eigenvalues=a["mu_eigenvalues"])
                if "mu_units" in a
                else None
            ),
        )
    except (KeyError, TypeError, ValueError, json.JSONDecodeError) as exc:
        raise ModelFormatError(f"unit-corpus archive is inconsistent: {exc}") from None
    k = corpus.n_coefficients
    if (
        stored.pca_components.shape != (k, stored.pca_mean.shape[0])
        or stored.neutral.shape != (len(stored.landmark_indices), 3)
        or stored.pca_mean.shape[0] != 3 * len(stored.landmark_indices)
    ):
        raise ModelFormatError("unit-corpus PCA, landmark indices and neutral face disagree in size")
    if stored.motion_units is not None and stored.motion_units.dim != stored.pca_mean.shape[0]:
        raise ModelFormatError("unit-corpus Motion Units and landmark PCA disagree in size")
    return stored
