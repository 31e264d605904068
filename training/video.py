"""Mouth parameters measured on a talking-face video (``facecast extract``).

Theory of operation
-------------------
1. **Decode.** ffprobe reads the streams (frame rate, size, start times); ffmpeg decodes the
   audio to mono 16-bit PCM at ``audio_rate_hz`` and the video to raw RGB frames. A video
   whose decoded frame count falls short of its declared duration is truncated.
2. **Landmarks.** MediaPipe's face mesh (468 3D landmarks + iris, video mode so it tracks
   between frames) gives per frame normalised ``x, y`` (image width/height = 1) and ``z``
   (same scale as ``x``); we convert to pixels: ``(x W, y H, z W)``. Frames without a face
   are filled by linear interpolation; too few faces is an error.
3. **Head pose removed.** The rigid part of the face (forehead, nose bridge, eye corners,
   temples: :data:`STABLE` - never lips or jaw) of every frame is aligned to a reference by
   a similarity Procrustes fit (rotation, translation and uniform scale: Umeyama 1991); the
   reference is the iterated Procrustes mean of the clip. The reference is then expressed
   in a face frame: x from the subject's right eye centre to the left, y downwards (towards
   the mouth, orthogonal to x in the image plane of the mean face), z = x cross y. So "up"
   is the face's own up, whatever the head does.
4. **Measure** (definitions in :mod:`training.params`, unit = the reference's inter-ocular
   distance between eye-corner midpoints): upper-lip outer midpoint height, mouth-corner
   distance, inner-lip gap (upper inner midpoint to lower inner midpoint, 3D distance),
   corner height relative to the mean of the outer lip midpoints.
5. **Neutral.** The neutral pose is estimated from the clip itself: the median of each raw
   measurement over the frames whose inner-lip gap is in the lowest ``neutral_quantile``
   (lips closed and at rest; talking-face clips start and end at rest). Each parameter is
   the raw measurement minus its neutral value.
6. **Resample** from the video rate (25 fps for GRID) to exactly 30 fps by linear
   interpolation at ``t = k / 30`` (k = 0 .. ceil(audio duration * 30) - 1), with the
   video's start time relative to the audio taken into account; values beyond the last
   video frame are held.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from assets.audio import SILENCE_PEAK
from realtime_core.face.registration import fit_similarity as similarity_fit
from realtime_core.features import loudness_db
from training.corpus import write_manifest, write_utterance
from training.errors import (
    ConfigError,
    MissingDependencyError,
    NoFaceError,
    NotAudioError,
    NotVideoError,
    SilentAudioError,
    TruncatedFileError,
)
from training.params import FPS, N_PARAMS, n_frames_for

# MediaPipe face-mesh landmark indices (canonical_face_model.obj numbering).
UPPER_LIP_OUTER, UPPER_LIP_INNER, LOWER_LIP_INNER, LOWER_LIP_OUTER = 0, 13, 14, 17
MOUTH_CORNERS = (61, 291)
RIGHT_EYE_CORNERS = (33, 133)  # the subject's right eye (image left in a frontal video)
LEFT_EYE_CORNERS = (362, 263)
STABLE = (10, 151, 9, 8, 168, 6, 197, 195, 5, 4, 33, 133, 362, 263, 127, 356, 70, 300, 105, 334, 46, 276, 108, 337)
"""Landmarks that move with the skull only: forehead, nose bridge/tip, eye corners, brows' outer
ends, temples. Used for the pose fit; lips, cheeks and jaw are excluded."""

VIDEO_SUFFIXES = (".mp4", ".mpg", ".mpeg", ".webm", ".mov", ".avi", ".mkv")
WORD_ALIGN_UNIT_S = 1.0 / 25000.0
"""GRID ``.align`` times are in 1/25000 s (1000 units per 25 fps frame): a 3 s clip ends at 75000."""


@dataclass(frozen=True)
class ExtractConfig:
    """Settings of :func:`extract_video`.

    audio_rate_hz:     rate of the extracted audio (mono int16).
    neutral_quantile:  fraction of frames (smallest inner-lip gap) that defines the neutral pose.
    min_face_fraction: below this fraction of frames with a face the video is refused.
    min_detection_confidence / min_tracking_confidence: MediaPipe face-mesh thresholds.
    language:          language code written to the manifest.
    """

    audio_rate_hz: int = 16000
    neutral_quantile: float = 0.1
    min_face_fraction: float = 0.8
    min_detection_confidence: float = 0.5
    min_tracking_confidence: float = 0.5
    language: str = "en"

    def __post_init__(self) -> None:
        if self.audio_rate_hz not in (8000, 16000, 22050, 44100, 48000):
            raise ConfigError(f"audio_rate_hz must be 8000/16000/22050/44100/48000, got {self.audio_rate_hz}")
        if not 0.0 < self.neutral_quantile <= 0.5:
            raise ConfigError(f"neutral_quantile must be in (0, 0.5], got {self.neutral_quantile}")
        if not 0.0 < self.min_face_fraction <= 1.0:
            raise ConfigError(f"min_face_fraction must be in (0, 1], got {self.min_face_fraction}")


@dataclass(frozen=True)
class VideoTrack:
    """What :func:`measure_video` returns.

    samples:          (n,) float32 mono audio in [-1, 1] at ``sample_rate_hz``.
    params:           (ceil(n / rate * 30), 4) float64 mouth parameters at 30 fps, IOD units.
    video_params:     (n_video_frames, 4) the same at the video's own frame times (before resampling).
    video_times_s:    (n_video_frames,) frame times on the audio's clock, seconds.
    face_fraction:    fraction of video frames in which a face was found.
    iod_px:           inter-ocular distance of the reference face, pixels.
    """

    path: Path
    samples: np.ndarray
    sample_rate_hz: int
    params: np.ndarray
    video_params: np.ndarray
    video_times_s: np.ndarray
    video_fps: float
    face_fraction: float
    iod_px: float


# --------------------------------------------------------------------------- ffmpeg
_DAMAGE = re.compile(r"damaged|corrupt|truncat|incomplete|partial file|error while decoding|invalid nal|"
                     r"missing picture|concealing|end of file", re.I)
def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise MissingDependencyError(f"{name} is not installed (Debian package ffmpeg)")
    return path


def probe(path: Path) -> dict:
    """ffprobe's stream list of ``path`` as {"video": {...}|None, "audio": {...}|None}."""
    cmd = [_tool("ffprobe"), "-v", "error", "-show_entries",
           "stream=codec_type,width,height,r_frame_rate,avg_frame_rate,start_time,duration,sample_rate,nb_frames"
           ":format=duration", "-of", "json", str(path)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        msg = proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"ffprobe exit {proc.returncode}"
        with path.open("rb") as fh:
            head = fh.read(12)
        # an MP4 (valid "ftyp" box first) cut before its index (moov) was written
        if "moov atom not found" in proc.stderr and head[4:8] == b"ftyp":
            raise TruncatedFileError(path, "truncated video: the MP4 index (moov atom) is missing")
        raise NotVideoError(path, f"not a video: ffprobe cannot read it ({msg})")
    doc = json.loads(proc.stdout or "{}")
    streams = doc.get("streams", [])
    pick = lambda kind: next((s for s in streams if s.get("codec_type") == kind), None)  # noqa: E731
    return {"video": pick("video"), "audio": pick("audio"), "format": doc.get("format", {})}


def _rate(s: dict) -> float:
    for key in ("avg_frame_rate", "r_frame_rate"):
        v = s.get(key, "0/0")
        try:
            f = Fraction(v)
        except (ValueError, ZeroDivisionError):
            continue
        if f > 0:
            return float(f)
    return 0.0


def decode_audio(path: Path, rate_hz: int) -> np.ndarray:
    """(n,) float32 mono audio of a media file at ``rate_hz``."""
    cmd = [_tool("ffmpeg"), "-v", "error", "-nostdin", "-i", str(path), "-vn", "-ac", "1", "-ar", str(rate_hz),
           "-f", "s16le", "-acodec", "pcm_s16le", "pipe:1"]
    proc = subprocess.run(cmd, capture_output=True)
    if proc.returncode != 0 or not proc.stdout:
        raise NotAudioError(path, f"not audio: ffmpeg cannot decode an audio stream ({proc.stderr.decode(errors='replace').strip()[-200:]})")
    return np.frombuffer(proc.stdout, "<i2").astype(np.float32) / 32768.0


def decode_frames(path: Path, width: int, height: int) -> tuple[np.ndarray, str]:
    """(n_frames, height, width, 3) uint8 RGB frames and ffmpeg's error text (may be empty)."""
    cmd = [_tool("ffmpeg"), "-v", "error", "-nostdin", "-i", str(path), "-an", "-f", "rawvideo",
           "-pix_fmt", "rgb24", "-vsync", "passthrough", "pipe:1"]
    proc = subprocess.run(cmd, capture_output=True)
    size = width * height * 3
    n = len(proc.stdout) // size
    frames = np.frombuffer(proc.stdout[: n * size], np.uint8).reshape(n, height, width, 3)
    return frames, proc.stderr.decode(errors="replace").strip()


# --------------------------------------------------------------------------- landmarks
def track_landmarks(frames: np.ndarray, cfg: ExtractConfig, *, progress=None) -> np.ndarray:
    """MediaPipe face mesh on every frame: (n_frames, 468, 3) pixels (x W, y H, z W), NaN
    where no face was found."""
    import os

    # MediaPipe's C++ logging (glog/absl) floods stderr with per-graph notices; keep warnings+.
    os.environ.setdefault("GLOG_minloglevel", "2")
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    try:
        import mediapipe as mp  # lazy: optional extra "video"
    except ImportError as exc:
        raise MissingDependencyError(
            "facecast extract needs MediaPipe: pip install 'facecast[video]' (mediapipe==0.10.14)"
        ) from exc
    n, h, w, _ = frames.shape
    out = np.full((n, 468, 3), np.nan)
    wrap = progress or (lambda it, **_: it)
    import warnings

    with warnings.catch_warnings(), mp.solutions.face_mesh.FaceMesh(
        static_image_mode=False, max_num_faces=1, refine_landmarks=True,
        min_detection_confidence=cfg.min_detection_confidence, min_tracking_confidence=cfg.min_tracking_confidence,
    ) as mesh:
        # mediapipe 0.10.14 calls a protobuf API that protobuf 4.25 marks deprecated, per frame
        warnings.filterwarnings("ignore", message="SymbolDatabase.GetPrototype", category=UserWarning)
        for k in wrap(range(n), total=n, desc="face mesh", unit="frame", leave=False):
            res = mesh.process(frames[k])
            if res.multi_face_landmarks:
                lm = res.multi_face_landmarks[0].landmark
                out[k] = np.array([(p.x * w, p.y * h, p.z * w) for p in lm[:468]])
    return out


def remove_head_pose(landmarks: np.ndarray, iterations: int = 3) -> tuple[np.ndarray, float]:
    """Align every frame's face to the clip's Procrustes-mean face, in the face frame.

    landmarks: (n, 468, 3) pixels, no NaN. Returns (aligned (n, 468, 3) in face-frame pixels,
    with x = the subject's right-to-left eye axis and y pointing down the face; iod_px).
    """
    stable = list(STABLE)
    ref = landmarks[0].copy()
    aligned = landmarks.copy()
    for _ in range(iterations):
        for k in range(len(landmarks)):
            s, r, t = similarity_fit(landmarks[k, stable], ref[stable])
            aligned[k] = s * landmarks[k] @ r.T + t
        ref = aligned.mean(axis=0)
    # face frame of the reference: origin between the eyes, x right->left eye, y down the face
    eye_r = ref[list(RIGHT_EYE_CORNERS)].mean(0)
    eye_l = ref[list(LEFT_EYE_CORNERS)].mean(0)
    mouth = ref[[UPPER_LIP_OUTER, LOWER_LIP_OUTER]].mean(0)
    origin = 0.5 * (eye_r + eye_l)
    x = (eye_l - eye_r) / np.linalg.norm(eye_l - eye_r)
    y = mouth - origin
    y -= (y @ x) * x
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    basis = np.stack([x, y, z])  # rows: face axes in image coordinates
    face = (aligned - origin) @ basis.T
    return face, float(np.linalg.norm(eye_l - eye_r))


def raw_measurements(face: np.ndarray) -> np.ndarray:
    """(n, 468, 3) face-frame points -> (n, 4) raw geometry in pixels (before neutral/IOD):
    [-y of upper-lip outer midpoint, corner distance, inner-lip gap, corner y - lip-midline y]."""
    upper = face[:, UPPER_LIP_OUTER]
    c1, c2 = face[:, MOUTH_CORNERS[0]], face[:, MOUTH_CORNERS[1]]
    gap = np.linalg.norm(face[:, UPPER_LIP_INNER] - face[:, LOWER_LIP_INNER], axis=1)
    midline_y = 0.5 * (face[:, UPPER_LIP_OUTER, 1] + face[:, LOWER_LIP_OUTER, 1])
    corners_y = 0.5 * (c1[:, 1] + c2[:, 1])
    return np.stack([-upper[:, 1], np.linalg.norm(c1 - c2, axis=1), gap, corners_y - midline_y], axis=1)


def _fill_gaps(x: np.ndarray) -> np.ndarray:
    """Linear interpolation over NaN frames of an (n, ...) array (edges held)."""
    flat = x.reshape(len(x), -1).copy()
    ok = ~np.isnan(flat[:, 0])
    idx = np.arange(len(x))
    for j in range(flat.shape[1]):
        flat[:, j] = np.interp(idx, idx[ok], flat[ok, j])
    return flat.reshape(x.shape)


# --------------------------------------------------------------------------- the pipeline
def measure_video(path: str | Path, config: ExtractConfig = ExtractConfig(), *, progress=None) -> VideoTrack:
    """Audio and 30 fps mouth parameters of one talking-face video (see the module doc)."""
    path = Path(path)
    if not path.is_file():
        raise NotVideoError(path, "not found")
    info = probe(path)
    v, a = info["video"], info["audio"]
    if v is None or int(v.get("width", 0) or 0) == 0:
        raise NotVideoError(path, "not a video: no video stream")
    if a is None:
        raise NotAudioError(path, "not audio: the video has no audio track")
    fps = _rate(v)
    if fps <= 0:
        raise NotVideoError(path, "not a video: unknown frame rate")
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
    if float(np.max(np.abs(samples), initial=0.0)) < SILENCE_PEAK:
        raise SilentAudioError(path, "silent: the audio track holds no signal")

    lms = track_landmarks(frames, config, progress=progress)
    found = ~np.isnan(lms[:, 0, 0])
    fraction = float(found.mean())
    if fraction < config.min_face_fraction:
        raise NoFaceError(
            path, f"no face found in {int((~found).sum())} of {len(found)} frames "
            f"(need a face in at least {config.min_face_fraction:.0%})"
        )
    face, iod = remove_head_pose(_fill_gaps(lms))
    raw = raw_measurements(face)
    gap = raw[:, 2]
    rest = gap <= np.quantile(gap, config.neutral_quantile)
    neutral = np.median(raw[rest], axis=0)
    video_params = (raw - neutral) / iod

    # frame j of the video is shown at start_v + j / fps on the container clock; audio starts at start_a
    start_v = float(v.get("start_time") or 0.0)
    start_a = float(a.get("start_time") or 0.0)
    times = start_v - start_a + np.arange(len(frames)) / fps
    n_out = n_frames_for(len(samples) / config.audio_rate_hz)
    t_out = np.arange(n_out) / FPS
    params = np.stack([np.interp(t_out, times, video_params[:, j]) for j in range(N_PARAMS)], axis=1)
    return VideoTrack(path, samples, config.audio_rate_hz, params, video_params, times, fps, fraction, iod)


def read_word_alignment(path: str | Path) -> list[tuple[float, float, str]]:
    """GRID ``.align`` words: [(start_s, end_s, word)], times in 1/25000 s units."""
    path = Path(path)
    out = []
    for line in path.read_text().splitlines():
        parts = line.split()
        if len(parts) == 3:
            out.append((int(parts[0]) * WORD_ALIGN_UNIT_S, int(parts[1]) * WORD_ALIGN_UNIT_S, parts[2]))
    return out


def find_word_alignment(video: Path) -> Path | None:
    """The ``.align`` of a video: same stem, or one whose stem ends the video's stem (GRID's
    ``id2_vcd_swwp2s.mpg`` <- ``swwp2s.align``)."""
    same = video.with_suffix(".align")
    if same.is_file():
        return same
    for cand in sorted(video.parent.glob("*.align")):
        if video.stem.endswith(cand.stem):
            return cand
    return None


def save_plot(track: VideoTrack, png: Path, words: list[tuple[float, float, str]] | None = None) -> Path:
    """PNG: mouth_open (and the other parameters, lighter) over time, audio level, words."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(track.params)) / FPS
    energy = loudness_db(track.samples, track.sample_rate_hz, len(track.params))
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax.plot(t, track.params[:, 2], "k-", lw=2, label="mouth_open (30 fps)")
    ax.plot(track.video_times_s, track.video_params[:, 2], "o", ms=3, color="tab:red", label="video frames")
    for j, (name, col) in enumerate(zip(("upper_lip_raise", "lip_stretch", None, "lip_corner_depress"),
                                        ("tab:blue", "tab:green", None, "tab:purple"))):
        if name:
            ax.plot(t, track.params[:, j], color=col, lw=1, alpha=0.7, label=name)
    ax.axhline(0, color="grey", lw=0.5)
    ax.set_ylabel("IOD units")
    ax.legend(loc="upper right", fontsize=7)
    ax2.plot(t, energy, color="tab:orange")
    ax2.set_ylabel("audio dB")
    ax2.set_xlabel("time (s)")
    for a0, a1, w in words or []:
        for axis in (ax, ax2):
            axis.axvline(a0, color="grey", lw=0.5, ls=":")
        bil = any(c in w.lower() for c in "pbm") and w != "sil"
        ax.text(0.5 * (a0 + a1), ax.get_ylim()[1] * 0.92, w, ha="center", fontsize=9,
                color="tab:red" if bil else "black", weight="bold" if bil else "normal")
    ax.set_title(f"{track.path.name}: face in {track.face_fraction:.0%} of frames, IOD {track.iod_px:.1f} px")
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return png


def extract_videos(videos: list[Path], out_dir: Path, config: ExtractConfig = ExtractConfig(), *,
                   plot: bool = False, progress=None) -> tuple[Path, list[VideoTrack]]:
    """Measure every video and write them as one corpus (source "video"). Returns the
    manifest path and the tracks (for reporting)."""
    out_dir = Path(out_dir)
    entries, tracks = [], []
    wrap = progress or (lambda it, **_: it)
    for video in wrap(list(videos), desc="videos", unit="video"):
        video = Path(video)
        track = measure_video(video, config, progress=progress)
        uid = f"video-{video.stem}"
        entries.append(write_utterance(
            out_dir, utt_id=uid, samples=track.samples, sample_rate_hz=track.sample_rate_hz, params=track.params,
            phonemes=(), language=config.language, voice=f"video:{video.stem}", source="video",
            speaker_group=f"video:{video.stem}",
            extra={"origin": video.name, "video_fps": track.video_fps, "face_fraction": round(track.face_fraction, 4),
                   "iod_px": round(track.iod_px, 3)},
        ))
        if plot:
            align = find_word_alignment(video)
            save_plot(track, out_dir / uid / "mouth_open.png", read_word_alignment(align) if align else None)
        tracks.append(track)
    return write_manifest(out_dir, entries, seed=None), tracks
