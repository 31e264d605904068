"""A plausible mouth track for the tests of track files and exporters."""

from __future__ import annotations

import numpy as np

from realtime_core.track import Track


def syllable_track(n: int = 90, seed: int = 0) -> Track:
    """n frames of plausible mouth motion (IOD): a syllable-rate open/close with small other units."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    p = np.stack(
        [
            0.04 * np.sin(k / 7.0),
            0.10 * np.sin(k / 11.0 + 1),
            0.22 * (1 - np.cos(k / 4.0)) + 0.002 * rng.standard_normal(n),
            0.03 * np.cos(k / 5.0),
        ],
        axis=1,
    )
    return Track(values=p.astype(np.float32))
