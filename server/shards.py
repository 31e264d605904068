"""Connection workers: whole sessions, with their ingest and viewer sockets, in other processes
(``ServerConfig.workers = N`` with ``worker_mode = "connections"``).

Theory of operation
-------------------
A compute worker (:mod:`server.workers`) moves a session's model off the event loop, but the
receive path (a wake-up and a WebSocket parse per 20 ms block per session) and the viewers' socket
writes stay on the one loop, and every block crosses a pipe twice. Here a *worker* is a whole
:class:`server.app.FacecastServer` (the same code as a single-process server, without a listener)
in its own process, and the *front* (the process that listens) hands it accepted TCP connections:

* The front's listener is python-websockets' as usual. When a connection is made the front stops
  reading it, peeks (``MSG_PEEK``: nothing is consumed) at the request line and decides: ``/ingest``
  goes to the least loaded worker, ``/view?session=X`` to the worker that owns session X; anything
  else (plain HTTP, ``/text``, a viewer of a session the front runs itself or of no session, a request
  line that does not come) stays in the front. A connection handed over is sent with ``SCM_RIGHTS``
  (``socket.send_fds``) over the worker's control socket; the front then drops its own descriptor.
  The worker adopts it (``FacecastServer.adopt``: ``loop.connect_accepted_socket`` with a connection
  built as its websockets server builds an accepted one) and runs the whole handshake (Host, Origin,
  token checks) and the connection there, so a session's receive, model, encoding and fan-out all
  happen in the process that owns it.
* Session names stay unique server-wide: a worker opening a session *claims* the name from the front
  (the front runs the one admission check, ``FacecastServer._admission``, over its own sessions and
  every worker's) and releases it when the session ends. The front routes viewers by that registry.
* ``/health``, ``/metrics`` and ``/sessions`` are answered by the front from its own state and each
  worker's, asked over the control socket.

A frame is computed and encoded by the same code as in a single process, so frames are identical.
Per-client connection limits and ``max_viewers`` apply per process (each worker keeps its own
counters); ``max_sessions`` and ``max_batch_sessions`` are server-wide.

If a worker dies, the connections it owned die with it (clients see 1006, abnormal closure): the
frames of its sessions not yet sent are lost and those sessions end. The front logs it, frees the
session names (a client can reconnect under the same name) and starts a replacement worker.
Workers end when the front tells them to (their sessions are flushed as in a single process'
shutdown) or when the front's end of the control socket closes.

Control messages are JSON, one per ``SOCK_SEQPACKET`` packet: ``{"op": ...}``, with ``"id"`` when
an answer (``{"op": "answer", "id", "data"}``) is expected.
"""

from __future__ import annotations

import asyncio
import contextlib
import copyreg
import io
import itertools
import json
import logging
import multiprocessing as mp
import os
import pickle
import signal
import socket
import types
import urllib.parse
from collections.abc import Awaitable, Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from server.errors import ServerError
from server.eventloop import run as run_on_loop
from server.workers import model_file_bytes
from wire import protocol as P

if TYPE_CHECKING:
    from websockets.asyncio.server import ServerConnection

    from server.app import FacecastServer
    from server.config import ServerConfig

log = logging.getLogger("facecast.shards")

MAX_PACKET = 1 << 20  # largest control message read (a worker's session rows; ~0.4 KB per session)
MAX_REQUEST_LINE = 8192  # longer request lines stay in the front, whose websockets answers them
ASK_TIMEOUT_S = 2.0  # a worker that does not answer /health, /metrics or /sessions in time is left out


