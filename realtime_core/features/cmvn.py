"""Streaming cepstral mean/variance normalisation (CMVN).

Theory of operation
-------------------
A new speaker or microphone shifts MFCCs by a roughly constant offset and scale; the
audio-visual model, trained on other voices, then sees features it never saw. Running
CMVN removes that shift causally: per-coefficient mean ``m`` and variance ``v`` are
running averages with weight ``1 / c`` where the count ``c`` starts at ``prior_frames``
(a warm start from the model's training statistics, so the first frames of a stream are
already normalised sensibly) and grows to ``max_frames`` (after which the statistics
forget slowly, following a speaker or room that changes).

Only speech-like frames update the statistics: frames whose level is below
``gate_db`` leave ``m`` and ``v`` untouched. Otherwise a long silence would become the
"mean" and, once normalised, look like average speech, making a silent head move.

Every frame is normalised with the statistics *after* its own update, so the output of
frame ``t`` depends only on frames ``<= t``: the same whether the frames arrive whole or
one at a time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError, InvalidFeaturesError


@dataclass(frozen=True, kw_only=True)
class CmvnConfig:
    """prior_frames: weight (in frames) of the warm-start statistics.
    max_frames: the count stops growing here (memory of about max_frames / 30 s).
    gate_db: frames with level (dB, see :func:`mel_level_db`) below this do not update.
    var_floor: added to the variance before the square root.
    """

    prior_frames: float = 300.0
    max_frames: float = 900.0
    gate_db: float = -60.0
    var_floor: float = 1e-6

    def __post_init__(self) -> None:
        if not 1.0 <= self.prior_frames <= self.max_frames:
            raise ConfigError(f"need 1 <= prior_frames <= max_frames, got {self.prior_frames}, {self.max_frames}")
        if self.var_floor <= 0:
            raise ConfigError(f"var_floor must be > 0, got {self.var_floor}")


def mel_level_db(c0: np.ndarray, n_mels: int) -> np.ndarray:
    """Frame level in dB from the orthonormal-DCT c0: ``10 log10(e) * c0 / sqrt(n_mels)``.

    ``c0``: ``(k,)`` -> ``(k,)`` dB (the mean log mel energy, in decibels).
    """
    return c0 * (10.0 / np.log(10.0) / np.sqrt(n_mels))


class RunningCmvn:
    """Causal CMVN: ``push(features (k, d), level_db (k,)) -> (k, d) float64``."""

    def __init__(self, config: CmvnConfig, *, mean: np.ndarray, var: np.ndarray, kernel: str = "numba") -> None:
        """kernel: "numba" (the per-frame loop compiled, :mod:`realtime_core.features.compiled`) or
        "numpy" (the reference; the two agree to rounding)."""
        if kernel not in ("numba", "numpy"):
            raise ConfigError(f"kernel must be 'numba' or 'numpy', got {kernel!r}")
        self.kernel = kernel
        if kernel == "numba":
            from realtime_core.features.compiled import cmvn_push  # numba's import is paid only here

            self._compiled_push = cmvn_push
        mean = np.asarray(mean, dtype=np.float64)
        var = np.asarray(var, dtype=np.float64)
        if mean.ndim != 1 or var.shape != mean.shape:
            raise InvalidFeaturesError(f"CMVN mean/var must be equal 1-D shapes, got {mean.shape}, {var.shape}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var > 0)):
            raise InvalidFeaturesError("CMVN warm-start statistics must be finite with positive variance")
        self.config = config
        self._mean0 = mean.copy()
        self._var0 = var.copy()
        self.reset()

    @property
    def dim(self) -> int:
        return self._mean0.size

    @property
    def initial_state(self) -> tuple[np.ndarray, np.ndarray, float]:
        """``(mean (d,), var (d,), count)`` float64 copies of the warm start a reset returns to: what a
        fused kernel that keeps the running statistics itself starts from."""
        return self._mean0.copy(), self._var0.copy(), float(self.config.prior_frames)

    def reset(self) -> None:
        self._m = self._mean0.copy()
        self._v = self._var0.copy()
        self._c = float(self.config.prior_frames)

    def push(self, features: np.ndarray, level_db: np.ndarray) -> np.ndarray:
        x = np.asarray(features, dtype=np.float64)
        lv = np.asarray(level_db, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.dim or lv.shape != (x.shape[0],):
            raise InvalidFeaturesError(
                f"CMVN expects features (k, {self.dim}) and levels (k,), got {x.shape}, {lv.shape}"
            )
        cfg = self.config
        if self.kernel == "numba":
            out, self._m, self._v, self._c = self._compiled_push(
                x, lv, self._m, self._v, self._c, cfg.gate_db, cfg.max_frames, cfg.var_floor
            )
            return out
        out = np.empty_like(x)
        m, v, c = self._m, self._v, self._c
        for i in range(x.shape[0]):
            if lv[i] >= cfg.gate_db:
                c = min(c + 1.0, cfg.max_frames)
                a = 1.0 / c
                d = x[i] - m
                m = m + a * d
                v = (1.0 - a) * (v + a * d * d)
            out[i] = (x[i] - m) / np.sqrt(v + cfg.var_floor)
        self._m, self._v, self._c = m, v, c
        return out
