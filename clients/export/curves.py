"""The four mouth parameters over time (:class:`Track`) and their CSV / JSON curves.

CSV: header ``t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress``, one row per frame,
t in seconds (frame k at ``start_s + k / fps``, 6 decimals), values in inter-ocular distances (IOD)
with 9 significant digits, which round-trips float32 exactly (the wire carries float32).

JSON (``facecast-curves`` version 1)::

    {"format": "facecast-curves", "version": 1, "fps": 30.0, "units": "IOD",
     "names": [...4 names...], "t": [...F times, s...],
     "curves": {"upper_lip_raise": [...F values...], ...}, "audio": "take.wav" | null}
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass

import numpy as np

from clients.export.errors import ExportError
from realtime_core import VISUAL_PARAMS

JSON_FORMAT = "facecast-curves"
JSON_VERSION = 1


@dataclass(frozen=True, kw_only=True)
class Track:
    """params: (F, len(names)) float64 values in IOD, row k at time ``start_s + k / fps`` seconds;
    fps: frames per second (> 0); start_s: media time of row 0 (s); names: one per column."""

    params: np.ndarray
    fps: float = 30.0
    start_s: float = 0.0
    names: tuple[str, ...] = VISUAL_PARAMS

    def __post_init__(self) -> None:
        p = np.array(self.params, dtype=np.float64)  # a private copy: the track is immutable
        if p.ndim != 2 or p.shape[1] != len(self.names):
            raise ExportError(f"params must be (frames, {len(self.names)}), got shape {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ExportError("params contain NaN or infinite values")
        if not (isinstance(self.fps, (int, float)) and np.isfinite(self.fps) and self.fps > 0):
            raise ExportError(f"fps must be a positive number, got {self.fps!r}")
        if not np.isfinite(self.start_s) or self.start_s < 0:
            raise ExportError(f"start_s must be a finite time >= 0 s, got {self.start_s!r}")
        p.setflags(write=False)
        object.__setattr__(self, "params", p)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "fps", float(self.fps))
        object.__setattr__(self, "start_s", float(self.start_s))

    @property
    def n_frames(self) -> int:
        return int(self.params.shape[0])

    def times(self) -> np.ndarray:
        """(F,) float64 seconds: the media time of each row."""
        return self.start_s + np.arange(self.n_frames) / self.fps

    @property
    def duration_s(self) -> float:
        """Seconds covered: F / fps (the last frame lasts one frame period)."""
        return self.n_frames / self.fps


def csv_bytes(track: Track) -> bytes:
    """The track as UTF-8 CSV text (see the module docstring)."""
    out = io.StringIO()
    out.write(",".join(("t", *track.names)) + "\n")
    for t, row in zip(track.times(), track.params):
        out.write(f"{t:.6f}," + ",".join(f"{v:.9g}" for v in row) + "\n")
    return out.getvalue().encode("utf-8")


def read_csv(data: bytes, *, fps: float = 30.0) -> Track:
    """Parse :func:`csv_bytes` output (or ``facecast animate --csv``) back into a Track.

    Times must be ``start + k / fps`` within 1 ms (a CSV of another rate is rejected, not resampled)."""
    try:
        rows = list(csv.reader(io.StringIO(data.decode("utf-8"))))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ExportError(f"cannot read CSV: {exc}") from exc
    if not rows or rows[0][:1] != ["t"] or len(rows[0]) < 2:
        raise ExportError(f"CSV must start with a header 't,<names>', got {rows[:1]}")
    names = tuple(rows[0][1:])
    try:
        a = np.array([[float(x) for x in r] for r in rows[1:] if r], dtype=np.float64).reshape(-1, len(names) + 1)
    except ValueError as exc:
        raise ExportError(f"CSV has a non-numeric or missing value: {exc}") from exc
    start = float(a[0, 0]) if len(a) else 0.0
    if len(a) and np.max(np.abs(a[:, 0] - (start + np.arange(len(a)) / fps))) > 1e-3:
        raise ExportError(f"CSV times are not frames at {fps:g} fps")
    return Track(params=a[:, 1:], fps=fps, start_s=start, names=names)


def json_bytes(track: Track, *, audio: str | None = None) -> bytes:
    """The track as UTF-8 JSON (see the module docstring); ``audio``: name of the audio file beside it."""
    doc = {
        "format": JSON_FORMAT,
        "version": JSON_VERSION,
        "fps": track.fps,
        "start_s": track.start_s,
        "units": "IOD",
        "names": list(track.names),
        "t": [round(float(t), 9) for t in track.times()],
        "curves": {n: [float(v) for v in track.params[:, j]] for j, n in enumerate(track.names)},
        "audio": audio,
    }
    return (json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n").encode("utf-8")


def read_json(data: bytes) -> Track:
    """Parse :func:`json_bytes` output back into a Track."""
    try:
        doc = json.loads(data)
    except ValueError as exc:
        raise ExportError(f"not JSON: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("format") != JSON_FORMAT or doc.get("version") != JSON_VERSION:
        raise ExportError(f"expected {JSON_FORMAT} version {JSON_VERSION}")
    try:
        names = tuple(doc["names"])
        params = np.array([doc["curves"][n] for n in names], dtype=np.float64).T.reshape(-1, len(names))
        return Track(params=params, fps=doc["fps"], start_s=doc.get("start_s", 0.0), names=names)
    except (KeyError, TypeError, ValueError) as exc:
        raise ExportError(f"inconsistent curves JSON: {exc}") from exc
