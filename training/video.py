"""Talking-face video -> pose-free landmark tracks and mouth parameters (``facecast extract``).

Theory of operation
-------------------
1. **Decode.** ffprobe reads the streams (frame rate, size, start times); ffmpeg decodes the
   audio to mono 16-bit PCM at ``audio_rate_hz`` and the video to raw RGB frames. A video whose
   decoded frame count falls short of its declared duration is refused as truncated; audio and
   video whose durations differ by more than ``max_av_mismatch_s`` are refused too.
2. **Landmarks.** MediaPipe's face mesh (468 3D landmarks, video mode so it tracks between
   frames; one graph per process, reset between clips) gives per frame normalised ``x, y``
   (image width/height = 1) and ``z`` (same scale as ``x``); we keep pixels ``(x W, y H, z W)``.
   This raw track and the audio are what the cache keeps (:mod:`training.facetrack`); the steps
   below are derived from it on every load (:func:`derive_track`, milliseconds).
3. **Gaps.** Frames without a face are filled by linear interpolation and flagged in
   ``face_found``; a clip with too few faces (``min_face_fraction``) or one gap longer than
   ``max_gap_s`` is refused (:class:`NoFaceError`).
4. **Head pose removed.** The rigid part of the face (:data:`STABLE`: forehead, nose bridge, eye
   corners, temples; never lips or jaw) of every frame is aligned to a reference by a similarity
   Procrustes fit (rotation, translation, uniform scale: Umeyama 1991); the reference is the
   iterated Procrustes mean of the clip. It is expressed in the face frame (origin midway between
   the eye centres, x right->left eye, y down the face, z = x cross y) and divided by its
   inter-ocular distance (IOD), so positions are in IOD units whatever the head does.
5. **Resample** from the video rate (25 fps for GRID) to exactly 30 fps by linear interpolation
   at ``t = k / 30`` on the audio clock (k = 0 .. ceil(audio duration * 30) - 1), the video's
   start time relative to the audio taken into account; values beyond the last frame are held.
6. **Neutral** (the face at rest): the median face over rest frames. Rest frames are the
   silences of the word alignment (``sil`` spans, minus ``rest_margin_s`` next to speech: the
   lips move before the sound starts and after it ends) when the clip has one; otherwise the
   quietest frames by audio level (the acoustic equivalent of a silence); with too few of
   either, the frames of smallest lip gap (``neutral_quantile``).
7. **Parameters** from the landmarks and the neutral face (definitions in
   :mod:`training.params`, measured by :func:`mouth_params`).
"""

from __future__ import annotations

import hashlib
import multiprocessing
import os
import re
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from assets.audio import is_silent, read_audio
from assets.grid import SILENCE_WORDS, align_for_video, read_words
from assets.mediapipe_log import native_stderr_quiet
from assets.video import decode_frames, frame_times, probe_picture
from realtime_core.face.registration import fit_similarity as similarity_fit
from training.corpus import write_json, write_manifest, write_utterance
from training.errors import (
    ConfigError,
    FileProblem,
    LengthMismatchError,
    MissingDependencyError,
    NoFaceError,
    NotAudioError,
    SilentAudioError,
    TruncatedFileError,
)
from training.facetrack import (
    CHEEKS,
    EXTRACTOR_VERSION,
    JAW,
    LEFT_EYE_CORNERS,
    LIP_GAP_PAIRS,
    LIPS_INNER,
    LIPS_OUTER,
    LOWER_FACE,
    LOWER_LIP_OUTER,
    MOUTH_CORNERS,
    N_LANDMARKS,
    RIGHT_EYE_CORNERS,
    STABLE,
    UPPER_LIP_MIDDLE,
    UPPER_LIP_OUTER,
    FaceTrack,
    RawTrack,
    cache_path,
    default_cache_dir,
    read_raw,
    write_raw,
)
from training.params import FPS, n_frames_for

__all__ = [
    "CHEEKS",
    "EXTRACTOR_VERSION",
    "JAW",
    "LIPS_INNER",
    "LIPS_OUTER",
    "LOWER_FACE",
    "ExtractConfig",
    "ExtractReport",
    "FaceTrack",
    "derive_track",
    "extract_corpus",
    "load_face_track",
    "measure_video",
    "mouth_params",
]

# Containers ffmpeg reads, cameras' own included (AVCHD .mts/.m2ts, broadcast .mxf): a folder of a camera's
# .MTS files was passed over without a word ("no video found").
VIDEO_SUFFIXES = (".mp4", ".m4v", ".mpg", ".mpeg", ".webm", ".mov", ".avi", ".mkv", ".mts", ".m2ts", ".mxf")
Words = Sequence[tuple[float, float, str]]


