"""Streaming level normalisation: the frame level relative to the talker's own speech level.

Theory of operation
-------------------
c0 (log energy) carries loudness, and loudness predicts mouth opening; but its absolute value
is the recording's gain and the talker's vocal effort as much as the mouth. A model trained on one
talker at one microphone gain reads a voice 12 dB quieter as a mouth that barely opens (measured
on the shipped model: s1 val r(mouth_open) 0.865 -> 0.778 at -12 dB). The running CMVN corrects
an offset only slowly (its warm start weighs 300 frames, 10 s), and its fixed dB gates (silence
floor, CMVN update gate) cut a recording's pauses at different places depending on its gain.

:class:`LevelTracker` follows two levels per stream, both in dB:

- the **speech peak** ``P``: rises fast towards a louder frame (``peak_attack`` of the gap per
  frame) and falls slowly towards quieter *speech* frames (``peak_release``; only frames more than
  ``speech_above_floor_db`` above the floor, so a pause never drags it down);
- the **noise floor** ``F``: falls fast towards a quieter frame (``floor_attack``) and rises slowly
  (``floor_release``).

Both start from the stream's first frame (``P = level + start_peak_above_db``, ``F = level``)
and every update is a convex step towards the frame, so the tracker is exactly *equivariant*: a
gain of g dB shifts ``P``, ``F`` and the level by g, and the relative level ``level - P`` is
unchanged from the first frame on. The front end then uses ``c0 - P`` (in c0 units) instead of
c0 and treats frames more than ``silence_below_peak_db`` under the peak, or less than
``silence_above_floor_db`` above the floor, as silence (replacing the absolute
``silence_floor_db``), so the whole front end is invariant to the recording gain (exactly, as long
as no mel band sits at the MFCC energy floor, i.e. away from near-digital silence).

Frame ``t``'s output uses the state after its own update (causal: frames ``<= t`` only), so
whole-signal and streaming runs agree for any chunking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError, InvalidFeaturesError


@dataclass(frozen=True, kw_only=True)
class LevelNormConfig:
    """Rates are fractions of the gap closed per frame (30 fps), levels in dB.

    peak_attack / peak_release: speech-peak rise towards louder frames / fall towards quieter speech.
    floor_attack / floor_release: noise-floor fall towards quieter frames / rise towards louder ones.
    speech_above_floor_db: a frame this far above the floor counts as speech (may lower the peak).
    start_peak_above_db: the peak starts this far above the first frame's level (a stream usually
    starts in a pause, and a peak set too low is corrected by the attack within frames, one too high
    only by the release, in about a second).
    silence_below_peak_db: frames further under the peak are silence (one fixed feature vector).
    silence_above_floor_db: frames less than this above the noise floor are silence too, so steady
    noise alone (a quiet room at any level, no speech peak yet) gives no motion.
    """

    peak_attack: float = 0.3
    peak_release: float = 0.02
    floor_attack: float = 0.3
    floor_release: float = 0.005
    speech_above_floor_db: float = 10.0
    start_peak_above_db: float = 30.0
    silence_below_peak_db: float = 30.0
    silence_above_floor_db: float = 6.0

    def __post_init__(self) -> None:
        for name in ("peak_attack", "peak_release", "floor_attack", "floor_release"):
            v = getattr(self, name)
            if not 0.0 < v <= 1.0:
                raise ConfigError(f"LevelNormConfig.{name} must be in (0, 1], got {v}")
        for name in (
            "speech_above_floor_db",
            "start_peak_above_db",
            "silence_below_peak_db",
            "silence_above_floor_db",
        ):
            v = getattr(self, name)
            if not 0.0 <= v <= 120.0:
                raise ConfigError(f"LevelNormConfig.{name} must be in [0, 120] dB, got {v}")


class LevelTracker:
    """``push(level_db (k,)) -> peak_db (k,) float64``: the speech-peak estimate after each frame;
    ``track(level_db)`` -> ``(peak_db (k,), floor_db (k,))``."""

    def __init__(self, config: LevelNormConfig) -> None:
        self.config = config
        self.reset()

    def reset(self) -> None:
        self._peak = float("nan")  # nan = no frame yet (the state starts from the first frame)
        self._floor = float("nan")

    def push(self, level_db: np.ndarray) -> np.ndarray:
        return self.track(level_db)[0]

    def track(self, level_db: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lv = np.asarray(level_db, dtype=np.float64)
        if lv.ndim != 1 or not np.all(np.isfinite(lv)):
            raise InvalidFeaturesError(f"levels must be a finite 1-D array, got shape {lv.shape}")
        cfg = self.config
        out = np.empty_like(lv)
        floor = np.empty_like(lv)
        p, f = self._peak, self._floor
        for i in range(lv.size):
            x = lv[i]
            if p != p:  # first frame of the stream
                p, f = x + cfg.start_peak_above_db, x
            f += (cfg.floor_attack if x < f else cfg.floor_release) * (x - f)
            if x > p:
                p += cfg.peak_attack * (x - p)
            elif x > f + cfg.speech_above_floor_db:
                p += cfg.peak_release * (x - p)
            out[i] = p
            floor[i] = f
        self._peak, self._floor = p, f
        return out, floor
