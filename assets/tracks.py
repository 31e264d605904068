"""The one codec of parameter tracks (:class:`realtime_core.track.Track`): CSV and JSON.

CSV (corpora's ``params.csv``, ``facecast animate --csv``, exports, the renderer's input)::

    t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress
    0.000000,0.0123,...

one row per frame; t in seconds, frame k at ``start_s + k / fps``, written with 6 decimals; values
written with 9 significant digits, so float32 values (what the model computes and the wire carries)
round-trip exactly and float64 values to 1e-9 relative.

Three ways in, one parser:

- :func:`decode_csv` / :func:`read_csv` read a track back: times must lie on the frame grid
  (within 10 us); ``names`` / ``n_frames`` / ``start_s`` make it strict (the corpus contract:
  the exact header, exactly ``n_frames`` rows - fewer is :class:`TruncatedFileError` - and t = k / 30).
- :func:`read_csv_resampled` (the renderer): any sample times, strictly increasing, columns picked by
  name in any order, put on the video's frame grid by :func:`realtime_core.track.frames_from_samples`;
  :func:`read_params_resampled` the same for a CSV or a JSON of curves (``facecast render --params``).

JSON (``facecast-curves`` version 1)::

    {"format": "facecast-curves", "version": 1, "fps": 30.0, "start_s": 0.0, "units": "IOD" (or what the curves are),
     "names": [...], "t": [...F times, s...], "curves": {"<name>": [...F values...], ...},
     "audio": "take.wav" | null}

Errors name the file (or the ``source`` label of in-memory bytes) and the problem.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from assets.errors import CorpusFormatError, TruncatedFileError
from assets.files import atomic_write_bytes
from realtime_core import VISUAL_PARAMS
from realtime_core.blendshapes import BLENDSHAPE_SETS, blendshape_names
from realtime_core.errors import ConfigError
from realtime_core.track import DEFAULT_FPS, Track, frames_from_samples

JSON_FORMAT = "facecast-curves"
JSON_VERSION = 1
TIME_TOLERANCE_S = 1e-5
"""How far a CSV time may sit from its frame's exact time (the 6-decimal rounding is 5e-7 s)."""


def csv_header(names: tuple[str, ...]) -> str:
    return ",".join(("t", *names))


def encode_csv(track: Track) -> bytes:
    """The track as UTF-8 CSV (see the module docstring)."""
    out = io.StringIO()
    out.write(csv_header(track.names) + "\n")
    for t, row in zip(track.times(), track.values, strict=True):
        out.write(f"{t:.6f}," + ",".join(f"{v:.9g}" for v in row) + "\n")
    return out.getvalue().encode("utf-8")


def write_csv(path: str | Path, track: Track) -> Path:
    """Write :func:`encode_csv` atomically to ``path``."""
    p = Path(path)
    atomic_write_bytes(p, encode_csv(track))
    return p


def _parse(data: bytes, source: str | Path) -> tuple[tuple[str, ...], np.ndarray]:
    """(column names after t, (rows, 1 + columns) float64 with t first) of CSV bytes."""
    try:
        rows = [r for r in csv.reader(io.StringIO(data.decode("utf-8"))) if r and any(c.strip() for c in r)]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise CorpusFormatError(source, f"cannot be read as CSV ({exc})") from exc
    if not rows or rows[0][:1] != ["t"] or len(rows[0]) < 2:
        got = ",".join(rows[0]) if rows else ""
        got = got if len(got) <= 60 else got[:60] + "..."  # a one-line JSON given as CSV is all "header"
        raise CorpusFormatError(source, f"header must be 't,<channel names>', got {got!r}")
    names = tuple(c.strip() for c in rows[0][1:])
    width = len(names) + 1
    for k, r in enumerate(rows[1:], start=1):
        if len(r) != width:
            raise CorpusFormatError(source, f"row {k} has {len(r)} columns, the header has {width}")
    try:
        a = np.array([[float(x) for x in r] for r in rows[1:]], dtype=np.float64).reshape(-1, width)
    except ValueError as exc:
        raise CorpusFormatError(source, f"non-numeric value ({exc})") from exc
    if not np.all(np.isfinite(a)):
        raise CorpusFormatError(source, "values must be finite (no NaN or inf)")
    return names, a


