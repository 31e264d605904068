"""The asyncio streaming server: ingest and viewer WebSockets plus plain HTTP on one port.

Theory of operation
-------------------
One process, one event loop. A *live session* couples one audio source (a WebSocket ingest
connection, the microphone or a file) with a sans-I/O :class:`server.session.Session` and any number
of viewers. When a block of audio arrives the session computes the frames now final inline on the
loop (a few hundred microseconds per frame with the paper's model; measured by
``benchmarks/server_latency.py``: handing such short work to a thread pool costs more than it
saves and the GIL serialises it anyway; with ``ServerConfig.workers`` it runs in compute processes
instead, see :mod:`server.workers`), then *fans out*: each frame is encoded once per
(kind, encoding) that somebody watches, given one header with the send time, and offered to every
viewer of that kind.

Viewers never slow the session or each other. A viewer that keeps up (nothing queued, socket
buffer under 64 KiB) gets each message written synchronously, as python-websockets' ``broadcast``
does, without a task switch per message. Otherwise the message goes to the viewer's bounded queue,
drained by its own sender task with backpressure; offering a message never waits. When a queue is
full the oldest message is dropped and counted (the freshest frame matters most for live
animation); a viewer that keeps dropping for ``viewer_max_behind_s`` is closed with 4000. This is the per-client queue design of
python-websockets' broadcast guide, with drop-oldest instead of unbounded buffering.

Every protocol breach raises :class:`server.errors.ProtocolViolation` inside that connection's
handler, which closes that connection with the violation's code and reason; the server and the other
sessions go on. Plain HTTP (``/health``, ``/metrics``, ``/head/...``, ``/``) is answered from the
websockets ``process_request`` hook before any WebSocket handshake.
"""

from __future__ import annotations

import asyncio
import collections
import hmac
import json
import logging
import signal
import socket
import time
import urllib.parse
from collections.abc import AsyncIterator
from dataclasses import dataclass
from http import HTTPStatus
from pathlib import Path

import numpy as np
from websockets.asyncio.server import Server, ServerConnection, broadcast, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from assets.heads.mesh import HeadMesh
from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from realtime_core.blendshapes import blendshape_names
from realtime_core.face.rig import Rig
from server.config import ServerConfig
from server.errors import AudioFormatError, ControlError, ProtocolViolation, ServerConfigError, ServerError
from server.glb import mesh_glb, mesh_json, texture_mime
from server.session import Output, Session, SessionConfig
from server.timing import StageTimes
from server.workers import RemoteSession, WorkerPool
from wire import JS_PROTOCOL
from wire import protocol as P

log = logging.getLogger("facecast.server")

FAIR_SLICE_S = 0.1  # audio processed per turn of the loop when a client sends a large block
# A viewer whose socket buffer holds less than this gets messages written synchronously
# (websockets' broadcast); others go through their queue and sender task (backpressure, drops).
FAST_PATH_BUFFER_BYTES = 64 * 1024


def _deliver(viewers: list["Viewer"], msg: bytes, now: float) -> None:
    """Hand one message to viewers: a synchronous write for those keeping up (no task switch per
    message), the bounded queue for the others."""
    fast = []
    for v in viewers:
        if v.writable_now():
            fast.append(v)
        else:
            v.offer(msg, now)
    if fast:
        broadcast([v.ws for v in fast], msg)
        for v in fast:
            v.sent += 1


@dataclass(frozen=True)
class Head:
    """The head viewers animate: its rig (moving vertices, deltas) and mesh (download)."""

    rig: Rig
    mesh: HeadMesh


