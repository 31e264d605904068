"""The sans-I/O session core: audio bytes in, animation frames out.

Theory of operation
-------------------
A session is one audio stream and does four things: it decodes a binary block (pcm_s16le or f32le,
interleaved channels, mixed down to mono by the channel mean), runs it through the live chain
:class:`realtime_core.pipeline.SpeechToParams` (resampling to the model's rate, front end, streaming
inverter: the same objects as ``speech_to_params``, so a live session's raw mouth parameters equal
``facecast animate`` frame for frame), applies the controls (:mod:`server.controls`) and encodes
frames for viewers. Each push returns the frames now final and the model-rate audio block the chain
heard, both stamped with media time (seconds of session audio at the model rate: frame ``k`` at
``k / fps``; audio by its first sample). Stage timings come from the chain's observer.

Output encodings are computed lazily per frame (:meth:`Frame.payload`) and cached, so a frame with
a thousand parameter viewers is encoded once, and vertex deltas are only computed when somebody
watches them. No sockets, clocks or tasks here except ``perf_counter`` for stage timings.
"""

from __future__ import annotations

import base64
import binascii
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from assets.audio import is_silent
from realtime_core.adaptation import MAX_ENROL_S, MIN_ENROL_S  # one rule with `facecast adapt` and `send --enrol`
from realtime_core.avmodel import AvModel
from realtime_core.blendshapes import blendshape_weights
from realtime_core.errors import ConfigError, NotSpeechError, RealtimeCoreError
from realtime_core.face.keyframes import MorphRig
from realtime_core.face.rig import Rig
from realtime_core.inversion import StreamConfig
from realtime_core.mapping import SpeechModel
from realtime_core.mapping.expression import express
from realtime_core.pipeline import SpeechToParams
from server.controls import ControlState, apply_controls
from server.errors import AudioFormatError, ServerConfigError, reason_value
from server.timing import StageTimes
from wire import protocol as P

F32_PEAK_MAX = 2.0
"""f32le audio is at full scale 1; a block with a sample beyond +-F32_PEAK_MAX (+6 dBFS) closes the ingest
(1007). The headroom is for float audio a client resampled or mixed, whose overshoot past 1 is routine
(the model hears it as it hears a loud recording; the audio relayed to viewers is clipped to int16). What
the check catches is int16 values sent as floats (hundreds to thousands on any block that is not
near-silent). The limit was 64, so 5.0 passed while the reason said [-1, 1]."""
MIN_RATE_HZ = 8000
MAX_RATE_HZ = 192000
MAX_CHANNELS = 8


