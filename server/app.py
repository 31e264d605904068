"""The asyncio shell of the service: ingest and viewer WebSockets plus plain HTTP on one port.

Theory of operation
-------------------
One process, one event loop, python-websockets underneath. This module only does I/O and
bookkeeping; the decisions live in sans-I/O modules:

* :mod:`server.protocol` decides what an ingest connection's messages mean (start, audio, control,
  end) and which replies and close codes go out; it also parses viewer queries. The shell here feeds
  it events and performs the actions it returns (``Send``, ``Close``, ``Open``, ``Feed``,
  ``Control``, ``Finish``).
* :mod:`server.live` holds live sessions (local or in a compute worker, one async interface) and
  fans frames out to viewers with per-viewer backpressure.
* :mod:`server.describe` writes the JSON descriptions; :mod:`server.http` routes plain HTTP.

A *live session* couples one audio source (a WebSocket ingest connection, the microphone or a file)
with a session and any number of viewers. When a block of audio arrives the session computes the
frames now final (inline on the loop: a few hundred microseconds per frame with the paper's model,
measured by ``benchmarks/server_latency.py``; with ``ServerConfig.workers`` in compute processes,
see :mod:`server.workers`), then fans them out.

Every protocol breach closes that one connection with a code and reason (docs/protocol.md); the
server and the other sessions go on. Plain HTTP is answered from the websockets
``process_request`` hook before any WebSocket handshake.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import signal
import socket
import threading
import time
import urllib.parse
from collections.abc import AsyncIterator, Callable, Coroutine
from dataclasses import replace
from http import HTTPStatus
from typing import TYPE_CHECKING, Any

import numpy as np
from threadpoolctl import threadpool_limits
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed, WebSocketException
from websockets.frames import DATA_OPCODES, Frame, Opcode
from websockets.http11 import Request, Response
from websockets.protocol import OPEN, Event
from websockets.server import ServerProtocol

from assets.heads.head import Head
from realtime_core.mapping import SpeechModel
from server import describe
from server import protocol as SP
from server.cluster import Cluster, RemoteFeed
from server.config import ServerConfig
from server.errors import (
    AudioFormatError,
    ControlError,
    IngestOverrun,
    ProtocolViolation,
    ServerConfigError,
    ServerError,
    ServerSideClose,
    reason_value,
)
from server.eventloop import running_loop_name
from server.guard import (
    ConnectionCounter,
    ConnectionRate,
    IncidentLog,
    IngestPacer,
    host_allowed,
    http_url,
    origin_allowed,
)
from server.http import HttpReply, HttpRouter
from server.live import (
    FAIR_SLICE_S,
    EndWake,
    HeldViewers,
    Hold,
    LiveSession,
    LocalSession,
    SessionHandle,
    TurnDeltas,
    Viewer,
    deliver,
    sessions_log,
)
from server.session import Session, SessionConfig, warm_up
from server.shards import ConnectionWorkers, FrontRegistry
from server.timing import GcPauses, StageTimes, freeze_heap
from server.workers import WorkerPool
from wire import protocol as P

if TYPE_CHECKING:  # imported lazily at run time: only `--text` servers load unit selection
    from server.text_session import TextBackend

log = logging.getLogger("facecast.server")

HELD_JOIN_S = 0.5
"""s: the longest a session's opening waits for its held viewers to subscribe (:meth:`FacecastServer.release_held`).
A held viewer subscribes within a turn or two of the loop (its description is written at once to a fresh socket);
one whose socket would not take it then joins late, as an unheld viewer would, rather than hold up the session."""
CLUSTER_HOLD_POLL_S = 0.05
"""s: how often a viewer held on a cluster node looks for its session in the registry (one opened on another node
wakes nobody here): the period at which the clients used to retry."""


class AdmissionRefused(ServerConfigError):
    """A session cannot open now: ``code`` is the close code an ingest is refused with."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