class Viewer:
    """One subscriber: a bounded queue of ready messages drained by its own sender task."""

    def __init__(self, ws: ServerConnection, live: "LiveSession", *, kind: int, encoding: int, audio: bool,
                 server: "FacecastServer") -> None:
        self.ws = ws
        self.live = live
        self.kind = kind
        self.encoding = encoding
        self.audio = audio
        self.server = server
        self.queue: collections.deque[bytes] = collections.deque()
        self.limit = server.config.viewer_queue
        self.wake = asyncio.Event()
        self.dropped = 0
        self.sent = 0
        self.behind_since: float | None = None
        self.closing = False
        self.sending = False

    def writable_now(self) -> bool:
        """True when a message can be written straight to the socket without reordering or
        buffering beyond the write limit: nothing queued or in flight, transport buffer low."""
        if self.closing or self.queue or self.sending:
            return False
        transport = self.ws.transport
        return transport is not None and transport.get_write_buffer_size() <= FAST_PATH_BUFFER_BYTES

    def offer(self, msg: bytes, now: float) -> None:
        """Queue one message without waiting; drop the oldest when full; close if behind too long."""
        if self.closing:
            return
        if len(self.queue) >= self.limit:
            self.queue.popleft()
            self.dropped += 1
            self.live.dropped += 1
            self.server.dropped += 1
            if self.behind_since is None:
                self.behind_since = now
            elif now - self.behind_since > self.server.config.viewer_max_behind_s:
                self.closing = True
                self.server.closed_slow += 1
                self.queue.clear()
                self.server.spawn(
                    self.server.close_ws(self.ws, P.CLOSE_TOO_SLOW, f"viewer too slow: behind for over "
                                         f"{self.server.config.viewer_max_behind_s:g} s, {self.dropped} messages dropped")
                )
                return
        self.queue.append(msg)
        self.wake.set()

    async def run(self) -> None:
        """Send queued messages until the connection closes."""
        while True:
            await self.wake.wait()
            self.wake.clear()
            self.sending = True
            try:
                while self.queue:
                    msg = self.queue.popleft()
                    await self.ws.send(msg)
                    self.sent += 1
            finally:
                self.sending = False
            self.behind_since = None


class LiveSession:
    """A session with its viewers: feed it audio, it fans frames out."""

    def __init__(self, name: str, session: "Session | RemoteSession", server: "FacecastServer", *,
                 source: str) -> None:
        self.name = name
        self.session = session
        self.remote = isinstance(session, RemoteSession)
        self.server = server
        self.source = source
        self.viewers: set[Viewer] = set()
        self.dropped = 0
        self.started = time.time()
        self.ended = asyncio.Event()

    async def feed_bytes(self, data: bytes) -> int:
        """One binary block of the session's format -> frames produced (AudioFormatError if bad)."""
        if self.remote:
            return self._fanout(await self.session.push_bytes(data))
        return self._fanout(self.session.push_bytes(data))

    async def feed_bytes_fairly(self, data: bytes) -> int:
        """Like :meth:`feed_bytes`, but a large block (a client sending faster than real time) is
        processed in slices of at most ``FAIR_SLICE_S`` of audio with a yield to the loop between
        them, so one session's burst never holds up the other sessions for more than a few frames."""
        s = self.session
        frame = s.frame_bytes
        step = max(1, int(FAIR_SLICE_S * s.config.sample_rate_hz)) * frame
        if len(data) <= step:
            return await self.feed_bytes(data)
        if len(data) % frame:
            return await self.feed_bytes(data)  # raises the AudioFormatError naming the problem
        n = 0
        for i in range(0, len(data), step):
            n += await self.feed_bytes(data[i:i + step])
            await asyncio.sleep(0)
        return n

    async def feed(self, samples: np.ndarray) -> int:
        """(n,) or (n, channels) float samples -> frames produced."""
        if self.remote:
            return self._fanout(await self.session.push(samples))
        return self._fanout(self.session.push(samples))

    async def finish(self) -> int:
        """End of the audio: flush the remaining frames to the viewers."""
        if self.remote:
            return self._fanout(await self.session.flush())
        return self._fanout(self.session.flush())

    async def control(self, msg: dict) -> dict:
        """Apply a control message (ControlError if rejected); returns the control state."""
        if self.remote:
            return await self.session.apply_control(msg)
        return self.session.apply_control(msg)

    def _fanout(self, out: Output) -> int:
        if not self.viewers:
            return len(out.frames)
        t0 = time.perf_counter()
        now = time.time()
        if out.audio is not None:
            listeners = [v for v in self.viewers if v.audio]
            if listeners:
                a = out.audio
                msg = P.pack_header(P.KIND_AUDIO, P.ENC_INT16, a.index, a.samples.size, 1 / 32768, a.media_time, now) + a.payload()
                _deliver(listeners, msg, now)
        if out.frames:
            groups: dict[tuple[int, int], list[Viewer]] = {}
            for v in self.viewers:
                groups.setdefault((v.kind, v.encoding), []).append(v)
            for frame in out.frames:
                for (kind, enc), members in groups.items():
                    payload, count, scale = frame.payload(kind, enc)
                    msg = P.pack_header(kind, enc, frame.index, count, scale, frame.media_time, now) + payload
                    _deliver(members, msg, now)
        self.server.times.add("fanout", time.perf_counter() - t0)
        return len(out.frames)

    def describe(self) -> dict:
        s = self.session
        return {
            "name": self.name,
            "source": self.source,
            "viewers": len(self.viewers),
            "frames": s.frames_out,
            "audio_s": round(s.samples_out / s.rate_hz, 3),
            "dropped": self.dropped,
            "input_rate_hz": s.config.sample_rate_hz,
            "channels": s.config.channels,
            "controls": s.control_state(),
        }


