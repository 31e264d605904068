"""The audio front end: samples -> MFCC -> running CMVN -> context-stacked vectors o_a,t.

One streaming object composes the three stages so the live server, ``facecast animate``
and training all compute exactly the same features. Fed whole, sample by sample or in
random chunks it gives the same rows.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import numpy as np

from realtime_core.errors import ConfigError, InvalidAudioError
from realtime_core.features.cmvn import CmvnConfig, RunningCmvn, mel_level_db
from realtime_core.features.context import ContextStacker
from realtime_core.features.gain import InputGain, InputGainConfig
from realtime_core.features.level import LevelNormConfig, LevelTracker
from realtime_core.features.mfcc import MfccConfig, MfccStream, as_float_samples


@dataclass(frozen=True, kw_only=True)
class FrontEndConfig:
    """mfcc: the MFCC settings (``include_c0`` must be False: see ``energy``).
    cmvn: running-CMVN settings, or None for raw MFCCs.
    tc: co-articulation context on each side (3 -> 7 frames -> 77 dims with 11 ceps).
    energy: also use c0 (log energy) as a feature, normalised by the running CMVN like the
    others (the paper uses c1..c11 only; c0 carries loudness, which predicts mouth opening
    in real speech). Each frame then has n_ceps + 1 values, c0 first.
    silence_floor_db: frames whose level (dB, :func:`mel_level_db`; about dBFS + 2 for white
    noise) is below this are replaced by the features of digital silence, so a quiet room's
    hiss looks exactly like the silent pauses the model was trained on and the mouth stays
    closed (None disables the gate). Ignored with ``level_norm``, whose gate is relative.
    level_norm: None (absolute c0 and levels), or the talker's own speech level removed
    (:mod:`realtime_core.features.level`): c0 becomes c0 minus the tracked speech peak, frames more
    than ``level_norm.silence_below_peak_db`` under the peak (or near the tracked noise floor) become
    silence, and the levels
    the CMVN gate sees are relative to the peak (so ``cmvn.gate_db`` is then dB re the peak). The
    whole front end is then invariant to the recording gain.
    input_gain: None (the samples as given), or a run-time gain in front of the MFCCs that brings the
    talker's tracked speech level to the training level (:mod:`realtime_core.features.gain`; the
    model is unchanged, only its input).
    """

    mfcc: MfccConfig = field(default_factory=MfccConfig)
    cmvn: CmvnConfig | None = field(default_factory=CmvnConfig)
    tc: int = 3
    energy: bool = False
    silence_floor_db: float | None = -60.0
    level_norm: LevelNormConfig | None = None
    input_gain: InputGainConfig | None = None

    def __post_init__(self) -> None:
        if self.mfcc.include_c0:
            raise ConfigError("FrontEndConfig.mfcc.include_c0 must be False (c0 is used for gating)")
        if not 0 <= self.tc <= 20:
            raise ConfigError(f"tc must be in 0..20, got {self.tc}")

    @property
    def n_feat(self) -> int:
        """Values per frame before stacking: n_ceps (+1 with ``energy``)."""
        return self.mfcc.n_ceps + (1 if self.energy else 0)

    @property
    def audio_dim(self) -> int:
        """Dimension of o_a,t: ``(2 tc + 1) * n_feat``."""
        return (2 * self.tc + 1) * self.n_feat

    @property
    def delay_frames(self) -> int:
        """Rows lag the newest complete MFCC frame by tc frames (the lookahead)."""
        return self.tc

    def algorithmic_delay_ms(self, lag: int = 0) -> float:
        """The algorithmic delay in ms with ``lag`` frames of fixed-lag smoothing: the one formula
        the CLI, the server, ``facecast bench latency`` and the docs use (docs/architecture.md, Delay).

        The output for video frame t (instant t / fps) depends on MFCC frame t + tc + lag (context,
        then smoothing), whose window of ``window_len`` samples starts at ``frame_start(t + tc + lag)``;
        so frame t is final ``frame_start(t + tc + lag) + window_len`` samples into the stream. Less
        t / fps, that is at most (equal whenever (t + tc + lag) * rate / fps is whole)

            delay = (tc + lag) / fps + window_len / sample_rate_hz

        e.g. tc = 3, window 2 hops (1067 samples at 16 kHz): 100 + 66.7 = 166.7 ms. A resampler in
        front (input not at the model rate) adds its own lookahead
        (:attr:`realtime_core.pipeline.SpeechToParams.algorithmic_delay_ms`).
        """
        if lag < 0:
            raise ConfigError(f"lag must be >= 0 frames, got {lag}")
        m = self.mfcc
        return 1e3 * ((self.tc + lag) / m.frame_rate_hz + m.window_len / m.sample_rate_hz)


class FrontEnd:
    """``push(samples (n,)) -> (k, audio_dim) float64``; ``flush()`` -> the rest.

    ``cmvn_mean``/``cmvn_var``: ``(n_feat,)`` warm-start statistics (the model's training
    statistics); required when ``config.cmvn`` is not None. kernel: "numba" (default) or "numpy" (the
    reference) for the MFCC and CMVN per-frame steps.
    """

    def __init__(
        self,
        config: FrontEndConfig,
        *,
        cmvn_mean: np.ndarray | None = None,
        cmvn_var: np.ndarray | None = None,
        kernel: str = "numba",
    ) -> None:
        self.config = config
        mcfg = config.mfcc
        self._mfcc = MfccStream(replace(mcfg, include_c0=True), kernel=kernel)
        self._gain = (
            InputGain(config.input_gain, sample_rate_hz=mcfg.sample_rate_hz) if config.input_gain is not None else None
        )
        if config.cmvn is not None:
            if cmvn_mean is None or cmvn_var is None:
                raise ConfigError("FrontEnd with CMVN needs cmvn_mean and cmvn_var (training statistics)")
            self._cmvn: RunningCmvn | None = RunningCmvn(config.cmvn, mean=cmvn_mean, var=cmvn_var, kernel=kernel)
        else:
            self._cmvn = None
        self._ctx = ContextStacker(dim=config.n_feat, tc=config.tc)
        self._level = _LevelStage(config, kernel=kernel)
        # The level gate, CMVN and context stacking in one compiled call per push (without level
        # normalisation, whose tracker stays numpy): the three stages were some fifteen numpy calls
        # per live frame, each slowed by the cache misses the inverter's matrices cause.
        self._tail = (
            _CompiledTail(config, self._level, self._cmvn) if kernel == "numba" and config.level_norm is None else None
        )
        self.last_level_db = np.zeros(0)
        """The levels (k,) dB (:func:`mel_level_db` of c0, before any gate) of the MFCC frames the last push/flush
        computed, in order: frame t of the stream is row t's centre (the output noise gate reads them)."""

    def reset(self) -> None:
        if self._tail is not None:
            self._tail.reset()
        self._mfcc.reset()
        if self._gain is not None:
            self._gain.reset()
        if self._cmvn is not None:
            self._cmvn.reset()
        self._ctx.reset()
        self._level.reset()

    @property
    def frames_out(self) -> int:
        """Rows released so far (row t is video frame t)."""
        return int(self._tail.cist[1]) if self._tail is not None else self._ctx._next

    def push(self, samples: np.ndarray) -> np.ndarray:
        if self._gain is not None:
            samples = self._gain.push(as_float_samples(samples))
        return self._rows(self._mfcc.push(samples), final=False)

    def flush(self) -> np.ndarray:
        return self._rows(self._mfcc.flush(), final=True)

    def _rows(self, c0_ceps: np.ndarray, *, final: bool) -> np.ndarray:
        """Raw ``[c0, c1..] (k, n_ceps + 1)`` -> the rows now final; keeps the frames' levels, computed once: by the
        compiled tail with its silence gate (the live path), else here for the reference stages."""
        if self._tail is not None:
            rows, self.last_level_db = self._tail.push(c0_ceps, final=final)
            return rows
        self.last_level_db = mel_level_db(c0_ceps[:, 0], self.config.mfcc.n_mels)
        ceps, level = self._level.push(c0_ceps, self.last_level_db)
        rows = self._ctx.push(ceps if self._cmvn is None else self._cmvn.push(ceps, level))
        return np.concatenate([rows, self._ctx.flush()]) if final else rows