@dataclass(frozen=True, kw_only=True)
class ExtractConfig:
    """Settings of the extraction (raw measurement) and of the derivation of a :class:`FaceTrack`.

    audio_rate_hz:      rate of the extracted audio (mono int16); part of the cache key.
    min_face_fraction:  below this fraction of video frames with a face the clip is refused.
    max_gap_s:          a face lost for longer than this in one stretch refuses the clip.
    max_av_mismatch_s:  audio and video durations may differ by at most this.
    rest_margin_s:      silence frames this close to speech are not rest (lips prepare/relax).
    min_rest_frames:    fewer rest frames than this fall back to the next neutral estimate.
    neutral_quantile:   last-resort neutral: the frames with the smallest lip gap (this fraction).
    closed_quantile:    mouth_open's zero (lips touching) = the mean of this fraction of smallest lip gaps.
    quiet_quantile:     no alignment: rest = the quietest frames (this fraction) ...
    quiet_below_db:     ... that are also this far below the clip's loudest frame.
    jump_iod:           a tracking jump: the lower face moves by more than this (median over its
                        landmarks, IOD) between consecutive video frames (real lips move < 0.05).
    min_detection_confidence / min_tracking_confidence: MediaPipe face-mesh thresholds.
    language:           language code written to the manifest.
    """

    audio_rate_hz: int = 16000
    min_face_fraction: float = 0.8
    max_gap_s: float = 0.5
    max_av_mismatch_s: float = 0.2
    rest_margin_s: float = 0.15
    min_rest_frames: int = 5
    neutral_quantile: float = 0.1
    closed_quantile: float = 0.05
    quiet_quantile: float = 0.2
    quiet_below_db: float = 30.0
    jump_iod: float = 0.08
    min_detection_confidence: float = 0.5
    min_tracking_confidence: float = 0.5
    language: str = "en"

    def __post_init__(self) -> None:
        if self.audio_rate_hz not in (8000, 16000, 22050, 44100, 48000):
            raise ConfigError(f"audio_rate_hz must be 8000/16000/22050/44100/48000, got {self.audio_rate_hz}")
        if not 0.0 < self.neutral_quantile <= 0.5:
            raise ConfigError(f"neutral_quantile must be in (0, 0.5], got {self.neutral_quantile}")
        if not 0.0 < self.closed_quantile <= 0.5:
            raise ConfigError(f"closed_quantile must be in (0, 0.5], got {self.closed_quantile}")
        if not 0.0 < self.quiet_quantile <= 0.5:
            raise ConfigError(f"quiet_quantile must be in (0, 0.5], got {self.quiet_quantile}")
        if not 0.0 < self.min_face_fraction <= 1.0:
            raise ConfigError(f"min_face_fraction must be in (0, 1], got {self.min_face_fraction}")
        for name in ("max_gap_s", "max_av_mismatch_s", "jump_iod"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.rest_margin_s < 0 or self.min_rest_frames < 1:
            raise ConfigError("rest_margin_s must be >= 0 and min_rest_frames >= 1")


# --------------------------------------------------------------------------- ffmpeg
_DAMAGE = re.compile(
    r"damaged|corrupt|truncat|incomplete|partial file|error while decoding|invalid nal|"
    r"missing picture|concealing|end of file",
    re.I,
)


def decode_audio(path: Path, rate_hz: int) -> np.ndarray:
    """(n,) float32 mono audio of a media file at ``rate_hz`` (the one ffmpeg decoder,
    :func:`assets.audio.read_audio`)."""
    return read_audio(path, rate_hz=rate_hz)[0]


# --------------------------------------------------------------------------- landmarks (MediaPipe)
class FaceMeshTracker:
    """One MediaPipe face-mesh graph (video mode), reused for many clips: :meth:`track` resets
    the tracking state first, so clips never see each other. Not thread-safe; one per process."""

    def __init__(self, config: ExtractConfig) -> None:
        # MediaPipe's C++ logging (glog/absl) floods stderr with per-graph notices; keep warnings+.
        os.environ.setdefault("GLOG_minloglevel", "2")
        os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
        try:
            import mediapipe as mp  # lazy: optional extra "video"
        except ImportError as exc:
            raise MissingDependencyError(
                "facecast extract needs MediaPipe: pip install 'facecast[video]' (mediapipe==0.10.14)"
            ) from exc
        self._mp, self._config = mp, config
        # Made on the first clip, inside its silenced window: its threads log while it starts up,
        # after the constructor has returned (one line leaked while the first clip was decoded).
        self._mesh: Any = None

    def track(self, frames: np.ndarray, *, progress=None) -> np.ndarray:
        """(n, H, W, 3) uint8 RGB -> (n, 468, 3) float32 pixels (x W, y H, z W), NaN where no face.
        Without ``progress`` the graph's C++ notices are kept off stderr (they come from its threads
        while the first frames run, so the whole clip is silenced; a progress bar keeps stderr)."""
        if progress is not None:
            return self._track(frames, progress)
        with native_stderr_quiet():
            return self._track(frames, None)

    def _track(self, frames: np.ndarray, progress) -> np.ndarray:
        import warnings

        if self._mesh is None:
            self._mesh = self._mp.solutions.face_mesh.FaceMesh(
                static_image_mode=False,
                max_num_faces=1,
                refine_landmarks=True,
                min_detection_confidence=self._config.min_detection_confidence,
                min_tracking_confidence=self._config.min_tracking_confidence,
            )
        else:
            self._mesh.reset()
        n, h, w, _ = frames.shape
        out = np.full((n, N_LANDMARKS, 3), np.nan, dtype=np.float32)
        wrap = progress or (lambda it, **_: it)
        with warnings.catch_warnings():
            # mediapipe 0.10.14 calls a protobuf API that protobuf 4.25 marks deprecated, per frame
            warnings.filterwarnings("ignore", message="SymbolDatabase.GetPrototype", category=UserWarning)
            for k in wrap(range(n), total=n, desc="face mesh", unit="frame", leave=False):
                res = self._mesh.process(frames[k])
                if res.multi_face_landmarks:
                    lm = res.multi_face_landmarks[0].landmark
                    out[k] = np.array([(p.x * w, p.y * h, p.z * w) for p in lm[:N_LANDMARKS]], dtype=np.float32)
        return out

    def close(self) -> None:
        if self._mesh is not None:
            self._mesh.close()


def file_sha1(path: Path) -> str:
    """SHA-1 (hex) of a file's bytes: the cache key of its measurement."""
    h = hashlib.sha1()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def measure_raw(
    path: str | Path, config: ExtractConfig, tracker: FaceMeshTracker, *, sha1: str | None = None, progress=None
) -> RawTrack:
    """Decode one video and track its face: the cached, expensive part (module doc, steps 1-2)."""
    path = Path(path)
    info, v, fps = probe_picture(path)
    if info["audio"] is None:
        raise NotAudioError(path, "not audio: the video has no audio track")
    width, height = int(v["width"]), int(v["height"])
    declared = float(v.get("duration") or info["format"].get("duration") or 0.0)
    frames, err = decode_frames(path, width, height)
    n_expected = int(round(declared * fps))
    if len(frames) == 0 or (n_expected and len(frames) < 0.95 * n_expected):
        raise TruncatedFileError(
            path, f"truncated video: decoded {len(frames)} of {n_expected} frames" + (f" ({err[-160:]})" if err else "")
        )
    # A cut MPEG program stream still parses: its duration is estimated from what is left, so
    # the frame count matches. The decoder's complaints about the cut-off picture give it away.
    if _DAMAGE.search(err):
        first = next(ln for ln in err.splitlines() if _DAMAGE.search(ln))
        raise TruncatedFileError(path, f"truncated or damaged video: ffmpeg reports {first.strip()[-120:]!r}")
    samples = decode_audio(path, config.audio_rate_hz)
    if is_silent(samples):
        raise SilentAudioError(path, "silent: the audio track holds no signal")
    times = frame_times(info, len(frames), fps)
    audio_s, video_s = len(samples) / config.audio_rate_hz, times[-1] + 1.0 / fps
    if abs(audio_s - video_s) > config.max_av_mismatch_s:
        raise LengthMismatchError(
            path,
            f"audio ({audio_s:.2f} s) and video ({video_s:.2f} s) differ in length by "
            f"more than {config.max_av_mismatch_s} s",
        )
    lms = tracker.track(frames, progress=progress)
    pcm = np.clip(np.round(samples * 32768.0), -32768, 32767).astype(np.int16)
    return RawTrack(
        source=path,
        sha1=sha1 or file_sha1(path),
        samples=pcm,
        sample_rate_hz=config.audio_rate_hz,
        video_landmarks=lms,
        video_times_s=times,
        video_fps=fps,
        width=width,
        height=height,
    )


# --------------------------------------------------------------------------- geometry
def remove_head_pose(landmarks: np.ndarray, iterations: int = 3) -> tuple[np.ndarray, float, np.ndarray]:
    """Align every frame's face to the clip's Procrustes-mean face, in the face frame, IOD units.

    landmarks: (n, 468, 3) pixels, no NaN. Returns (face (n, 468, 3) float64 in IOD units, with
    the origin midway between the eye centres, x = the subject's right-to-left eye axis, y down
    the face; iod_px of the mean face; residual (n,) RMS distance of the STABLE points from the
    mean face after the fit, IOD).
    """
    stable = list(STABLE)
    ref = landmarks[0].astype(np.float64)
    aligned = landmarks.astype(np.float64)
    for _ in range(iterations):
        for k in range(len(landmarks)):
            s, r, t = similarity_fit(landmarks[k, stable], ref[stable])
            aligned[k] = s * landmarks[k] @ r.T + t
        ref = aligned.mean(axis=0)
    eye_r = ref[list(RIGHT_EYE_CORNERS)].mean(0)
    eye_l = ref[list(LEFT_EYE_CORNERS)].mean(0)
    mouth = ref[[UPPER_LIP_OUTER, LOWER_LIP_OUTER]].mean(0)
    origin = 0.5 * (eye_r + eye_l)
    iod = float(np.linalg.norm(eye_l - eye_r))
    x = (eye_l - eye_r) / iod
    y = mouth - origin
    y -= (y @ x) * x
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    basis = np.stack([x, y, z])  # rows: face axes in image coordinates
    face = (aligned - origin) @ basis.T / iod
    ref_face = (ref - origin) @ basis.T / iod
    residual = np.sqrt(np.mean(np.sum((face[:, stable] - ref_face[stable]) ** 2, axis=2), axis=1))
    return face, iod, residual


def _fill_gaps(x: np.ndarray, found: np.ndarray) -> np.ndarray:
    """Linear interpolation over the frames where ``found`` is False of an (n, ...) array (edges held)."""
    flat = x.reshape(len(x), -1)
    ok = np.flatnonzero(found)
    if len(ok) == 1:
        return np.repeat(flat[ok], len(x), axis=0).reshape(x.shape)
    idx = np.arange(len(x))
    pos = np.clip(np.searchsorted(ok, idx), 1, len(ok) - 1)
    lo, hi = ok[pos - 1], ok[pos]
    w = np.clip((idx - lo) / (hi - lo), 0.0, 1.0)[:, None]
    out = (1 - w) * flat[lo] + w * flat[hi]
    out[found] = flat[found]
    return out.reshape(x.shape)


def _resample_at(times: np.ndarray, values: np.ndarray, t_out: np.ndarray) -> np.ndarray:
    """Linear interpolation of (n, ...) ``values`` sampled at increasing ``times`` onto ``t_out``
    (values beyond either end held)."""
    flat = values.reshape(len(values), -1)
    pos = np.clip(np.searchsorted(times, t_out, side="right"), 1, len(times) - 1)
    t0, t1 = times[pos - 1], times[pos]
    w = np.clip((t_out - t0) / np.maximum(t1 - t0, 1e-12), 0.0, 1.0)[:, None]
    if len(times) == 1:
        return np.repeat(flat[:1], len(t_out), axis=0).reshape((len(t_out), *values.shape[1:]))
    return ((1 - w) * flat[pos - 1] + w * flat[pos]).reshape((len(t_out), *values.shape[1:]))


def lip_gap(landmarks: np.ndarray) -> np.ndarray:
    """Inner-lip gap, (n, 468, 3) -> (n,): the mean 3D distance of the three midline pairs of
    inner-lip points (:data:`LIP_GAP_PAIRS`; three pairs halve the frame-to-frame jitter of one)."""
    lm = np.asarray(landmarks, np.float64)
    return np.mean([np.linalg.norm(lm[:, a] - lm[:, b], axis=1) for a, b in LIP_GAP_PAIRS], axis=0)


def mouth_params(landmarks: np.ndarray, neutral: np.ndarray, *, closed_gap: float | None = None) -> np.ndarray:
    """The four mouth parameters of :mod:`training.params` from pose-free landmarks.

    landmarks: (n, 468, 3) face frame, IOD units; neutral: (468, 3) the rest face, same frame;
    closed_gap: the inner-lip gap (IOD, :func:`lip_gap`) when the lips touch, the zero of
    mouth_open (default: the neutral face's gap, for a talker whose lips are closed at rest).
    Returns (n, 4) float64 IOD: [upper_lip_raise, lip_stretch, mouth_open, lip_corner_depress].
    """
    lm = np.concatenate([np.asarray(landmarks, np.float64), np.asarray(neutral, np.float64)[None]], axis=0)
    upper_y = lm[:, list(UPPER_LIP_MIDDLE), 1].mean(axis=1)
    width = np.linalg.norm(lm[:, MOUTH_CORNERS[0]] - lm[:, MOUTH_CORNERS[1]], axis=1)
    gap = lip_gap(lm)
    midline_y = 0.5 * (lm[:, UPPER_LIP_OUTER, 1] + lm[:, LOWER_LIP_OUTER, 1])
    corners_y = 0.5 * (lm[:, MOUTH_CORNERS[0], 1] + lm[:, MOUTH_CORNERS[1], 1])
    raw = np.stack([-upper_y, width, gap, corners_y - midline_y], axis=1)
    out = raw[:-1] - raw[-1]
    if closed_gap is not None:
        out[:, 2] = gap[:-1] - closed_gap
    return out


def closed_lip_gap(gap: np.ndarray, rest_gap: float, quantile: float = 0.05) -> float:
    """The inner-lip gap when the lips touch (IOD): the mean of the smallest ``quantile`` of a
    clip's gaps (its bilabial closures and closed rest), never above the rest gap."""
    gap = np.sort(np.asarray(gap, np.float64))
    k = max(1, int(round(quantile * len(gap))))
    return float(min(gap[:k].mean(), rest_gap))


def frame_energy_db(samples: np.ndarray, rate_hz: int, n_frames: int, window_s: float = 0.04) -> np.ndarray:
    """(n_frames,) RMS level in dB of a ``window_s`` window centred on each 30 fps frame time."""
    half = int(window_s * rate_hz / 2)
    centres = (np.arange(n_frames) * rate_hz / FPS).astype(int)
    out = np.empty(n_frames)
    for k, c in enumerate(centres):
        seg = samples[max(c - half, 0) : c + half]
        out[k] = 10 * np.log10(np.mean(np.square(seg, dtype=np.float64)) + 1e-10) if len(seg) else -100.0
    return out


def rest_frames(
    n_frames: int, words: Words | None, level_db: np.ndarray, config: ExtractConfig
) -> tuple[np.ndarray, str]:
    """(n_frames,) bool rest mask and how it was found ("silence" from the alignment, "quiet" from
    the audio level); see the module doc, step 6."""
    t = np.arange(n_frames) / FPS
    if words:
        rest = np.zeros(n_frames, bool)
        speech = [(a, b) for a, b, w in words if w.lower() not in SILENCE_WORDS]
        for a, b, w in words:
            if w.lower() not in SILENCE_WORDS:
                continue
            lo, hi = a, b
            # shrink only on the sides that touch speech (the clip's edges are rest anyway)
            if any(abs(se - a) < 1e-3 for _, se in speech):
                lo = a + config.rest_margin_s
            if any(abs(ss - b) < 1e-3 for ss, _ in speech):
                hi = b - config.rest_margin_s
            rest |= (t >= lo) & (t < hi)
        return rest, "silence"
    quiet = (level_db <= np.quantile(level_db, config.quiet_quantile)) & (
        level_db <= level_db.max() - config.quiet_below_db
    )
    return quiet, "quiet"


def derive_track(
    raw: RawTrack, words: Words | None = None, config: ExtractConfig = ExtractConfig(), *, alignment: Path | None = None
) -> FaceTrack:
    """A :class:`FaceTrack` from the cached raw measurement (module doc, steps 3-7).

    words: the clip's word alignment [(start_s, end_s, word)] (``sil``/``sp`` = silence) or None.
    Raises :class:`NoFaceError` when the face is missing too often or for too long.
    """
    path = raw.source
    lms = raw.video_landmarks
    found_v = ~np.isnan(lms[:, :, 0]).any(axis=1)
    n_v = len(found_v)
    fraction = float(found_v.mean()) if n_v else 0.0
    if not found_v.any():
        raise NoFaceError(path, f"no face found in {n_v} of {n_v} frames")
    # longest stretch without a face
    runs, cur = [], 0
    for ok in found_v:
        cur = 0 if ok else cur + 1
        runs.append(cur)
    longest_gap_s = max(runs, default=0) / raw.video_fps
    if longest_gap_s > config.max_gap_s:
        k_end = int(np.argmax(runs))
        t0 = raw.video_times_s[k_end - max(runs) + 1]
        raise NoFaceError(
            path, f"face lost for {longest_gap_s:.2f} s from {t0:.2f} s (longest allowed gap {config.max_gap_s} s)"
        )
    if fraction < config.min_face_fraction:
        raise NoFaceError(
            path,
            f"no face found in {int((~found_v).sum())} of {n_v} frames "
            f"(need a face in at least {config.min_face_fraction:.0%})",
        )
    face_v, iod_px, residual = remove_head_pose(_fill_gaps(lms, found_v))
    # tracking jumps: the lower face moving implausibly far between consecutive tracked frames
    step = np.median(np.linalg.norm(np.diff(face_v[:, list(LOWER_FACE)], axis=0), axis=2), axis=1)
    both = found_v[1:] & found_v[:-1]
    jumps = int(np.sum((step > config.jump_iod) & both))

    samples = raw.samples.astype(np.float32) / 32768.0
    n_out = n_frames_for(len(samples) / raw.sample_rate_hz)
    t_out = np.arange(n_out) / FPS
    landmarks = _resample_at(raw.video_times_s, face_v, t_out).astype(np.float32)
    pos = np.clip(np.searchsorted(raw.video_times_s, t_out, side="right"), 1, max(n_v - 1, 1))
    face_found = found_v[pos - 1] & found_v[np.minimum(pos, n_v - 1)]

    level = frame_energy_db(samples, raw.sample_rate_hz, n_out)
    rest, method = rest_frames(n_out, words, level, config)
    rest &= face_found
    if rest.sum() < config.min_rest_frames:
        gap = lip_gap(landmarks)
        rest = face_found & (gap <= np.quantile(gap[face_found], config.neutral_quantile))
        method = "smallest-gap"
    neutral = np.median(landmarks[rest], axis=0).astype(np.float32)
    gaps = lip_gap(landmarks)
    gap_rest = float(lip_gap(neutral[None])[0])
    closed = closed_lip_gap(gaps[face_found], gap_rest, config.closed_quantile)
    params = mouth_params(landmarks, neutral, closed_gap=closed)
    width_rest = float(np.linalg.norm(neutral[MOUTH_CORNERS[0]] - neutral[MOUTH_CORNERS[1]]))
    quality = {
        "file": str(path),
        "sha1": raw.sha1,
        "extractor_version": raw.extractor_version,
        "video_fps": raw.video_fps,
        "n_video_frames": n_v,
        "n_frames_30fps": n_out,
        "audio_s": round(len(samples) / raw.sample_rate_hz, 4),
        "video_s": round(float(raw.video_times_s[-1] + 1 / raw.video_fps) if n_v else 0.0, 4),
        "face_found_fraction": round(fraction, 4),
        "longest_gap_s": round(longest_gap_s, 3),
        "tracking_jumps": jumps,
        "max_lower_face_step_iod": round(float(step.max(initial=0.0)), 4),
        "pose_residual_iod_median": round(float(np.median(residual)), 5),
        "pose_residual_iod_max": round(float(residual.max()), 5),
        "iod_px": round(iod_px, 3),
        "alignment": str(alignment) if alignment else None,
        "neutral": {
            "method": method,
            "n_frames": int(rest.sum()),
            "lip_gap_iod": round(gap_rest, 4),
            "mouth_width_iod": round(width_rest, 4),
            "closed_lip_gap_iod": round(closed, 4),
            "mouth_open_at_rest": round(gap_rest - closed, 4),
        },
        "params_min": [round(float(v), 4) for v in params.min(axis=0)],
        "params_max": [round(float(v), 4) for v in params.max(axis=0)],
    }
    return FaceTrack(
        source=path,
        samples=samples,
        sample_rate_hz=raw.sample_rate_hz,
        landmarks=landmarks,
        neutral=neutral,
        params=params,
        face_found=face_found,
        closed_gap_iod=closed,
        quality=quality,
    )


# --------------------------------------------------------------------------- one clip, cached
def _words_for(video: Path, *, require: bool) -> tuple[list[tuple[float, float, str]] | None, Path | None]:
    """The word alignment of a video (assets.grid layout rules), or None when there is none
    (an error when ``require``). A malformed alignment is always an error."""
    align = align_for_video(video)
    if align is None:
        if require:
            raise FileProblem(video, "no word alignment found (missing .align)")
        return None, None
    return read_words(align), align


_TRACKER: FaceMeshTracker | None = None  # one per process (workers and the main process)


def _tracker(config: ExtractConfig) -> FaceMeshTracker:
    global _TRACKER
    if _TRACKER is None:
        _TRACKER = FaceMeshTracker(config)
    return _TRACKER


def _cached_raw(video: Path, config: ExtractConfig, cache_dir: Path | None, *, progress=None) -> tuple[RawTrack, bool]:
    """The raw measurement of ``video`` from the cache, measuring (and caching) it if missing.
    Returns (raw, was_cached)."""
    sha1 = file_sha1(video)
    cpath = cache_path(cache_dir, sha1, config.audio_rate_hz)
    if cpath.is_file():
        raw = read_raw(cpath)
        # the cache is keyed by content: report the path it was asked for, not the first one seen
        return RawTrack(**{**raw.__dict__, "source": video}), True
    raw = measure_raw(video, config, _tracker(config), sha1=sha1, progress=progress)
    write_raw(cpath, raw)
    return raw, False


def load_face_track(
    path_or_video: str | Path,
    *,
    cache_dir: str | Path | None = None,
    config: ExtractConfig = ExtractConfig(),
    words: Words | None = None,
    require_alignment: bool = False,
) -> FaceTrack:
    """The :class:`FaceTrack` of a video (or of a cache ``.npz``), measuring it if not cached.

    cache_dir: default ``$FACECAST_CACHE`` or ``~/.cache/facecast``. words: the word alignment;
    by default the one found beside the video (GRID layout, see :func:`assets.grid.align_for_video`).
    """
    path = Path(path_or_video)
    if path.suffix == ".npz":
        raw = read_raw(path)
        video = raw.source
    else:
        raw, _ = _cached_raw(path, config, Path(cache_dir) if cache_dir is not None else None)
        video = path
    align = None
    if words is None:
        words, align = _words_for(video, require=require_alignment)
    return derive_track(raw, words, config, alignment=align)


def measure_video(
    path: str | Path, config: ExtractConfig = ExtractConfig(), *, cache_dir: str | Path | None = None
) -> FaceTrack:
    """The :class:`FaceTrack` of one video (cached); the same as :func:`load_face_track`."""
    return load_face_track(path, cache_dir=cache_dir, config=config)


# --------------------------------------------------------------------------- a whole folder
@dataclass(frozen=True)
class ExtractReport:
    """What :func:`extract_corpus` did: per clip quality (ok clips), skipped clips with the reason,
    counts and the wall time."""

    clips: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    n_extracted: int = 0
    n_cached: int = 0
    seconds: float = 0.0
    workers: int = 1
    cache_dir: str = ""

    def as_json(self) -> dict:
        q = self.clips
        agg = {}
        if q:
            agg = {
                "face_found_fraction_min": min(c["face_found_fraction"] for c in q),
                "clips_with_jumps": sum(c["tracking_jumps"] > 0 for c in q),
                "clips_without_alignment": sum(c.get("alignment") is None for c in q),
                "neutral_methods": {
                    m: sum(c["neutral"]["method"] == m for c in q) for m in sorted({c["neutral"]["method"] for c in q})
                },
                "neutral_lip_gap_iod_median": round(float(np.median([c["neutral"]["lip_gap_iod"] for c in q])), 4),
                "neutral_mouth_width_iod_median": round(
                    float(np.median([c["neutral"]["mouth_width_iod"] for c in q])), 4
                ),
                "iod_px_median": round(float(np.median([c["iod_px"] for c in q])), 2),
            }
        return {
            "extractor_version": EXTRACTOR_VERSION,
            "cache_dir": self.cache_dir,
            "workers": self.workers,
            "n_videos": len(self.clips) + len(self.skipped),
            "n_ok": len(self.clips),
            "n_skipped": len(self.skipped),
            "n_extracted": self.n_extracted,
            "n_cached": self.n_cached,
            "seconds": round(self.seconds, 2),
            "summary": agg,
            "skipped": self.skipped,
            "clips": self.clips,
        }


def _work(job: tuple[str, ExtractConfig, str | None, bool]) -> dict:
    """One clip in a worker process: cache lookup or measurement, then derivation for the report.
    Never raises for a bad clip: returns {"status": "skipped", "reason": ...}."""
    video, config, cache_dir, require_alignment = job
    video_p = Path(video)
    t0 = time.perf_counter()
    try:
        raw, cached = _cached_raw(video_p, config, Path(cache_dir) if cache_dir else None)
        words, align = _words_for(video_p, require=require_alignment)
        track = derive_track(raw, words, config, alignment=align)
    except FileProblem as exc:
        # The file at fault named when it is not the clip (a malformed .align beside it: its line 1 was the clip's).
        reason = exc.problem if exc.path == video_p else f"{exc.path}: {exc.problem}"
        return {"file": video, "status": "skipped", "reason": reason}
    except OSError as exc:
        return {"file": video, "status": "skipped", "reason": f"cannot be read ({exc})"}
    return {
        "file": video,
        "status": "cached" if cached else "extracted",
        "quality": track.quality,
        "seconds": round(time.perf_counter() - t0, 3),
    }


def _init_worker() -> None:
    # MediaPipe's C++ side writes notices to stderr for every graph (absl, not silenced by
    # GLOG_minloglevel); a worker reports through its return value, so its stderr goes to /dev/null
    # instead of tearing the progress bar. Python exceptions still reach the parent through the pool.
    os.environ.setdefault("GLOG_minloglevel", "2")
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    os.close(devnull)


def find_videos(inputs: Sequence[str | Path]) -> list[Path]:
    """Video files among ``inputs`` (files, or folders searched recursively), sorted, unique."""
    return _folder_files(inputs, videos=True)


def passed_over(inputs: Sequence[str | Path]) -> list[Path]:
    """Files in the folders among ``inputs`` that :func:`find_videos` leaves out (no video suffix), sorted:
    ``facecast extract`` names them, so a container it does not know is not dropped silently."""
    return _folder_files(inputs, videos=False)


def _folder_files(inputs: Sequence[str | Path], *, videos: bool) -> list[Path]:
    out: set[Path] = set()
    for item in map(Path, inputs):
        if item.is_dir():
            out.update(
                p
                for p in item.rglob("*")
                if (p.suffix.lower() in VIDEO_SUFFIXES) == videos and p.is_file() and not p.name.startswith(".")
            )
        elif videos:
            out.add(item)
    return sorted(out)


def extract_corpus(
    videos: Sequence[str | Path],
    *,
    cache_dir: str | Path | None = None,
    workers: int = 2,
    config: ExtractConfig = ExtractConfig(),
    require_alignment: bool = False,
    progress: Callable | None = None,
    log: Callable[[str], None] | None = None,
) -> ExtractReport:
    """Measure every video into the cache, ``workers`` processes in parallel (one MediaPipe graph
    each); clips already cached cost a hash and a load. A bad clip is skipped with one line
    (``log``) naming it and the reason, and counted; it never aborts the run."""
    videos = find_videos(videos)
    cdir = str(Path(cache_dir) if cache_dir is not None else default_cache_dir())
    jobs = [(str(v), config, cdir, require_alignment) for v in videos]
    say = log or (lambda line: print(line, file=sys.stderr))
    wrap = progress or (lambda it, **_: it)
    t0 = time.perf_counter()
    results = []
    if workers <= 1 or len(jobs) <= 1:
        it: Iterator[dict] = map(_work, jobs)
        results = _collect(wrap(it, total=len(jobs), desc="extract", unit="clip"), say)
    else:
        ctx = multiprocessing.get_context("spawn")  # MediaPipe's graph threads do not survive fork
        with ctx.Pool(min(workers, len(jobs)), initializer=_init_worker) as pool:
            it = pool.imap_unordered(_work, jobs, chunksize=1)
            results = _collect(wrap(it, total=len(jobs), desc="extract", unit="clip"), say)
    ok = sorted((r for r in results if r["status"] != "skipped"), key=lambda r: r["file"])
    skipped = sorted(
        ({"file": r["file"], "reason": r["reason"]} for r in results if r["status"] == "skipped"),
        key=lambda r: r["file"],
    )
    return ExtractReport(
        clips=[r["quality"] for r in ok],
        skipped=skipped,
        n_extracted=sum(r["status"] == "extracted" for r in ok),
        n_cached=sum(r["status"] == "cached" for r in ok),
        seconds=time.perf_counter() - t0,
        workers=workers,
        cache_dir=cdir,
    )


def _collect(results, say: Callable[[str], None]) -> list[dict]:
    out = []
    for r in results:
        if r["status"] == "skipped":
            say(f"skipped {r['file']}: {r['reason']}")
        elif r["quality"].get("alignment") is None:
            # Kept without a word alignment (a talker's own video has none), but said: its rest pose then comes from
            # the audio level or the smallest lip gaps, not the aligned silences, and a corpus build for training
            # skips such clips (--require-alignment). Counted in the report's summary (clips_without_alignment).
            say(f"no word alignment for {r['file']}: kept, its rest pose without one (--require-alignment skips it)")
        out.append(r)
    return out


def write_report(report: ExtractReport, path: Path) -> Path:
    """The report as JSON (atomic)."""
    write_json(Path(path), report.as_json())
    return Path(path)


# --------------------------------------------------------------------------- corpus folder, plots
def grid_split_of(video: Path) -> str | None:
    """The GRID split of a video whose stem is a GRID sentence id (assets.grid), else None."""
    from assets.grid import sentence_text, split_of

    try:
        sentence_text(video.stem)
    except ValueError:
        return None
    return split_of(video.stem)


def write_track_corpus(tracks: Sequence[FaceTrack], out_dir: Path, *, language: str = "en") -> Path:
    """Write tracks as a corpus folder (source "video"; manifest extras: origin, grid_split,
    face_found_fraction). Returns the manifest path."""
    entries = []
    for track in tracks:
        video = Path(track.source)
        uid = f"video-{video.stem}"
        extra = {
            "origin": video.name,
            "face_found_fraction": track.quality.get("face_found_fraction"),
            "iod_px": track.quality.get("iod_px"),
        }
        split = grid_split_of(video)
        if split is not None:
            extra["grid_split"] = split
        entries.append(
            write_utterance(
                out_dir,
                utt_id=uid,
                samples=track.samples,
                sample_rate_hz=track.sample_rate_hz,
                params=track.params,
                phonemes=(),
                language=language,
                voice=f"video:{video.stem}",
                source="video",
                speaker_group=f"video:{video.stem}",
                extra=extra,
            )
        )
    return write_manifest(Path(out_dir), entries, seed=None)


def save_plot(track: FaceTrack, png: Path, words: Words | None = None) -> Path:
    """PNG: the four parameters over time with the audio level and words (left), and the neutral
    face's landmarks with the lower-face groups (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from training.params import PARAM_NAMES

    t = np.arange(len(track.params)) / FPS
    energy = frame_energy_db(track.samples, track.sample_rate_hz, len(track.params))
    fig = plt.figure(figsize=(14, 5.5))
    gs = fig.add_gridspec(2, 2, width_ratios=[3, 1], height_ratios=[3, 1])
    ax, ax2, ax3 = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[1, 0]), fig.add_subplot(gs[:, 1])
    colours = ("tab:blue", "tab:green", "black", "tab:purple")
    for j, (name, col) in enumerate(zip(PARAM_NAMES, colours)):
        ax.plot(t, track.params[:, j], color=col, lw=2 if name == "mouth_open" else 1, label=name)
    lost = ~track.face_found
    if lost.any():
        ax.plot(t[lost], track.params[lost, 2], "x", color="tab:red", label="face not found (interpolated)")
    ax.axhline(0, color="grey", lw=0.5)
    ax.set_ylabel("IOD units")
    ax.legend(loc="upper right", fontsize=7)
    ax2.plot(t, energy, color="tab:orange")
    ax2.set_ylabel("audio dB")
    ax2.set_xlabel("time (s)")
    ax2.sharex(ax)
    for a0, a1, w in words or []:
        for axis in (ax, ax2):
            axis.axvline(a0, color="grey", lw=0.5, ls=":")
        if w.lower() in SILENCE_WORDS:
            ax.axvspan(a0, a1, color="grey", alpha=0.1)
            continue
        bil = any(c in w.lower() for c in "pbm")
        ax.text(
            0.5 * (a0 + a1),
            ax.get_ylim()[1] * 0.92,
            w,
            ha="center",
            fontsize=9,
            color="tab:red" if bil else "black",
            weight="bold" if bil else "normal",
        )
    q = track.quality
    ax.set_title(
        f"{Path(track.source).name}: face in {q.get('face_found_fraction', 0):.0%} of frames, "
        f"{q.get('tracking_jumps', 0)} jumps, neutral from {q.get('neutral', {}).get('method')} "
        f"({q.get('neutral', {}).get('n_frames')} frames)",
        fontsize=9,
    )
    nf = track.neutral
    ax3.plot(nf[:, 0], nf[:, 1], ".", ms=1.5, color="lightgrey")
    for group, col, name in (
        (JAW, "tab:brown", "jaw"),
        (CHEEKS, "tab:olive", "cheeks"),
        (LIPS_OUTER, "tab:red", "lips outer"),
        (LIPS_INNER, "tab:pink", "lips inner"),
    ):
        ax3.plot(nf[list(group), 0], nf[list(group), 1], "o", ms=3, color=col, label=name)
    ax3.invert_yaxis()
    ax3.set_aspect("equal")
    ax3.set_title("neutral face (face frame, IOD)", fontsize=9)
    ax3.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=80)
    plt.close(fig)
    return png
