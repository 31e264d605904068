"""Co-articulation context stacking (paper Sec. 3), streaming and whole-utterance."""

from __future__ import annotations

import numpy as np

from realtime_core.errors import ConfigError, InvalidFeaturesError, StreamStateError


class ContextStacker:
    """Co-articulation context (paper Sec. 3): ``o_t = [a_{t-tc}; ...; a_t; ...; a_{t+tc}]``.

    ``push(frames (k, d))`` returns the stacked rows now ready, ``(j, (2 tc + 1) d)``: row
    ``t`` is released once frame ``t + tc`` has arrived (the lookahead delay). ``flush()``
    releases the rest. Edges are handled explicitly by replication: frames before the
    utterance start repeat frame 0, frames after its end repeat the last frame.
    """

    def __init__(self, *, dim: int, tc: int = 3) -> None:
        if tc < 0 or tc > 20:
            raise ConfigError(f"tc must be in 0..20, got {tc}")
        if dim < 1:
            raise ConfigError(f"dim must be >= 1, got {dim}")
        self.dim = dim
        self.tc = tc
        self.reset()

    @property
    def out_dim(self) -> int:
        return (2 * self.tc + 1) * self.dim

    def reset(self) -> None:
        self._buf = np.zeros((0, self.dim))  # frames from absolute index self._buf_start
        self._buf_start = 0
        self._n = 0  # frames received
        self._next = 0  # next row to release
        self._finished = False

    def push(self, frames: np.ndarray) -> np.ndarray:
        if self._finished:
            raise StreamStateError("ContextStacker.push() after flush(); call reset() first")
        f = np.asarray(frames, dtype=np.float64)
        if f.ndim != 2 or f.shape[1] != self.dim:
            raise InvalidFeaturesError(f"ContextStacker expects frames (k, {self.dim}), got {f.shape}")
        if f.shape[0]:
            self._buf = np.concatenate([self._buf, f])
            self._n += f.shape[0]
        return self._release(self._n - self.tc)

    def flush(self) -> np.ndarray:
        if self._finished:
            raise StreamStateError("ContextStacker.flush() called twice; call reset() first")
        self._finished = True
        return self._release(self._n)

    def _release(self, end: int) -> np.ndarray:
        """Rows ``self._next .. end - 1`` with replicated edges."""
        if end <= self._next or self._n == 0:
            return np.zeros((0, self.out_dim))
        lo, hi = self._next - self.tc, end - 1 + self.tc
        if lo >= 0 and hi <= self._n - 1:
            # Away from the edges each row is a contiguous slice of the buffer.
            b = lo - self._buf_start
            w = 2 * self.tc + 1
            if end - self._next == 1:  # the live case: one row, one copy
                rows = self._buf[b : b + w].reshape(1, -1).copy()
            else:
                rows = np.stack([self._buf[b + i : b + i + w].reshape(-1) for i in range(end - self._next)])
        else:
            t = np.arange(self._next, end)
            idx = np.clip(t[:, None] + np.arange(-self.tc, self.tc + 1)[None, :], 0, self._n - 1)
            rows = self._buf[idx - self._buf_start].reshape(t.size, self.out_dim)
        self._next = end
        keep_from = max(0, min(self._next - self.tc, self._n - 1))
        drop = keep_from - self._buf_start
        if drop > 0:
            self._buf = self._buf[drop:]
            self._buf_start = keep_from
        return rows


def stack_context(frames: np.ndarray, *, tc: int = 3) -> np.ndarray:
    """Whole-utterance context stacking: ``(T, d) -> (T, (2 tc + 1) d)`` (edges replicated)."""
    st = ContextStacker(dim=np.asarray(frames).shape[1], tc=tc)
    return np.concatenate([st.push(frames), st.flush()])
