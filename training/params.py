"""The four mouth parameters: the one place where they are defined.

facecast describes the mouth with four numbers per video frame, in the order of
``realtime_core.VISUAL_PARAMS`` everywhere (files, CSV columns, protocol). Each is measured on
a face **relative to that face's neutral pose** (lips relaxed and closed, mouth at rest) and
expressed in units of the face's **inter-ocular distance (IOD)**: the distance between the two
eye centres (midpoints of the eye corners). Dividing by the IOD makes the values independent of
the face's size, the camera distance and any one face model. Image "up" is the face's own up
axis after head pose has been removed (see :mod:`training.video`).

The **neutral pose** is the face at rest: on video, the median face over the silences of the
clip's word alignment (away from speech by 0.15 s: lips prepare before the sound and relax after
it), else over its quietest frames (:mod:`training.video`, step 6). It replaced "the frames with the
smallest lip gap", which made a talker whose lips are parted at rest read about 0.1 IOD open in
silence and measured stretch and corners against pressed lips (a bilabial closure) instead of rest.

``upper_lip_raise``
    Upward movement of the upper lip's outer contour at the midline (mean height of the
    midpoint and its two neighbours, MediaPipe 0, 37, 267: the philtrum's foot) relative to the
    neutral pose. Positive = lip moves up (towards the nose), as in /f v/ or a snarl and, a
    little, whenever the mouth opens; negative = the lip is pulled down or pressed, as in a
    bilabial closure. On GRID s1: +0.011 in f/v words, 0.000 in rounded ones, std 0.015.
    Typical range -0.05 .. +0.06 IOD.

``lip_stretch``
    Change of the mouth width: the distance between the two mouth corners minus its neutral
    value. Positive = wider (spread lips, /i/, /e/, smiling); negative = narrower (rounded lips,
    /u/ /o/ /w/). On GRID s1: -0.023 in rounded words, -0.001 in spread ones (relative to rest).
    Typical range -0.12 .. +0.10 IOD.

``mouth_open``
    The inner-lip vertical gap (mean 3D distance of three facing inner-lip point pairs at the
    midline, MediaPipe 13-14, 82-87, 312-317) minus the gap **when the lips touch** (the closed
    pose). 0 = lips touch (bilabial closure /p b m/, and rest for a talker whose lips close at
    rest); it is never meaningfully negative (a gap cannot be; video tracks dip by noise only, and
    model output is clamped at 0, the closed pose). On video the contact gap is the mean of a
    clip's smallest 5 % of gaps (its closures), never above the rest gap; so a talker who rests
    with parted lips reads their real rest opening in silence (GRID brbk7n: 0.10) while GRID s1,
    whose lips close at rest, reads about 0.01. Open vowels /a/ reach 0.2-0.4 IOD.
    Typical range 0 .. 0.45 IOD.

``lip_corner_depress``
    Downward movement of the mouth corners relative to the lip midline (the mean height of the
    upper- and lower-lip outer midpoints), minus its neutral value. Positive = corners lower than the
    lips' middle (a frown, the sagging corners of rounded /o u/ and /S Z/); negative = corners
    higher than the middle (a smile, spread /i e/). Because it is measured against the midline,
    dropping the jaw alone lowers the midline and so makes the value slightly negative (GRID s1:
    r = -0.41 with mouth_open); the articulatory rules and the video measurement share this
    definition. Typical range -0.10 .. +0.05 IOD.

Frame timing: 30 frames per second; frame ``k`` is the instant ``t = k / 30`` s exactly, and an
utterance of ``d`` seconds has ``n = ceil(d * 30)`` frames (frame 0 at t = 0).
"""

from __future__ import annotations

import math

import numpy as np

from realtime_core import VISUAL_PARAMS
from training.errors import ConfigError

FPS: int = 30
"""Video frame rate of every parameter track, frames per second."""

PARAM_NAMES: tuple[str, ...] = VISUAL_PARAMS
"""("upper_lip_raise", "lip_stretch", "mouth_open", "lip_corner_depress")."""

N_PARAMS: int = len(PARAM_NAMES)

DEFINITION_VERSION: int = 1
"""The version of the definitions above as measured on video: bump it whenever a definition, its
measurement (``training.video.mouth_params``) or the rest pose it is measured against
(``training.video``, step 6) changes. It is part of the cache key of everything stored that holds measured
parameters or rest-relative landmarks (the unit-selection corpus, ``training.unit_corpus``), so a changed
definition rebuilds them instead of mixing old and new values. The face-track cache holds only the raw
landmarks (keyed by ``training.facetrack.EXTRACTOR_VERSION``) and derives the parameters on every load."""

TYPICAL_RANGES: dict[str, tuple[float, float]] = {
    "upper_lip_raise": (-0.05, 0.06),
    "lip_stretch": (-0.15, 0.12),
    "mouth_open": (0.0, 0.45),
    "lip_corner_depress": (-0.10, 0.05),
}
"""Typical range of each parameter in IOD units (for sanity checks and plots, not clipping)."""


def n_frames_for(duration_s: float) -> int:
    """Number of 30 fps frames covering ``duration_s`` seconds: ``ceil(duration_s * 30)``.

    A tiny tolerance absorbs float error, so 1.0 s gives exactly 30 frames, not 31.
    """
    if duration_s < 0:
        raise ConfigError(f"duration must be >= 0 s, got {duration_s}")
    return int(math.ceil(duration_s * FPS - 1e-9))


def frame_times(n_frames: int) -> np.ndarray:
    """Times of frames 0..n-1 in seconds, shape (n_frames,), float64: ``k / 30``."""
    return np.arange(n_frames, dtype=np.float64) / FPS
