"""The output stage of every model's estimate: the closed pose is a floor, and near-closures close.

Two documented steps, per parameter with a closed pose (:data:`realtime_core.CLOSED_POSE`; today
``mouth_open`` = 0, the lips touching):

1. **Closure band** (``band`` IOD, chosen per model on held-out data; 0 = off). Eq. 7 is a
   posterior-weighted average of regressions, so an estimate shrinks towards the mean and a lip
   closure of 70-130 ms comes out as a shallow dip that stops a few hundredths of an IOD short of
   contact. Values within ``band`` of the closed pose are drawn onto it, and the range up to
   ``KNEE * band`` is stretched linearly to stay continuous: with ``c`` the closed pose and
   ``k = c + KNEE * band``, ``y = c + (x - c - band) * KNEE / (KNEE - 1)`` for ``c + band <= x < k``,
   ``y = c`` below, ``y = x`` from ``k`` up. Monotone, so it never reorders frames.
2. **Floor**: never below the closed pose (below it one lip would pass through the other).

Other parameters pass unchanged. Pure numpy on one frame ``(Dv,)`` or a track ``(T, Dv)``.
"""

from __future__ import annotations

import numpy as np

from realtime_core.errors import ConfigError

KNEE = 3.0
"""Above ``closed + KNEE * band`` the estimate is untouched."""


class OutputStage:
    """``floor``: ``(Dv,)`` closed pose per parameter, -inf where none; ``band``: closure band, IOD."""

    def __init__(self, floor: np.ndarray, band: float = 0.0) -> None:
        if not 0.0 <= band <= 0.1:
            raise ConfigError(f"closure band must be in [0, 0.1] IOD, got {band}")
        self.floor = np.asarray(floor, dtype=np.float64)
        self.band = float(band)
        self._closed = np.isfinite(self.floor)
        # (index, closed pose) pairs: one live frame is a few scalar operations (numpy's fancy
        # indexing on a 4-vector costs ~20x more)
        self._pairs = [(int(j), float(self.floor[j])) for j in np.flatnonzero(self._closed)] if band > 0 else []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """``(Dv,)`` or ``(T, Dv)`` estimates -> the same shape, float64."""
        y = np.maximum(x, self.floor)
        gain = KNEE / (KNEE - 1.0)
        if y.ndim == 1:
            for j, c in self._pairs:
                v = y[j]
                if v < c + KNEE * self.band:
                    y[j] = c + max(v - c - self.band, 0.0) * gain
        elif self._pairs:
            closed = self.floor[self._closed]
            vals = y[..., self._closed]
            stretched = closed + np.maximum(vals - closed - self.band, 0.0) * gain
            y[..., self._closed] = np.where(vals < closed + KNEE * self.band, stretched, vals)
        return y