class Link:
    """One end of a front <-> worker control socket (AF_UNIX SOCK_SEQPACKET): JSON messages, requests
    matched to answers by id, file descriptors passed with SCM_RIGHTS.

    ``handler(msg, fds)`` is awaited for every message that is not an answer; if the message has an
    ``"id"`` its return value is sent back as the answer. ``on_lost`` runs once when the peer is gone."""

    def __init__(
        self,
        sock: socket.socket,
        handler: Callable[[dict, list[int]], Awaitable[Any]],
        on_lost: Callable[[], None],
    ) -> None:
        sock.setblocking(False)
        self.sock = sock
        self.handler = handler
        self.on_lost = on_lost
        self.pending: dict[int, asyncio.Future] = {}
        self._ids = itertools.count(1)
        self._tasks: set[asyncio.Task] = set()
        self.lost = False

    def start(self) -> None:
        asyncio.get_running_loop().add_reader(self.sock.fileno(), self._readable)

    def send(self, msg: dict, fds: list[int] | None = None) -> None:
        """Send one message (and descriptors). ServerError if the peer is gone or not reading (its
        socket buffer full): the caller's one connection or request fails, nothing else."""
        if self.lost:
            raise ServerError("worker link lost")
        data = json.dumps(msg, separators=(",", ":")).encode()
        try:
            if fds:
                socket.send_fds(self.sock, [data], fds)
            else:
                self.sock.send(data)
        except BlockingIOError:
            raise ServerError("worker not reading its control socket") from None
        except OSError as exc:
            self._lose()
            raise ServerError(f"worker link lost: {exc}") from None

    async def request(self, msg: dict, timeout: float | None = None) -> Any:
        """Send a message expecting an answer; its ``data`` (ServerError if the link is lost, TimeoutError)."""
        k = next(self._ids)
        fut = asyncio.get_running_loop().create_future()
        self.pending[k] = fut
        try:
            self.send({**msg, "id": k})
            async with asyncio.timeout(timeout):
                return await fut
        finally:
            self.pending.pop(k, None)

    def close(self) -> None:
        if not self.lost:
            self.lost = True
            with contextlib.suppress(ValueError, OSError):
                asyncio.get_running_loop().remove_reader(self.sock.fileno())
        self.sock.close()

    def _readable(self) -> None:
        while not self.lost:
            try:
                data, fds, _flags, _addr = socket.recv_fds(self.sock, MAX_PACKET, 4)
            except BlockingIOError:
                return
            except OSError:
                data, fds = b"", []
            if not data:
                self._lose()
                return
            msg = json.loads(data)
            if msg.get("op") == "answer":
                fut = self.pending.get(msg["id"])
                if fut is not None and not fut.done():
                    fut.set_result(msg.get("data"))
                continue
            task = asyncio.get_running_loop().create_task(self._serve(msg, fds))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)

    async def _serve(self, msg: dict, fds: list[int]) -> None:
        result = await self.handler(msg, fds)
        if "id" in msg and not self.lost:
            with contextlib.suppress(ServerError):
                self.send({"op": "answer", "id": msg["id"], "data": result})

    def _lose(self) -> None:
        if self.lost:
            return
        self.lost = True
        with contextlib.suppress(ValueError, OSError):
            asyncio.get_running_loop().remove_reader(self.sock.fileno())
        for fut in self.pending.values():
            if not fut.done():
                fut.set_exception(ServerError("worker link lost"))
        self.on_lost()


def _dump_head(head: Any) -> bytes:
    """The head as pickle bytes for the workers (a process boundary, never a file). Rigs keep their
    named bases in read-only ``MappingProxyType`` views, which pickle cannot take: this pickler sends
    them as dicts and rebuilds the views (its own dispatch table: nothing global changes)."""
    buf = io.BytesIO()
    pickler = pickle.Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL)
    pickler.dispatch_table = {**copyreg.dispatch_table, types.MappingProxyType: _reduce_mappingproxy}
    pickler.dump(head)
    return buf.getvalue()


def _reduce_mappingproxy(m: types.MappingProxyType) -> tuple:
    return _mappingproxy, (dict(m),)


def _mappingproxy(d: dict) -> types.MappingProxyType:
    return types.MappingProxyType(d)


# -- the front ---------------------------------------------------------------------------------------


class _Shard:
    """The front's view of one worker: its process, control link and the sessions it owns."""

    def __init__(self, slot: int, proc: Any, link: Link) -> None:
        self.slot = slot
        self.proc = proc
        self.link = link
        self.names: set[str] = set()
        self.batch: set[str] = set()
        self.routed = 0  # ingests handed to it (ties between equally loaded workers go round-robin)
        self.ready: asyncio.Future = asyncio.get_running_loop().create_future()


