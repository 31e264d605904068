"""Run-time input gain: scale the samples so the talker's speech level sits at the training level.

Theory of operation
-------------------
The shipped model reads loudness as an absolute c0 and gates pauses at an absolute -60 dB, so the
same file 3 dB quieter moves its mouth differently. A retrained, level-normalised front end was
measured and not shipped; this stage leaves the model
alone and changes its input instead, causally and per stream:

- the input is cut into blocks of ``block_ms`` on the absolute sample index (so any chunking of
  the pushes gives the same blocks) and each block's RMS level in dBFS is measured;
- a noise floor follows the levels (the floor of
  :class:`realtime_core.features.level.LevelTracker`: fast down, slow up); a block more than
  ``tracker.speech_above_floor_db`` over it is speech;
- the speech level is a running mean of the speech blocks' levels in dB, warm-started at
  ``reference_db`` with the weight of ``prior_blocks`` blocks (as the running CMVN is) and
  forgetting beyond ``memory_blocks``. ``reference_db`` is the mean speech-block level of the
  model's training speech (:data:`S1_SPEECH_LEVEL_DBFS`), so input at the training level starts
  at 0 dB of gain;
- after block ``i`` the gain for block ``i + 1`` is ``reference_db`` minus the speech level,
  limited to +-``max_gain_db``, for every block alike: pauses move with the speech, as a gain on
  the whole recording would (holding them at 0 dB while the speech got +12 dB put speech onsets,
  judged from the block before them, 12 dB low: s1 val at -12 dB as one stream 0.854 against 0.899).
  Only speech blocks move the speech level, so steady noise alone (never more than the floor
  margin over the floor) keeps exactly 0 dB: it is never raised towards speech level;
- within a block the amplitude ramps linearly from the previous block's gain to the new one (a
  step would add a click the MFCCs see as a broadband burst).

The gain of block ``i`` uses blocks ``< i`` only: no lookahead, no added delay. Measured against
the shipped model and off in the shipped files: docs/default_model.md, "Run-time input gain".
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.features.level import LevelNormConfig, LevelTracker

S1_SPEECH_LEVEL_DBFS = -18.8
"""The mean level (dBFS RMS per 32 ms block) of GRID s1's speech blocks (the default tracker's
floor + 10 dB rule), over every 4th train sentence back to back (180 sentences, 9156 speech blocks;
``scripts/input_gain_check.py --measure-reference``): the level the shipped models were trained at."""


@dataclass(frozen=True, kw_only=True)
class InputGainConfig:
    """reference_db: the mean speech-block level (dBFS) the gain brings the input to (the model's training level).
    block_ms: block length for the level measurement and the gain steps.
    max_gain_db: the gain stays within +-this.
    prior_blocks: the reference's weight in blocks of speech (the speech level's warm start).
    memory_blocks: the running mean forgets beyond this many speech blocks (100: 3.2 s).
    tracker: the noise floor's rates per block and ``speech_above_floor_db`` (its peak and
    ``silence_*`` fields are unused here).
    """

    reference_db: float = S1_SPEECH_LEVEL_DBFS
    block_ms: float = 32.0
    max_gain_db: float = 20.0
    prior_blocks: int = 5
    memory_blocks: int = 100
    tracker: LevelNormConfig = field(default_factory=LevelNormConfig)

    def __post_init__(self) -> None:
        if not -100.0 <= self.reference_db <= 0.0:
            raise ConfigError(f"InputGainConfig.reference_db must be in [-100, 0] dBFS, got {self.reference_db}")
        if not 1.0 <= self.block_ms <= 200.0:
            raise ConfigError(f"InputGainConfig.block_ms must be in [1, 200] ms, got {self.block_ms}")
        if not 0.0 <= self.max_gain_db <= 60.0:
            raise ConfigError(f"InputGainConfig.max_gain_db must be in [0, 60] dB, got {self.max_gain_db}")
        if not 0 <= self.prior_blocks <= self.memory_blocks or self.memory_blocks < 1:
            raise ConfigError(
                f"InputGainConfig needs 0 <= prior_blocks <= memory_blocks and memory_blocks >= 1, "
                f"got {self.prior_blocks} and {self.memory_blocks}"
            )

    def block_len(self, sample_rate_hz: int) -> int:
        """Samples per block at ``sample_rate_hz``."""
        return max(1, round(sample_rate_hz * self.block_ms / 1000.0))


DIGITAL_SILENCE_DBFS = -80.0
"""A block this quiet (RMS, dBFS) is digital silence (padding, a muted stretch), not a room's noise floor."""