@dataclass(frozen=True, kw_only=True)
class SessionConfig:
    """sample_rate_hz: input rate (8000..192000 Hz); channels: interleaved input channels (1..8);
    sample_format: "pcm_s16le" or "f32le"; lag: extra fixed-lag smoothing frames of the inverter
    (adds lag / fps seconds of delay); enrol: optional enrolment recording of the talker, base64 of
    audio in the session's own input format (rate, format, channels), 1-120 s: the session animates
    with a copy of the model MAP-adapted to that voice (:mod:`realtime_core.adaptation`); auto_gain: True brings
    the input to the model's training speech level before its features (a causal gain stage,
    :class:`realtime_core.features.gain.InputGainConfig`: a quiet microphone moves the mouth as a loud one), None
    the server's default (:attr:`server.config.ServerConfig.auto_gain`)."""

    sample_rate_hz: int
    channels: int = 1
    sample_format: str = "f32le"
    lag: int = 0
    enrol: str | None = None
    auto_gain: bool | None = None
    # The enrolment decoded once, here: each look at it decoded the base64 again on the event loop (four times, 3-7
    # ms each for 60 s at 16 kHz) while other sessions' frames waited.
    _enrol_raw: bytes = field(default=b"", init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if (
            isinstance(self.sample_rate_hz, bool)
            or not isinstance(self.sample_rate_hz, int)
            or not (MIN_RATE_HZ <= self.sample_rate_hz <= MAX_RATE_HZ)
        ):
            raise ServerConfigError(
                f"sample_rate must be an integer in {MIN_RATE_HZ}..{MAX_RATE_HZ}, "
                f"got {reason_value(self.sample_rate_hz)}"
            )
        if (
            isinstance(self.channels, bool)
            or not isinstance(self.channels, int)
            or not 1 <= self.channels <= MAX_CHANNELS
        ):
            raise ServerConfigError(
                f"channels must be an integer in 1..{MAX_CHANNELS}, got {reason_value(self.channels)}"
            )
        if not isinstance(self.sample_format, str) or self.sample_format not in P.SAMPLE_FORMATS:
            raise ServerConfigError(
                f"format must be one of {sorted(P.SAMPLE_FORMATS)}, got {reason_value(self.sample_format)}"
            )
        if not isinstance(self.lag, int) or not 0 <= self.lag <= 30:
            raise ServerConfigError(f"lag must be an integer in 0..30 frames, got {reason_value(self.lag)}")
        if self.auto_gain is not None and not isinstance(self.auto_gain, bool):
            raise ServerConfigError(f"auto_gain must be true or false, got {reason_value(self.auto_gain)}")
        if self.enrol is not None:
            if not isinstance(self.enrol, str):
                raise ServerConfigError("enrol must be a base64 string of audio in the session's input format")
            try:
                object.__setattr__(self, "_enrol_raw", base64.b64decode(self.enrol, validate=True))
            except (binascii.Error, ValueError):
                raise ServerConfigError("enrol is not valid base64") from None
            frame = P.SAMPLE_FORMATS[self.sample_format].itemsize * self.channels
            if len(self.enrol_bytes()) % frame:
                raise ServerConfigError(
                    f"enrol is not a whole number of {self.channels}-channel {self.sample_format} "
                    f"samples ({frame} bytes each)"
                )
            seconds = self.enrol_seconds()
            if not MIN_ENROL_S <= seconds <= MAX_ENROL_S:
                raise ServerConfigError(
                    f"enrol holds {seconds:.1f} s of audio; {MIN_ENROL_S:g}-{MAX_ENROL_S:g} s accepted "
                    "(30-60 s is the intended amount)"
                )
            raw = np.frombuffer(self.enrol_bytes(), dtype=P.SAMPLE_FORMATS[self.sample_format])
            if is_silent(raw):
                # as `facecast adapt`: the silence's frames would pull a component towards digital silence
                raise ServerConfigError("enrol is silent: it needs a recording of the talker's speech")

    def enrol_seconds(self) -> float:
        """Length of the enrolment recording in seconds (0 without one)."""
        frame = P.SAMPLE_FORMATS[self.sample_format].itemsize * self.channels
        return len(self.enrol_bytes()) / (frame * self.sample_rate_hz)

    def enrol_bytes(self) -> bytes:
        """The enrolment recording's raw bytes (empty without one)."""
        return self._enrol_raw


@dataclass(eq=False)
class Frame:
    """One video frame of a session.

    index: k; media_time: k / fps (s); params: (4,) float64 after controls and expression (IOD);
    raw_params: (4,) float64 as the model produced them; work_s: server compute spent on this
    frame so far (s); ready_perf: ``perf_counter()`` when it became final; expression:
    ``(len(EXPRESSIONS),)`` intensities of this frame and speech_params the parameters before the
    expression (None: no expression, ``params`` are speech only).
    """

    index: int
    media_time: float
    params: np.ndarray
    raw_params: np.ndarray
    work_s: float
    ready_perf: float
    rig: Rig | MorphRig | None = None
    times: StageTimes | None = None
    expression: np.ndarray | None = None
    speech_params: np.ndarray | None = None
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
            if isinstance(self.rig, MorphRig):  # the batch path, so alone or batched the same bytes
                morph_delta_payloads([self], encoding)
                return self._payloads[key]
            values = self.rig.displacements(self.params)  # (n_moving, 3) float32, head units
            stage = "encode_deltas"
        elif kind == P.KIND_ARKIT52:
            # ARKit has the expressions' own shapes: speech weights plus the recipes.
            if self.expression is None:
                values = blendshape_weights(self.params, "arkit52")
            else:
                assert self.speech_params is not None  # set together with expression
                values = blendshape_weights(self.speech_params, "arkit52", expression=self.expression)
            stage = "encode_blendshapes"
        elif kind == P.KIND_MORPH:
            if not isinstance(self.rig, MorphRig):
                raise ServerConfigError("morph weights need a head driven by its own morph targets")
            # (P,) float32, the rig's target order (MorphRig.rest: < 0); the expression drives the head's face shapes
            values = self.rig.weights(self.params, self.expression)
            stage = "encode_morph"
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


def morph_delta_payloads(frames: list[Frame], encoding: int) -> None:
    """The vertex-delta payloads (``KIND_DELTAS`` in ``encoding``) of frames sharing one morph-target rig,
    computed together and cached in each frame (``Frame.payload`` then returns them).

    Why together: a server's loop turn has several sessions' frames to encode (:class:`server.live.TurnDeltas`),
    and frame by frame each re-reads the rig's 632 KB of targets (the built-in head) and runs six numpy
    passes of the int16 encoding; here one compiled pass over the targets serves every frame
    (:meth:`MorphRig.displacements_rows`; with int16, the product and one compiled pass per frame for the
    encoding in one call, :func:`realtime_core.face.compiled.morph_displacements_int16`, the encoding
    byte-equal to ``wire.protocol.encode_payload``).
    Each frame's weights come from its own ``rig.weights`` call and each output row is computed in a
    fixed order, so a frame's bytes do not depend on the batch it was computed in
    (tests/server/test_session.py). Frames whose payload is cached already are skipped; the time is
    shared equally among the frames computed (stage ``encode_deltas``)."""
    key = (P.KIND_DELTAS, encoding)
    todo = [f for f in frames if key not in f._payloads]
    if not todo:
        return
    rig = todo[0].rig
    assert isinstance(rig, MorphRig) and all(f.rig is rig for f in todo)
    t0 = time.perf_counter()
    w = np.empty((len(todo), len(rig.names)), dtype=np.float32)
    for i, f in enumerate(todo):
        w[i] = rig.weights(f.params, f.expression)  # each frame's own call: the same weights alone or batched
    if encoding == P.ENC_INT16:
        from realtime_core.face.compiled import morph_displacements_int16

        values, scales = np.empty((len(todo), 3 * len(rig.moving)), dtype=np.float32), np.empty(len(todo))
        w, rows = rig.active(w)  # the face shapes' rows only when an expression moves them
        q = morph_displacements_int16(
            np.ascontiguousarray(w), rows, values, np.empty(values.shape, dtype="<i2"), scales
        )
        out = [(q[i].tobytes(), values.shape[1], float(scales[i])) for i in range(len(todo))]
    else:
        values = rig.displacements_rows(w)  # (B, n_moving*3) float32
        out = []
        for v in values:
            data, scale = P.encode_payload(v, encoding)
            out.append((data, values.shape[1], scale))
    dt = (time.perf_counter() - t0) / len(todo)
    for f, payload in zip(todo, out):
        f._payloads[key] = payload
        f.work_s += dt
        if f.times is not None:
            f.times.add("encode_deltas", dt)


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

    def __init__(
        self,
        model: SpeechModel,
        *,
        config: SessionConfig,
        rig: Rig | MorphRig | None = None,
        times: StageTimes | None = None,
    ) -> None:
        self.model = model
        self.config = config
        self.rig = rig
        self.times = times if times is not None else StageTimes()
        self.rate_hz = model.sample_rate_hz
        self.fps = int(model.frontend.mfcc.frame_rate_hz)
        self._dtype = P.SAMPLE_FORMATS[config.sample_format]
        self._frame_bytes = self._dtype.itemsize * config.channels
        self.enrolment: dict | None = None
        self.adapted_during: tuple[float, float] | None = None  # perf_counter s at the enrolment's start and end
        if config.auto_gain:
            # Before the enrolment: its recording is heard at the level the live input will be brought to.
            from realtime_core.pipeline import with_auto_gain

            self.model = model = with_auto_gain(model)
        if config.enrol is not None:
            if not isinstance(model, AvModel):
                raise ServerConfigError("enrol adapts the HMM model; it is not available with the MLP mapper")
            self.model = model = self._enrolled(model)
        try:
            self._chain = SpeechToParams(
                model, rate_hz=config.sample_rate_hz, stream=StreamConfig(lag=config.lag), observer=self._observe
            )
        except ConfigError as exc:  # e.g. a lag with the MLP mapper, which has none
            raise ServerConfigError(str(exc)) from None
        self.delay_frames = self._chain.delay_frames
        self.controls = ControlState()
        self.frames_out = 0
        self.samples_in = 0  # input samples (per channel) received
        self.samples_out = 0  # model-rate samples produced
        self._audio_index = 0
        self._mark = 0.0  # perf_counter() at the end of the previous stage
        self.finished = False

    def _enrolled(self, model: AvModel) -> AvModel:
        """This session's copy of ``model`` adapted to the enrolment recording (the shared model is
        untouched). CPU work of about 0.3 s per 10 s of speech: callers on an event loop run the
        constructor in a thread."""
        from realtime_core.adaptation import adapt_av_model
        from realtime_core.features.resample import resample_audio

        began = time.perf_counter()
        x = self.decode(self.config.enrol_bytes())
        x = resample_audio(x, self.config.sample_rate_hz, model.sample_rate_hz)
        try:
            adapted, result = adapt_av_model(model, [x])
        except NotSpeechError as exc:  # a tone or noise: refused as the start's other bad enrolments are
            # Or speech at another rate than the start's: ~50 s of LJ Speech (22050 Hz) sent as 48000 Hz was refused as
            # "a tone, noise or music?" (as 8000 Hz it passes: slowed speech still sounds like speech).
            raise ServerConfigError(f"enrol: {exc} Recorded at {self.config.sample_rate_hz} Hz?") from None
        except RealtimeCoreError as exc:
            raise AudioFormatError(f"the model rejected the enrolment audio: {exc}") from exc
        self.enrolment = dict(adapted.metadata.get("adaptation", {"frames": result.n_frames}))
        self.adapted_during = (began, time.perf_counter())
        return adapted

    def _observe(self, stage: str) -> None:
        now = time.perf_counter()
        self.times.add(stage, now - self._mark)
        self._mark = now

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

    @property
    def algorithmic_delay_s(self) -> float:
        """From a frame's media time to the end of the audio it needs: delay_frames / fps + window
        (the model's formula, :meth:`realtime_core.features.FrontEndConfig.algorithmic_delay_ms`)."""
        return self.model.frontend.algorithmic_delay_ms(self.config.lag) / 1e3

    # -- pushing audio ---------------------------------------------------------------------------

    def decode(self, data: bytes) -> np.ndarray:
        """Binary block -> (n,) float64 mono, full scale 1 (f32le peaks up to F32_PEAK_MAX pass as they are);
        AudioFormatError naming the problem."""
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
            peak = np.abs(x).max(initial=0.0)
            if peak > F32_PEAK_MAX:
                raise AudioFormatError(
                    f"f32le samples must be in [-1, 1] (peaks up to {F32_PEAK_MAX:g} pass), got {reason_value(peak)}"
                )
        if self.config.channels > 1:
            x = x.reshape(-1, self.config.channels).mean(axis=1)
        return x

    def push_bytes(self, data: bytes) -> Output:
        """One binary block (any whole number of sample frames) -> Output."""
        t0 = time.perf_counter()
        cpu0 = time.thread_time()  # CPU time: excludes being descheduled
        x = self.decode(data)
        self._mark = time.perf_counter()
        self.times.add("decode", self._mark - t0)
        return self._run(x, t0, cpu0)

    def push(self, samples: np.ndarray) -> Output:
        """samples: (n,) mono or (n, channels) float in [-1, 1] at the input rate -> Output."""
        t0 = time.perf_counter()
        cpu0 = time.thread_time()
        x = np.asarray(samples, dtype=np.float64)
        if x.ndim == 2:
            if x.shape[1] != self.config.channels:
                raise AudioFormatError(f"block has {x.shape[1]} channels, session has {self.config.channels}")
            x = x.mean(axis=1)
        elif x.ndim != 1:
            raise AudioFormatError(f"samples must be (n,) or (n, channels), got shape {x.shape}")
        if not np.isfinite(x).all():
            raise AudioFormatError("audio block contains NaN or infinite samples")
        self._mark = time.perf_counter()
        return self._run(x, t0, cpu0)

    def flush(self) -> Output:
        """End of the stream: the remaining frames (audio zero-padded, as ``speech_to_params``)."""
        if self.finished:
            return Output([], None)
        t0 = self._mark = time.perf_counter()
        cpu0 = time.thread_time()
        self.finished = True
        try:
            params = self._chain.flush()
        except RealtimeCoreError as exc:
            raise AudioFormatError(f"the model rejected the audio: {exc}") from exc
        return Output(self._frames(params, t0, cpu0), self._audio(self._chain.model_audio))

    def _run(self, x: np.ndarray, t0: float, cpu0: float) -> Output:
        if self.finished:
            raise AudioFormatError("audio after the end of the session")
        self.samples_in += x.size
        try:
            params = self._chain.push(x)
        except RealtimeCoreError as exc:
            raise AudioFormatError(f"the model rejected the audio: {exc}") from exc
        return Output(self._frames(params, t0, cpu0), self._audio(self._chain.model_audio))

    def _audio(self, y: np.ndarray) -> AudioBlock | None:
        if y.size == 0:
            return None
        block = AudioBlock(self._audio_index, self.samples_out, self.samples_out / self.rate_hz, y)
        self._audio_index += 1
        self.samples_out += y.size
        return block

    def _frames(self, params: np.ndarray, t0: float, cpu0: float) -> list[Frame]:
        if len(params) == 0:
            return []
        controlled = [self.controls.apply(row, self.fps) for row in params]
        # The session's expression, eased on the media clock (None: none was ever set).
        alpha, speech = self.controls.expression_at((self.frames_out + np.arange(len(params))) / self.fps), None
        if alpha is not None:
            speech = controlled
            # Paper 002's second-stage MLPs when the mapper emits MUPs (an MLP model with expression
            # stages); otherwise each expression's fixed change of the four parameters.
            controlled = list(
                express(
                    np.array(controlled),
                    alpha,
                    mups=self._chain.last_mups,
                    mapper=getattr(self.model, "expressions", None),
                )
            )
        now = time.perf_counter()
        work = (now - t0) / len(params)
        self.times.add("push_per_frame", work)
        self.times.add("push_per_frame_cpu", (time.thread_time() - cpu0) / len(params))
        frames = []
        for i, (row, p) in enumerate(zip(params, controlled)):
            k = self.frames_out
            frames.append(
                Frame(
                    k,
                    k / self.fps,
                    p,
                    row,
                    work,
                    now,
                    self.rig,
                    self.times,
                    None if alpha is None else alpha[i],
                    None if speech is None else speech[i],
                )
            )
            self.frames_out += 1
        return frames

    # -- controls --------------------------------------------------------------------------------

    def apply_control(self, msg: dict) -> dict:
        """Apply a control message ``{"type": "control", NAME: VALUE, ...}`` (see :mod:`server.controls`:
        gain {parameter: factor in 0..10}, smoothing_ms 0..1000, expression {name, intensity, at},
        expression_ease_s 0..10). Returns the control state; raises ControlError (nothing applied) for
        an unknown control or an invalid value."""
        self.controls = apply_controls(self.controls, msg, now_s=self.frames_out / self.fps)
        return self.control_state()

    def control_state(self) -> dict:
        return self.controls.describe()


def warm_up(model: SpeechModel, rig: Rig | MorphRig | None = None) -> None:
    """Run half a second of noise through a throw-away session (and the rig), so the per-frame
    compiled kernels are loaded (or compiled, on a fresh install) before the first real session
    instead of stalling it: numba compiles on first call."""
    rng = np.random.default_rng(0)
    s = Session(model, config=SessionConfig(sample_rate_hz=model.sample_rate_hz), rig=rig)
    out = s.push(0.1 * rng.standard_normal(model.sample_rate_hz // 2))
    for f in out.frames[:1]:
        if rig is not None:
            f.payload(P.KIND_DELTAS, P.ENC_INT16)
