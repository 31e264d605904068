"""Optional compute workers: run sessions' per-frame work in other processes (``ServerConfig.workers``).

Theory of operation
-------------------
One event loop handles every socket, but one process uses at most one core, and on the paper-size
model the per-frame work (MFCC, inversion) is most of a session's CPU. With ``workers = N > 0``
the server starts N processes, each holding the model, and places every new session on the least
loaded one. The sans-I/O :class:`server.session.Session` runs there unchanged; the loop sends it
each audio block over a pipe and gets back the frames' parameters, the resampled audio and the
stage timings, then encodes and fans out as for a local session. A session lives on one worker
and the pipe is FIFO, so its frames stay in order; a reply is matched to the oldest pending request
of that worker.

Vertex deltas are encoded there too: the loop names, with each push, the (kind, encoding) pairs
of vertex-delta viewers the session has (its ``precompute``), the worker encodes those payloads with
its copy of the head rig and sends them back with the frames, so the loop's fan-out finds them ready
(a head's morph-target solve and GEMV cost ~0.15-0.4 ms per frame, the largest per-frame cost a
viewer adds on the loop).

Cost: two pipe messages per audio block (tens of microseconds) against the ~0.3-0.5 ms of work
per frame they move off the loop. Sending blocks the loop only if a worker's pipe (64 KiB) is
full, i.e. if that worker is far behind real time.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import multiprocessing as mp
import os
import pickle
import time
from dataclasses import fields, replace

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from realtime_core.face.keyframes import MorphRig
from realtime_core.face.rig import Rig
from realtime_core.mapping import SpeechModel
from server.errors import AudioFormatError, ControlError, ServerConfigError, ServerError
from server.session import AudioBlock, Frame, Output, SessionConfig
from server.timing import StageTimes, freeze_heap

log = logging.getLogger("facecast.workers")

_ERRORS = {"AudioFormatError": AudioFormatError, "ControlError": ControlError, "ServerConfigError": ServerConfigError}


class _Recorder(StageTimes):
    """StageTimes that also keeps this push's (stage, seconds) pairs for the reply."""

    def __init__(self) -> None:
        super().__init__(capacity=16)
        self.log: list[tuple[str, float]] = []

    def add(self, name: str, seconds: float) -> None:
        self.log.append((name, seconds))


def _pack(out: Output, rec: _Recorder, precompute: tuple = ()) -> tuple:
    frames = out.frames
    # Payloads the loop asked for (vertex deltas), per frame: {(kind, encoding): (bytes, count, scale)}.
    pre = [{key: f.payload(*key) for key in precompute} for f in frames] if precompute and frames else None
    raw = np.array([f.raw_params for f in frames]).reshape(len(frames), len(VISUAL_PARAMS))
    params = np.array([f.params for f in frames]).reshape(len(frames), len(VISUAL_PARAMS))
    work = frames[0].work_s if frames else 0.0
    audio = None if out.audio is None else (out.audio.index, out.audio.start, out.audio.samples)
    log, rec.log = rec.log, []
    expr = [(f.expression, f.speech_params) for f in frames]  # (None, None) without an expression
    return raw, params, work, audio, log, expr, pre


def _worker_main(conn, model_bytes: bytes, rig_bytes: bytes | None = None) -> None:
    """Worker process: decode the model (and unpickle the head rig) once, then serve session
    requests until "stop"."""
    from threadpoolctl import threadpool_limits

    from realtime_core.mapping import decode_speech_model
    from server.session import Session, warm_up

    with threadpool_limits(1):
        model = decode_speech_model(model_bytes)
        rig: Rig | MorphRig | None = None if rig_bytes is None else pickle.loads(rig_bytes)
        warm_up(model, rig)  # the compiled kernels loaded before the first session
        freeze_heap()  # no full collection rescans the model and the modules between frames
        conn.send(("ok", None))  # ready
        sessions: dict[int, tuple[Session, _Recorder]] = {}
        while True:
            try:
                msg = conn.recv()
            except EOFError:
                return
            op = msg[0]
            if op == "stop":
                return
            sid = msg[1]
            try:
                if op == "open":
                    rec = _Recorder()
                    m = model
                    if len(msg) > 3:  # enrolled by the server: its adapted audio means and mixture weights
                        assert isinstance(model, AvModel)
                        m = model.with_hmm(replace(model.hmm, means=msg[3][0], weights=msg[3][1]))
                    sessions[sid] = (Session(m, config=SessionConfig(**msg[2]), rig=rig, times=rec), rec)
                    conn.send(("ok", None))
                elif op == "push":
                    s, rec = sessions[sid]
                    out = s.push_bytes(msg[2]) if isinstance(msg[2], bytes) else s.push(msg[2])
                    conn.send(("ok", _pack(out, rec, msg[3] if len(msg) > 3 else ())))
                elif op == "flush":
                    s, rec = sessions[sid]
                    conn.send(("ok", _pack(s.flush(), rec)))
                elif op == "control":
                    conn.send(("ok", sessions[sid][0].apply_control(msg[2])))
                elif op == "close":
                    sessions.pop(sid, None)
                    conn.send(("ok", None))
                else:
                    conn.send(("err", "ServerError", f"unknown worker request {op!r}"))
            except ServerError as exc:
                conn.send(("err", type(exc).__name__, str(exc)))