def decode_csv(
    data: bytes,
    *,
    source: str | Path = "<csv>",
    fps: float = DEFAULT_FPS,
    names: tuple[str, ...] | None = None,
    n_frames: int | None = None,
    start_s: float | None = None,
) -> Track:
    """CSV bytes -> Track at ``fps``. Times must be ``start + k / fps`` (start = the first row's time,
    or exactly ``start_s`` when given). Strict options: ``names`` (the header must be exactly
    ``t,<names>``), ``n_frames`` (exactly that many rows: fewer raises :class:`TruncatedFileError`)."""
    got, a = _parse(data, source)
    if names is not None and got != tuple(names):
        raise CorpusFormatError(source, f"header must be {csv_header(tuple(names))!r}, got {csv_header(got)!r}")
    if n_frames is not None and len(a) < n_frames:
        raise TruncatedFileError(source, f"truncated: {len(a)} frames, expected {n_frames}")
    if n_frames is not None and len(a) > n_frames:
        raise CorpusFormatError(source, f"{len(a)} frames, expected {n_frames}")
    t0 = float(start_s) if start_s is not None else (float(a[0, 0]) if len(a) else 0.0)
    if len(a):
        err = np.abs(a[:, 0] - (t0 + np.arange(len(a)) / fps))
        if err.max() > TIME_TOLERANCE_S:
            k = int(np.argmax(err))
            raise CorpusFormatError(
                source, f"the t column must be {t0:g} + k/{fps:g} s for row k; row {k} has t = {a[k, 0]:.6f}"
            )
    try:
        return Track(values=a[:, 1:], names=got, fps=fps, start_s=max(t0, 0.0))
    except ConfigError as exc:
        raise CorpusFormatError(source, str(exc)) from exc


def _read_bytes(path: str | Path, what: str = "track file") -> bytes:
    p = Path(path)
    if not p.is_file():
        raise CorpusFormatError(p, f"{what} not found")
    try:
        return p.read_bytes()
    except OSError as exc:
        raise CorpusFormatError(p, f"cannot be read ({exc})") from exc


def read_csv(
    path: str | Path,
    *,
    fps: float = DEFAULT_FPS,
    names: tuple[str, ...] | None = None,
    n_frames: int | None = None,
    start_s: float | None = None,
) -> Track:
    """:func:`decode_csv` of a file (errors name it)."""
    return decode_csv(_read_bytes(path), source=Path(path), fps=fps, names=names, n_frames=n_frames, start_s=start_s)


def read_csv_resampled(path: str | Path, fps: float, *, names: tuple[str, ...] | None = None) -> Track:
    """A CSV of samples at any strictly increasing times (the renderer's input: another tool's rate,
    extra columns, any column order) -> the ``names`` channels (default: the four mouth parameters)
    on the frame grid ``k / fps`` by :func:`realtime_core.track.frames_from_samples`, covering as long as the
    file does (as :meth:`Track.at_fps`): every frame that starts before its last row's own frame ends, that row
    lasting the file's median row spacing. Put on the grid only through the last row's time, `animate --fps 24`'s
    2.14 s of speech rendered at 30 fps made a 2.133 s video (64 frames for 65), and at 60 fps 2 frames short."""
    want = tuple(VISUAL_PARAMS if names is None else names)
    got, a = _parse(_read_bytes(path, "parameters file"), Path(path))
    missing = [n for n in want if n not in got]
    if missing or not len(a):
        raise CorpusFormatError(path, _not_these_curves(want, got, "columns", "row"))
    if np.any(np.diff(a[:, 0]) <= 0):
        raise CorpusFormatError(path, "times must be strictly increasing")
    cols = [1 + got.index(n) for n in want]
    t = a[:, 0]
    until_s = float(t[-1] + np.median(np.diff(t))) if len(t) > 1 else None  # one row: one frame, its length unknown
    return frames_from_samples(t, a[:, cols], fps, names=want, until_s=until_s)