class ConnectionWorkers:
    """The front's side: N worker processes, the session-name registry, and the routing of accepted
    connections. ``await start()``, then :meth:`route` each new connection; ``await stop()``."""

    def __init__(self, server: FacecastServer, n: int) -> None:
        if not 1 <= n <= 64:
            raise ServerError(f"workers must be in 1..64, got {n}")
        self.server = server
        self.n = n
        self.shards: list[_Shard] = []
        self.owner: dict[str, _Shard] = {}
        self.stopping = False
        self._spawn_args: tuple = ()
        self._tasks: set[asyncio.Task] = set()

    # lifecycle

    async def start(self) -> None:
        srv = self.server
        # The head goes pickled once, as the compute workers' rig does (server.workers): the same
        # bytes to each worker; the model as its file bytes.
        head = None if srv.head is None else _dump_head(srv.head)
        self._spawn_args = (model_file_bytes(srv.model), head, srv.config)
        self.shards = [self._spawn(i) for i in range(self.n)]
        await asyncio.gather(*(s.ready for s in self.shards))

    def _spawn(self, slot: int) -> _Shard:
        ctx = mp.get_context("spawn")  # no fork of a process with a running loop and threads
        front_end, worker_end = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        for s in (front_end, worker_end):  # room for a few hundred session rows per answer
            with contextlib.suppress(OSError):
                s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, MAX_PACKET)
        proc = ctx.Process(target=_worker_main, args=(worker_end, *self._spawn_args), daemon=True)
        proc.start()
        worker_end.close()
        shard: _Shard
        link = Link(front_end, lambda msg, fds: self._on_message(shard, msg, fds), lambda: self._on_lost(shard))
        shard = _Shard(slot, proc, link)
        link.start()
        return shard

    async def stop(self) -> None:
        """Tell every worker to shut down (each ends its sessions as a single server does), wait for
        them (at most close_timeout_s + 5 s), then kill what is left."""
        self.stopping = True
        for s in self.shards:
            with contextlib.suppress(ServerError):
                s.link.send({"op": "stop"})
        loop = asyncio.get_running_loop()
        wait_s = self.server.config.close_timeout_s + 5
        await asyncio.gather(*(loop.run_in_executor(None, s.proc.join, wait_s) for s in self.shards))
        for s in self.shards:
            if s.proc.is_alive():
                log.warning("connection worker %d did not stop in %.0f s: killed", s.slot, wait_s)
                s.proc.kill()
            s.link.close()
        self.shards = []
        self.owner.clear()

    def _on_lost(self, shard: _Shard) -> None:
        if not shard.ready.done():
            shard.ready.set_exception(ServerError(f"connection worker {shard.slot} exited while starting"))
        for name in shard.names:
            if self.owner.get(name) is shard:
                del self.owner[name]
        lost = sorted(shard.names)
        shard.names.clear()
        shard.batch.clear()
        if self.stopping or shard not in self.shards:
            return
        if shard.proc.is_alive():  # its link broke but it runs on: it cannot be reached, so it goes
            shard.proc.kill()
        shard.proc.join(0.5)
        log.error(
            "connection worker %d exited (code %s): its %d sessions ended (%s); starting a new one",
            shard.slot,
            shard.proc.exitcode,
            len(lost),
            ", ".join(lost[:10]) + (" ..." if len(lost) > 10 else ""),
        )
        shard.link.close()
        new = self._spawn(shard.slot)
        self.shards[self.shards.index(shard)] = new
        task = asyncio.get_running_loop().create_task(self._await_ready(new))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _await_ready(self, shard: _Shard) -> None:
        with contextlib.suppress(ServerError):
            await shard.ready

    # registry

    def owns(self, name: str) -> bool:
        return name in self.owner

    def session_count(self) -> int:
        return len(self.owner)

    def batch_count(self) -> int:
        return sum(len(s.batch) for s in self.shards)

    async def _on_message(self, shard: _Shard, msg: dict, fds: list[int]) -> Any:
        for fd in fds:  # workers pass no descriptors to the front
            os.close(fd)
        op = msg.get("op")
        if op == "ready":
            if not shard.ready.done():
                shard.ready.set_result(None)
            return None
        if op == "claim":
            name, batch = str(msg["name"]), bool(msg.get("batch"))
            refused = self.server.admission_refusal(name, batch=batch)
            if refused is not None:
                return list(refused)
            self.owner[name] = shard
            # Viewers held here for it (view query wait) cannot follow a session into the worker: told to
            # connect again, they are routed there (and held there until it opens, if they come before). Normal
            # operation: one INFO line, not a client error per viewer (it was "closed a client connection: 4004").
            reason = f"session {name!r} started in a worker: connect again"
            n_held = self.server.holds.refuse(name, P.CLOSE_NOT_FOUND, reason)
            if n_held:
                log.info(
                    "session %r opened in connection worker %d: %d viewer(s) held for it told to connect again "
                    "(4004), to be handed to that worker",
                    name,
                    shard.slot,
                    n_held,
                )
            shard.names.add(name)
            if batch:
                shard.batch.add(name)
            return None
        if op == "release":
            name = str(msg["name"])
            if self.owner.get(name) is shard:
                del self.owner[name]
            shard.names.discard(name)
            shard.batch.discard(name)
            return None
        log.warning("connection worker %d sent an unknown message %r", shard.slot, op)
        return None

    async def ask(self, what: str) -> list[Any]:
        """Every ready worker's answer to ``what`` (health, metrics, rows); one that does not answer
        within ASK_TIMEOUT_S is left out."""
        live = [s for s in self.shards if s.ready.done() and not s.ready.exception() and not s.link.lost]

        async def one(s: _Shard) -> Any:
            try:
                return await s.link.request({"op": "ask", "what": what}, timeout=ASK_TIMEOUT_S)
            except (ServerError, TimeoutError):
                return None

        return [a for a in await asyncio.gather(*(one(s) for s in live)) if a is not None]

    # routing

    def target(self, request_line: bytes) -> _Shard | None:
        """The worker a connection goes to, from its request line (None: the front keeps it)."""
        parts = request_line.split(b" ")
        if len(parts) != 3 or parts[0] != b"GET":
            return None
        split = urllib.parse.urlsplit(parts[1].decode("latin-1"))
        ready = [s for s in self.shards if s.ready.done() and not s.ready.exception() and not s.link.lost]
        if not ready:
            return None
        if split.path == "/ingest":
            shard = min(ready, key=lambda s: (len(s.names), s.routed))
            shard.routed += 1
            return shard
        if split.path == "/view":
            try:
                args = dict(urllib.parse.parse_qsl(split.query, max_num_fields=32))
            except ValueError:
                return None  # the front answers it (the same refusal a worker would give)
            return self.owner.get(args.get("session", ""))
        return None

    def route(self, connection: ServerConnection) -> None:
        """A new connection (the front's websockets has not read from it): hand it to a worker, or
        give it back to the front's websockets."""
        transport = connection.transport
        transport.pause_reading()
        task = asyncio.get_running_loop().create_task(self._route(connection))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _route(self, connection: ServerConnection) -> None:
        transport = connection.transport
        raw = transport.get_extra_info("socket")
        if raw is None or transport.is_closing():
            return
        sock = socket.socket(fileno=os.dup(raw.fileno()))  # our own descriptor: peek, then pass it on
        sock.setblocking(False)
        try:
            line = await _request_line(sock, self.server.config.handshake_timeout_s)
            shard = None if line is None or self.stopping else self.target(line)
            if shard is not None:
                try:
                    shard.link.send({"op": "conn"}, [sock.fileno()])
                except ServerError as exc:
                    log.warning("connection worker %d: cannot hand over a connection (%s)", shard.slot, exc)
                else:
                    # Closes this process's descriptor only (no shutdown): the worker holds the connection.
                    transport.abort()
                    return
        finally:
            sock.close()
        transport.resume_reading()


