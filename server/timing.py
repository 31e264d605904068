"""Per-stage timing: a fixed ring of recent durations per stage, summarised on demand.

Recording is one array store (cheap enough for every push); percentiles are computed only when
metrics are read.
"""

from __future__ import annotations

import contextlib
import gc
import time

import numpy as np


class StageTimes:
    """name -> ring of the last ``capacity`` durations (seconds) plus lifetime count and total."""

    def __init__(self, capacity: int = 4096) -> None:
        self.capacity = int(capacity)
        self._rings: dict[str, np.ndarray] = {}
        self._counts: dict[str, int] = {}
        self._totals: dict[str, float] = {}

    def add(self, name: str, seconds: float) -> None:
        ring = self._rings.get(name)
        if ring is None:
            ring = self._rings[name] = np.zeros(self.capacity)
            self._counts[name] = 0
            self._totals[name] = 0.0
        n = self._counts[name]
        ring[n % self.capacity] = seconds
        self._counts[name] = n + 1
        self._totals[name] += seconds

    def samples(self, name: str) -> np.ndarray:
        """The recent durations (s) of one stage, (m,) float64 (unordered)."""
        n = self._counts.get(name, 0)
        return self._rings[name][: min(n, self.capacity)].copy() if n else np.zeros(0)

    def names(self) -> list[str]:
        return list(self._rings)

    def merge_into(self, other: StageTimes) -> None:
        """Add this object's recent samples to ``other`` (for server-wide summaries)."""
        for name in self._rings:
            for s in self.samples(name):
                other.add(name, float(s))

    def summary(self) -> dict[str, dict[str, float]]:
        """{stage: {count, mean_ms, p50_ms, p99_ms, max_ms}} over the recent window (count: lifetime)."""
        out = {}
        for name in self._rings:
            s = self.samples(name) * 1e3
            out[name] = {
                "count": self._counts[name],
                "mean_ms": round(float(s.mean()), 4),
                "p50_ms": round(float(np.percentile(s, 50)), 4),
                "p99_ms": round(float(np.percentile(s, 99)), 4),
                "max_ms": round(float(s.max()), 4),
            }
        return out


def summarise(values_s: np.ndarray) -> dict[str, float]:
    """Durations (n,) in seconds -> {n, median_ms, p99_ms, max_ms, mean_ms}."""
    v = np.asarray(values_s, dtype=np.float64) * 1e3
    if v.size == 0:
        return {"n": 0}
    return {
        "n": int(v.size),
        "median_ms": round(float(np.median(v)), 4),
        "p99_ms": round(float(np.percentile(v, 99)), 4),
        "max_ms": round(float(v.max()), 4),
        "mean_ms": round(float(v.mean()), 4),
    }


def freeze_heap() -> None:
    """Move every object alive now (modules, the model, the compiled kernels: ~200,000 objects) out
    of the garbage collector's reach (``gc.freeze``). Call once a long-running process has loaded
    everything. Why: a full (generation 2) collection scans every tracked object and took 30-400 ms
    here on the loaded server; with the startup heap frozen it scans only what came after, so the
    per-connection allocations of busy traffic no longer stall the event loop for a frame or ten."""
    gc.freeze()


class GcPauses:
    """Records each garbage collection's pause in ``times`` as ``gc_gen{0,1,2}`` (so /metrics shows
    whether the collector stalls the loop); :meth:`close` stops recording."""

    def __init__(self, times: StageTimes) -> None:
        self.times = times
        self._t0 = 0.0
        gc.callbacks.append(self._on_gc)

    def _on_gc(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._t0 = time.perf_counter()
        else:
            self.times.add(f"gc_gen{info['generation']}", time.perf_counter() - self._t0)

    def close(self) -> None:
        with contextlib.suppress(ValueError):
            gc.callbacks.remove(self._on_gc)