class _OneBlasThread:
    """BLAS held at one thread while any :class:`FacecastServer` of the process serves: per-frame products and unit
    selection's are tiny, and on a shared 2-core machine more BLAS threads only contend (and the thread count changes
    unit selection's sums in their last digits: a text session then matches `facecast say`, which pins it too).
    threadpoolctl's limit is the process's (OpenBLAS has one thread count), so the servers of a process share it: the
    first to start sets it, the last to stop gives an embedding process its own count back."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._servers = 0
        self._limits: threadpool_limits | None = None

    def hold(self) -> None:
        with self._lock:
            if self._servers == 0:
                self._limits = threadpool_limits(1)
            self._servers += 1

    def release(self) -> None:
        with self._lock:
            self._servers -= 1
            if self._servers == 0 and self._limits is not None:
                self._limits.restore_original_limits()
                self._limits = None


_ONE_BLAS_THREAD = _OneBlasThread()


class FacecastServer:
    """The service. ``await start()``, then ``await stop()``; or :func:`run_server` for a process.

    model: the audio-visual model every session runs; head: the rig and mesh for vertex deltas and
    the head download (None: params and blendshapes only); config: limits and network settings.
    """

    def __init__(self, model: SpeechModel, *, head: Head | None = None, config: ServerConfig = ServerConfig()) -> None:
        self.model = model
        self.head = head
        self.config = config
        self.sessions: dict[str, LiveSession] = {}
        self.times = StageTimes()
        self.turn_deltas = TurnDeltas()  # vertex deltas computed once per loop turn (server.live)
        self.dropped = 0
        self.closed_slow = 0
        self.closes: collections.Counter[int] = collections.Counter()
        self.n_viewers = 0  # viewers watching or held (a view query's wait) on this process
        self.holds = HeldViewers()  # viewers held for sessions that have not opened yet
        self._server: Server | None = None
        self._tasks: set[asyncio.Task] = set()
        self.started = time.time()
        self.stopping = False
        self.pool: WorkerPool | None = None
        self.shards: ConnectionWorkers | None = None  # worker_mode "connections": this is the front
        self._connection_class: type[FacecastConnection] = FacecastConnection  # with a router at a front (start)
        self.registry: FrontRegistry | None = None  # set in a connection worker: names are claimed at the front
        self.cluster: Cluster | None = None
        self.text_backend: TextBackend | None = None  # enables /text (set by `facecast serve --text`)
        self.http = HttpRouter(
            web_root=config.web_root, node_modules=config.node_modules, head=head, sessions=self.session_list
        )
        self.http.route("/health", lambda: HttpReply.json(self.health()), private=False)
        self.http.route("/metrics", lambda: HttpReply.json(self.metrics()))
        self.http.route("/sessions", self._sessions_reply)
        self.clients = ConnectionCounter(config.max_connections_per_client)
        self._handled: set[ServerConnection] = set()  # WebSocket connections whose handler runs (stop() tells them)
        self.connect_rate = ConnectionRate(config.connect_rate_per_s, config.connect_burst)
        self.incidents = IncidentLog(log)
        self._gc_pauses: GcPauses | None = None
        self._holds_blas = False  # between start and stop (_ONE_BLAS_THREAD)
        self._enrolling = asyncio.Lock()  # enrolments adapt one at a time (_new_session)

    # -- lifecycle ---------------------------------------------------------------------------------

    async def start(self, *, listen: bool = True) -> None:
        """Bind and start accepting connections (port 0 picks a free port: see :attr:`port`).
        listen=False: no listener; connections come through :meth:`adopt` (a connection worker).

        BLAS is held at one thread from here until :meth:`stop` (:class:`_OneBlasThread`), for every server: `facecast
        serve`, a test's, an embedder's."""
        _ONE_BLAS_THREAD.hold()
        self._holds_blas = True
        try:
            await self._start(listen)
        except BaseException:
            self._release_blas()
            raise

    def _release_blas(self) -> None:
        if self._holds_blas:
            self._holds_blas = False
            _ONE_BLAS_THREAD.release()

    async def _start(self, listen: bool) -> None:
        cfg = self.config
        if cfg.workers and cfg.worker_mode == "connections":
            if running_loop_name() != "asyncio":  # it would read every request itself: server.eventloop.process_loop
                raise ServerConfigError("the front of connection workers must run on asyncio's event loop")
            self.shards = ConnectionWorkers(self, cfg.workers)
        self._connection_class = _connection_class(self.shards)
        where: dict[str, Any] = {"host": cfg.host, "port": cfg.port}
        if not listen:
            # websockets answers 503 unless its server is serving: it serves on a Unix socket of no name
            # (Linux gives it an abstract address; nobody is told it), the connections come by adopt().
            hidden = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            hidden.bind("")  # an empty name: Linux picks an abstract one
            where = {"sock": hidden}
        try:
            self._server = await serve(
                self._handle,
                compression=None,  # permessage-deflate would cost ~20x the CPU of a frame
                open_timeout=cfg.handshake_timeout_s,
                **_protocol_options(cfg),
                **_connection_options(cfg),
                process_request=self._process_request,
                server_header="facecast",
                create_connection=self._connection_class,
                **where,
            )
        except OSError as exc:
            raise ServerError(f"cannot listen on {cfg.host}:{cfg.port}: {exc.strerror or exc}") from None
        if cfg.redis_url is not None:
            import os
            import socket as _socket

            node = cfg.node_id or f"{_socket.gethostname()}-{os.getpid()}-{self.port}"
            self.cluster = Cluster(
                cfg.redis_url,
                node=node,
                advertise=cfg.advertise_url or self.url,
                heartbeat_s=cfg.heartbeat_s,
                role=cfg.role,
                deliver=self._deliver_remote,
                end_feed=self._end_feed,
            )
            try:
                await self.cluster.start()
            except ServerError:
                self.cluster = None
                self._server.close()
                await self._server.wait_closed()
                raise
        # Compiled per-frame kernels load (or compile) on first call: here, not in the first session.
        await asyncio.to_thread(warm_up, self.model, self.head.rig if self.head else None)
        if self.shards is not None:
            try:
                await self.shards.start()
            except ServerError:
                await self.shards.stop()
                self._server.close()
                await self._server.wait_closed()
                raise
        elif cfg.workers:
            self.pool = WorkerPool(self.model, cfg.workers, rig=self.head.rig if self.head else None)
            await self.pool.start()
        self._gc_pauses = GcPauses(self.times)
        self.spawn(self._watch_loop_lag())

    async def _watch_loop_lag(self, period_s: float = 0.01) -> None:
        """Record how late a 10 ms timer fires ("loop_lag"): the time any callback waits for the loop,
        whether the loop is busy with frames or the process is not scheduled (a shared machine).
        "loop_lag_cpu" bounds the part of each lag the loop's own work can explain: the CPU time the
        loop's thread used in that interval, when less than the lag (the rest is time the process
        waited for a core)."""
        loop = asyncio.get_running_loop()
        while True:
            t, cpu = loop.time(), time.thread_time()
            await asyncio.sleep(period_s)
            lag = max(0.0, loop.time() - t - period_s)
            self.times.add("loop_lag", lag)
            self.times.add("loop_lag_cpu", min(lag, time.thread_time() - cpu))

    async def adopt(self, sock: socket.socket) -> None:
        """Serve a connection accepted elsewhere (the front of connection workers, server.shards) as
        if this server's listener had accepted it: the same handshake checks and handlers.

        Built from websockets' public pieces as its ``serve`` builds an accepted connection: a sans-I/O
        ``ServerProtocol`` and a ``ServerConnection`` (our class, ``serve``'s ``create_connection``) of this
        server, whose ``connection_made`` starts the server's handler (handshake with ``open_timeout``,
        then :meth:`_handle`), with the options ``serve`` was given (:func:`_protocol_options`,
        :func:`_connection_options`; the rest are the same defaults on both sides: no compression means
        no extensions, and Origin is checked in :meth:`_process_request`, not by ``origins``)."""
        server = self._server
        assert server is not None  # started
        cfg = self.config

        def connection() -> ServerConnection:
            protocol = ServerProtocol(**_protocol_options(cfg))
            return self._connection_class(protocol, server, **_connection_options(cfg))

        await asyncio.get_running_loop().connect_accepted_socket(connection, sock)

    @property
    def port(self) -> int:
        if self._server is None:
            raise ServerError("server not started")
        return int(next(iter(self._server.sockets)).getsockname()[1])

    @property
    def url(self) -> str:
        return http_url(self.config.host, self.port)

    async def stop(self) -> None:
        """Graceful shutdown: end every session (viewers get their last frames, then 1001), wait for
        them (at most close_timeout_s), then close the listener and the remaining connections."""
        self.stopping = True
        self.holds.refuse(None, P.CLOSE_GOING_AWAY, "server shutting down")
        for live in list(self.sessions.values()):
            live.ended.set()
        shards_stopped = asyncio.ensure_future(self.shards.stop()) if self.shards is not None else None
        deadline = time.monotonic() + self.config.close_timeout_s
        while self.sessions and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        # Connections with no session to end (a source that had not sent its start, one whose enrolment was being
        # adapted) are told why as the sessions' were: the listener's own close said 1001 with no reason.
        left = [ws for ws in self._handled if ws.protocol.state is OPEN]
        await asyncio.gather(*(self.close_ws(ws, P.CLOSE_GOING_AWAY, "server shutting down") for ws in left))
        if self._server is not None:
            self._server.close(close_connections=True)
            await self._server.wait_closed()
        for task in list(self._tasks):
            task.cancel()
        if self.cluster is not None:
            await self.cluster.stop()
            self.cluster = None
        if self.pool is not None:
            await self.pool.stop()
            self.pool = None
        if shards_stopped is not None:
            await shards_stopped
            self.shards = None
        if self._gc_pauses is not None:
            self._gc_pauses.close()
            self._gc_pauses = None
        self._release_blas()

    def spawn(self, coro: Coroutine[Any, Any, Any]) -> asyncio.Task[Any]:
        """Run a coroutine in the background, holding a reference until it is done."""
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    async def close_ws(self, ws: ServerConnection, code: int, reason: str) -> None:
        """Close one connection with a code and reason (counted in metrics when this call closes it: a shutdown and
        the connection's own handler may both ask)."""
        if ws.protocol.state is OPEN:
            self.closes[code] += 1
        with contextlib.suppress(ConnectionClosed):
            await ws.close(code, SP.fit_close_reason(reason))

    # -- sessions ----------------------------------------------------------------------------------

    def _admission(self, name: str, *, batch: bool = False) -> None:
        """Raise AdmissionRefused if a session ``name`` cannot open now (the one admission check)."""
        refused = self.admission_refusal(name, batch=batch)
        if refused is not None:
            raise AdmissionRefused(*refused)

    def admission_refusal(self, name: str, *, batch: bool = False) -> tuple[int, str] | None:
        """Why a session ``name`` cannot open now, as (close code, reason); None if it can. Counts the
        sessions of connection workers too when this is their front."""
        shards = self.shards
        if not P.SESSION_NAME.match(name):
            return P.CLOSE_BAD_REQUEST, f"{P.SESSION_NAME_RULE}, got {reason_value(name)}"
        if self.stopping:
            return P.CLOSE_GOING_AWAY, "server shutting down"
        if name in self.sessions or (shards is not None and shards.owns(name)):
            return P.CLOSE_CONFLICT, f"session {name!r} already exists"
        n = len(self.sessions) + (shards.session_count() if shards is not None else 0)
        if n >= self.config.max_sessions:
            return P.CLOSE_TRY_LATER, f"server is full ({self.config.max_sessions} sessions)"
        n_batch = sum(live.batch for live in self.sessions.values()) + (shards.batch_count() if shards else 0)
        if batch and n_batch >= self.config.max_batch_sessions:
            return P.CLOSE_TRY_LATER, f"batch sessions are full ({self.config.max_batch_sessions})"
        return None

    async def open_session(
        self, name: str, config: SessionConfig, *, source: str, batch: bool = False, paced: bool = False
    ) -> LiveSession:
        """Register a new live session (AdmissionRefused, a ServerConfigError, if the name is taken or
        the server is full). paced: hold its input to real time plus ``ingest_burst_s``."""
        if config.auto_gain is None:  # the start did not say: this server's default
            config = replace(config, auto_gain=self.config.auto_gain)
        self._admission(name, batch=batch)
        registry = self.registry
        if registry is not None:  # a connection worker: the name is claimed server-wide, at the front
            refused = await registry.claim(name, batch=batch)
            if refused is not None:
                raise AdmissionRefused(*refused)
        try:
            session = await self._new_session(config)
        except BaseException:
            if registry is not None:
                registry.release(name)
            raise
        try:
            self._admission(name, batch=batch)  # opening a worker session awaited: another one may have come in
        except AdmissionRefused:
            await session.close()
            if registry is not None:
                registry.release(name)
            raise
        live = LiveSession(name, session, self, source=source)
        live.batch = batch
        if paced and not batch:
            live.pacer = IngestPacer(self.config.ingest_burst_s)
            live.overrun = self.config.ingest_overrun
        self.sessions[name] = live
        if self.cluster is not None:
            owner = await self.cluster.claim(live)
            if owner is not None:
                del self.sessions[name]
                await session.close()
                raise AdmissionRefused(P.CLOSE_CONFLICT, f"session {name!r} already exists (on node {owner})")
        await self.release_held(live)
        sessions_log.info(
            "session %r started: %s, %d Hz x %d%s%s",
            name,
            source,
            config.sample_rate_hz,
            config.channels,
            ", enrolled" if config.enrol is not None else "",
            ", auto gain" if config.auto_gain else "",
        )
        return live

    async def release_held(self, live: LiveSession) -> None:
        """Subscribe the viewers held for a session that has just opened (view query ``wait``), before it is fed:
        wake them, then wait until each has joined (at most :data:`HELD_JOIN_S`). Called by whatever registers a
        session (:meth:`open_session`, text sessions) once it is registered and before its first block."""
        joining = self.holds.open(live)
        if joining:
            await asyncio.wait(joining, timeout=HELD_JOIN_S)

    async def _new_session(self, config: SessionConfig) -> SessionHandle:
        rig = self.head.rig if self.head else None
        if config.enrol is not None:  # adaptation is CPU work: keep the event loop serving others
            # One at a time: the adaptation holds the GIL for much of its ~0.6 s (60 s of speech), and each thread
            # adapting at once took another share of it from the loop: a streaming session's frames came up to 112 ms
            # late while three enrolments adapted together, beyond the browser viewer's 80 ms jitter buffer.
            async with self._enrolling:
                session = await asyncio.to_thread(Session, self.model, config=config, rig=rig, times=self.times)
            if self.pool is None:
                return LocalSession(session)
            # Adapted here, not in the worker: a worker serves its sessions one request at a time, and adapting there
            # froze every other session on it (with --workers 1, 1.6-1.9 s of frames late for 60 s of enrolment).
            return await self.pool.open(config, rig=rig, times=self.times, enrolled=session.model)
        if self.pool is not None:
            return await self.pool.open(config, rig=rig, times=self.times)
        return LocalSession(Session(self.model, config=config, rig=rig, times=self.times))

    async def run_source(
        self,
        name: str,
        source: AsyncIterator[np.ndarray],
        *,
        sample_rate_hz: int,
        channels: int = 1,
        label: str = "local",
    ) -> LiveSession:
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
        self.turn_deltas.flush()  # its frames waiting for the turn's end go before the close
        n_viewers = len(live.viewers)
        sessions_log.info(
            # computed: a text session stopped mid-answer had frames made that were never released to its viewers
            "session %r ended (%d %s): %d frames computed, %d viewer%s",
            live.name,
            code,
            reason,
            live.session.frames_out,
            n_viewers,
            "" if n_viewers == 1 else "s",
        )
        if self.sessions.get(live.name) is live:
            del self.sessions[live.name]
            if self.registry is not None:
                self.registry.release(live.name)
        live.ended.set()
        if self.cluster is not None:
            await self.cluster.release(live, code, reason)
        await live.session.close()  # a worker session that never flushed
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
        path = urllib.parse.urlsplit(_request_path(ws)).path
        client = _client_address(ws)
        self.clients.add(client)
        self._handled.add(ws)
        try:
            if path == "/ingest" and self.config.role == "edge":
                await self._forward_ingest(ws)
            elif path == "/ingest":
                await self._ingest(ws)
            elif path == "/view":
                await self._view(ws)
            elif path == "/text":
                from server.text_session import handle_text

                await handle_text(self, ws)
            else:
                raise ProtocolViolation(P.CLOSE_NOT_FOUND, "no WebSocket endpoint here (use /ingest or /view)")
        except ServerSideClose as exc:  # normal operation (the hand-off to a connection worker), said where it happens
            await self.close_ws(ws, exc.code, exc.reason)
        except ProtocolViolation as exc:
            self.incidents.client_error(exc.code, exc.reason, time.monotonic())
            await self.close_ws(ws, exc.code, exc.reason)
        except ConnectionClosed:
            pass
        except Exception as exc:  # noqa: BLE001 - connection boundary: a bug closes this connection only
            self.incidents.internal_error(path, exc, time.monotonic())
            await self.close_ws(ws, P.CLOSE_INTERNAL, "internal server error")  # never a traceback or path
        finally:
            self.clients.remove(client)
            self._handled.discard(ws)

    async def _forward_ingest(self, ws: ServerConnection) -> None:
        """An edge node relays an ingest to the least loaded computing node, both ways, close code
        and reason included; the client never knows."""
        from websockets.asyncio.client import ClientConnection, connect

        target = await self.cluster.compute_node() if self.cluster is not None else None
        if target is None:
            raise ProtocolViolation(P.CLOSE_TRY_LATER, "no computing node is available")
        url = target["url"].replace("http", "ws", 1) + "/ingest"
        try:
            upstream = await connect(
                url,
                compression=None,
                max_size=self.config.max_message_bytes,
                open_timeout=self.config.handshake_timeout_s,
            )
        except (OSError, TimeoutError, WebSocketException):
            raise ProtocolViolation(P.CLOSE_TRY_LATER, "the computing node cannot be reached") from None

        async def pump(src: ServerConnection | ClientConnection, dst: ServerConnection | ClientConnection) -> None:
            async for msg in src:
                await dst.send(msg)

        async with upstream:
            tasks = [asyncio.ensure_future(pump(ws, upstream)), asyncio.ensure_future(pump(upstream, ws))]
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            if upstream.close_code is not None and ws.close_code is None:
                await self.close_ws(ws, upstream.close_code, upstream.close_reason or "")
            elif ws.close_code is not None:
                await upstream.close()

    async def _ingest(self, ws: ServerConnection) -> None:
        """Drive one ingest connection through :class:`server.protocol.IngestProtocol`."""
        proto = SP.IngestProtocol(token=self.config.token, lag=self.config.lag)
        got_first = False
        try:
            first = await asyncio.wait_for(ws.recv(), self.config.start_timeout_s)
        except TimeoutError:
            actions = proto.start_timed_out(self.config.start_timeout_s)
        else:
            actions, got_first = proto.receive(first), True
        live: LiveSession | None = None
        try:
            live = await self._perform(ws, proto, actions, None)
            if got_first:
                _handled(ws)
            if live is None:
                return
            # Each message is awaited directly under one timeout (the idle limit), which a shutdown moves
            # to now (EndWake): under a flood of other connections' work every loop turn counts.
            loop = asyncio.get_running_loop()
            wake = EndWake(live.ended)
            fast = ws if isinstance(ws, FacecastConnection) else None
            if fast is not None:
                self._fast_feed(fast, proto, live)
            per_second = live.session.frame_bytes * live.session.config.sample_rate_hz  # bytes of one second
            share = 0.0  # seconds of audio handled since this task last let the loop run others
            try:
                idle_s = self.config.idle_timeout_s
                idle_from = loop.time()
                while proto.state is SP.State.STREAMING:
                    received = False
                    if live.ended.is_set():  # server shutting down: first, even if a message is waiting too
                        actions = proto.shutdown()
                    else:
                        try:
                            if fast is not None and fast.queued:
                                # A whole message is queued (a backlog): recv() returns it without
                                # waiting, so no idle timer (a Timeout and a timer handle per block).
                                msg = await ws.recv()
                            else:
                                async with wake.until(idle_from + idle_s):
                                    msg = await ws.recv()
                        except TimeoutError:
                            if live.ended.is_set():
                                actions = proto.shutdown()
                            elif fast is not None and fast.last_fed > idle_from:  # blocks came by the fast path
                                idle_from = fast.last_fed
                                continue
                            else:
                                actions = proto.idle_timed_out(idle_s)
                        except ConnectionClosed:
                            actions = proto.connection_lost()
                        else:
                            actions, received, idle_from = proto.receive(msg), True, loop.time()
                    await self._perform(ws, proto, actions, live)
                    if received:
                        _handled(ws)
                        if isinstance(msg, bytes):
                            share += len(msg) / per_second
                        if share >= FAIR_SLICE_S:
                            # A backlog (an overloaded server, a batch ingest): recv() of a queued message
                            # does not yield, so without this one connection's buffered blocks would all be
                            # processed in one loop turn, holding up timers, /health and other sessions.
                            share = 0.0
                            await asyncio.sleep(0)
            finally:
                wake.close()
                if fast is not None:
                    fast.sink = None
        finally:
            if live is not None:
                await self._end_session(live, *proto.viewer_close)

    def _fast_feed(self, ws: FacecastConnection, proto: SP.IngestProtocol, live: LiveSession) -> None:
        """Let the connection feed binary blocks to the session straight from its data callback
        (:class:`FacecastConnection`), skipping the message queue and this handler's wake-up, when
        nothing needs awaiting (:meth:`LiveSession.feed_now`)."""
        loop = asyncio.get_running_loop()
        per_second = live.session.frame_bytes * live.session.config.sample_rate_hz  # bytes of one second

        def sink(data: bytes) -> bool:
            if ws.turn_audio_s >= FAIR_SLICE_S:  # this callback's share is used: the handler takes the rest
                return False
            if not proto.feeds_binary() or not live.feed_now(data):
                return False
            ws.turn_audio_s += len(data) / per_second
            ws.last_fed = loop.time()
            return True

        ws.sink = sink

    async def _perform(
        self, ws: ServerConnection, proto: SP.IngestProtocol, actions: list[SP.Action], live: LiveSession | None
    ) -> LiveSession | None:
        """Carry out the protocol's actions in order (and those its answers add); returns the live
        session once one is open."""
        todo = collections.deque(actions)
        while todo:
            action = todo.popleft()
            if isinstance(action, SP.Send):
                await ws.send(P.dumps(action.message))
            elif isinstance(action, SP.Close):
                await self.close_ws(ws, action.code, action.reason)
            elif isinstance(action, SP.Feed):
                assert live is not None  # the protocol feeds, controls and finishes only an open session
                try:
                    await live.feed_bytes_fairly(action.data)
                except AudioFormatError as exc:
                    todo.extend(proto.audio_rejected(str(exc)))
                except IngestOverrun as exc:
                    todo.extend(proto.too_fast(str(exc)))
            elif isinstance(action, SP.Control):
                assert live is not None
                try:
                    todo.extend(proto.control_applied(await live.control(action.message)))
                except ControlError as exc:
                    todo.extend(proto.control_rejected(str(exc)))
            elif isinstance(action, SP.Finish):
                assert live is not None
                await live.finish()
                s = live.session
                todo.extend(proto.finished(s.frames_out, s.samples_out / s.rate_hz))
            elif isinstance(action, SP.Open):
                try:
                    live = await self.open_session(
                        action.name, action.config, source="ingest", batch=action.batch, paced=True
                    )
                except AdmissionRefused as exc:
                    todo.extend(proto.refused(exc.code, exc.reason))
                except AudioFormatError as exc:  # e.g. an enrolment recording the model rejects
                    todo.extend(proto.refused(P.CLOSE_INVALID_PAYLOAD, str(exc)))
                except ServerConfigError as exc:  # an enrolment that is not speech: a bad start, as a silent one
                    todo.extend(proto.refused(P.CLOSE_BAD_REQUEST, str(exc)))
                else:
                    todo.extend(proto.opened(describe.started(live)))
        return live

    async def _view(self, ws: ServerConnection) -> None:
        args = SP.query_args(_request_path(ws))
        req = SP.parse_view_query(  # the token first: nobody unauthorised is held
            args,
            token=self.config.token,
            has_head=self.head is not None,
            morph_head="morph" in self.view_kinds(),
        )
        wait_s = SP.view_wait_s(args, longest_s=self.config.max_view_wait_s)
        live = self.sessions.get(req.session)
        if live is None and self.cluster is not None:
            row = await self.cluster.lookup(req.session)
            if row is not None:
                return await self._view_remote(ws, req, row)
        if live is None and (not wait_s or self.stopping):
            raise ProtocolViolation(P.CLOSE_NOT_FOUND, f"no session {req.session!r}")
        if self.n_viewers >= self.config.max_viewers:
            raise ProtocolViolation(P.CLOSE_TRY_LATER, f"server is full ({self.config.max_viewers} viewers)")
        self.n_viewers += 1  # from here: a held viewer counts towards max_viewers too
        hold = None
        elsewhere = None
        try:
            if live is None:
                hold = self.holds.add(req.session)
                found = await self._held(ws, hold, wait_s)
                if isinstance(found, LiveSession):
                    await self._watch(ws, req, found, hold)
                elif found is not None:
                    elsewhere = found
            else:
                await self._watch(ws, req, live, None)
        finally:
            if hold is not None:
                self.holds.drop(hold)
            self.n_viewers -= 1
        if elsewhere is not None:  # opened on another node of the cluster while held here
            await self._view_remote(ws, req, elsewhere)

    async def _held(self, ws: ServerConnection, hold: Hold, wait_s: float) -> LiveSession | dict | None:
        """Hold a viewer until its session opens (:meth:`release_held` wakes it) or ``wait_s`` runs out (4004
        saying how long it waited). Returns the session, or in a cluster the registry row of one opened on
        another node (looked up every :data:`CLUSTER_HOLD_POLL_S`), or None when the viewer went away."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + wait_s
        closed = asyncio.ensure_future(ws.wait_closed())
        either: set[asyncio.Future[Any]] = {hold.opened, closed}
        try:
            while True:
                if hold.opened.done():
                    return hold.opened.result()  # raises what the hold was refused with (server stopping)
                if closed.done():
                    return None
                if loop.time() >= deadline:
                    raise ProtocolViolation(
                        P.CLOSE_NOT_FOUND, f"no session {hold.name!r} (waited {wait_s:g} s for it to start)"
                    )
                step = deadline - loop.time()
                if self.cluster is not None:
                    row = await self.cluster.lookup(hold.name)
                    if row is not None and not hold.opened.done():
                        return row
                    step = min(step, CLUSTER_HOLD_POLL_S)
                await asyncio.wait(either, timeout=step, return_when=asyncio.FIRST_COMPLETED)
        finally:
            closed.cancel()

    async def _watch(self, ws: ServerConnection, req: SP.ViewRequest, live: LiveSession, hold: Hold | None) -> None:
        """Serve one viewer of a session on this process until either ends (counted in n_viewers by the caller).
        hold: set for a viewer that was held for the session, told once the viewer is subscribed."""
        if self.config.viewer_socket_buffer_bytes is not None:
            sock = ws.transport.get_extra_info("socket")
            if sock is not None:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.config.viewer_socket_buffer_bytes)
        await ws.send(describe.view_description_text(live, req, self.head))
        # A text session's sentence now playing, from its first frame (docs/protocol.md section 3): none for a
        # held viewer (it joins as the session opens), so it gets no sentence twice.
        await live.send_sentence(ws, req.header_kind, req.header_encoding, req.audio)
        if self.sessions.get(live.name) is not live:  # ended while we were sending the description
            raise ProtocolViolation(P.CLOSE_NORMAL, "session ended")
        viewer = Viewer(ws, live, kind=req.header_kind, encoding=req.header_encoding, audio=req.audio, server=self)
        live.viewers.add(viewer)
        if hold is not None:
            hold.done_joining()
        sender = self.spawn(viewer.run())
        try:
            while True:
                reader = asyncio.ensure_future(ws.recv())
                done, _ = await asyncio.wait({reader, sender}, return_when=asyncio.FIRST_COMPLETED)
                if reader in done and reader.exception() is None:
                    # An expression control (the browser's picker) is answered; anything else closes.
                    try:
                        ctl = SP.parse_viewer_message(reader.result())
                    except ProtocolViolation:
                        viewer.closing = True
                        raise
                    try:
                        await ws.send(P.dumps({"type": "ack", "controls": await live.control(ctl)}))
                    except ControlError as exc:
                        await ws.send(P.dumps({"type": "rejected", "reason": str(exc)}))
                    continue
                break
            reader.cancel()
            failure = sender.exception() if sender in done else None
            if failure is not None and not isinstance(failure, ConnectionClosed):
                raise failure
        finally:
            sender.cancel()
            live.viewers.discard(viewer)

    async def _view_remote(self, ws: ServerConnection, req: SP.ViewRequest, row: dict) -> None:
        """A viewer of a session owned by another node: fed from that session's Redis channel."""
        cluster = self.cluster
        assert cluster is not None  # only a cluster node looks up remote sessions
        if self.n_viewers >= self.config.max_viewers:
            raise ProtocolViolation(P.CLOSE_TRY_LATER, f"server is full ({self.config.max_viewers} viewers)")
        feed = await cluster.feed(req.session, row, req.header_kind, req.header_encoding, req.audio)
        viewer = Viewer(ws, feed, kind=req.header_kind, encoding=req.header_encoding, audio=req.audio, server=self)
        join = None
        sender = None
        try:
            await ws.send(describe.view_description_text(feed, req, self.head))
            if feed.row.get("replay"):
                # A text session's sentence now playing, from the owner (as _view's send_sentence): then
                # what came since, straight to the socket; registered with no await after the last check,
                # so every later message reaches the viewer once.
                join = await cluster.replay(
                    feed, req.header_kind, req.header_encoding, req.audio, limit=self.config.viewer_queue
                )
                await cluster.answer(join)
                while (msg := join.next_message()) is not None:
                    await ws.send(msg)
                cluster.forget(feed, join)
                # Counted as the viewer's queue counts its drops (Viewer.offer).
                viewer.dropped += join.dropped
                feed.dropped += join.dropped
                self.dropped += join.dropped
            if feed.ended.is_set():  # ended while it joined (its viewers were closed): it has had every frame
                raise ProtocolViolation(*feed.end)
            feed.viewers.add(viewer)
            self.n_viewers += 1
            sender = self.spawn(viewer.run())
            reader = asyncio.ensure_future(ws.recv())
            done, _ = await asyncio.wait({reader, sender}, return_when=asyncio.FIRST_COMPLETED)
            if reader in done and reader.exception() is None:
                viewer.closing = True
                raise ProtocolViolation(P.CLOSE_POLICY, "viewers do not send messages")
            reader.cancel()
        finally:
            if sender is not None:
                sender.cancel()
                feed.viewers.discard(viewer)
                self.n_viewers -= 1
            if join is not None:
                cluster.forget(feed, join)
            await cluster.drop_feed_if_idle(feed)

    def _deliver_remote(self, feed: RemoteFeed, msg: bytes, kind: int, enc: int) -> None:
        """A message of a remote session from Redis -> this node's viewers of it that want it."""
        if kind == P.KIND_AUDIO:
            members = [v for v in feed.viewers if v.audio]
        else:
            members = [v for v in feed.viewers if v.kind == kind and v.encoding == enc]
        if members:
            deliver(members, msg, time.time())

    async def _end_feed(self, feed: RemoteFeed) -> None:
        code, reason = feed.end
        for v in list(feed.viewers):
            v.wake.set()
        await asyncio.sleep(0)
        await asyncio.gather(*(self._close_viewer_after_drain(v, code, reason) for v in list(feed.viewers)))

    # -- plain HTTP --------------------------------------------------------------------------------

    async def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        """Every request before any handshake: Host (DNS rebinding), then for WebSocket upgrades the
        Origin and the per-client connection limit, else plain HTTP with the token for private routes."""
        cfg = self.config
        headers = request.headers
        if not host_allowed(headers.get("Host"), bound_host=cfg.host, allowed=cfg.allowed_hosts):
            return self._refuse(HTTPStatus.FORBIDDEN, "Host not allowed")
        split = urllib.parse.urlsplit(request.path)
        path = split.path
        upgrade = headers.get("Upgrade", "").lower() == "websocket"
        if upgrade or path in ("/ingest", "/view", "/text"):
            if path not in ("/ingest", "/view", "/text"):
                return self._refuse(HTTPStatus.NOT_FOUND, "no WebSocket endpoint here (use /ingest, /view or /text)")
            if not origin_allowed(headers.get("Origin"), headers.get("Host"), cfg.allowed_origins):
                return self._refuse(HTTPStatus.FORBIDDEN, "Origin not allowed")
            client = _client_address(connection)
            if self.clients.full(client):
                return self._refuse(
                    HTTPStatus.TOO_MANY_REQUESTS,
                    f"too many connections from this client ({cfg.max_connections_per_client})",
                )
            if not self.connect_rate.allow(client, time.monotonic()):
                return self._refuse(
                    HTTPStatus.TOO_MANY_REQUESTS,
                    f"too many new connections from this client (over {cfg.connect_rate_per_s:g}/s)",
                )
            return None  # the WebSocket handshake proceeds (websockets answers 426 if it is not one)
        authorized = SP.token_ok(_request_token(split.query, headers.get("Authorization")), cfg.token)
        if path == "/sessions" and authorized:
            return _response(await self._sessions_reply_async())
        if self.shards is not None and (path == "/health" or (path == "/metrics" and authorized)):
            return _response(HttpReply.json(await (self._health_all() if path == "/health" else self._metrics_all())))
        return _response(self.http.handle(path, authorized=authorized))

    def _refuse(self, status: HTTPStatus, text: str) -> Response:
        self.incidents.client_error(status.value, text, time.monotonic())
        return _response(HttpReply.text(status, text + "\n"))

    def health(self) -> dict:
        """``status`` ok, or degraded while the cluster's Redis is away (``redis`` says why)."""
        out = {
            "status": "ok",
            "sessions": len(self.sessions),
            "viewers": self.n_viewers,
            "uptime_s": round(time.time() - self.started, 3),
        }
        if self.cluster is not None:
            out.update(self.cluster.health())
            if not self.cluster.up:
                out["status"] = "degraded"
        return out

    async def _health_all(self) -> dict:
        """/health of a front: its own, with the connection workers' sessions and viewers added."""
        out = self.health()
        for h in await self._ask_shards("health"):
            out["sessions"] += h["sessions"]
            out["viewers"] += h["viewers"]
        return out

    async def _metrics_all(self) -> dict:
        """/metrics of a front: counts summed over it and its connection workers; ``timings_ms`` are the
        front's own (its loop), each worker's under ``workers``."""
        out = self.metrics()
        closes = collections.Counter({int(k): v for k, v in out["closes"].items()})
        out["workers"] = []
        for m in await self._ask_shards("metrics"):
            for key in (
                "sessions",
                "viewers",
                "viewers_held",
                "dropped_messages",
                "viewers_closed_slow",
                "delta_batches",
                "delta_batch_frames",
            ):
                out[key] += m[key]
            closes.update({int(k): v for k, v in m["closes"].items()})
            out["session_list"] += m["session_list"]
            out["workers"].append(
                {
                    "sessions": m["sessions"],
                    "viewers": m["viewers"],
                    "timings_ms": m["timings_ms"],
                    "event_loop": m["event_loop"],
                }
            )
        out["closes"] = {str(k): v for k, v in sorted(closes.items())}
        out["session_list"].sort(key=lambda r: r["name"])
        return out

    async def _ask_shards(self, what: str) -> list[Any]:
        return [] if self.shards is None else await self.shards.ask(what)

    def view_kinds(self) -> list[str]:
        """The frame kinds a viewer may ask this node for, best first (docs/protocol.md section 3): ``morph`` for a
        head driven by its own targets, ``deltas`` for any head, ``params`` always."""
        if self.head is None:
            return ["params"]
        return (["morph"] if self.head.kind == "morph" else []) + ["deltas", "params"]

    def _sessions_reply(self, rows: list[dict] | None = None, **extra: str) -> HttpReply:
        # view_kinds: a page asks for the best kind this node offers at once (the browser asked for morph first and
        # was refused, 4400, by every server whose head has no targets of its own)
        rows = self.session_list() if rows is None else rows
        return HttpReply.json({"sessions": rows, **extra, "view_kinds": self.view_kinds()})

    async def _sessions_reply_async(self) -> HttpReply:
        """/sessions: cluster-wide from the registry when there is one (this node's own otherwise)."""
        if self.cluster is not None:
            rows = await self.cluster.list_sessions()
            if rows is not None:
                local = {r["name"] for r in rows}
                rows += [dict(r, node=self.cluster.node) for r in self.session_list() if r["name"] not in local]
                return self._sessions_reply(sorted(rows, key=lambda r: r["name"]), scope="cluster")
            return self._sessions_reply(scope="node (Redis away)")
        if self.shards is not None:
            rows = self.session_list() + [r for rows in await self._ask_shards("rows") for r in rows]
            return self._sessions_reply(sorted(rows, key=lambda r: r["name"]))
        return self._sessions_reply()

    def session_list(self) -> list[dict]:
        return [live.describe() for live in self.sessions.values()]

    def metrics(self) -> dict:
        """Sessions, viewers, per-stage timings (ms), dropped frames, closes by code."""
        return {
            "sessions": len(self.sessions),
            "viewers": self.n_viewers,
            "viewers_held": len(self.holds),  # of those, held for a session not yet started (view query wait)
            "dropped_messages": self.dropped,
            "viewers_closed_slow": self.closed_slow,
            # vertex deltas by loop turn (server.live.TurnDeltas): turns that computed deltas, and the
            # frames they held (frames / batches: how many frames a turn's batch shares)
            "delta_batches": self.turn_deltas.batches,
            "delta_batch_frames": self.turn_deltas.frames,
            "closes": {str(k): v for k, v in sorted(self.closes.items())},
            "timings_ms": self.times.summary(),
            "session_list": self.session_list(),
            "uptime_s": round(time.time() - self.started, 3),
            "event_loop": running_loop_name(),
        }


class FacecastConnection(ServerConnection):
    """websockets' server connection with three additions.

    * A fast path for ingest blocks: while ``sink`` is set (by the ingest handler of a streaming
      session), a complete binary message is offered to it straight from ``process_event`` (the
      override point websockets documents), in the data callback, instead of going through the
      message queue to a ``recv()`` and a wake-up of the handler task: about half of a block's
      receive cost. Order is kept: the sink is used only while no message is queued or being handled
      by the handler (``queued``, which the handler decrements as it finishes each one; see
      :func:`_handled`); a message the sink declines goes the usual way.
    * A per-turn budget: the sink takes at most ``FAIR_SLICE_S`` of audio per data callback (one
      read of the socket, this connection's share of a loop turn); the rest of a large read (a
      backlog, when the server is overloaded) goes to the queue, and the handler yields to the loop
      after each such share, so timers, /health and other connections run between shares.
    * ``router`` (the front of connection workers, server.shards): each new connection is offered to
      the workers before a byte of it is read."""

    router: ConnectionWorkers | None = None

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.sink: Callable[[bytes], bool] | None = None
        self.queued = 0  # complete data messages passed to the queue and not yet handled
        self.last_fed = 0.0  # loop time of the last block the sink took (the idle timeout counts it)
        self.turn_audio_s = 0.0  # audio the sink took in this data callback (at most FAIR_SLICE_S: see sink)

    def data_received(self, data: bytes) -> None:
        # One data callback is this connection's share of a loop turn: the sink takes at most
        # FAIR_SLICE_S of audio of it; the rest queues for the handler, which yields between shares.
        self.turn_audio_s = 0.0
        super().data_received(data)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        router = self.router
        if router is not None and not router.stopping:
            router.route(self)

    def process_event(self, event: Event) -> None:
        if isinstance(event, Frame) and event.opcode in DATA_OPCODES:
            sink = self.sink
            if sink is not None and not self.queued and event.opcode is Opcode.BINARY and event.fin:
                try:
                    if sink(bytes(event.data)):
                        return
                except Exception:  # noqa: BLE001 - a bug: the usual path meets it again and closes with 1011
                    self.sink = None
            if event.fin:
                self.queued += 1
        super().process_event(event)


def _handled(ws: ServerConnection) -> None:
    """The handler is done with a message it received (the fast path may go on, see FacecastConnection)."""
    if isinstance(ws, FacecastConnection):
        ws.queued -= 1


def _protocol_options(cfg: ServerConfig) -> dict[str, Any]:
    """Options of websockets' ``ServerProtocol`` that differ from its defaults (``serve`` and adopt)."""
    return {"max_size": cfg.max_message_bytes}


def _connection_options(cfg: ServerConfig) -> dict[str, Any]:
    """Options of websockets' ``ServerConnection`` that differ from its defaults (``serve`` and adopt)."""
    return {"close_timeout": cfg.close_timeout_s}


def _connection_class(shards: ConnectionWorkers | None) -> type[FacecastConnection]:
    """The connection class of one server (with its router, when it is the front of connection workers)."""
    if shards is None:
        return FacecastConnection

    class RoutedConnection(FacecastConnection):
        router = shards

    return RoutedConnection


def _request_path(ws: ServerConnection) -> str:
    """The path and query of a connection's opening request."""
    assert ws.request is not None  # set by the opening handshake, before any handler runs
    return ws.request.path


def _client_address(connection: ServerConnection) -> str:
    """The peer's IP address (the per-client limit's key)."""
    peer = connection.remote_address
    return str(peer[0]) if peer else "?"


def _request_token(query: str, authorization: str | None) -> str | None:
    """The token of a plain HTTP request: ``Authorization: Bearer T`` or ``?token=T``."""
    if authorization is not None and authorization.lower().startswith("bearer "):
        return authorization[7:].strip()
    try:
        return dict(urllib.parse.parse_qsl(query, max_num_fields=32)).get("token")
    except ValueError:
        return None


def _response(reply: HttpReply) -> Response:
    headers = Headers(
        [
            ("Content-Type", reply.content_type),
            ("Content-Length", str(len(reply.body))),
            ("Cache-Control", "no-store"),
            ("Connection", "close"),
        ]
    )
    return Response(reply.status.value, reply.status.phrase, headers, reply.body)


async def run_server(server: FacecastServer, *, ready: asyncio.Future | None = None, extra: list | None = None) -> None:
    """Run until SIGINT/SIGTERM (or ``extra`` coroutines all finish), then shut down gracefully.
    (BLAS is on one thread while the server serves: :meth:`FacecastServer.start`.)"""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await server.start()
    freeze_heap()  # this process is the server's: the startup heap needs no more collecting
    if ready is not None and not ready.done():
        ready.set_result(server)
    try:
        waiters = [asyncio.ensure_future(stop.wait())]
        if extra:
            work = asyncio.ensure_future(asyncio.gather(*extra))
            waiters.append(work)
        await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
        for w in waiters:
            failure = w.exception() if w.done() and w is not waiters[0] else None
            if failure is not None:
                raise failure
    finally:
        for w in waiters:
            w.cancel()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        await server.stop()
