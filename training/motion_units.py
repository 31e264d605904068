"""Paper 002 on real data: Motion Units of the GRID s1 lips, the audio-to-MUP mappers, the numbers.

Theory of operation
-------------------
1. **Data.** Every GRID s1 sentence's pose-free 3D landmark track comes from the one extraction
   (:func:`training.video.load_face_track`, cached; nothing here measures video). A frame's
   deformation is the Motion Units' landmarks (:data:`training.facetrack.MU_LANDMARKS`: both lip
   contours, the chin midline and the 24 perioral cheek points, paper 002's marker layout) minus the
   clip's neutral face, in IOD units, flattened to ``(3 L,)``. The whole lower face
   (:data:`training.facetrack.LOWER_FACE`, adding the jaw outline and outer cheeks) is kept beside it
   for the variance comparison only.
2. **Utterance MUs**: PCA of the *train* split's deformations (:mod:`realtime_core.motion_units`);
   the variance explained by 1..20 units is reported. UMUPs are the training targets.
3. **Audio features**: the live front end (16 kHz MFCCs c0..c11 at 30 fps, running CMVN warm-started
   with the train split's statistics, 3 frames of context each side = the paper's 7 frames).
4. **Mappers**, trained on the train split: the GMM-selected bank of small MLPs for each candidate K
   (chosen on *val* by eq. 6's R), the single large MLP of the paper's argument, and the audio-visual
   HMM of paper 000 trained on the same UMUPs (so both paths are compared on the same targets).
5. **Numbers** (paper 002 Sec. VII-A) on train and test: deformations rebuilt from estimated UMUPs,
   every coordinate divided by its maximum absolute value over the training data, then R (eq. 6),
   nu (eq. 7) and MSE (eq. 8); also the four mouth parameters via the least-squares readout.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from realtime_core.errors import FacecastError
from realtime_core.features import FrontEndConfig, extract_features
from realtime_core.mapping import MlpMapper
from realtime_core.metrics import average_std, normalised_mse, pearson_per_param, pearson_r_trace
from realtime_core.motion_units import MotionUnits
from training.errors import ConfigError

Say = Callable[[str], None]


@dataclass(frozen=True, eq=False)
class Clip:
    """One sentence: ``deform (T, 3 L) float32`` IOD, ``params (T, 4)``, ``samples (n,) float32`` at
    ``sample_rate_hz``; ``split`` from :func:`assets.grid.split_of`."""

    sentence_id: str
    split: str
    samples: np.ndarray
    sample_rate_hz: int
    deform: np.ndarray
    params: np.ndarray
    neutral: np.ndarray = field(repr=False)  # (468, 3) float32, the clip's rest face
    lower_face: np.ndarray | None = field(default=None, repr=False)  # (T, 3 x 103) LOWER_FACE deformations
    features: np.ndarray | None = field(default=None, repr=False)  # (T, Da) o_a once computed


def mu_landmark_indices() -> tuple[int, ...]:
    from training.facetrack import MU_LANDMARKS

    return tuple(MU_LANDMARKS)


def lower_face_indices() -> tuple[int, ...]:
    from training.facetrack import LOWER_FACE

    return tuple(LOWER_FACE)


def deformation_of(landmarks: np.ndarray, neutral: np.ndarray, indices: Sequence[int]) -> np.ndarray:
    """``(T, n_landmarks, 3)`` track and ``(n_landmarks, 3)`` neutral -> ``(T, 3 L)`` float32 deformations."""
    idx = np.asarray(indices)
    d = np.asarray(landmarks, dtype=np.float32)[:, idx] - np.asarray(neutral, dtype=np.float32)[idx]
    return d.reshape(len(d), -1)


def load_clips(
    root: str | Path | None = None,
    *,
    cache_dir: str | Path | None = None,
    limit: int | None = None,
    progress: bool = True,
    skipped: list[str] | None = None,
) -> list[Clip]:
    """Every GRID s1 sentence under ``root`` as a :class:`Clip` (the face tracks from the shared cache).

    skipped: when given, sentences the extractor refuses (face lost, damaged file) are left out and
    listed there with the reason; otherwise the first refusal is raised."""
    from assets.grid import default_root, sentences
    from assets.progress import Progress
    from training.video import load_face_track

    root = Path(root) if root is not None else default_root()
    items = sentences(root)
    if limit is not None:
        items = items[:limit]
    if not items:
        raise ConfigError(f"no GRID sentences (video + align) under {root}")
    idx, lower = mu_landmark_indices(), lower_face_indices()
    out = []
    for s in Progress(items, desc="face tracks", disable=not progress, unit="clip"):
        try:
            tr = load_face_track(s.video, cache_dir=cache_dir)
        except FacecastError as exc:  # the extractor refuses a clip it cannot measure (e.g. face lost)
            if skipped is None:
                raise
            skipped.append(f"{s.sentence_id}: {exc}")
            continue
        t = min(len(tr.landmarks), len(tr.params))
        out.append(
            Clip(
                s.sentence_id,
                s.split,
                np.asarray(tr.samples, dtype=np.float32),
                int(tr.sample_rate_hz),
                deformation_of(tr.landmarks[:t], tr.neutral, idx),
                np.asarray(tr.params[:t]),
                np.asarray(tr.neutral, dtype=np.float32),
                deformation_of(tr.landmarks[:t], tr.neutral, lower),
            )
        )
    return out


def with_features(clips: Sequence[Clip], frontend: FrontEndConfig, mean: np.ndarray, var: np.ndarray) -> list[Clip]:
    """The clips with ``features`` (T trimmed to the shorter of audio features and face track)."""
    out = []
    for c in clips:
        oa = extract_features(c.samples, frontend, cmvn_mean=mean, cmvn_var=var)
        t = min(len(oa), len(c.deform))
        out.append(
            Clip(
                c.sentence_id,
                c.split,
                c.samples,
                c.sample_rate_hz,
                c.deform[:t],
                c.params[:t],
                c.neutral,
                None if c.lower_face is None else c.lower_face[:t],
                oa[:t],
            )
        )
    return out


def of_split(clips: Sequence[Clip], split: str) -> list[Clip]:
    return [c for c in clips if c.split == split]


def variance_report(mu: MotionUnits, up_to: int = 20) -> list[dict]:
    """Cumulative variance explained by 1..``up_to`` units (JSON rows)."""
    cum = mu.explained()
    return [{"units": k, "explained": float(cum[k - 1])} for k in range(1, min(up_to, len(cum)) + 1)]


@dataclass(frozen=True)
class Scores:
    """Paper 002 Table I/II numbers on normalised displacements, plus the mouth parameters."""

    r: float
    nu_true: float
    nu_est: float
    mse: float
    r_params: dict
    frames: int

    def as_json(self) -> dict:
        return {
            "R": self.r,
            "nu_d": self.nu_true,
            "nu_d_est": self.nu_est,
            "MSE": self.mse,
            "r_mouth_params": self.r_params,
            "frames": self.frames,
        }


def displacement_scale(clips: Sequence[Clip]) -> np.ndarray:
    """``(3 L,)`` maximum absolute displacement of each coordinate over ``clips`` (the paper's normaliser)."""
    s = np.max([np.abs(c.deform).max(axis=0) for c in clips], axis=0).astype(np.float64)
    return np.where(s > 0, s, 1.0)


def score(truth_d: np.ndarray, est_d: np.ndarray, scale: np.ndarray, truth_p: np.ndarray, est_p: np.ndarray) -> Scores:
    t, e = truth_d / scale, est_d / scale
    r = pearson_per_param(truth_p, est_p)
    return Scores(
        r=pearson_r_trace(t, e),
        nu_true=average_std(t),
        nu_est=average_std(e),
        mse=normalised_mse(t, e, scale=np.ones(t.shape[1])),
        r_params=dict(zip(VISUAL_PARAMS, map(float, r))),
        frames=len(t),
    )


def score_mups(
    clips: Sequence[Clip],
    est_mups: Sequence[np.ndarray],
    mu: MotionUnits,
    scale: np.ndarray,
    readout: tuple[np.ndarray, np.ndarray],
) -> Scores:
    """Scores of estimated UMUPs ``est_mups[i] (T_i, A)`` against the clips' true deformations."""
    td = np.concatenate([c.deform for c in clips]).astype(np.float64)
    tp = np.concatenate([c.params for c in clips])
    em = np.concatenate(est_mups)
    return score(td, mu.reconstruct(em), scale, tp, em @ readout[0].T + readout[1])


def mlp_estimates(mapper: MlpMapper, clips: Sequence[Clip]) -> list[np.ndarray]:
    """The MLP bank's estimates of each clip's UMUPs from its ``features`` (see :func:`with_features`)."""
    out = []
    for c in clips:
        if c.features is None:
            raise ConfigError(f"{c.sentence_id}: no audio features computed (run with_features first)")
        out.append(mapper.mups(c.features))
    return out


def hmm_estimates(model: AvModel, clips: Sequence[Clip]) -> list[np.ndarray]:
    """The HMM's live (streaming) estimates of each clip's UMUPs."""
    from realtime_core.pipeline import speech_to_params

    out = []
    for c in clips:
        e = speech_to_params(model, c.samples)
        t = len(c.deform)
        out.append(np.vstack([e, np.repeat(e[-1:], max(0, t - len(e)), axis=0)])[:t])
    return out