def _not_these_curves(want: tuple[str, ...], got: tuple[str, ...] | list[str], what: str, row: str) -> str:
    """Why a curves file lacks the ``want`` curves. A file of blendshape weights (``animate --curves arkit52|ovr15``)
    is named as such with what to give instead: listing its 52 columns against the four wanted said neither what the
    file was nor which file to give (`render --params` of an `animate --curves arkit52` CSV)."""
    for which in BLENDSHAPE_SETS:
        if tuple(want) == VISUAL_PARAMS and set(blendshape_names(which)) <= set(got):
            return (
                f"holds {which} blendshape weights (animate --curves {which}), not the four mouth parameters; give "
                "the curves of 'facecast animate SPEECH -o OUT.csv' (or .json) without --curves"
            )
    t = ["t"] if what == "columns" else []
    return f"expected {what} {[*t, *want]} and at least one {row}, got {[*t, *got]}"


def encode_json(track: Track, *, audio: str | None = None, units: str = "IOD") -> bytes:
    """The track as UTF-8 JSON (see the module docstring); ``audio``: name of the audio file beside it; ``units``:
    what the curves measure (the mouth parameters' IOD, or e.g. blendshape weights)."""
    doc = {
        "format": JSON_FORMAT,
        "version": JSON_VERSION,
        "fps": track.fps,
        "start_s": track.start_s,
        "units": units,
        "names": list(track.names),
        "t": [round(float(t), 9) for t in track.times()],
        "curves": {n: [float(v) for v in track.values[:, j]] for j, n in enumerate(track.names)},
        "audio": audio,
    }
    return (json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n").encode("utf-8")


def decode_json(data: bytes, *, source: str | Path = "<json>") -> Track:
    """Parse :func:`encode_json` output back into a Track (values exact: JSON floats are float64 reprs)."""
    try:
        doc = json.loads(data)
    except ValueError as exc:
        raise CorpusFormatError(source, f"not JSON ({exc})") from exc
    if not isinstance(doc, dict) or doc.get("format") != JSON_FORMAT or doc.get("version") != JSON_VERSION:
        raise CorpusFormatError(source, f"expected {JSON_FORMAT} version {JSON_VERSION}")
    try:
        names = tuple(doc["names"])
        values = np.array([doc["curves"][n] for n in names], dtype=np.float64).T.reshape(-1, len(names))
        return Track(values=values, names=names, fps=doc["fps"], start_s=doc.get("start_s", 0.0))
    except (KeyError, TypeError, ValueError) as exc:  # ConfigError is a ValueError
        raise CorpusFormatError(source, f"inconsistent curves JSON ({exc})") from exc


def read_json(path: str | Path) -> Track:
    """:func:`decode_json` of a file (errors name it)."""
    return decode_json(_read_bytes(path), source=Path(path))


def read_params_resampled(path: str | Path, fps: float, *, names: tuple[str, ...] | None = None) -> Track:
    """:func:`read_csv_resampled`, or for a ``.json`` file (``facecast animate --json``, ``say -o x.json``) its
    curves picked by name and put on the frame grid ``k / fps`` the same way. `render --params x.json` was
    refused with "header must be 't,<channel names>'" for facecast's own JSON export."""
    if Path(path).suffix.lower() != ".json":
        return read_csv_resampled(path, fps, names=names)
    want = tuple(VISUAL_PARAMS if names is None else names)
    tr = read_json(path)
    missing = [n for n in want if n not in tr.names]
    if missing or not len(tr.values):
        raise CorpusFormatError(path, _not_these_curves(want, tr.names, "curves", "frame"))
    cols = [tr.names.index(n) for n in want]
    return Track(values=tr.values[:, cols], names=want, fps=tr.fps, start_s=tr.start_s).at_fps(fps)