DIGITAL_SILENCE_PEAK = 1e-4
"""The same level as a peak (full scale 1, -80 dBFS): samples whose absolute peak stays under it are digital silence
(``assets.audio.is_silent`` of a whole recording, the enrolment's frames in :mod:`realtime_core.adaptation`)."""


def speech_level_db(samples: np.ndarray, sample_rate_hz: int, config: InputGainConfig | None = None) -> float | None:
    """The mean level (dBFS, RMS per ``config.block_ms`` block) of the speech blocks of a whole recording ``samples``
    (n,) float in [-1, 1]: blocks more than ``config.tracker.speech_above_floor_db`` over the tracked noise floor, the
    rule :data:`S1_SPEECH_LEVEL_DBFS` was measured by, so the two compare. Blocks under :data:`DIGITAL_SILENCE_DBFS` are
    left out: after a file's digitally silent padding the floor sat at -120 dB and took the speech's quiet tails for
    speech (LJ Speech's LJ001-0001 between 3 s of zeros: -27.6 dBFS against its own -24.0). None when no block is
    speech (silence, steady noise, shorter than a block)."""
    cfg = InputGainConfig() if config is None else config
    x = np.asarray(samples, dtype=np.float64)
    b = cfg.block_len(sample_rate_hz)
    n = x.size // b
    level = 10.0 * np.log10(np.maximum(np.mean(x[: n * b].reshape(n, b) ** 2, axis=1), 1e-12))
    level = level[level > DIGITAL_SILENCE_DBFS]
    if level.size == 0:
        return None
    _, floor = LevelTracker(cfg.tracker).track(level)
    speech = level > floor + cfg.tracker.speech_above_floor_db
    return float(level[speech].mean()) if speech.any() else None


class InputGain:
    """``push(samples (n,) float64) -> (n,) float64`` scaled samples, no delay (``flush()`` -> none);
    ``reset()``.

    Chunk-invariant: any split of the input into pushes gives the same output bit for bit."""

    def __init__(self, config: InputGainConfig, *, sample_rate_hz: int) -> None:
        self.config = config
        self.block_len = config.block_len(sample_rate_hz)
        self._tracker = LevelTracker(config.tracker)  # its noise floor only
        self._ramp = np.arange(1, self.block_len + 1, dtype=np.float64) / self.block_len
        self.reset()

    def reset(self) -> None:
        self._tracker.reset()
        self._n = 0
        self._block = np.empty(self.block_len)
        self._fill = 0
        self._amp = 1.0
        self._curve = np.ones(self.block_len)  # the current block's amplitude per sample
        self.gain_db = 0.0
        """The gain (dB) the current block ramps to."""
        self.speech_db = self.config.reference_db
        """The tracked speech level (dBFS)."""

    def push(self, samples: np.ndarray) -> np.ndarray:
        x = np.asarray(samples, dtype=np.float64)
        out = np.empty_like(x)
        i = 0
        while i < x.size:
            m = min(self.block_len - self._fill, x.size - i)
            a, b = self._fill, self._fill + m
            np.multiply(x[i : i + m], self._curve[a:b], out=out[i : i + m])
            self._block[a:b] = x[i : i + m]
            self._fill = b
            i += m
            if self._fill == self.block_len:
                self._next_gain()
        return out

    def flush(self) -> np.ndarray:
        """Nothing is held back (the gain has no lookahead): an empty block."""
        return np.zeros(0)

    def _next_gain(self) -> None:
        cfg = self.config
        level = 10.0 * np.log10(max(float(np.dot(self._block, self._block)) / self.block_len, 1e-12))
        _, floor = self._tracker.track(np.array([level]))
        speech = level > floor[0] + cfg.tracker.speech_above_floor_db
        if speech:
            self._n += 1
            self.speech_db += (level - self.speech_db) / min(cfg.prior_blocks + self._n, cfg.memory_blocks)
        g = min(max(cfg.reference_db - self.speech_db, -cfg.max_gain_db), cfg.max_gain_db)
        self.gain_db = g
        amp = 10.0 ** (g / 20.0)
        self._curve = self._amp + (amp - self._amp) * self._ramp
        self._amp = amp
        self._fill = 0
