"""Rhubarb Lip Sync style mouth-shape cues from the four mouth parameters, as TSV for 2D tools.

Rhubarb's shapes: A closed (P, B, M), B slightly open with the teeth together (most consonants),
C open (EH, AE), D wide open (AA), E slightly rounded (AO, ER), F puckered (UW, OW, W), G upper
teeth on the lower lip (F, V), H tongue raised (L), X idle (rest, pauses).

Each frame's shape, from p = (upper_lip_raise, lip_stretch, mouth_open, lip_corner_depress) in
inter-ocular distances (IOD), by the first rule that matches (thresholds: :class:`ShapeThresholds`):

    mouth_open < closed (0.02):   A if upper_lip_raise <= -press (-0.03, lips pressed) else X
    upper_lip_raise >= teeth_on_lip (0.005) and mouth_open < g_open (0.075):           G
    lip_stretch <= -round (-0.03):  F if mouth_open < rounded_open (0.25) else E
    mouth_open < b_open (0.15): B;   mouth_open < c_open (0.21): C;   otherwise D

The thresholds are fitted on real lips (``scripts/rhubarb_thresholds.py``): GRID s1's train sentences, their
measured parameters and the shipped model's outputs on their audio, against the shape each frame's phone
calls for (:data:`PHONE_SHAPES`, Rhubarb's own assignment); set earlier against the synthetic training ranges
(``training.params.TYPICAL_RANGES``), real lips and the model trained on them almost never reached D, E, F
or G (held-out test sentences, macro-F1 over the eight shapes: the model's outputs 0.253 -> 0.325, the
measured lips 0.243 -> 0.343; docs/accuracy.md, "Mouth shapes").

H is never chosen: the four parameters do not observe the tongue. Lips closed for at most
``closure_s`` (0.2 s) between open frames are a closure, A, pressed or not: X is Rhubarb's idle
shape for pauses, and a /m/ closed without the press read as a pause inside the word. Consecutive
frames of one shape merge into one cue; a run shorter than ``min_cue_s`` (2 frames at 30 fps) joins the cue
before it (Rhubarb, too, avoids one-frame flicker), except A: a closure is shown however short (merged, a
one-frame /b/ vanished into the vowel before it; 3 of the 9 /p b m/ of a 10-word `facecast say`
sentence had no A cue). Both are durations, read at the track's own rate: counted in frames, ``animate --fps 60``
let 33 ms G cues flicker that the 30 fps cues of the same speech merge. TSV: one ``start<TAB>shape`` line per cue,
start in seconds with 2 decimals, and always a last ``end<TAB>X`` line at the track's end, as Rhubarb writes
(its closing line: the only place a TSV says how long the animation lasts).

Cues written at another frame rate (``animate --fps 24``) are the cues of the model's own frames, each start moved to
the nearest frame ``k / fps`` of that rate (:func:`cues`' ``fps``), a closure keeping a frame of its own: cues of the
curves interpolated onto 24 fps lost a one-frame /m b p/ wherever the 30 fps closure fell between two 24 fps frames
(the interpolated lips never closed there; 5 of 6 phases of one synthetic closure had no A cue at 24 fps, 5 at 25).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clients.export.errors import ExportError
from realtime_core import VISUAL_PARAMS
from realtime_core.track import Track

SHAPES = "ABCDEFGHX"

PHONE_SHAPES: dict[str, str] = {
    **dict.fromkeys(("P", "B", "M"), "A"),
    **dict.fromkeys(("IY", "IH", "Y", "K", "G", "NG", "S", "Z", "T", "D", "N"), "B"),
    **dict.fromkeys(("CH", "JH", "SH", "ZH", "TH", "DH", "HH", "R"), "B"),
    **dict.fromkeys(("EH", "AE", "AH", "EY"), "C"),
    **dict.fromkeys(("AA", "AW", "AY"), "D"),
    **dict.fromkeys(("AO", "ER", "OY"), "E"),
    **dict.fromkeys(("UW", "OW", "W", "UH"), "F"),
    **dict.fromkeys(("F", "V"), "G"),
    "L": "H",
    "SIL": "X",
}
"""ARPAbet phone (no stress digit, ``SIL`` for silence) -> the shape Rhubarb Lip Sync shows for it (its
documentation's assignment, diphthongs by their first part): what :class:`ShapeThresholds` were fitted to."""


@dataclass(frozen=True, kw_only=True)
class ShapeThresholds:
    """Thresholds of the rules in the module docstring, in IOD; min_cue_s > 0 and closure_s >= 0 in seconds (at the
    track's own frame rate: a run lasts its frames over the fps)."""

    closed: float = 0.02
    press: float = 0.03
    teeth_on_lip: float = 0.005
    g_open: float = 0.075
    round: float = 0.03
    rounded_open: float = 0.25
    b_open: float = 0.15
    c_open: float = 0.21
    min_cue_s: float = 2 / 30
    closure_s: float = 0.2

    def __post_init__(self) -> None:
        if not 0 < self.closed < self.b_open < self.c_open:
            raise ExportError("thresholds must satisfy 0 < closed < b_open < c_open")
        if not self.min_cue_s > 0:
            raise ExportError(f"min_cue_s must be > 0 seconds, got {self.min_cue_s!r}")
        if not self.closure_s >= 0:
            raise ExportError(f"closure_s must be >= 0 seconds, got {self.closure_s!r}")


@dataclass(frozen=True)
class Cue:
    """A mouth shape (one of SHAPES) from ``start_s`` (seconds) until the next cue."""

    start_s: float
    shape: str


def frame_shapes(params: np.ndarray, th: ShapeThresholds = ShapeThresholds()) -> list[str]:
    """params (F, 4) IOD in VISUAL_PARAMS order -> F shape letters by the documented rules."""
    p = np.asarray(params, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != len(VISUAL_PARAMS):
        raise ExportError(f"params must be (frames, {len(VISUAL_PARAMS)}), got {p.shape}")
    out = []
    for ulr, stretch, op, _cd in p:
        if op < th.closed:
            out.append("A" if ulr <= -th.press else "X")
        elif ulr >= th.teeth_on_lip and op < th.g_open:
            out.append("G")
        elif stretch <= -th.round:
            out.append("F" if op < th.rounded_open else "E")
        elif op < th.b_open:
            out.append("B")
        elif op < th.c_open:
            out.append("C")
        else:
            out.append("D")
    return out


def cues(track: Track, th: ShapeThresholds = ShapeThresholds(), *, fps: float | None = None) -> list[Cue]:
    """The track's cues: runs of equal shapes, short runs merged into the previous cue. fps: the frame rate they are
    written at (frames ``k / fps`` s from 0 s; None: the track's own frames): each start on the nearest such frame, a
    closure (A) on a frame of its own (the cue it would share a frame with gives way: the one before it, a frame
    shorter than one output frame at this rate, or the one after it, a frame later)."""
    if track.names != VISUAL_PARAMS:
        raise ExportError(f"mouth shapes need the parameters {VISUAL_PARAMS}, got {track.names}")
    shapes = frame_shapes(track.values, th)
    # The durations in frames at this track's rate (a hair of slack: 0.2 s at 30 fps is 6 frames, not 5.999...).
    min_cue = th.min_cue_s * track.fps - 1e-6
    closure = th.closure_s * track.fps + 1e-6
    closed = [s in "AX" for s in shapes]
    k = 0
    while k < len(shapes):  # a short closed run between open frames is a closure: A
        if not closed[k]:
            k += 1
            continue
        end = k
        while end < len(shapes) and closed[end]:
            end += 1
        if k > 0 and end < len(shapes) and end - k <= closure:
            shapes[k:end] = ["A"] * (end - k)
        k = end
    runs: list[list] = []  # [first frame, shape, length]
    for k, s in enumerate(shapes):
        if runs and runs[-1][1] == s:
            runs[-1][2] += 1
        else:
            runs.append([k, s, 1])
    merged: list[list] = []
    for first, shape, length in runs:
        if merged and ((length < min_cue and shape != "A") or merged[-1][1] == shape):
            merged[-1][2] += length  # too short to show, or equal to the cue it now follows
        else:
            merged.append([first, shape, length])
    out = [Cue(track.start_s + first / track.fps, shape) for first, shape, _ in merged]
    return out if fps is None else _on_frames(out, fps)


def _on_frames(cs: list[Cue], fps: float) -> list[Cue]:
    """Cues (strictly increasing starts) with each start moved to the nearest frame ``k / fps``. Two landing on one
    frame keep the later one, unless the earlier is a closure (A), which keeps the frame and moves the later one to
    the next; equal shapes that then meet merge, a closure merged into the one before still showing on its own
    nearest frame. Starts stay strictly increasing, none later than the frame after its nearest, and every closure's
    nearest frame shows A."""
    if not fps > 0:
        raise ExportError(f"fps must be > 0, got {fps!r}")
    placed: list[list] = []  # [first frame, shape, last frame it must show: a closure's nearest frames, else its first]
    for c in cs:
        k = int(np.floor(c.start_s * fps + 0.5))  # the nearest frame (a half: the later)
        while placed and k <= placed[-1][2] and placed[-1][1] != "A":
            placed.pop()  # shorter than a frame at this rate: the later cue is what that frame shows
        if placed and placed[-1][1] == c.shape:
            if c.shape == "A":  # two closures a frame apart or less: the one cue shows both their frames
                placed[-1][2] = max(placed[-1][2], k)
            continue
        if placed and k <= placed[-1][2]:  # (the cue before is a closure: only closures are left there)
            k = placed[-1][2] + 1  # the closure keeps its frames, this cue starts after them
        placed.append([k, c.shape, k])
    return [Cue(k / fps, shape) for k, shape, _ in placed]


def tsv_bytes(track: Track, th: ShapeThresholds = ShapeThresholds(), *, fps: float | None = None) -> bytes:
    """Rhubarb TSV text (UTF-8) of the track's cues, ending with ``end<TAB>X`` at the track's end, whatever the last
    cue (Rhubarb's closing line; without it a take ending in a pause said nothing of the seconds after its last cue).
    fps: the cues placed on the frames of this rate (:func:`cues`), the end that of :meth:`Track.at_fps` at it."""
    end_s = track.start_s + track.duration_s if fps is None else track.at_fps(fps).duration_s
    end = f"{end_s:.2f}"
    lines = [f"{c.start_s:.2f}\t{c.shape}" for c in cues(track, th, fps=fps)]
    # A cue starting within the track's last hundredth (a high --fps) would print at the end's own time: read_tsv and
    # Rhubarb's readers take times that increase, so the closing line replaces it.
    lines = [line for line in lines if not line.startswith(f"{end}\t")] + [f"{end}\tX"]
    return ("\n".join(lines) + "\n").encode("utf-8")


def read_tsv(data: bytes) -> list[Cue]:
    """Parse Rhubarb TSV (``start<TAB>shape`` lines); ExportError on a bad line or decreasing times."""
    out: list[Cue] = []
    for n, line in enumerate(data.decode("utf-8").splitlines(), 1):
        if not line.strip():
            continue
        parts = line.split("\t")
        if len(parts) != 2 or parts[1] not in SHAPES:
            raise ExportError(f"TSV line {n}: expected '<seconds>\\t<one of {SHAPES}>', got {line!r}")
        try:
            t = float(parts[0])
        except ValueError:
            raise ExportError(f"TSV line {n}: bad time {parts[0]!r}") from None
        if out and t <= out[-1].start_s:
            raise ExportError(f"TSV line {n}: time {t} does not increase")
        out.append(Cue(t, parts[1]))
    return out