async def _request_line(sock: socket.socket, timeout: float) -> bytes | None:
    """The request line of a new connection, peeked (not consumed); None if it does not come whole
    within ``timeout`` s and MAX_REQUEST_LINE bytes, or the peer hangs up."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    poll_s = 0.001
    while True:
        try:
            data = sock.recv(MAX_REQUEST_LINE, socket.MSG_PEEK)
        except BlockingIOError:
            data = None
        except OSError:
            return None
        if data == b"":
            return None
        if data is not None:
            end = data.find(b"\r\n")
            if end >= 0:
                return data[:end]
            if len(data) >= MAX_REQUEST_LINE:
                return None
        remaining = deadline - loop.time()
        if remaining <= 0:
            return None
        if data is None:  # nothing yet: wait until readable
            ready: asyncio.Future[None] = loop.create_future()
            loop.add_reader(sock.fileno(), _set_once, ready)
            try:
                async with asyncio.timeout(remaining):
                    await ready
            except TimeoutError:
                return None
            finally:
                loop.remove_reader(sock.fileno())
        else:  # part of a line: readable stays true until it is consumed, so poll, backing off
            # (a client trickling its request line costs the front a few wake-ups a second, not a busy loop)
            await asyncio.sleep(min(poll_s, remaining))
            poll_s = min(2 * poll_s, 0.1)


def _set_once(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


# -- a worker ----------------------------------------------------------------------------------------


class FrontRegistry:
    """A worker's side of the name registry: claims and releases session names at the front."""

    def __init__(self, link: Link) -> None:
        self.link = link

    async def claim(self, name: str, *, batch: bool) -> tuple[int, str] | None:
        """None if the name is now this worker's; else the (close code, reason) to refuse with (1013
        when the front does not answer within ASK_TIMEOUT_S or is gone)."""
        try:
            refused = await self.link.request({"op": "claim", "name": name, "batch": batch}, timeout=ASK_TIMEOUT_S)
        except (ServerError, TimeoutError):
            return P.CLOSE_TRY_LATER, "the server cannot register a session now"
        return None if refused is None else (int(refused[0]), str(refused[1]))

    def release(self, name: str) -> None:
        with contextlib.suppress(ServerError):
            self.link.send({"op": "release", "name": name})