def model_file_bytes(model: SpeechModel) -> bytes:
    """The model as its file bytes, the form worker processes receive it in (ServerConfigError for a
    model kind without a file format: only HMM and MLP models go)."""
    from realtime_core.avmodel import AvModel
    from realtime_core.mapping import MlpSpeechModel, encode_speech_model

    if not isinstance(model, AvModel | MlpSpeechModel):
        raise ServerConfigError(f"worker processes need an HMM or MLP model file, got {type(model).__name__}")
    return encode_speech_model(model)


class _Worker:
    def __init__(self, ctx, model_bytes: bytes, rig_bytes: bytes | None) -> None:
        self.conn, child = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_worker_main, args=(child, model_bytes, rig_bytes), daemon=True)
        self.proc.start()
        child.close()
        self.pending: collections.deque[asyncio.Future] = collections.deque()
        self.sessions = 0

    def request(self, msg: tuple) -> asyncio.Future:
        fut = asyncio.get_running_loop().create_future()
        self.pending.append(fut)
        self.conn.send(msg)
        return fut

    def on_readable(self) -> None:
        while self.conn.poll():
            try:
                reply = self.conn.recv()
            except EOFError:
                self._fail(ServerError("compute worker died"))
                return
            fut = self.pending.popleft()
            if fut.done():
                continue
            if reply[0] == "ok":
                fut.set_result(reply[1])
            else:
                fut.set_exception(_ERRORS.get(reply[1], ServerError)(reply[2]))

    def _fail(self, exc: Exception) -> None:
        asyncio.get_running_loop().remove_reader(self.conn.fileno())
        while self.pending:
            fut = self.pending.popleft()
            if not fut.done():
                fut.set_exception(exc)


class WorkerPool:
    """N compute processes holding the model (and the head rig, for vertex deltas); ``await start()``,
    ``open()`` sessions, ``await stop()``."""

    def __init__(self, model: SpeechModel, n: int, *, rig: Rig | MorphRig | None = None) -> None:
        if not 1 <= n <= 64:
            raise ServerConfigError(f"workers must be in 1..64, got {n}")
        self.model = model
        self.n = n
        self.rig = rig
        self.workers: list[_Worker] = []
        self._next_id = 0

    async def start(self) -> None:
        ctx = mp.get_context("spawn")  # no fork of a process with a running loop and threads
        data = model_file_bytes(self.model)
        rig_bytes = None
        if self.rig is not None:
            # Pickled once here, the same bytes to every worker (each Process would pickle the rig
            # again: 1.5 MB for the built-in head); a rig that cannot go keeps its deltas on the loop.
            try:
                rig_bytes = pickle.dumps(self.rig, protocol=pickle.HIGHEST_PROTOCOL)
            except (TypeError, AttributeError, pickle.PicklingError) as exc:
                log.info("vertex deltas stay on the event loop: the head rig cannot go to workers (%s)", exc)
                self.rig = None
        loop = asyncio.get_running_loop()
        self.workers = [_Worker(ctx, data, rig_bytes) for _ in range(self.n)]
        for w in self.workers:
            fut = loop.create_future()
            w.pending.append(fut)
            loop.add_reader(w.conn.fileno(), w.on_readable)
            # uvloop's add_reader makes the descriptor non-blocking (libuv polls it so); multiprocessing's
            # Connection reads and writes whole messages and needs it blocking, as asyncio's loop leaves it
            # (else a message half arrived raises BlockingIOError mid-read and the stream is lost).
            os.set_blocking(w.conn.fileno(), True)
        await asyncio.gather(*(w.pending[0] for w in self.workers))

    async def stop(self) -> None:
        loop = asyncio.get_running_loop()
        for w in self.workers:
            loop.remove_reader(w.conn.fileno())
            with contextlib.suppress(BrokenPipeError, OSError):
                w.conn.send(("stop",))
        for w in self.workers:
            await loop.run_in_executor(None, w.proc.join, 5)
            if w.proc.is_alive():
                w.proc.kill()
        self.workers = []

    async def open(
        self,
        config: SessionConfig,
        *,
        rig: Rig | MorphRig | None,
        times: StageTimes,
        enrolled: SpeechModel | None = None,
    ) -> RemoteSession:
        """A session in the least busy worker. enrolled: the session's model already adapted to ``config.enrol`` by
        the caller (the worker gets its audio means and mixture weights, the rest of the model it holds)."""
        w = min(self.workers, key=lambda x: x.sessions)
        self._next_id += 1
        sid = self._next_id
        options = {f.name: getattr(config, f.name) for f in fields(config) if f.init}  # not its decoded enrol
        if enrolled is None:
            await w.request(("open", sid, options))
        else:
            assert isinstance(enrolled, AvModel)  # a Session adapts only an HMM model
            options["enrol"] = None
            await w.request(("open", sid, options, (enrolled.hmm.means, enrolled.hmm.weights)))
        w.sessions += 1
        return RemoteSession(self.model, config, w, sid, rig=rig, times=times, worker_rig=self.rig is not None)


