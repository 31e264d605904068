"""The sans-I/O session core: audio bytes in, animation frames out.

Theory of operation
-------------------
A session is one audio stream. :meth:`Session.push_bytes` (or :meth:`Session.push` for arrays)
decodes a block (pcm_s16le or f32le, interleaved channels), mixes it down to mono (channel mean),
resamples it to the model's rate with :class:`realtime_core.features.resample.StreamingResampler` (equal to
``scipy.signal.resample_poly`` on the whole stream, whatever the chunking), and runs the same
streaming objects as :func:`realtime_core.pipeline.speech_to_params` (front end, then the streaming
inverter), so a live session's raw mouth parameters equal ``facecast animate`` frame for frame.
Controls (per-parameter gain, then one-pole smoothing) apply after the model. Each push returns the
frames now final and the resampled audio block, both stamped with media time (seconds of session
audio at the model rate: frame ``k`` at ``k / fps``; audio by its first sample).

Output encodings are computed lazily per frame (:meth:`Frame.payload`) and cached, so a frame with
a thousand parameter viewers is encoded once, and vertex deltas are only computed when somebody
watches them. No sockets, clocks or tasks here except ``perf_counter`` for stage timings.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from realtime_core.blendshapes import blendshape_weights
from realtime_core.errors import RealtimeCoreError
from realtime_core.face.rig import Rig
from realtime_core.features.resample import StreamingResampler
from realtime_core.inversion import StreamConfig
from server.errors import AudioFormatError, ControlError, ServerConfigError
from server.timing import StageTimes
from wire import protocol as P

MIN_RATE_HZ = 8000
MAX_RATE_HZ = 192000
MAX_CHANNELS = 8


@dataclass(frozen=True, kw_only=True)
class SessionConfig:
    """sample_rate_hz: input rate (8000..192000 Hz); channels: interleaved input channels (1..8);
    sample_format: "pcm_s16le" or "f32le"; lag: extra fixed-lag smoothing frames of the inverter
    (adds lag / fps seconds of delay)."""

    sample_rate_hz: int
    channels: int = 1
    sample_format: str = "f32le"
    lag: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.sample_rate_hz, bool) or not isinstance(self.sample_rate_hz, int) or not (
            MIN_RATE_HZ <= self.sample_rate_hz <= MAX_RATE_HZ
        ):
            raise ServerConfigError(f"sample_rate must be an integer in {MIN_RATE_HZ}..{MAX_RATE_HZ}, got {self.sample_rate_hz!r}")
        if isinstance(self.channels, bool) or not isinstance(self.channels, int) or not 1 <= self.channels <= MAX_CHANNELS:
            raise ServerConfigError(f"channels must be an integer in 1..{MAX_CHANNELS}, got {self.channels!r}")
        if self.sample_format not in P.SAMPLE_FORMATS:
            raise ServerConfigError(f"format must be one of {sorted(P.SAMPLE_FORMATS)}, got {self.sample_format!r}")
        if not isinstance(self.lag, int) or not 0 <= self.lag <= 30:
            raise ServerConfigError(f"lag must be an integer in 0..30 frames, got {self.lag!r}")


@dataclass(eq=False)
class Frame:
    """One video frame of a session.

    index: k; media_time: k / fps (s); params: (4,) float64 after controls (IOD);
    raw_params: (4,) float64 as the model produced them; work_s: server compute spent on this
    frame so far (s); ready_perf: ``perf_counter()`` when it became final.
    """

    index: int
    media_time: float
    params: np.ndarray
    raw_params: np.ndarray
    work_s: float
    ready_perf: float
    rig: Rig | None = None
    times: StageTimes | None = None
    _payloads: dict = field(default_factory=dict)

    def payload(self, kind: int, encoding: int) -> tuple[bytes, int, float]:
        """(payload bytes, value count, scale) for a header kind/encoding; computed once per frame."""
        key = (kind, encoding)
        hit = self._payloads.get(key)
        if hit is not None:
            return hit
        t0 = time.perf_counter()
        if kind == P.KIND_PARAMS:
            values = self.params
            stage = "encode_params"
        elif kind == P.KIND_DELTAS:
            if self.rig is None:
                raise ServerConfigError("vertex deltas need a head rig")
            values = self.rig.displacements(self.params)  # (n_moving, 3) float32, head units
            stage = "encode_deltas"
        elif kind == P.KIND_ARKIT52:
            values = blendshape_weights(self.params, "arkit52")
            stage = "encode_blendshapes"
        elif kind == P.KIND_OVR15:
            values = blendshape_weights(self.params, "ovr15")
            stage = "encode_blendshapes"
        else:
            raise ValueError(f"frames have no payload of kind {kind}")
        data, scale = P.encode_payload(values, encoding)
        out = (data, int(np.size(values)), scale)
        self._payloads[key] = out
        dt = time.perf_counter() - t0
        self.work_s += dt
        if self.times is not None:
            self.times.add(stage, dt)
        return out


@dataclass(eq=False)
class AudioBlock:
    """Resampled mono session audio: samples (n,) float64 in [-1, 1] at the model rate, first sample
    index ``start`` (media time ``start / rate``), sequence number ``index``."""

    index: int
    start: int
    media_time: float
    samples: np.ndarray
    _payload: bytes | None = None

    def payload(self) -> bytes:
        if self._payload is None:
            self._payload = P.encode_audio_payload(self.samples)
        return self._payload


class Output(NamedTuple):
    """What one push returns: frames now final (in order) and the audio block (None if empty)."""

    frames: list[Frame]
    audio: AudioBlock | None


class Session:
    """One live audio stream through the model. Not thread-safe: one owner calls push/flush/control.

    model: the audio-visual model; config: the input's format; rig: the head rig for vertex deltas
    (None: deltas unavailable); times: where stage durations go (a fresh StageTimes by default).
    """

    def __init__(self, model: AvModel, *, config: SessionConfig, rig: Rig | None = None,
                 times: StageTimes | None = None) -> None:
        self.model = model
        self.config = config
        self.rig = rig
        self.times = times if times is not None else StageTimes()
        self.rate_hz = model.sample_rate_hz
        self.fps = int(model.frontend.mfcc.frame_rate_hz)
        self._dtype = P.SAMPLE_FORMATS[config.sample_format]
        self._frame_bytes = self._dtype.itemsize * config.channels
        self._resampler = StreamingResampler(config.sample_rate_hz, self.rate_hz)
        self._fe = model.front_end()
        self._inv = model.inverter(StreamConfig(lag=config.lag))
        self.delay_frames = model.frontend.tc + config.lag
        self.gains = np.ones(len(VISUAL_PARAMS))
        self.smoothing_ms = 0.0
        self._smoothed: np.ndarray | None = None
        self.frames_out = 0
        self.samples_in = 0  # input samples (per channel) received
        self.samples_out = 0  # model-rate samples produced
        self._audio_index = 0
        self._cpu0 = 0.0
        self.finished = False

    @property
    def frame_bytes(self) -> int:
        """Bytes of one sample frame (all channels) in the input format."""
        return self._frame_bytes

    # -- timing facts ----------------------------------------------------------------------------

    @property
    def window_len(self) -> int:
        return int(self.model.frontend.mfcc.window_len)

    def model_samples_needed(self, k: int) -> int:
        """Model-rate samples that must have arrived for frame ``k`` to be final (streaming, not flush)."""
        return self.model.frontend.mfcc.frame_start(k + self.delay_frames) + self.window_len

    def input_samples_needed(self, k: int) -> int:
        """Input-rate samples (per channel) that must have arrived for frame ``k`` to be final."""
        m = self.model_samples_needed(k) - 1
        return self._resampler.n_hi(m) + 1 if not self._resampler.passthrough else m + 1

    @property
    def algorithmic_delay_s(self) -> float:
        """From a frame's media time to the end of the audio it needs: delay_frames / fps + window."""
        return self.delay_frames / self.fps + self.window_len / self.rate_hz

    # -- pushing audio ---------------------------------------------------------------------------

    def decode(self, data: bytes) -> np.ndarray:
        """Binary block -> (n,) float64 mono in [-1, 1]; AudioFormatError naming the problem."""
        if len(data) % self._frame_bytes:
            raise AudioFormatError(
                f"audio block of {len(data)} bytes is not a whole number of {self.config.channels}-channel "
                f"{self.config.sample_format} samples ({self._frame_bytes} bytes each)"
            )
        raw = np.frombuffer(data, dtype=self._dtype)
        if self._dtype.kind == "i":
            x = raw.astype(np.float64) / 32768.0
        else:
            x = raw.astype(np.float64)
            if not np.isfinite(x).all():
                raise AudioFormatError("f32le audio block contains NaN or infinite samples")
            if np.abs(x).max(initial=0.0) > 64.0:
                raise AudioFormatError("f32le samples must be in [-1, 1] (found values beyond 64: not float audio)")
        if self.config.channels > 1:
            x = x.reshape(-1, self.config.channels).mean(axis=1)
        return x

    def push_bytes(self, data: bytes) -> Output:
        """One binary block (any whole number of sample frames) -> Output."""
        t0 = time.perf_counter()
        self._cpu0 = time.thread_time()  # CPU time: excludes being descheduled
        x = self.decode(data)
        self.times.add("decode", time.perf_counter() - t0)
        return self._run(x, t0)

    def push(self, samples: np.ndarray) -> Output:
        """samples: (n,) mono or (n, channels) float in [-1, 1] at the input rate -> Output."""
        t0 = time.perf_counter()
        self._cpu0 = time.thread_time()  # CPU time: excludes being descheduled
        x = np.asarray(samples, dtype=np.float64)
        if x.ndim == 2:
            if x.shape[1] != self.config.channels:
                raise AudioFormatError(f"block has {x.shape[1]} channels, session has {self.config.channels}")
            x = x.mean(axis=1)
        elif x.ndim != 1:
            raise AudioFormatError(f"samples must be (n,) or (n, channels), got shape {x.shape}")
        if not np.isfinite(x).all():
            raise AudioFormatError("audio block contains NaN or infinite samples")
        return self._run(x, t0)

    def flush(self) -> Output:
        """End of the stream: the remaining frames (audio zero-padded, as ``speech_to_params``)."""
        if self.finished:
            return Output([], None)
        t0 = time.perf_counter()
        self._cpu0 = time.thread_time()  # CPU time: excludes being descheduled
        self.finished = True
        y = self._resampler.flush()
        audio = self._audio(y)
        t1 = time.perf_counter()
        try:
            oa = np.concatenate([self._fe.push(y), self._fe.flush()])
            t2 = time.perf_counter()
            params = np.concatenate([self._inv.push(oa), self._inv.flush()])
        except RealtimeCoreError as exc:
            raise AudioFormatError(f"the model rejected the audio: {exc}") from exc
        t3 = time.perf_counter()
        return Output(self._frames(params, t0, (t1, t2, t3)), audio)

    def _run(self, x: np.ndarray, t0: float) -> Output:
        if self.finished:
            raise AudioFormatError("audio after the end of the session")
        self.samples_in += x.size
        t1 = time.perf_counter()
        y = self._resampler.push(x)
        audio = self._audio(y)
        t2 = time.perf_counter()
        try:
            oa = self._fe.push(y)
            t3 = time.perf_counter()
            params = self._inv.push(oa)
        except RealtimeCoreError as exc:
            raise AudioFormatError(f"the model rejected the audio: {exc}") from exc
        t4 = time.perf_counter()
        self.times.add("resample", t2 - t1)
        return Output(self._frames(params, t0, (t2, t3, t4)), audio)

    def _audio(self, y: np.ndarray) -> AudioBlock | None:
        if y.size == 0:
            return None
        block = AudioBlock(self._audio_index, self.samples_out, self.samples_out / self.rate_hz, y)
        self._audio_index += 1
        self.samples_out += y.size
        return block

    def _frames(self, params: np.ndarray, t0: float, marks: tuple[float, float, float]) -> list[Frame]:
        t_res, t_fe, t_inv = marks
        self.times.add("features", t_fe - t_res)
        self.times.add("inversion", t_inv - t_fe)
        if len(params) == 0:
            return []
        out = []
        for row in params:
            out.append(self._controlled(row))
        now = time.perf_counter()
        work = (now - t0) / len(params)
        self.times.add("push_per_frame", work)
        self.times.add("push_per_frame_cpu", (time.thread_time() - self._cpu0) / len(params))
        frames = []
        for row, p in zip(params, out):
            k = self.frames_out
            frames.append(Frame(k, k / self.fps, p, row, work, now, self.rig, self.times))
            self.frames_out += 1
        return frames

    def _controlled(self, row: np.ndarray) -> np.ndarray:
        p = row * self.gains
        if self.smoothing_ms > 0:
            if self._smoothed is not None:
                a = math.exp(-1000.0 / (self.fps * self.smoothing_ms))
                p = a * self._smoothed + (1.0 - a) * p
            self._smoothed = p
        else:
            self._smoothed = p
        return p

    # -- controls --------------------------------------------------------------------------------

    CONTROLS = ("gain", "smoothing_ms")

    def apply_control(self, msg: dict) -> dict:
        """Apply a control message ``{"type": "control", "gain": {...}, "smoothing_ms": x}``.

        gain: {parameter name: factor in [0, 10]} (others unchanged); smoothing_ms: time constant of
        a one-pole low-pass on the parameters, 0..1000 ms (0 = off). Returns the control state.
        Raises ControlError (nothing applied) for an unknown control or an invalid value.
        """
        gains = self.gains.copy()
        smoothing = self.smoothing_ms
        for key, value in msg.items():
            if key == "type":
                continue
            if key == "gain":
                if not isinstance(value, dict) or not value:
                    raise ControlError("gain must be an object {parameter: factor}")
                for name, g in value.items():
                    if name not in VISUAL_PARAMS:
                        raise ControlError(f"gain: unknown parameter {name!r} (known: {', '.join(VISUAL_PARAMS)})")
                    if isinstance(g, bool) or not isinstance(g, (int, float)) or not 0 <= g <= 10:
                        raise ControlError(f"gain for {name} must be a number in 0..10, got {g!r}")
                    gains[VISUAL_PARAMS.index(name)] = float(g)
            elif key == "smoothing_ms":
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1000:
                    raise ControlError(f"smoothing_ms must be a number in 0..1000, got {value!r}")
                smoothing = float(value)
            else:
                raise ControlError(f"unknown control {key!r} (known: {', '.join(self.CONTROLS)})")
        self.gains, self.smoothing_ms = gains, smoothing
        return self.control_state()

    def control_state(self) -> dict:
        return {"gain": dict(zip(VISUAL_PARAMS, map(float, self.gains))), "smoothing_ms": self.smoothing_ms}
