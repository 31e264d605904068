"""Streaming polyphase resampling whose output equals ``scipy.signal.resample_poly`` on the whole signal.

Theory of operation
-------------------
``resample_poly(x, up, down)`` (default Kaiser window, beta 5) upsamples by ``up`` (zero
insertion), filters with a linear-phase low-pass ``h`` of ``2 L + 1`` taps (``L = 10 max(up, down)``,
cutoff ``1 / max(up, down)`` of Nyquist, gain ``up``) and keeps every ``down``-th sample, shifted
so the output is aligned with the input (zero phase). Written out, output sample ``m`` is

    y[m] = sum_n x[n] h[m down + L - n up],      0 <= m down + L - n up <= 2 L,

so ``y[m]`` needs the input up to ``n_hi(m) = floor((m down + L) / up)``: a lookahead of about
``L / up`` input samples (10 samples at 48 -> 16 kHz, under 1 ms). :class:`StreamingResampler`
emits ``y[m]`` as soon as ``x[n_hi(m)]`` has arrived, and :meth:`flush` zero-pads the end exactly as
``resample_poly`` does, giving ``ceil(n up / down)`` samples in all. Each ``y[m]`` is computed from
the same samples with the same operations whatever the chunking, so any split of the input gives
bit-identical output.

Polyphase form: with ``p = m down + L``, ``r = p mod up`` and ``n = n_hi - k``, the tap is
``h[r + k up]``; the filter is stored as ``(up, K)`` phases, ``K = ceil((2 L + 1) / up)``.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from realtime_core.errors import ConfigError


def resample_audio(samples: np.ndarray, rate_from_hz: int, rate_to_hz: int) -> np.ndarray:
    """Whole-signal polyphase resampling: ``(n,)`` -> ``(ceil(n up / down),)`` float64.

    Exactly ``scipy.signal.resample_poly`` with the rates reduced by their gcd, which is also what
    :class:`StreamingResampler` emits for the same signal in any chunking.
    """
    x = np.asarray(samples, dtype=np.float64)
    if int(rate_from_hz) <= 0 or int(rate_to_hz) <= 0:
        raise ConfigError(f"resampling rates must be positive, got {rate_from_hz} -> {rate_to_hz}")
    if int(rate_from_hz) == int(rate_to_hz):
        return x
    g = math.gcd(int(rate_from_hz), int(rate_to_hz))
    return scipy.signal.resample_poly(x, int(rate_to_hz) // g, int(rate_from_hz) // g)


class StreamingResampler:
    """``push(x (n,) float) -> (j,) float64`` at ``rate_to_hz``; ``flush()`` ends the stream.

    rate_from_hz, rate_to_hz: positive integers (Hz). Equal rates pass samples through unchanged.
    """

    def __init__(self, rate_from_hz: int, rate_to_hz: int) -> None:
        if int(rate_from_hz) <= 0 or int(rate_to_hz) <= 0:
            raise ConfigError(f"resampling rates must be positive, got {rate_from_hz} -> {rate_to_hz}")
        g = math.gcd(int(rate_from_hz), int(rate_to_hz))
        self.up = int(rate_to_hz) // g
        self.down = int(rate_from_hz) // g
        self.passthrough = self.up == self.down == 1
        max_rate = max(self.up, self.down)
        self.half_len = 0 if self.passthrough else 10 * max_rate
        h = np.ones(1)
        if not self.passthrough:
            h = scipy.signal.firwin(2 * self.half_len + 1, 1.0 / max_rate, window=("kaiser", 5.0)) * self.up
        self.n_taps = -(-(2 * self.half_len + 1) // self.up)
        padded = np.zeros(self.n_taps * self.up)
        padded[: h.size] = h
        # phases[r, k] = h[r + k up]
        self._phases = np.ascontiguousarray(padded.reshape(self.n_taps, self.up).T)
        self.reset()

    def reset(self) -> None:
        self._buf = np.zeros(0)  # input samples from absolute index self._buf_start
        self._buf_start = 0
        self._n_in = 0
        self._next_out = 0

    @property
    def delay_samples_in(self) -> int:
        """Input samples of lookahead needed beyond an output sample's own time (``ceil(L / up)``)."""
        return -(-self.half_len // self.up)

    def n_hi(self, m: int) -> int:
        """Last input index that output ``m`` depends on."""
        return (m * self.down + self.half_len) // self.up

    def push(self, x: np.ndarray) -> np.ndarray:
        """x: (n,) float samples at rate_from_hz -> the output samples now final, (j,) float64."""
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        if self.passthrough:
            self._n_in += x.size
            return x.copy()
        self._buf = np.concatenate([self._buf, x])
        self._n_in += x.size
        # Outputs with n_hi(m) <= n_in - 1.
        m_end = ((self._n_in - 1) * self.up - self.half_len) // self.down + 1 if self._n_in else 0
        return self._emit(max(m_end, self._next_out))

    def flush(self) -> np.ndarray:
        """End of stream: the remaining outputs (input zero-padded), ``ceil(n_in up / down)`` in all."""
        if self.passthrough:
            return np.zeros(0)
        total = -(-self._n_in * self.up // self.down)
        out = self._emit(max(total, self._next_out), final=True)
        return out

    def _emit(self, m_end: int, *, final: bool = False) -> np.ndarray:
        m0 = self._next_out
        if m_end <= m0:
            return np.zeros(0)
        m = np.arange(m0, m_end, dtype=np.int64)
        p = m * self.down + self.half_len
        n_hi = p // self.up
        r = p - n_hi * self.up
        # Gather x[n_hi - k] for k = 0..K-1 (zero outside [0, n_in)).
        idx = n_hi[:, None] - np.arange(self.n_taps)[None, :] - self._buf_start
        lo_needed = int(idx.min())
        hi_needed = int(idx.max())
        pad_front = max(0, -lo_needed)
        pad_back = max(0, hi_needed + 1 - self._buf.size)
        buf = self._buf
        if pad_front or pad_back:
            buf = np.concatenate([np.zeros(pad_front), buf, np.zeros(pad_back)])
        X = buf[idx + pad_front]
        y = (X * self._phases[r]).sum(axis=1)
        self._next_out = m_end
        # Keep only the input the next output can still need: from n_lo of output m_end.
        keep_from = (m_end * self.down + self.half_len) // self.up - self.n_taps + 1
        drop = min(max(0, keep_from - self._buf_start), self._buf.size)
        if drop:
            self._buf = self._buf[drop:]
            self._buf_start += drop
        return y