class RemoteSession:
    """A :class:`server.session.Session` running in a worker: the same facts, async methods."""

    def __init__(
        self,
        model: SpeechModel,
        config: SessionConfig,
        worker: _Worker,
        sid: int,
        *,
        rig: Rig | MorphRig | None,
        times: StageTimes,
        worker_rig: bool = False,
    ) -> None:
        self.model = model
        self._worker_rig = worker_rig and rig is not None
        self.config = config
        self.rig = rig
        self.times = times
        self._w = worker
        self._sid = sid
        self.rate_hz = model.sample_rate_hz
        self.fps = int(model.frontend.mfcc.frame_rate_hz)
        self.delay_frames = model.frontend.tc + config.lag
        self.window_len = int(model.frontend.mfcc.window_len)
        self.frame_bytes = _sample_bytes(config) * config.channels
        self.frames_out = 0
        self.samples_out = 0
        self.finished = False
        self.precompute: tuple[tuple[int, int], ...] = ()
        """(kind, encoding) payloads the worker encodes with each push (set by the live session:
        the vertex-delta kinds its viewers watch)."""
        self._state = {"gain": {n: 1.0 for n in VISUAL_PARAMS}, "smoothing_ms": 0.0, "expression": []}

    @property
    def algorithmic_delay_s(self) -> float:
        return self.model.frontend.algorithmic_delay_ms(self.config.lag) / 1e3

    def control_state(self) -> dict:
        return self._state

    async def push_bytes(self, data: bytes) -> Output:
        return self._unpack(await self._w.request(("push", self._sid, bytes(data), self._precompute())))

    async def push(self, samples: np.ndarray) -> Output:
        samples = np.asarray(samples, dtype=np.float64)
        return self._unpack(await self._w.request(("push", self._sid, samples, self._precompute())))

    def _precompute(self) -> tuple[tuple[int, int], ...]:
        # Only when the worker holds the same rig (WorkerPool(rig=...)); else the loop encodes.
        return self.precompute if self._worker_rig else ()

    async def flush(self) -> Output:
        if self.finished:
            return Output([], None)
        self.finished = True
        out = self._unpack(await self._w.request(("flush", self._sid)))
        await self.close()
        return out

    async def apply_control(self, msg: dict) -> dict:
        self._state = await self._w.request(("control", self._sid, msg))
        return self._state

    async def close(self) -> None:
        if self._sid:
            sid, self._sid = self._sid, 0
            self._w.sessions -= 1
            await self._w.request(("close", sid))

    def _unpack(self, packed: tuple) -> Output:
        raw, params, work, audio, log, expr, pre = packed
        for name, seconds in log:
            self.times.add(name, seconds)
        now = time.perf_counter()
        frames = []
        for i, (r, p, (alpha, speech)) in enumerate(zip(raw, params, expr)):
            k = self.frames_out
            frame = Frame(k, k / self.fps, p, r, work, now, self.rig, self.times, alpha, speech)
            if pre is not None:
                frame._payloads.update(pre[i])
            frames.append(frame)
            self.frames_out += 1
        block = None
        if audio is not None:
            index, start, samples = audio
            block = AudioBlock(index, start, start / self.rate_hz, samples)
            self.samples_out = start + samples.size
        return Output(frames, block)


def _sample_bytes(config: SessionConfig) -> int:
    from wire.protocol import SAMPLE_FORMATS

    return SAMPLE_FORMATS[config.sample_format].itemsize
