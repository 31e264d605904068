"""Noise gate on the output: a room's steady noise alone fades the mouth to the rest pose.

Theory of operation
-------------------
The shipped models were trained on GRID s1, whose pauses sit at -55 to -60 dB (mel level) with the talker's
in-breath a few dB over them, mouth open 0.1-0.15 IOD. They learned to read quiet sound just over the absolute
silence gate (``FrontEndConfig.silence_floor_db``, -60 dB) as that in-breath, so an idle microphone in a room at
-54 dBFS (white noise) opened the mouth 0.05-0.1 IOD for as long as it ran. The features cannot tell the two apart
(a quiet room is as loud as s1's breath); their course in time can: a room's noise is steady, at its own floor,
while the in-breath rises over the floor of the pause it starts in.

Per MFCC frame (30 fps) the gate takes the frame's level ``L`` (dB, :func:`realtime_core.features.mel_level_db`
of c0, the measure of the absolute silence gate) and the stream's noise floor ``F``: the minimum over the last
``floor_window_frames`` (1.5 s) of the level smoothed by ``floor_smoothing`` of its gap a frame (minimum statistics,
Martin 2001). It falls with the room at once and rises to a noise that steps up (a fan switched on) one window
later; speech never lifts it to its own level, as no 1.5 s of speech lacks a gap between syllables far under its
vowels (LJ Speech read for 3.7 min, clean and under noise: no frame faded). Smoothing keeps a steady noise's frames
within 1.53 dB of it (white, pink, brown, fan, 60 s each, two seeds; the unsmoothed minimum: 2.17 dB; the earlier
floor, ``LevelTracker``'s, which rose by 0.5 % of the gap a frame: 1.76 dB and 12-17 s to follow a step). Digital
silence, under :data:`realtime_core.features.gain.DIGITAL_SILENCE_DBFS`, leaves it alone. The frame's openness is
``a = clip((L - F - margin_db) / ramp_db, 0, 1)``: 0 within ``margin_db`` of the floor, 1 from
``margin_db + ramp_db`` over it. The gain of output row ``t`` (video frame ``t``) is then

- the largest openness of frames ``t - hold_frames .. t`` (a pause between words, shorter than the hold, is
  never touched), or of a frame ``t + d`` up to ``lookahead`` ahead weighted ``1 - d / (lookahead + 1)`` (the
  mouth fades in over the frames before the sound, as it moves before it; the lookahead is the front end's own
  context ``tc``, which the row waits for anyway: no added delay);
- falling by at most ``1 / release_frames`` per frame (a fade, not a step, when the gate closes);
- 1 before the stream's first frame over digital silence and for ``warmup_frames`` from it, while the floor is
  one frame's guess (r(mouth_open) on s1 val 0.9012 ungated, 0.8997 gated from the first frame, 0.9007 with the
  warm-up; on the other GRID talkers 0.663, 0.644, 0.661: the talkers hold the mouth open before speaking);
  a take of digital silence alone is left exactly as the model gives it (no motion);

and the row becomes ``gain * row``: the rest pose is the neutral face, every parameter 0 (:meth:`NoiseGate.fade`
fades other values of the rows, the MLP mapper's MU parameters, towards their own rest alike). Row ``t`` uses frames
``<= t + lookahead`` only, all of which the front end has computed before it releases the row, so the output is
the same for any chunking of the input. Measured: docs/default_model.md, "Room noise".
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.features.gain import DIGITAL_SILENCE_DBFS


@dataclass(frozen=True, kw_only=True)
class NoiseGateConfig:
    """margin_db: frames this close to the tracked noise floor (dB) are noise (openness 0).
    ramp_db: the openness rises linearly to 1 over this many dB above the margin.
    hold_frames: a row stays open while any of the last this many frames (30 fps) was open (1 s).
    release_frames: the gain falls to 0 over at least this many frames when the gate closes (0: at once).
    warmup_frames: the first this many rows of a stream pass unchanged (the floor is not known yet).
    floor_window_frames: the noise floor is the minimum of the smoothed level over the last this many frames
        over digital silence (minimum statistics; a noise that steps up is the floor this many frames later).
    floor_smoothing: the smoothed level closes this fraction of its gap to the frame's level per frame
        (1: the levels as they are).
    """

    margin_db: float = 2.5
    ramp_db: float = 2.0
    hold_frames: int = 30
    release_frames: int = 6
    warmup_frames: int = 10
    floor_window_frames: int = 45
    floor_smoothing: float = 0.3

    def __post_init__(self) -> None:
        for name in ("margin_db", "ramp_db"):
            v = getattr(self, name)
            if not 0.0 <= v <= 60.0:
                raise ConfigError(f"NoiseGateConfig.{name} must be in [0, 60] dB, got {v}")
        for name in ("hold_frames", "release_frames", "warmup_frames"):
            v = getattr(self, name)
            if not 0 <= v <= 3000:
                raise ConfigError(f"NoiseGateConfig.{name} must be in 0..3000 frames, got {v}")
        if not 1 <= self.floor_window_frames <= 3000:
            raise ConfigError(f"NoiseGateConfig.floor_window_frames must be in 1..3000, got {self.floor_window_frames}")
        if not 0.0 < self.floor_smoothing <= 1.0:
            raise ConfigError(f"NoiseGateConfig.floor_smoothing must be in (0, 1], got {self.floor_smoothing}")


class NoiseGate:
    """``push_levels(level_db (k,))`` with each batch of MFCC frames, in order; ``apply(rows (m, Dv)) -> (m, Dv)``
    float64 with each batch of output rows, in order (row ``t`` is frame ``t``; its frames up to ``t + lookahead``
    must have been pushed, or be the stream's last); ``reset()``."""

    def __init__(self, config: NoiseGateConfig, *, lookahead: int) -> None:
        if lookahead < 0:
            raise ConfigError(f"NoiseGate lookahead must be >= 0 frames, got {lookahead}")
        self.config = config
        self.lookahead = int(lookahead)
        self.reset()

    def reset(self) -> None:
        self._smooth = float("nan")  # the smoothed level (dB); nan before the first frame over digital silence
        self._recent: deque[float] = deque(maxlen=self.config.floor_window_frames)  # its last values
        self._open: list[float] = []  # openness of frames self._first .. self._first + len - 1
        self._first = 0
        self._row = 0
        self._heard: int | None = None  # the stream's first frame over digital silence
        self._gain = 1.0
        self.gain = np.ones(0)
        """The gains (m,) the last :meth:`apply` used."""

    def push_levels(self, level_db: np.ndarray) -> None:
        cfg = self.config
        # The levels rounded to float32 (6e-6 dB at -50 dB), as the inverter reads its features: the front end's
        # levels of one frame differ in their last bits with the chunking (2e-14 dB whole against sample by sample,
        # the batched FFT's rounding), and a fractional openness or a floor passes that on to the gain.
        for x in np.asarray(level_db, dtype=np.float32).astype(np.float64).ravel():
            if x < DIGITAL_SILENCE_DBFS:  # padding, a muted stretch: no evidence of the room's floor
                self._open.append(0.0)
                continue
            if self._heard is None:
                self._heard = self._first + len(self._open)
            s = x if self._smooth != self._smooth else self._smooth + cfg.floor_smoothing * (x - self._smooth)
            self._smooth = s
            self._recent.append(s)
            over = float(x) - min(self._recent) - cfg.margin_db
            self._open.append(min(max(over / cfg.ramp_db, 0.0), 1.0) if cfg.ramp_db > 0 else float(over > 0))

    def apply(self, rows: np.ndarray) -> np.ndarray:
        cfg = self.config
        y = np.array(rows, dtype=np.float64)
        gains = np.ones(len(y))
        a, first = self._open, self._first
        for i in range(len(y)):
            t = self._row
            if t - first >= len(a):
                raise ConfigError(f"NoiseGate: row {t} before its frame's level (levels up to {first + len(a) - 1})")
            g = max(a[max(t - cfg.hold_frames, first) - first : t - first + 1])
            for d in range(1, self.lookahead + 1):
                if t + d - first < len(a):
                    g = max(g, a[t + d - first] * (1.0 - d / (self.lookahead + 1)))
            if self._heard is None or t < self._heard + cfg.warmup_frames:
                g = 1.0
            elif cfg.release_frames > 0:
                g = max(g, self._gain - 1.0 / cfg.release_frames)
                if g < 1e-9:  # the fade's steps of 1/r leave rounding (1e-16) where the rest pose must be exact
                    g = 0.0
            self._gain = g
            gains[i] = g
            self._row += 1
        # keep only the frames a later row can still look back to
        drop = max(self._row - cfg.hold_frames - first, 0)
        if drop > 0:
            del a[:drop]
            self._first = first + drop
        self.gain = gains
        y *= gains[:, None]
        return y

    def fade(self, values: np.ndarray, rest: np.ndarray) -> np.ndarray:
        """Other values ``(m, D)`` of the rows the last :meth:`apply` gated (e.g. the mapper's MU parameters) ->
        ``(m, D)`` float64 faded by the same gains towards their own rest ``rest (D,)``; rows at gain 1 are left
        bit for bit as they are."""
        v = np.asarray(values, dtype=np.float64)
        g = self.gain[:, None]
        if len(v) != len(g):
            raise ConfigError(f"NoiseGate.fade: {len(v)} rows for the {len(g)} the last apply gated")
        return np.where(g == 1.0, v, rest + g * (v - rest))