class FacecastServer:
    """The service. ``await start()``, then ``await stop()``; or :func:`run_server` for a process.

    model: the audio-visual model every session runs; head: the rig and mesh for vertex deltas and
    the head download (None: params and blendshapes only); config: limits and network settings.
    """

    def __init__(self, model: AvModel, *, head: Head | None = None, config: ServerConfig = ServerConfig()) -> None:
        self.model = model
        self.head = head
        self.config = config
        self.sessions: dict[str, LiveSession] = {}
        self.times = StageTimes()
        self.dropped = 0
        self.closed_slow = 0
        self.closes: collections.Counter[int] = collections.Counter()
        self.n_viewers = 0
        self._server: Server | None = None
        self._http_cache: dict[str, tuple[bytes, str]] = {}
        self._tasks: set[asyncio.Task] = set()
        self.started = time.time()
        self.stopping = False
        self.pool: WorkerPool | None = None

    # -- lifecycle ---------------------------------------------------------------------------------

    async def start(self) -> None:
        """Bind and start accepting connections (port 0 picks a free port: see :attr:`port`)."""
        cfg = self.config
        try:
            self._server = await serve(
                self._handle,
                cfg.host,
                cfg.port,
                compression=None,  # permessage-deflate would cost ~20x the CPU of a frame
                max_size=cfg.max_message_bytes,
                close_timeout=cfg.close_timeout_s,
                process_request=self._process_request,
                server_header="facecast",
            )
        except OSError as exc:
            raise ServerError(f"cannot listen on {cfg.host}:{cfg.port}: {exc.strerror or exc}") from None
        if cfg.workers:
            self.pool = WorkerPool(self.model, cfg.workers)
            await self.pool.start()
        lag = asyncio.ensure_future(self._watch_loop_lag())
        self._tasks.add(lag)

    async def _watch_loop_lag(self, period_s: float = 0.01) -> None:
        """Record how late a 10 ms timer fires ("loop_lag"): the time any callback waits for the loop,
        whether the loop is busy with frames or the process is not scheduled (a shared machine)."""
        loop = asyncio.get_running_loop()
        while True:
            t = loop.time()
            await asyncio.sleep(period_s)
            self.times.add("loop_lag", max(0.0, loop.time() - t - period_s))

    @property
    def port(self) -> int:
        if self._server is None:
            raise ServerError("server not started")
        return int(next(iter(self._server.sockets)).getsockname()[1])

    @property
    def url(self) -> str:
        return f"http://{self.config.host}:{self.port}"

    async def stop(self) -> None:
        """Graceful shutdown: end every session (viewers get their last frames, then 1001), wait for
        them (at most close_timeout_s), then close the listener and the remaining connections."""
        self.stopping = True
        for live in list(self.sessions.values()):
            live.ended.set()
        deadline = time.monotonic() + self.config.close_timeout_s
        while self.sessions and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        if self._server is not None:
            self._server.close(close_connections=True)
            await self._server.wait_closed()
        for task in list(self._tasks):
            task.cancel()
        if self.pool is not None:
            await self.pool.stop()
            self.pool = None

    def spawn(self, coro) -> asyncio.Task:
        """Run a coroutine in the background, holding a reference until it is done."""
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    async def close_ws(self, ws: ServerConnection, code: int, reason: str) -> None:
        """Close one connection with a code and reason (counted in metrics)."""
        self.closes[code] += 1
        try:
            await ws.close(code, reason[:120])
        except ConnectionClosed:
            pass

    # -- local sources -----------------------------------------------------------------------------

    async def open_session(self, name: str, config: SessionConfig, *, source: str) -> LiveSession:
        """Register a new live session (ServerError if the name is taken or the server is full)."""
        if not P.SESSION_NAME.match(name):
            raise ServerConfigError(f"session name must match {P.SESSION_NAME.pattern}, got {name!r}")
        if (refused := self._no_room(name)) is not None:
            raise ServerConfigError(refused[1])
        session = await self._new_session(config)
        if (refused := self._no_room(name)) is not None:  # the await may have let another one in
            await self._discard(session)
            raise ServerConfigError(refused[1])
        live = LiveSession(name, session, self, source=source)
        self.sessions[name] = live
        return live

    def _no_room(self, name: str) -> tuple[int, str] | None:
        """Why a session ``name`` cannot open now, as (close code, reason); None if it can."""
        if name in self.sessions:
            return P.CLOSE_CONFLICT, f"session {name!r} already exists"
        if len(self.sessions) >= self.config.max_sessions:
            return P.CLOSE_TRY_LATER, f"server is full ({self.config.max_sessions} sessions)"
        return None

    async def _new_session(self, config: SessionConfig) -> "Session | RemoteSession":
        rig = self.head.rig if self.head else None
        if self.pool is not None:
            return await self.pool.open(config, rig=rig, times=self.times)
        return Session(self.model, config=config, rig=rig, times=self.times)

    @staticmethod
    async def _discard(session: "Session | RemoteSession") -> None:
        if isinstance(session, RemoteSession):
            await session.close()

    async def run_source(self, name: str, source: AsyncIterator[np.ndarray], *, sample_rate_hz: int,
                         channels: int = 1, label: str = "local") -> LiveSession:
        """Run a session from an async iterator of (n,) / (n, channels) float blocks until it ends."""
        cfg = SessionConfig(sample_rate_hz=int(sample_rate_hz), channels=channels, lag=self.config.lag)
        live = await self.open_session(name, cfg, source=label)
        try:
            async for block in source:
                await live.feed(block)
                if live.ended.is_set():
                    break
            await live.finish()
        finally:
            if self.stopping:
                await self._end_session(live, P.CLOSE_GOING_AWAY, "server shutting down")
            else:
                await self._end_session(live, P.CLOSE_NORMAL, "session ended")
        return live

    async def _end_session(self, live: LiveSession, code: int, reason: str) -> None:
        self.sessions.pop(live.name, None)
        live.ended.set()
        await self._discard(live.session)  # a worker session that never flushed
        # Let senders drain what is queued (bounded: each viewer queue is small), then close.
        for v in list(live.viewers):
            v.wake.set()
        await asyncio.sleep(0)
        await asyncio.gather(*(self._close_viewer_after_drain(v, code, reason) for v in list(live.viewers)))

    async def _close_viewer_after_drain(self, v: Viewer, code: int, reason: str) -> None:
        deadline = time.monotonic() + self.config.close_timeout_s
        while v.queue and not v.closing and time.monotonic() < deadline:
            await asyncio.sleep(0.005)
        if not v.closing:
            v.closing = True
            await self.close_ws(v.ws, code, reason)

    # -- WebSocket connections ---------------------------------------------------------------------

    async def _handle(self, ws: ServerConnection) -> None:
        path = urllib.parse.urlsplit(ws.request.path).path
        try:
            if path == "/ingest":
                await self._ingest(ws)
            elif path == "/view":
                await self._view(ws)
            else:
                raise ProtocolViolation(P.CLOSE_NOT_FOUND, f"no WebSocket endpoint {path!r} (use /ingest or /view)")
        except ProtocolViolation as exc:
            await self.close_ws(ws, exc.code, exc.reason)
        except ConnectionClosed:
            pass
        except Exception:  # noqa: BLE001 - connection boundary: a bug closes this connection only
            log.exception("internal error on %s", path)
            await self.close_ws(ws, P.CLOSE_INTERNAL, "internal server error")

    def _check_token(self, given: object) -> None:
        want = self.config.token
        if want is None:
            return
        if not isinstance(given, str) or not hmac.compare_digest(given.encode(), want.encode()):
            raise ProtocolViolation(P.CLOSE_UNAUTHORIZED, "missing or wrong token")

    async def _ingest(self, ws: ServerConnection) -> None:
        try:
            first = await asyncio.wait_for(ws.recv(), self.config.start_timeout_s)
        except TimeoutError:
            raise ProtocolViolation(P.CLOSE_POLICY, f"no start message within {self.config.start_timeout_s:g} s") from None
        if not isinstance(first, str):
            raise ProtocolViolation(P.CLOSE_UNSUPPORTED_DATA, "expected a JSON start message (text) first, got binary")
        start = _parse_json(first, "start message")
        if start.get("type") != "start":
            raise ProtocolViolation(P.CLOSE_POLICY, f"first message must be {{\"type\": \"start\"}}, got type {start.get('type')!r}")
        self._check_token(start.get("token"))
        unknown = sorted(set(start) - {"type", "sample_rate", "format", "channels", "session", "token"})
        if unknown:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"unknown start fields {unknown}")
        if "sample_rate" not in start:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, "start message lacks sample_rate")
        name = start.get("session")
        if not isinstance(name, str) or not P.SESSION_NAME.match(name):
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, "session must be 1-64 characters of A-Z a-z 0-9 _ . -")
        try:
            cfg = SessionConfig(sample_rate_hz=start["sample_rate"], channels=start.get("channels", 1),
                                sample_format=start.get("format", "pcm_s16le"), lag=self.config.lag)
        except ServerConfigError as exc:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, str(exc)) from None
        if (refused := self._no_room(name)) is not None:
            raise ProtocolViolation(*refused)
        session = await self._new_session(cfg)
        if (refused := self._no_room(name)) is not None:  # the await may have let another one in
            await self._discard(session)
            raise ProtocolViolation(*refused)
        live = LiveSession(name, session, self, source="ingest")
        self.sessions[name] = live
        code, reason = P.CLOSE_NORMAL, "session ended"
        try:
            s = live.session
            await ws.send(P.dumps({
                "type": "started", "session": name, "model_rate_hz": s.rate_hz, "fps": s.fps,
                "algorithmic_delay_s": s.algorithmic_delay_s, "view_path": f"/view?session={name}",
            }))
            ended_task = asyncio.ensure_future(live.ended.wait())
            try:
                while True:
                    recv = asyncio.ensure_future(ws.recv())
                    done, _ = await asyncio.wait({recv, ended_task}, return_when=asyncio.FIRST_COMPLETED)
                    if recv not in done:  # server shutting down
                        recv.cancel()
                        await live.finish()
                        code, reason = P.CLOSE_GOING_AWAY, "server shutting down"
                        break
                    msg = recv.result()
                    if isinstance(msg, bytes):
                        try:
                            await live.feed_bytes_fairly(msg)
                        except AudioFormatError as exc:
                            raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, str(exc)) from None
                        continue
                    try:
                        ctl = json.loads(msg)
                    except ValueError:
                        raise ProtocolViolation(P.CLOSE_UNSUPPORTED_DATA,
                                                "text message is not JSON: audio must be sent as binary messages") from None
                    if not isinstance(ctl, dict):
                        raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, "a control message must be a JSON object")
                    kind = ctl.get("type")
                    if kind == "control":
                        try:
                            state = await live.control(ctl)
                            await ws.send(P.dumps({"type": "ack", "controls": state}))
                        except ControlError as exc:
                            await ws.send(P.dumps({"type": "rejected", "reason": str(exc)}))
                    elif kind == "end":
                        await live.finish()
                        await ws.send(P.dumps({"type": "ended", "frames": live.session.frames_out,
                                               "audio_s": live.session.samples_out / live.session.rate_hz}))
                        break
                    elif kind == "start":
                        raise ProtocolViolation(P.CLOSE_POLICY, "second start message: the session has started")
                    else:
                        raise ProtocolViolation(P.CLOSE_POLICY, f"unknown message type {kind!r} (expected control or end)")
            finally:
                ended_task.cancel()
        except ProtocolViolation as exc:
            code, reason = P.CLOSE_NORMAL, "session ended: its source broke the protocol"
            raise exc
        except ConnectionClosed:
            # The source hung up without "end": finish what it sent.
            await live.finish()
        finally:
            await self._end_session(live, code, reason)
        await self.close_ws(ws, code, reason)

    async def _view(self, ws: ServerConnection) -> None:
        q = urllib.parse.parse_qs(urllib.parse.urlsplit(ws.request.path).query)
        arg = {k: v[-1] for k, v in q.items()}
        self._check_token(arg.get("token"))
        name = arg.get("session", "")
        live = self.sessions.get(name)
        if live is None:
            raise ProtocolViolation(P.CLOSE_NOT_FOUND, f"no session {name!r}")
        kind = arg.get("kind", "params")
        encodings = P.VIEW_KINDS.get(kind)
        if encodings is None:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"kind must be one of {sorted(P.VIEW_KINDS)}, got {kind!r}")
        enc_name = arg.get("encoding", next(iter(encodings)))
        if enc_name not in encodings:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"encoding for {kind} must be one of {sorted(encodings)}, got {enc_name!r}")
        if kind == "deltas" and self.head is None:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, "this server has no head rig: vertex deltas are unavailable")
        audio = arg.get("audio", "1")
        if audio not in ("0", "1"):
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, "audio must be 0 or 1")
        if self.n_viewers >= self.config.max_viewers:
            raise ProtocolViolation(P.CLOSE_TRY_LATER, f"server is full ({self.config.max_viewers} viewers)")
        hk, he = encodings[enc_name]
        if self.config.viewer_socket_buffer_bytes is not None:
            sock = ws.transport.get_extra_info("socket")
            if sock is not None:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.config.viewer_socket_buffer_bytes)
        await ws.send(P.dumps(self._description(live, kind, enc_name, hk, he, audio == "1")))
        if live.name not in self.sessions:  # ended while we were sending the description
            raise ProtocolViolation(P.CLOSE_NORMAL, "session ended")
        viewer = Viewer(ws, live, kind=hk, encoding=he, audio=audio == "1", server=self)
        live.viewers.add(viewer)
        self.n_viewers += 1
        sender = asyncio.ensure_future(viewer.run())
        self._tasks.add(sender)
        try:
            reader = asyncio.ensure_future(ws.recv())
            done, _ = await asyncio.wait({reader, sender}, return_when=asyncio.FIRST_COMPLETED)
            if reader in done and reader.exception() is None:
                viewer.closing = True
                raise ProtocolViolation(P.CLOSE_POLICY, "viewers do not send messages")
            reader.cancel()
            if sender in done and sender.exception() is not None and not isinstance(sender.exception(), ConnectionClosed):
                raise sender.exception()
        finally:
            sender.cancel()
            self._tasks.discard(sender)
            live.viewers.discard(viewer)
            self.n_viewers -= 1

    def _description(self, live: LiveSession, kind: str, enc_name: str, hk: int, he: int, audio: bool) -> dict:
        s = live.session
        d: dict = {
            "type": "description",
            "protocol": P.PROTOCOL_VERSION,
            "session": live.name,
            "fps": s.fps,
            "kind": kind,
            "encoding": enc_name,
            "header_kind": hk,
            "header_encoding": he,
            "header_bytes": P.HEADER_BYTES,
            "params": {"names": list(VISUAL_PARAMS), "units": "inter-ocular distances (IOD)"},
            "algorithmic_delay_s": s.algorithmic_delay_s,
            "audio": {"rate_hz": s.rate_hz, "channels": 1, "encoding": "int16", "scale": 1 / 32768} if audio else None,
            "values_per_frame": 4,
        }
        if self.head is not None:
            rig, mesh = self.head.rig, self.head.mesh
            d["head"] = {
                "mesh_url": "/head/mesh",
                "mesh_json_url": "/head/mesh.json",
                "texture_url": "/head/texture" if mesh.texture is not None else None,
                "vertex_count": int(len(mesh.vertices)),
                "moving_vertices": rig.moving.astype(int).tolist(),
                "units": "mesh units",
            }
        else:
            d["head"] = None
        if kind == "deltas":
            d["values_per_frame"] = 3 * int(len(self.head.rig.moving))
            d["layout"] = "x, y, z of each moving vertex in moving_vertices order, added to the neutral mesh"
        elif kind == "blendshapes":
            d["names"] = list(blendshape_names(enc_name))
            d["values_per_frame"] = len(d["names"])
        return d

    # -- plain HTTP --------------------------------------------------------------------------------

    def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        path = urllib.parse.urlsplit(request.path).path
        if path in ("/ingest", "/view"):
            return None  # WebSocket handshake proceeds (websockets answers 426 if it is not one)
        if request.headers.get("Upgrade", "").lower() == "websocket":
            return _response(HTTPStatus.NOT_FOUND, b"no WebSocket endpoint here (use /ingest or /view)\n", "text/plain")
        if path == "/health":
            body = {"status": "ok", "sessions": len(self.sessions), "viewers": self.n_viewers,
                    "uptime_s": round(time.time() - self.started, 3)}
            return _response(HTTPStatus.OK, P.dumps(body).encode(), "application/json")
        if path == "/metrics":
            return _response(HTTPStatus.OK, P.dumps(self.metrics()).encode(), "application/json")
        if path.startswith("/head/"):
            return self._head_response(path)
        if path in ("/", "/index.html"):
            return self._index()
        return self._static(path)

    def metrics(self) -> dict:
        """Sessions, viewers, per-stage timings (ms), dropped frames, closes by code."""
        return {
            "sessions": len(self.sessions),
            "viewers": self.n_viewers,
            "dropped_messages": self.dropped,
            "viewers_closed_slow": self.closed_slow,
            "closes": {str(k): v for k, v in sorted(self.closes.items())},
            "timings_ms": self.times.summary(),
            "session_list": [live.describe() for live in self.sessions.values()],
            "uptime_s": round(time.time() - self.started, 3),
        }

    def _head_response(self, path: str) -> Response:
        if self.head is None:
            return _response(HTTPStatus.NOT_FOUND, b"this server has no head\n", "text/plain")
        mesh = self.head.mesh
        hit = self._http_cache.get(path)
        if hit is None:
            if path == "/head/mesh":
                hit = (mesh_glb(mesh), "model/gltf-binary")
            elif path == "/head/mesh.json":
                hit = (mesh_json(mesh), "application/json")
            elif path == "/head/texture" and mesh.texture is not None:
                hit = (mesh.texture, texture_mime(mesh) or "application/octet-stream")
            else:
                return _response(HTTPStatus.NOT_FOUND, b"not found\n", "text/plain")
            self._http_cache[path] = hit
        return _response(HTTPStatus.OK, hit[0], hit[1])

    def _index(self) -> Response:
        root = self.config.web_root
        if root is not None and (root / "index.html").is_file():
            return _response(HTTPStatus.OK, (root / "index.html").read_bytes(), "text/html; charset=utf-8")
        rows = "".join(
            f"<li><code>{n}</code> ({live.source}, {live.session.frames_out} frames, {len(live.viewers)} viewers): "
            f"<code>ws://HOST/view?session={n}&amp;kind=params</code></li>"
            for n, live in sorted(self.sessions.items())
        ) or "<li>none</li>"
        page = (
            "<!doctype html><meta charset=utf-8><title>facecast</title>"
            "<h1>facecast</h1><p>The browser viewer is not built yet. Live sessions:</p>"
            f"<ul>{rows}</ul><p>See <a href=/health>/health</a>, <a href=/metrics>/metrics</a>, "
            "<a href=/head/mesh>/head/mesh</a> (glTF) and docs/protocol.md.</p>"
        )
        return _response(HTTPStatus.OK, page.encode(), "text/html; charset=utf-8")

    # Files of npm packages the browser viewer imports (its import map points at /vendor/three/).
    _VENDOR = {"three": ("build/", "examples/jsm/")}

    def _static(self, path: str) -> Response:
        root = self.config.web_root
        if path == "/js/protocol.js":  # the wire format's JS twin lives with the Python one
            root, path = JS_PROTOCOL.parent, JS_PROTOCOL.name
        if path.startswith("/vendor/") and self.config.node_modules is not None:
            package, _, rel = path[len("/vendor/"):].partition("/")
            prefix = next((d for d in self._VENDOR.get(package, ()) if rel.startswith(d)), None)
            if prefix is not None:  # root = the allowed folder itself, so ../ cannot leave it
                root, path = self.config.node_modules / package / prefix, rel[len(prefix):]
        if root is not None:
            target = (root / path.lstrip("/")).resolve()
            if target.is_file() and root.resolve() in target.parents:
                ctype = {".html": "text/html; charset=utf-8", ".js": "text/javascript", ".css": "text/css",
                         ".json": "application/json", ".png": "image/png", ".jpg": "image/jpeg",
                         ".glb": "model/gltf-binary", ".wasm": "application/wasm"}.get(target.suffix, "application/octet-stream")
                return _response(HTTPStatus.OK, target.read_bytes(), ctype)
        return _response(HTTPStatus.NOT_FOUND, b"not found\n", "text/plain")