def _worker_main(sock: socket.socket, model_bytes: bytes, head_bytes: bytes | None, config: ServerConfig) -> None:
    """A connection worker's process: a FacecastServer without a listener, fed connections by the front."""
    from threadpoolctl import threadpool_limits

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the front decides
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    logging.getLogger("websockets").setLevel(logging.WARNING)
    with threadpool_limits(1):
        run_on_loop(_worker(sock, model_bytes, head_bytes, config), config.event_loop)


async def _worker(sock: socket.socket, model_bytes: bytes, head_bytes: bytes | None, config: ServerConfig) -> None:
    from realtime_core.mapping import decode_speech_model
    from server.app import FacecastServer
    from server.timing import freeze_heap

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    loop.add_signal_handler(signal.SIGTERM, stop.set)
    model = decode_speech_model(model_bytes)
    head = None if head_bytes is None else pickle.loads(head_bytes)
    server = FacecastServer(model, head=head, config=replace(config, workers=0, worker_mode="compute"))

    async def handle(msg: dict, fds: list[int]) -> Any:
        op = msg.get("op")
        if op == "conn":
            for fd in fds:
                conn = socket.socket(fileno=fd)
                try:
                    await server.adopt(conn)
                except OSError as exc:  # the client hung up while it was handed over: nothing to serve
                    log.info("a connection handed over was already gone (%s)", exc)
                    conn.close()
            return None
        for fd in fds:
            os.close(fd)
        if op == "stop":
            stop.set()
        elif op == "ask":
            what = msg.get("what")
            if what == "health":
                return {"sessions": len(server.sessions), "viewers": server.n_viewers}
            if what == "metrics":
                return server.metrics()
            if what == "rows":
                return server.session_list()
        return None

    link = Link(sock, handle, stop.set)
    server.registry = FrontRegistry(link)
    await server.start(listen=False)
    freeze_heap()
    link.start()
    link.send({"op": "ready"})
    try:
        await stop.wait()
    finally:
        await server.stop()
        link.close()
