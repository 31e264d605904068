"""Pose-free 3D face landmark tracks of a talking face (:class:`FaceTrack`) and the cache file.

A :class:`FaceTrack` is what ``facecast extract`` measures on one talking-face video and what
every consumer of real faces codes against (real-lips training, Motion Units, unit selection):

- the audio (``samples``, ``sample_rate_hz``);
- ``landmarks``: (n_frames, 468, 3) float32 MediaPipe face-mesh points at 30 fps (frame k at
  k/30 s on the audio clock), head pose removed, in the **face frame** (origin midway between
  the eye centres, x from the subject's right eye to the left, y down the face, z = x cross y,
  i.e. pointing into the face, away from the camera) in **IOD units** (inter-ocular distance of
  the clip's mean face = 1). Positions are absolute, not relative to the neutral face;
- ``neutral``: (468, 3) float32 the face at rest in the same frame (see
  :func:`training.video.derive_track` for how rest is found);
- ``params``: (n_frames, 4) float64 the four mouth parameters (:mod:`training.params`);
- ``face_found``: (n_frames,) bool, False where the face was not tracked (those frames are
  interpolated from the nearest tracked ones).

Landmark index groups (MediaPipe numbering, canonical_face_model.obj): :data:`LIPS_OUTER`,
:data:`LIPS_INNER`, :data:`JAW`, :data:`CHEEKS`, and :data:`LOWER_FACE` = their union; :data:`MU_LANDMARKS`
(the Motion Units' 69: lips, chin midline, :data:`PERIORAL_CHEEKS`).

The **cache file** (one ``.npz`` per video, no pickle) keeps what is expensive to measure: the
decoded audio and the raw per-video-frame landmarks in image pixels (NaN where no face). Pose
removal, neutral and parameters are derived from it on load (milliseconds), so changing those
definitions never needs MediaPipe again. The file name is the SHA-1 of the video's bytes, in a
folder named after :data:`EXTRACTOR_VERSION` and the audio rate: the same content under another
name or path hits the cache; an edited file or a new extractor misses it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from assets.files import atomic_write_bytes
from training.errors import CorpusFormatError

N_LANDMARKS = 468
"""MediaPipe face-mesh landmarks kept (the 10 iris points of the refined mesh are dropped)."""

EXTRACTOR_VERSION = "mp0.10.14-fm1"
"""Version of the raw measurement kept in the cache (decoder + MediaPipe face mesh settings).
Bump it when anything that changes the cached raw landmarks or audio changes."""

# Outer lip contour, clockwise from the subject's right mouth corner (61) over the lower lip.
LIPS_OUTER: tuple[int, ...] = (
    61,
    146,
    91,
    181,
    84,
    17,
    314,
    405,
    321,
    375,
    291,
    409,
    270,
    269,
    267,
    0,
    37,
    39,
    40,
    185,
)
# Inner lip contour (the edge of the mouth opening), same order.
LIPS_INNER: tuple[int, ...] = (
    78,
    95,
    88,
    178,
    87,
    14,
    317,
    402,
    318,
    324,
    308,
    415,
    310,
    311,
    312,
    13,
    82,
    81,
    80,
    191,
)
# Jaw line from below the right ear over the chin to below the left ear, and the chin midline
# under the lower lip (18, 200, 199, 175).
JAW: tuple[int, ...] = (58, 172, 136, 150, 149, 176, 148, 152, 377, 400, 378, 379, 365, 397, 288, 18, 200, 199, 175)
# Cheeks and the skin around the mouth (nasolabial folds, mouth-corner muscles), mirrored pairs.
CHEEKS: tuple[int, ...] = (
    36,
    50,
    57,
    92,
    101,
    116,
    117,
    118,
    123,
    147,
    165,
    186,
    187,
    192,
    203,
    205,
    206,
    207,
    212,
    213,
    214,
    216,
    266,
    280,
    287,
    322,
    330,
    345,
    346,
    347,
    352,
    376,
    391,
    410,
    411,
    416,
    423,
    425,
    426,
    427,
    432,
    433,
    434,
    436,
)
LOWER_FACE: tuple[int, ...] = tuple(sorted(set(LIPS_OUTER) | set(LIPS_INNER) | set(JAW) | set(CHEEKS)))
"""Every landmark that moves with speech (lips, jaw, cheeks)."""

CHIN_MIDLINE: tuple[int, ...] = (18, 200, 199, 175, 152)
"""Skin points on the chin's midline from under the lower lip to the chin's tip."""
PERIORAL_CHEEKS: tuple[int, ...] = (
    36, 57, 92, 165, 186, 203, 205, 206, 207, 212, 214, 216,
    266, 287, 322, 391, 410, 423, 425, 426, 427, 432, 434, 436,
)  # fmt: skip
"""The 24 :data:`CHEEKS` landmarks nearest the mouth (within 0.83 IOD of the mouth centre on the GRID s1
neutral face), mirrored pairs: the cheek skin around the mouth, where paper 002 put its 24 cheek markers."""
MU_LANDMARKS: tuple[int, ...] = tuple(
    sorted(set(LIPS_OUTER) | set(LIPS_INNER) | set(CHIN_MIDLINE) | set(PERIORAL_CHEEKS))
)
"""The Motion Units' landmarks (69): paper 002's marker layout on the lower face (30 markers around
the lips and 24 on the cheeks, Sec. IV-A) in MediaPipe's mesh: both lip contours, the chin midline and
the 24 perioral cheek points. Left out of :data:`LOWER_FACE`: the jaw outline (silhouette points that
slide over the skin as the jaw turns; the paper marked none) and the outer cheeks (featureless skin
whose points MediaPipe places from the whole face rather than tracks: their share of what 8 MUs leave
unexplained is 3x their share of the variance, the lips' 0.85x; see docs/motion_units.md)."""

# Single points of the parameter definitions (training.params).
UPPER_LIP_OUTER, UPPER_LIP_INNER, LOWER_LIP_INNER, LOWER_LIP_OUTER = 0, 13, 14, 17
MOUTH_CORNERS = (61, 291)
UPPER_LIP_MIDDLE = (0, 37, 267)
"""Upper lip's outer contour at the midline and either side of it (the philtrum's foot)."""
LIP_GAP_PAIRS = ((13, 14), (82, 87), (312, 317))
"""Facing inner-lip points at the midline and either side of it (upper, lower)."""
RIGHT_EYE_CORNERS = (33, 133)  # the subject's right eye (image left in a frontal video)
LEFT_EYE_CORNERS = (362, 263)
NOSE_TIP, SUBNASALE = 4, 2
STABLE: tuple[int, ...] = (
    10,
    151,
    9,
    8,
    168,
    6,
    197,
    195,
    5,
    4,
    33,
    133,
    362,
    263,
    127,
    356,
    70,
    300,
    105,
    334,
    46,
    276,
    108,
    337,
)
"""Landmarks that move with the skull only: forehead, nose bridge/tip, eye corners, brows' outer
ends, temples. Used for the pose fit; lips, cheeks and jaw are excluded."""


@dataclass(frozen=True, kw_only=True)
class FaceTrack:
    """One talking-face clip, pose-free (see the module doc for frames and units).

    source:          the video file.
    samples:         (n,) float32 mono audio in [-1, 1].
    sample_rate_hz:  rate of ``samples``.
    landmarks:       (n_frames, 468, 3) float32, 30 fps, face frame, IOD units, absolute.
    neutral:         (468, 3) float32, the face at rest, same frame.
    params:          (n_frames, 4) float64 mouth parameters (training.params), IOD units.
    face_found:      (n_frames,) bool.
    closed_gap_iod:  the inner-lip gap when the lips touch (mouth_open's zero), IOD:
                     ``params == video.mouth_params(landmarks, neutral, closed_gap=closed_gap_iod)``.
    n_frames = ceil(n / sample_rate_hz * 30).
    quality:         per-clip measurement report (face found fraction, jumps, neutral stats).
    """

    source: Path
    samples: np.ndarray
    sample_rate_hz: int
    landmarks: np.ndarray
    neutral: np.ndarray
    params: np.ndarray
    face_found: np.ndarray
    closed_gap_iod: float
    quality: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        n = len(self.landmarks)
        if self.landmarks.shape != (n, N_LANDMARKS, 3) or self.landmarks.dtype != np.float32:
            raise ValueError(
                f"landmarks must be (n_frames, {N_LANDMARKS}, 3) float32, got "
                f"{self.landmarks.shape} {self.landmarks.dtype}"
            )
        if self.neutral.shape != (N_LANDMARKS, 3) or self.neutral.dtype != np.float32:
            raise ValueError(f"neutral must be ({N_LANDMARKS}, 3) float32, got {self.neutral.shape}")
        if self.params.shape != (n, 4) or self.params.dtype != np.float64:
            raise ValueError(f"params must be ({n}, 4) float64, got {self.params.shape} {self.params.dtype}")
        if self.face_found.shape != (n,) or self.face_found.dtype != np.bool_:
            raise ValueError(f"face_found must be ({n},) bool, got {self.face_found.shape} {self.face_found.dtype}")
        if self.samples.ndim != 1 or self.samples.dtype != np.float32:
            raise ValueError("samples must be (n,) float32")

    @property
    def duration_s(self) -> float:
        return len(self.samples) / self.sample_rate_hz

    @property
    def n_frames(self) -> int:
        return len(self.landmarks)


@dataclass(frozen=True, kw_only=True)
class RawTrack:
    """What the cache keeps for one video (expensive to measure).

    samples:          (n,) int16 mono audio at ``sample_rate_hz``.
    video_landmarks:  (n_video_frames, 468, 3) float32 image pixels (x W, y H, z W), NaN where no face.
    video_times_s:    (n_video_frames,) float64 frame times on the audio's clock.
    """

    source: Path
    sha1: str
    samples: np.ndarray
    sample_rate_hz: int
    video_landmarks: np.ndarray
    video_times_s: np.ndarray
    video_fps: float
    width: int
    height: int
    extractor_version: str = EXTRACTOR_VERSION


def default_cache_dir() -> Path:
    """``$FACECAST_CACHE`` or ``~/.cache/facecast`` (shared by every checkout; never in the repo)."""
    env = os.environ.get("FACECAST_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "facecast"


def cache_path(cache_dir: str | Path | None, sha1: str, sample_rate_hz: int) -> Path:
    """Cache file of a video with content hash ``sha1`` (hex) at an audio rate."""
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return root / "facetracks" / f"{EXTRACTOR_VERSION}-{sample_rate_hz}hz" / f"{sha1}.npz"


def write_raw(path: Path, raw: RawTrack) -> Path:
    """Atomically write a :class:`RawTrack` as a compressed ``.npz``."""
    import io

    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        samples=raw.samples.astype(np.int16),
        sample_rate_hz=np.int64(raw.sample_rate_hz),
        video_landmarks=raw.video_landmarks.astype(np.float32),
        video_times_s=raw.video_times_s.astype(np.float64),
        video_fps=np.float64(raw.video_fps),
        width=np.int64(raw.width),
        height=np.int64(raw.height),
        source=np.str_(str(raw.source)),
        sha1=np.str_(raw.sha1),
        extractor_version=np.str_(raw.extractor_version),
    )
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)


def read_raw(path: str | Path) -> RawTrack:
    """Read a cache file written by :func:`write_raw` (no pickle)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            raw = RawTrack(
                source=Path(str(z["source"])),
                sha1=str(z["sha1"]),
                samples=z["samples"],
                sample_rate_hz=int(z["sample_rate_hz"]),
                video_landmarks=z["video_landmarks"],
                video_times_s=z["video_times_s"],
                video_fps=float(z["video_fps"]),
                width=int(z["width"]),
                height=int(z["height"]),
                extractor_version=str(z["extractor_version"]),
            )
    except (OSError, KeyError, ValueError) as exc:
        raise CorpusFormatError(path, f"not a face-track cache file ({exc})") from exc
    if raw.video_landmarks.ndim != 3 or raw.video_landmarks.shape[1:] != (N_LANDMARKS, 3):
        raise CorpusFormatError(path, f"video_landmarks has shape {raw.video_landmarks.shape}")
    if len(raw.video_times_s) != len(raw.video_landmarks):
        raise CorpusFormatError(path, "video_times_s and video_landmarks differ in length")
    return raw