def _response(status: HTTPStatus, body: bytes, ctype: str) -> Response:
    headers = Headers([("Content-Type", ctype), ("Content-Length", str(len(body))), ("Cache-Control", "no-store"),
                       ("Connection", "close")])
    return Response(status.value, status.phrase, headers, body)


def _parse_json(text: str, what: str) -> dict:
    try:
        obj = json.loads(text)
    except ValueError:
        raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, f"{what} is not valid JSON") from None
    if not isinstance(obj, dict):
        raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, f"{what} must be a JSON object")
    return obj


async def run_server(server: FacecastServer, *, ready: "asyncio.Future | None" = None,
                     extra: list | None = None) -> None:
    """Run until SIGINT/SIGTERM (or ``extra`` coroutines all finish), then shut down gracefully.

    BLAS is pinned to one thread for the whole run: per-frame products are tiny and on a shared
    2-core machine multi-threaded BLAS only adds contention.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await server.start()
        if ready is not None and not ready.done():
            ready.set_result(server)
        try:
            waiters = [asyncio.ensure_future(stop.wait())]
            if extra:
                work = asyncio.ensure_future(asyncio.gather(*extra))
                waiters.append(work)
            await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
            for w in waiters:
                if w.done() and w is not waiters[0] and w.exception() is not None:
                    raise w.exception()
        finally:
            for w in waiters:
                w.cancel()
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)
            await server.stop()


def load_head(*, head: Path | None = None, landmarks: Path | None = None, rig: Path | None = None,
              builtin: bool = True) -> Head | None:
    """The head to serve: a rig file, a mesh to rig now (with its landmarks JSON, or the one shipped
    for it), the built-in head, or None."""
    if rig is not None:
        from assets.heads.rigfile import load_rig

        r, m = load_rig(rig)
        return Head(r, m)
    if head is not None:
        from assets.heads.landmarks import read_landmarks, shipped_landmarks
        from assets.heads.mesh import load_mesh
        from assets.heads.rigging import rig_head

        m = load_mesh(head)
        lm_path = landmarks or shipped_landmarks(head)
        r, m = rig_head(m, None if lm_path is None else read_landmarks(lm_path), landmark_source=str(lm_path))
        return Head(r, m)
    if builtin:
        from assets.heads.rigfile import builtin_rig

        r, m = builtin_rig()
        return Head(r, m)
    return None