_SILENT_DB = -1000.0
"""The level (dB re the speech peak) given to the CMVN for frames that level normalisation made silence."""


class _LevelStage:
    """Raw ``[c0, c1..] (k, n_ceps + 1)`` -> ``(features (k, n_feat), level_db (k,))`` before CMVN:
    the silence gate (absolute ``silence_floor_db``, or relative with ``level_norm``), c0 made relative
    to the tracked speech peak with ``level_norm``, c0 dropped unless ``energy``."""

    def __init__(self, config: FrontEndConfig, *, kernel: str = "numba") -> None:
        self.config = config
        mcfg = config.mfcc
        # Raw [c0, c1..] of digital silence (every mel band at the energy floor), shared read-only.
        self._silence = _silence_row(replace(mcfg, include_c0=True), kernel)
        self._db_per_c0 = float(mel_level_db(np.ones(1), mcfg.n_mels)[0])
        self._tracker = LevelTracker(config.level_norm) if config.level_norm is not None else None
        if config.level_norm is not None:
            # silence under level normalisation: the silence spectrum at the gate's relative level
            self._silence = self._silence.copy()
            self._silence[0] = -config.level_norm.silence_below_peak_db / self._db_per_c0

    def reset(self) -> None:
        if self._tracker is not None:
            self._tracker.reset()

    def push(self, c0_ceps: np.ndarray, level_db: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``level_db``: the frames' levels (k,) when already computed (:func:`mel_level_db` of c0)."""
        level = mel_level_db(c0_ceps[:, 0], self.config.mfcc.n_mels) if level_db is None else level_db
        if self._tracker is not None and self.config.level_norm is not None:
            ln = self.config.level_norm
            peak, floor = self._tracker.track(level)
            quiet = (level < peak - ln.silence_below_peak_db) | (level < floor + ln.silence_above_floor_db)
            # silence never updates the CMVN statistics: its level goes far under any gate
            level = np.where(quiet, _SILENT_DB, level - peak)
            c0_ceps = np.concatenate([c0_ceps[:, :1] - (peak / self._db_per_c0)[:, None], c0_ceps[:, 1:]], axis=1)
        elif self.config.silence_floor_db is not None:
            quiet = level < self.config.silence_floor_db
        else:
            quiet = np.zeros(level.shape, dtype=bool)
        if quiet.any():
            c0_ceps = np.where(quiet[:, None], self._silence, c0_ceps)
        return (c0_ceps if self.config.energy else c0_ceps[:, 1:]), level


class _CompiledTail:
    """Level gate -> running CMVN -> context stacking as one compiled call
    (:func:`realtime_core.features.compiled.normalise_stack`) on state kept in place; ``_LevelStage``,
    :class:`RunningCmvn` and :class:`ContextStacker` are the reference. Without level normalisation."""

    def __init__(self, config: FrontEndConfig, level: _LevelStage, cmvn: RunningCmvn | None) -> None:
        from realtime_core.features.compiled import normalise_stack  # numba's import is paid only here

        self._kernel = normalise_stack
        self.config = config
        self._silence = level._silence
        self._db_per_c0 = level._db_per_c0
        floor = config.silence_floor_db
        self._floor_db = -np.inf if floor is None else float(floor)
        self._cmvn = cmvn
        c = config.cmvn
        self._cmvn_consts = (c.gate_db, c.max_frames, c.var_floor) if c is not None else (0.0, 1.0, 1.0)
        self.reset()

    def reset(self) -> None:
        cm = self._cmvn
        d = self.config.n_feat
        m, v, count = cm.initial_state if cm is not None else (np.zeros(d), np.ones(d), 1.0)
        self._m, self._v = m, v
        self._cst = np.array([count])
        self._ring = np.zeros((2 * self.config.tc + 1, d))
        self.cist = np.zeros(2, dtype=np.int64)
        """[frames received, rows released]"""

    def push(self, c0_ceps: np.ndarray, *, final: bool) -> tuple[np.ndarray, np.ndarray]:
        """-> ``(rows now final, levels (k,) dB of the frames before the silence gate)``."""
        out: tuple[np.ndarray, np.ndarray] = self._kernel(
            c0_ceps,
            self._db_per_c0,
            self._floor_db,
            self._silence,
            self.config.energy,
            self._cmvn is not None,
            self._m,
            self._v,
            self._cst,
            *self._cmvn_consts,
            self._ring,
            self.cist,
            self.config.tc,
            final,
        )
        return out


def raw_mfcc_with_level(samples: np.ndarray, config: FrontEndConfig) -> tuple[np.ndarray, np.ndarray]:
    """Whole-utterance MFCCs and levels for computing CMVN training statistics.

    Returns ``(ceps (T, n_feat), level_db (T,))`` on the front end's frame grid: the features the
    CMVN sees and the levels its gate compares (relative to the speech peak with ``level_norm``).
    The absolute silence gate is not applied (gated frames are below the CMVN gate by default).
    """
    mfcc = config.mfcc
    x = as_float_samples(samples)
    if x.size < mfcc.window_len:
        raise InvalidAudioError(f"audio too short: {x.size} samples < one window ({mfcc.window_len})")
    s = MfccStream(replace(mfcc, include_c0=True))
    rows = np.concatenate([s.push(x), s.flush()])
    if config.level_norm is not None:
        return _LevelStage(config).push(rows)
    return (rows if config.energy else rows[:, 1:]), mel_level_db(rows[:, 0], mfcc.n_mels)


def extract_features(
    samples: np.ndarray,
    config: FrontEndConfig,
    *,
    cmvn_mean: np.ndarray | None = None,
    cmvn_var: np.ndarray | None = None,
) -> np.ndarray:
    """Whole-utterance o_a: ``(n,)`` samples -> ``(n_frames, audio_dim) float64``.

    Identical to the streaming :class:`FrontEnd` fed the same samples and flushed.
    """
    x = as_float_samples(samples)
    if x.size < config.mfcc.window_len:
        raise InvalidAudioError(
            f"audio too short: {x.size} samples, need at least one window of {config.mfcc.window_len}"
        )
    fe = FrontEnd(config, cmvn_mean=cmvn_mean, cmvn_var=cmvn_var)
    return np.concatenate([fe.push(x), fe.flush()])


@functools.lru_cache(maxsize=32)
def _silence_row(mcfg: MfccConfig, kernel: str) -> np.ndarray:
    """Raw ``[c0, c1..]`` of digital silence (every mel band at the energy floor), ``(n_outputs,)``
    float64, read-only: computed once per configuration, not once per session."""
    row = MfccStream(mcfg, kernel=kernel).push(np.zeros(mcfg.window_len))[0]
    row.flags.writeable = False
    return row
