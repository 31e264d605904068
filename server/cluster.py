"""Scale-out over Redis: a cluster-wide session registry and per-session frame channels.

Theory of operation
-------------------
Several facecast processes (on one machine or many) share one Redis (``ServerConfig.redis_url``).
Every node can own sessions (the node an ingest lands on computes it) and serve viewers of any
session:

* **Registry.** A node that opens a session claims ``facecast:session:NAME`` with ``SET NX`` (so
  a name is unique cluster-wide; a taken name answers 4009 naming the owner's node) holding the
  session's row (its facts for viewer descriptions and its ``/sessions`` row, plus the owner's node
  id and URL), with a TTL of ``3 x heartbeat``. A heartbeat task refreshes the rows and the node's
  own key ``facecast:node:ID`` every ``heartbeat_s``; a node that dies drops out within the TTL.
  ``/sessions`` lists every node's sessions from Redis. A node with viewers of another node's session
  keeps their number in ``facecast:viewers:NAME:ID`` (TTL); the owner adds those to its own viewers in
  the row, so every node lists a session with all its viewers.
* **Frames.** The owner publishes each binary message it sends its own viewers (exactly those
  bytes: header with the owner's send time, payload) on the Redis pub/sub channel
  ``facecast:frames:NAME``, for each (kind, encoding) some node wants, the audio relay included; at
  the end it publishes an end marker carrying the close code and reason (and, just before, leaves the
  same in ``facecast:ended:NAME`` for :data:`ENDED_KEEP_MS`: a viewer whose node subscribed only after
  the marker went out reads it there and closes with it). Another node's viewers of
  that session attach to a :class:`RemoteFeed` (one per session per node, one subscription for
  all its viewers) that hands the messages to them through the same fan-out as local sessions.
* **Wants.** A node with viewers of a remote session sets ``facecast:want:NAME:KIND:ENC`` (TTL,
  refreshed by the heartbeat) and publishes it on the owner's control channel so the owner starts
  publishing that kind at once; the owner re-reads the wants every heartbeat. So a kind nobody
  outside the owner watches (vertex deltas, say) is never encoded for Redis.
* **Late text viewers.** A viewer joining a text session on another node mid-sentence gets what a
  viewer joining on the owner gets (the sentence so far, then live): its node asks the owner
  (:meth:`Cluster.replay`), which answers on the asking node's control channel in order with the frames
  (:class:`ReplayJoin`).
* **Roles.** ``role = "both"`` (default) computes the sessions whose ingest lands on it and serves
  viewers; ``"edge"`` computes nothing: an ingest landing on it is forwarded (a WebSocket relay,
  both ways, close code included) to the least loaded computing node; ``"compute"`` is a hint for
  the proxy in front (docs/deploy.md) and otherwise acts as ``both``.
* **Failure.** A Redis error never reaches a session: publishing goes through a bounded queue
  drained by one task (messages dropped and counted while Redis is away), the heartbeat retries
  and re-registers every local session when Redis returns, and ``/health`` says
  ``"redis": "down: ..."`` (status ``degraded``) meanwhile. Remote feeds resubscribe when Redis
  returns; their viewers stay connected. A node started with a wrong Redis address says so in one
  line and does not start. A node that dies sends no end marker: the other nodes see its sessions'
  rows expire and close their viewers of them with 1001 "session lost" (:meth:`Cluster._end_lost_feeds`).

Publishing costs one socket write per message: a second, write-only connection to Redis with
replies switched off (``CLIENT REPLY OFF``) takes the PUBLISH commands straight from the fan-out, in
the same turn of the loop as the local viewers' writes. Through redis-py's pipeline each frame cost
a client object, a task switch and a round trip (~0.1 ms of loop CPU, and a frame waited for the
previous batch's replies); that path remains the fallback (TLS or Unix-socket URLs, reconnecting).

Pub/sub rather than Streams: measured with ``benchmarks/server_redis_transport.py`` (see
docs/deploy.md); pub/sub delivers with lower latency and less Redis CPU, stores nothing, and a live
viewer has no use for frames older than its reconnection (Streams' replay).
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import logging
import os
import time
import urllib.parse
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any

from server.errors import ServerConfigError, ServerError
from wire import protocol as P

if TYPE_CHECKING:
    import redis.asyncio as aioredis
    from redis.asyncio.client import PubSub

    from server.live import LiveSession
    from server.protocol import ViewRequest

log = logging.getLogger("facecast.cluster")

PREFIX = "facecast"
END_MARK = b"\x00END"  # first bytes of the end marker: never a binary frame (those start with version 1)
# A text session's sentence replayed to one joining viewer on another node (see Cluster.replay): each
# message as REPLAY_MARK + request id + the message, then REPLAY_DONE + request id.
REPLAY_MARK = b"\x00RPL"
REPLAY_DONE = b"\x00RPD"
REQUEST_ID_BYTES = 16  # a request id: 16 hex characters
SUBSCRIBE_WAIT_S = 2.0  # how long a replay request waits for Redis to confirm the feed's subscription
ANSWER_WAIT_S = 2.0  # how long a joining viewer waits for the owner's replay before joining without it
PUBLISH_QUEUE = 4096  # messages waiting for Redis before the oldest is dropped
ENDED_KEEP_MS = 10_000  # how long a session's end record outlives it: longer than a viewer's join takes
# The close of far viewers whose session's node stopped without ending it (its row expired).
LOST = (P.CLOSE_GOING_AWAY, "session lost: its node stopped")


REFRESH_ROW = """
local cur = redis.call('GET', KEYS[1])
if cur then
  local ok, row = pcall(cjson.decode, cur)
  if ok and type(row) == 'table' and type(row.node) == 'string' and row.node ~= ARGV[2] then
    return row.node
  end
end
redis.call('SET', KEYS[1], ARGV[1], 'PX', ARGV[3])
return false
"""
"""A heartbeat's refresh of one local session's row (KEYS[1]; ARGV: the row, this node, the TTL in ms), in one step
in Redis: written unless the row names another node, whose name it returns (a session of that name opened there
while this one was unregistered: Redis away, or restarted empty). Claims are SET NX (:meth:`Cluster.claim`)."""


def check_reachable(url: str, timeout_s: float = 2.0) -> None:
    """Raise ServerError ``cannot reach Redis at URL: REASON`` unless a Redis at ``url`` answers a PING within
    ``timeout_s``. ``facecast serve`` asks before it loads its model and head (seconds): a wrong address was said
    only once the server started, 13.8 s after the command (``Cluster.start`` still asks, for an embedder)."""
    import redis
    from redis.exceptions import RedisError

    client = redis.Redis.from_url(url, socket_connect_timeout=timeout_s, socket_timeout=timeout_s)
    try:
        client.ping()
    except (RedisError, OSError) as exc:
        raise ServerError(unreachable(url, exc)) from None
    finally:
        client.close()


def unreachable(url: str, exc: BaseException) -> str:
    """The one line saying a Redis cannot be reached (its password hidden)."""
    return f"cannot reach Redis at {shown_url(url)}: {exc}"


def shown_url(url: str) -> str:
    """``url`` with its password (``redis://user:PASSWORD@host`` or a ``password=`` query field) shown as
    ``***``, for start-up lines, errors and logs: docs/deploy.md keeps a Redis password in the config
    file's URL, and the lines that named the URL printed it to the terminal and the logs."""
    parts = urllib.parse.urlsplit(url)
    netloc = parts.netloc
    if parts.password is not None:
        user, _, host = netloc.rpartition("@")
        netloc = f"{user.partition(':')[0]}:***@{host}"
    fields = urllib.parse.parse_qsl(parts.query, keep_blank_values=True)
    query = urllib.parse.urlencode([(k, "***" if k == "password" else v) for k, v in fields], safe="*")
    # Rebuilt by hand: urlunsplit writes unix:///path as unix:/path.
    head, sep, _ = url.partition("?")
    return head.replace(parts.netloc, netloc, 1) + sep + (query if sep else "")


def session_key(name: str) -> str:
    return f"{PREFIX}:session:{name}"


def frames_channel(name: str) -> str:
    return f"{PREFIX}:frames:{name}"


def ended_key(name: str) -> str:
    return f"{PREFIX}:ended:{name}"


def control_channel(node: str) -> str:
    return f"{PREFIX}:ctl:{node}"


def want_key(name: str, kind: int, encoding: int) -> str:
    return f"{PREFIX}:want:{name}:{kind}:{encoding}"


def viewers_key(name: str, node: str) -> str:
    return f"{PREFIX}:viewers:{name}:{node}"


class SessionFacts:
    """What a viewer description needs of a session that runs on another node (from its row)."""

    def __init__(self, row: dict) -> None:
        self.fps = int(row["fps"])
        self.rate_hz = int(row["rate_hz"])
        self.algorithmic_delay_s = float(row["algorithmic_delay_s"])
        self.frames_out = int(row.get("frames", 0))
        self.samples_out = int(round(float(row.get("audio_s", 0.0)) * self.rate_hz))
        self.row = row


class RemoteFeed:
    """The viewers this node holds of one session that runs on another node."""

    def __init__(self, name: str, row: dict) -> None:
        self.name = name
        self.row = row
        self.facts = SessionFacts(row)
        self.viewers: set = set()  # server.live.Viewer objects
        self.ended = asyncio.Event()
        self.end: tuple[int, str] = (P.CLOSE_NORMAL, "session ended")
        self.frames = 0
        self.dropped = 0
        self.session = self.facts  # what descriptions read, as of a LiveSession
        self.source = str(row.get("source", "ingest"))  # the session's source kind, as LiveSession.source
        # A viewer on this node sends nothing (its message closes it: the owner is on another node), so its
        # description offers no expressions (server.describe.view_description).
        self.takes_viewer_controls = False
        self.descriptions: dict[ViewRequest, str] = {}  # server.describe.view_description_text's cache
        self.joining: dict[bytes, ReplayJoin] = {}  # viewers being sent the owner's replay, by request id


class ReplayJoin:
    """One viewer joining a remote text session: what it is to be sent before it joins the feed's
    fan-out, in order. The owner's answer (the sentence so far, then a done marker) leaves on the owner's
    one publish connection in the same turn that adds the viewer's kind to its wants, so on this node's
    one subscription connection every live message of the session arrives either before the done marker
    (already in the sentence, or before it: dropped, as the owner's own joining viewer never gets it) or
    after it (held here until the viewer has been sent the sentence). Without an answer within the
    timeout the viewer joins without the sentence (``gave_up``).

    The held live messages are bounded like the viewer's own queue (server.live.Viewer.offer): at
    ``limit`` (the server's ``viewer_queue``) the oldest is dropped and counted in ``dropped``, so a
    viewer slow to take the sentence costs this node at most one queue's worth of messages; the
    sentence itself is not bounded here (the owner's sentence is, and the viewer needs all of it)."""

    def __init__(self, kind: int, encoding: int, audio: bool, *, limit: int) -> None:
        self.kind, self.encoding, self.audio = kind, encoding, audio
        self.limit = limit
        self.messages: collections.deque[bytes] = collections.deque()  # the owner's answer
        self.held: collections.deque[bytes] = collections.deque()  # live messages after it (bounded)
        self.dropped = 0
        self.answered = asyncio.Event()
        self.gave_up = False
        self.request_id = b""

    def replayed(self, message: bytes) -> None:
        if not self.gave_up and not self.answered.is_set():
            self.messages.append(message)

    def live(self, message: bytes, kind: int, encoding: int) -> None:
        """A live message of the session: held once the answer is complete (or given up on), if the
        viewer watches its kind; the oldest held is dropped at the bound."""
        if not (self.answered.is_set() or self.gave_up):
            return
        if (kind == P.KIND_AUDIO and self.audio) or (kind == self.kind and encoding == self.encoding):
            if len(self.held) >= self.limit:
                self.held.popleft()
                self.dropped += 1
            self.held.append(message)

    def next_message(self) -> bytes | None:
        """The next message to send the viewer (the sentence, then the held live ones), None when done."""
        if self.messages:
            return self.messages.popleft()
        if self.held:
            return self.held.popleft()
        return None


def _resp(*parts: bytes) -> bytes:
    """One Redis command in RESP (the wire format): an array of bulk strings."""
    out = [b"*%d\r\n" % len(parts)]
    for p in parts:
        out.append(b"$%d\r\n%s\r\n" % (len(p), p))
    return b"".join(out)


RAW_BUFFER_LIMIT = 4 << 20  # bytes waiting in the publish socket before messages are dropped (Redis stalled)


class RawPublisher:
    """A write-only Redis connection for PUBLISH with replies off: :meth:`write` is one synchronous
    socket write (no await, no reply to read). Plain TCP only (``redis://``); the caller falls back to
    redis-py otherwise."""

    def __init__(self) -> None:
        self.writer: asyncio.StreamWriter | None = None
        self._reader: asyncio.StreamReader | None = None

    @staticmethod
    def supports(redis: aioredis.Redis) -> bool:
        from redis.asyncio.connection import Connection

        return redis.connection_pool.connection_class is Connection

    async def connect(self, redis: aioredis.Redis, timeout_s: float = 2.0) -> None:
        """Open the connection with the client's address, credentials and database (OSError, TimeoutError
        or ServerError if Redis refuses)."""
        kw = redis.connection_pool.connection_kwargs
        reader, writer = await asyncio.wait_for(
            asyncio.open_connection(kw.get("host", "localhost"), int(kw.get("port", 6379))), timeout_s
        )
        try:
            setup = []
            if kw.get("password"):
                user = kw.get("username")
                auth = (b"AUTH", user.encode(), kw["password"].encode()) if user else (b"AUTH", kw["password"].encode())
                setup.append(_resp(*auth))
            if int(kw.get("db") or 0):
                setup.append(_resp(b"SELECT", str(int(kw["db"])).encode()))
            for cmd in setup:  # these two answer: check before replies go off
                writer.write(cmd)
                line = await asyncio.wait_for(reader.readline(), timeout_s)
                if not line.startswith(b"+"):
                    raise ServerError(f"Redis refused the publish connection: {line.decode(errors='replace').strip()}")
            writer.write(_resp(b"CLIENT", b"REPLY", b"OFF"))
        except BaseException:
            writer.close()
            raise
        self._reader, self.writer = reader, writer

    @property
    def ready(self) -> bool:
        """Open, and Redis has not closed its end (an unread reader sees the EOF; the transport of a
        half-closed TCP socket would stay open until a write failed)."""
        w, r = self.writer, self._reader
        return w is not None and r is not None and not w.is_closing() and not r.at_eof()

    def write(self, channel: str, message: bytes) -> bool:
        """PUBLISH one message now; False if the connection is gone or Redis has stopped reading
        (the caller queues or drops it)."""
        w = self.writer
        if not self.ready or w is None or w.transport.get_write_buffer_size() > RAW_BUFFER_LIMIT:
            return False
        w.write(_resp(b"PUBLISH", channel.encode(), message))
        return True

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
        self.writer = self._reader = None


class Cluster:
    """One node's view of the cluster. ``await start()`` (ServerError in one line if Redis cannot be
    reached), ``await stop()``.

    url: Redis URL; node: this node's id; advertise: the URL clients reach this node at;
    heartbeat_s: registry refresh period; deliver: (feed, message bytes, kind, encoding) -> None,
    the server's fan-out to a feed's viewers; end_feed: (feed) -> coroutine closing its viewers."""

    def __init__(
        self,
        url: str,
        *,
        node: str,
        advertise: str,
        heartbeat_s: float,
        role: str = "both",
        deliver: Callable[[RemoteFeed, bytes, int, int], None],
        end_feed: Callable[[RemoteFeed], Coroutine[Any, Any, None]],
    ) -> None:
        self.url = url
        self.node = node
        self.advertise = advertise
        self.heartbeat_s = heartbeat_s
        self.role = role
        self.ttl_ms = int(3000 * heartbeat_s)
        self._deliver = deliver
        self._end_feed = end_feed
        self.redis: aioredis.Redis | None = None
        self.up = False
        self.error = ""
        self.local: dict[str, LiveSession] = {}
        self.wanted: dict[str, set[tuple[int, int]]] = collections.defaultdict(set)
        # Viewers other nodes hold of each local session (their viewers keys, read every heartbeat): the
        # session's registry row counts them with its own, so /sessions on any node shows all its viewers.
        self.far_viewers: dict[str, int] = {}
        # Wants announced while the heartbeat scans the want keys (None when it is not scanning): kept
        # through the scan's result, which may have missed their keys.
        self._wanted_meanwhile: set[tuple[str, int, int]] | None = None
        self.feeds: dict[str, RemoteFeed] = {}
        self.published = 0
        self.publish_dropped = 0
        self._queue: collections.deque[tuple[str, bytes]] = collections.deque()
        self._wake = asyncio.Event()
        self._raw = RawPublisher()
        self._tasks: list[asyncio.Task] = []
        # One-shot tasks started from message callbacks (unsubscribe, end a feed): held here until done,
        # since the loop keeps only a weak reference to a task.
        self._oneshots: set[asyncio.Task[None]] = set()
        self._pubsub: PubSub | None = None
        # True once the listener's SUBSCRIBE returned: until then the pubsub has no connection yet, and the
        # heartbeat must not read that as a lost subscription (every node logged Redis down at start).
        self._pubsub_ready = False
        self._subscribed: set[str] = set()
        self._confirmed: dict[str, asyncio.Event] = {}  # channel -> set when Redis confirms the subscription
        self._joins: dict[bytes, ReplayJoin] = {}  # this node's replay requests waiting for their answer
        self.replays_answered = 0
        self._up_since = 0.0  # time.monotonic() when Redis was last seen back (or first reached)
        self.feeds_lost = 0
        self.names_yielded = 0  # local sessions whose name another node held when Redis came back (_yield_name)
        # Local sessions whose registry row Redis has confirmed as this node's since Redis was last reached: a claim
        # that set it, or a heartbeat's refresh. Only they publish. While Redis is away (and after, until the next
        # heartbeat) a session of the same name may open on another node; the first heartbeat back decides whose it
        # is (REFRESH_ROW). Publishing before that let both nodes' frames onto the one channel in that window (a
        # third node's viewer saw indices go backwards, under load).
        self.held: set[str] = set()

    @property
    def _client(self) -> aioredis.Redis:
        """The Redis client, which exists from :meth:`start` on."""
        if self.redis is None:
            raise ServerError("the cluster is used before start()")
        return self.redis

    # -- lifecycle -------------------------------------------------------------------------------------

    async def start(self) -> None:
        import redis.asyncio as aioredis
        from redis.exceptions import RedisError

        self.redis = aioredis.Redis.from_url(
            self.url, socket_connect_timeout=2, socket_timeout=5, health_check_interval=0
        )
        try:
            await self.redis.ping()
        except (RedisError, OSError) as exc:
            await self.redis.aclose()
            raise ServerError(unreachable(self.url, exc)) from None
        self.up = True
        self._up_since = time.monotonic()
        self._tasks = [
            asyncio.ensure_future(self._publisher()),
            asyncio.ensure_future(self._heartbeat()),
            asyncio.ensure_future(self._listen()),
        ]

    async def stop(self) -> None:
        deadline = time.monotonic() + 1.0  # let the end markers of the last sessions go out
        while self._queue and self.up and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        for t in self._tasks:
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._raw.close()
        if self.redis is not None and self.up:
            try:
                names = list(self.local)
                if names:
                    await self.redis.delete(*(session_key(n) for n in names))
                await self.redis.delete(f"{PREFIX}:node:{self.node}")
            except Exception:  # noqa: BLE001 - best effort on the way out: the keys expire anyway
                pass
        if self._pubsub is not None:
            with contextlib.suppress(Exception):  # the connection may already be gone
                await self._pubsub.aclose()
        if self.redis is not None:
            await self.redis.aclose()

    def health(self) -> dict:
        return {
            "redis": "ok" if self.up else f"down: {self.error}",
            "node": self.node,
            "remote_feeds": len(self.feeds),
            "published": self.published,
            "publish_dropped": self.publish_dropped,
            "replays_answered": self.replays_answered,
            "feeds_lost": self.feeds_lost,
            "names_yielded": self.names_yielded,
        }

    # -- sessions this node owns --------------------------------------------------------------------------

    def _row(self, live: LiveSession) -> str:
        from server.describe import summary

        s = live.session
        row = summary(live)
        row.update(
            {
                "viewers": row["viewers"] + self.far_viewers.get(live.name, 0),
                "node": self.node,
                "node_url": self.advertise,
                "fps": s.fps,
                "rate_hz": s.rate_hz,
                "algorithmic_delay_s": s.algorithmic_delay_s,
                "published_kinds": sorted(self.wanted.get(live.name, ())),
                "replay": live.replay is not None,  # a joining viewer first gets the sentence so far
            }
        )
        return json.dumps(row)

    async def claim(self, live: LiveSession) -> str | None:
        """Register a new local session; returns the owner's node id if the name is taken elsewhere.
        With Redis away the session opens locally (registered when Redis returns)."""
        from redis.exceptions import RedisError

        try:
            ok = await self._client.set(session_key(live.name), self._row(live), nx=True, px=self.ttl_ms)
            if ok:  # an earlier session of this name has ended: its end record is not this one's
                await self._client.delete(ended_key(live.name))
                self.held.add(live.name)
            else:
                raw = await self._client.get(session_key(live.name))
                owner = json.loads(raw).get("node", "?") if raw else None
                if owner is not None and owner != self.node:
                    return owner
        except (RedisError, OSError) as exc:
            self._down(exc)
        self.local[live.name] = live
        return None

    async def release(self, live: LiveSession, code: int, reason: str) -> None:
        """A local session ended: tell remote viewers (end marker) and drop its registry row."""
        from redis.exceptions import RedisError

        if self.local.get(live.name) is not live:
            return
        del self.local[live.name]
        self.wanted.pop(live.name, None)
        if live.name not in self.held:  # the row may be another node's now: its end and row are not this one's
            return
        self.held.discard(live.name)
        end = json.dumps({"code": code, "reason": reason})
        try:
            # Before the marker: a node that subscribes after the marker went out finds the end here
            # (Cluster.feed), one that subscribed before it gets the marker.
            await self._client.set(ended_key(live.name), end, px=max(ENDED_KEEP_MS, self.ttl_ms))
        except (RedisError, OSError) as exc:
            self._down(exc)
        self.publish(live.name, END_MARK + end.encode())
        try:
            await self._client.delete(session_key(live.name))
        except (RedisError, OSError) as exc:
            self._down(exc)

    def _yield_name(self, name: str, live: LiveSession, owner: str) -> None:
        """Another node registered a live session of this name while this node's was unregistered (both opened
        while Redis was away, or this one then): the name is the other's in the cluster. This node's session
        goes on for its own ingest and viewers, no longer registered or published (its end publishes nothing and
        deletes no row). Before, both nodes rewrote the row every heartbeat and published on the one channel: a
        viewer on a third node got the two sessions' frames interleaved, then 1001 "session lost"."""
        if self.local.get(name) is not live:
            return
        del self.local[name]
        self.wanted.pop(name, None)
        self.held.discard(name)
        self.names_yielded += 1
        log.warning(
            "session %r is also live on node %s (both opened while Redis was away): the cluster's is %s's; this "
            "node's goes on for its own ingest and viewers, unpublished",
            name,
            owner,
            owner,
        )

    def wants(self, name: str) -> set[tuple[int, int]]:
        """(kind, encoding) pairs other nodes watch of local session ``name`` (audio: KIND_AUDIO, int16); none while
        Redis has not confirmed the name as this node's (:attr:`held`)."""
        return self.wanted.get(name, set()) if name in self.held else set()

    def publish(self, name: str, message: bytes) -> None:
        """Send one message to the session's channel: written at once on the publish connection when it
        is up and nothing is queued before it, else queued (bounded); never waits, never raises."""
        self._publish_to(frames_channel(name), message)

    def _publish_to(self, channel: str, message: bytes) -> None:
        """:meth:`publish` to any channel: one path for every message, so they reach Redis in the order
        they were published (a replay answer and the session's frames, see :class:`ReplayJoin`)."""
        if not self._queue and self._raw.write(channel, message):
            self.published += 1
            return
        if len(self._queue) >= PUBLISH_QUEUE:
            self._queue.popleft()
            self.publish_dropped += 1
        self._queue.append((channel, message))
        self._wake.set()

    async def _publisher(self) -> None:
        """Drain the queue: through the publish connection once it is (re)opened, else through redis-py."""
        from redis.exceptions import RedisError

        raw_ok = self.redis is not None and RawPublisher.supports(self.redis)
        while True:
            await self._wake.wait()
            self._wake.clear()
            if raw_ok and not self._raw.ready and self.up:
                self._raw.close()
                try:
                    await self._raw.connect(self._client)
                except (OSError, TimeoutError, ServerError) as exc:
                    log.debug("publish connection to Redis failed: %s (using the client)", exc)
                    self._raw.close()
            while self._queue:
                if self._raw.ready:
                    channel, msg = self._queue[0]
                    if not self._raw.write(channel, msg):
                        break  # Redis stalled: keep the rest queued (the oldest drop when full)
                    self._queue.popleft()
                    self.published += 1
                    continue
                batch = [self._queue.popleft() for _ in range(min(len(self._queue), 256))]
                try:
                    pipe = self._client.pipeline(transaction=False)
                    for channel, msg in batch:
                        pipe.publish(channel, msg)
                    await pipe.execute()
                    self.published += len(batch)
                except (RedisError, OSError) as exc:
                    self.publish_dropped += len(batch)
                    self._down(exc)
                    await asyncio.sleep(0.2)
            if self._queue:  # stalled: try again shortly
                await asyncio.sleep(0.05)
                self._wake.set()

    # -- heartbeat, wants, recovery ------------------------------------------------------------------------

    def _down(self, exc: BaseException) -> None:
        if self.up:
            log.warning("Redis unreachable at %s: %s (sessions go on; retrying)", shown_url(self.url), exc)
        self.up = False
        self.held.clear()  # whose each name is gets decided again by the first heartbeat back
        self.error = str(exc)[:200] or type(exc).__name__

    async def _heartbeat(self) -> None:
        from redis.exceptions import RedisError

        while True:
            try:
                await self._beat()
                if not self.up:
                    log.warning(
                        "Redis is back at %s: %d local sessions re-registered", shown_url(self.url), len(self.local)
                    )
                    self._up_since = time.monotonic()
                self.up, self.error = True, ""
                await self._end_lost_feeds()
            except (RedisError, OSError) as exc:
                self._down(exc)
            await asyncio.sleep(self.heartbeat_s if self.up else min(self.heartbeat_s, 0.5))

    async def _beat(self) -> None:
        r = self._client
        pipe = r.pipeline(transaction=False)
        pipe.set(
            f"{PREFIX}:node:{self.node}",
            json.dumps({"node": self.node, "url": self.advertise, "role": self.role, "sessions": len(self.local)}),
            px=self.ttl_ms,
        )
        local = list(self.local.items())
        for name, live in local:  # refreshed, unless another node holds the name (below)
            pipe.eval(REFRESH_ROW, 1, session_key(name), self._row(live), self.node, self.ttl_ms)
        for name, feed in self.feeds.items():
            for kind, enc in {(v.kind, v.encoding) for v in feed.viewers} | (
                {(P.KIND_AUDIO, P.ENC_INT16)} if any(v.audio for v in feed.viewers) else set()
            ):
                pipe.set(want_key(name, kind, enc), self.node, px=self.ttl_ms)
            pipe.set(viewers_key(name, self.node), len(feed.viewers), px=self.ttl_ms)
        results = await pipe.execute()
        for (name, live), owner in zip(local, results[1 : 1 + len(local)]):
            if owner is not None:
                self._yield_name(name, live, owner.decode() if isinstance(owner, bytes) else str(owner))
            elif self.local.get(name) is live:  # still live (not ended while the pipeline ran): the row is this node's
                self.held.add(name)
        # The owner's side: which kinds of its sessions other nodes want now.
        wanted: dict[str, set[tuple[int, int]]] = collections.defaultdict(set)
        self._wanted_meanwhile = set()
        try:
            for name in list(self.local):
                async for key in r.scan_iter(match=f"{PREFIX}:want:{name}:*", count=100):
                    k = key.decode() if isinstance(key, bytes) else key
                    _, _, _, kind, enc = k.rsplit(":", 4)
                    wanted[name].add((int(kind), int(enc)))
            for name, kind, enc in self._wanted_meanwhile:
                if name in self.local:
                    wanted[name].add((kind, enc))
            self.wanted = wanted
        finally:
            self._wanted_meanwhile = None
        far: collections.Counter[str] = collections.Counter()
        keys = [k async for k in r.scan_iter(match=f"{PREFIX}:viewers:*", count=500)] if self.local else []
        for key, n in zip(keys, await r.mget(keys) if keys else []):
            name = (key.decode() if isinstance(key, bytes) else key).split(":")[2]
            if name in self.local and n is not None:
                far[name] += int(n)
        self.far_viewers = dict(far)
        if self._pubsub is not None and self._pubsub_ready and self._pubsub.connection is None:
            raise ConnectionError("subscription lost")

    async def _end_lost_feeds(self) -> None:
        """End the feeds of remote sessions whose node stopped without ending them (killed, cut off from
        Redis): no end marker will come, and their viewers would wait with no frames and no close. Such a
        session's row expires ``ttl`` after its node's last heartbeat (or names another node: the name was
        claimed again), so one heartbeat here later its viewers are closed with :data:`LOST`, within four
        heartbeats of the node's death. A row missing because the session ended normally left its end
        record first (:meth:`release`): that code is used (the marker may still be on its way).

        Only once Redis has been up, as this node saw it, for a whole TTL: a Redis that restarted empty
        holds no rows until each live node's next heartbeat re-registers its sessions."""
        if not self.feeds or time.monotonic() - self._up_since < self.ttl_ms / 1000:
            return
        feeds = list(self.feeds.values())
        names = [f.name for f in feeds]
        values = await self._client.mget([session_key(n) for n in names] + [ended_key(n) for n in names])
        for feed, raw, end in zip(feeds, values[: len(names)], values[len(names) :]):
            if self.feeds.get(feed.name) is not feed:  # ended while Redis answered (a new feed is read next time)
                continue
            if raw is not None and json.loads(raw).get("node") == feed.row.get("node"):
                continue
            if raw is None and end is not None:
                record = json.loads(end)
                self._feed_ended(feed, int(record["code"]), str(record["reason"]))
                continue
            log.warning("session %r lost: its node %s stopped without ending it", feed.name, feed.row.get("node"))
            self.feeds_lost += 1
            self._feed_ended(feed, *LOST)

    # -- feeds of remote sessions ----------------------------------------------------------------------

    async def lookup(self, name: str) -> dict | None:
        """The registry row of session ``name`` on another node (None: unknown or Redis away)."""
        from redis.exceptions import RedisError

        try:
            raw = await self._client.get(session_key(name))
        except (RedisError, OSError) as exc:
            self._down(exc)
            return None
        if raw is None:
            return None
        row = json.loads(raw)
        return None if row.get("node") == self.node else row

    async def compute_node(self) -> dict | None:
        """The least loaded live node that computes sessions (role compute or both), or None."""
        from redis.exceptions import RedisError

        try:
            keys = [k async for k in self._client.scan_iter(match=f"{PREFIX}:node:*", count=500)]
            rows = [json.loads(r) for r in (await self._client.mget(keys) if keys else []) if r is not None]
        except (RedisError, OSError) as exc:
            self._down(exc)
            return None
        rows = [r for r in rows if r.get("role", "both") != "edge" and r.get("node") != self.node]
        return min(rows, key=lambda r: r.get("sessions", 0), default=None)

    async def list_sessions(self) -> list[dict] | None:
        """Every node's session rows (None when Redis is away)."""
        from redis.exceptions import RedisError

        try:
            keys = [k async for k in self._client.scan_iter(match=f"{PREFIX}:session:*", count=500)]
            rows = await self._client.mget(keys) if keys else []
        except (RedisError, OSError) as exc:
            self._down(exc)
            return None
        return [json.loads(r) for r in rows if r is not None]

    async def feed(self, name: str, row: dict, kind: int, encoding: int, audio: bool) -> RemoteFeed:
        """The feed of remote session ``name`` (created and subscribed on first use); tells the
        owner at once that this node wants ``kind``/``encoding`` (and audio)."""
        feed = self.feeds.get(name)
        if feed is None:
            feed = self.feeds[name] = RemoteFeed(name, row)
            await self._subscribe(frames_channel(name))
            await self._end_if_ended(feed)
        pairs = [(kind, encoding)] + ([(P.KIND_AUDIO, P.ENC_INT16)] if audio else [])
        pipe = self._client.pipeline(transaction=False)
        for k, e in pairs:
            pipe.set(want_key(name, k, e), self.node, px=self.ttl_ms)
            pipe.publish(control_channel(row["node"]), json.dumps({"want": [name, k, e]}))
        await pipe.execute()
        return feed

    async def _end_if_ended(self, feed: RemoteFeed) -> None:
        """A session that ended between this node's lookup and its subscription published its end marker
        to no one here: once the subscription is confirmed, its end record (:meth:`release`, written before
        the marker) says whether it ended, and how. Without it, every later end marker arrives."""
        from redis.exceptions import RedisError

        confirmed = self._confirmed.get(frames_channel(feed.name))
        try:
            if confirmed is None:
                raise ConnectionError("the feed is not subscribed")
            await asyncio.wait_for(confirmed.wait(), SUBSCRIBE_WAIT_S)
            raw = await self._client.get(ended_key(feed.name))
        except (RedisError, OSError, TimeoutError) as exc:
            log.debug("end record of %r not read: %s", feed.name, exc)
            return
        if raw is not None and self.feeds.get(feed.name) is feed:
            end = json.loads(raw)
            self._feed_ended(feed, int(end["code"]), str(end["reason"]))

    def _feed_ended(self, feed: RemoteFeed, code: int, reason: str) -> None:
        """Remote session ``feed`` ended with ``code``/``reason``: close its viewers, drop the feed."""
        feed.end = (code, reason)
        feed.ended.set()
        for join in feed.joining.values():  # nothing more will come: they send what they have
            join.answered.set()
        self.feeds.pop(feed.name, None)
        self._oneshot(self._unsubscribe(frames_channel(feed.name)))
        self._oneshot(self._end_feed(feed))

    async def replay(self, feed: RemoteFeed, kind: int, encoding: int, audio: bool, *, limit: int) -> ReplayJoin:
        """Ask the owner of remote text session ``feed`` for the sentence now playing, encoded for one
        joining viewer (``kind``/``encoding``, and audio), as its own joining viewer gets it
        (server.live.LiveSession.send_sentence), then at most ``limit`` live messages held after it. The
        answer comes on this node's control channel, in order with the session's frames
        (:class:`ReplayJoin`); wait for it with :meth:`answer`, then send the join's messages
        (:meth:`ReplayJoin.next_message`) and register the viewer, and :meth:`forget` the join in any case.

        Request/answer rather than the owner keeping the sentence in Redis (a stream): the replay is
        encoded for the joining viewer's kind, which the owner would otherwise publish in every kind for
        every frame of every text session; it holds the sentence in memory already; and an answer on
        the owner's one publish connection lines up with the live frames, so the viewer gets each
        output once with no gap (a stream read and a subscription are two connections, unordered)."""
        from redis.exceptions import RedisError

        join = ReplayJoin(kind, encoding, audio, limit=limit)
        join.request_id = rid = os.urandom(REQUEST_ID_BYTES // 2).hex().encode()
        feed.joining[rid] = join
        self._joins[rid] = join
        confirmed = self._confirmed.get(frames_channel(feed.name))
        try:
            # The answer's done marker is where the viewer switches to the live frames: the feed's
            # subscription must be in place before the owner sends it, or frames right after it are lost.
            if confirmed is None:
                raise ConnectionError("the feed is not subscribed")
            await asyncio.wait_for(confirmed.wait(), SUBSCRIBE_WAIT_S)
            request = {"replay": [feed.name, kind, encoding, audio, self.node, rid.decode()]}
            await self._client.publish(control_channel(feed.row["node"]), json.dumps(request))
        except (RedisError, OSError, TimeoutError) as exc:
            log.debug("replay request for %r failed: %s (the viewer joins without it)", feed.name, exc)
            join.gave_up = True
        return join

    async def answer(self, join: ReplayJoin, timeout_s: float = ANSWER_WAIT_S) -> None:
        """Wait for the owner's whole answer (or the end of the session); without it in ``timeout_s`` the
        viewer joins without the sentence."""
        if join.gave_up:
            return
        try:
            await asyncio.wait_for(join.answered.wait(), timeout_s)
        except TimeoutError:
            log.warning("no replay from the owner within %g s (the viewer joins without it)", timeout_s)
            join.gave_up = True
            join.messages.clear()
            join.held.clear()

    def forget(self, feed: RemoteFeed, join: ReplayJoin) -> None:
        feed.joining.pop(join.request_id, None)
        self._joins.pop(join.request_id, None)

    def _answer_replay(self, request: list) -> None:
        """The owner's side of :meth:`replay`: note the viewer's kinds as wanted, then publish the sentence
        so far and the done marker to the asking node, all in this turn of the loop."""
        try:
            name, kind, encoding, audio, node, rid = request
            kind, encoding, reply, tag = int(kind), int(encoding), control_channel(str(node)), str(rid).encode()
        except (ValueError, TypeError):  # not from a node of this version: nothing to answer
            log.warning("malformed replay request %.200r ignored", request)
            return
        live = self.local.get(name)
        if live is not None and name in self.held:  # not held: the name may be another node's (answered: done)
            self._want(name, kind, encoding)
            if audio:
                self._want(name, P.KIND_AUDIO, P.ENC_INT16)
            try:
                messages = live.sentence_messages(kind, encoding, bool(audio))
            except ServerConfigError as exc:  # a kind this node cannot encode (no head here): frames only
                log.warning("replay of %r as kind %d/%d failed: %s", name, kind, encoding, exc)
                messages = []
            for m in messages:
                self._publish_to(reply, REPLAY_MARK + tag + m)
        self._publish_to(reply, REPLAY_DONE + tag)
        self.replays_answered += 1

    def _want(self, name: str, kind: int, encoding: int) -> None:
        """Another node wants ``kind``/``encoding`` of local session ``name`` now (its want key is set)."""
        self.wanted[name].add((kind, encoding))
        if self._wanted_meanwhile is not None:
            self._wanted_meanwhile.add((name, kind, encoding))

    async def drop_feed_if_idle(self, feed: RemoteFeed) -> None:
        if feed.viewers or feed.joining or self.feeds.get(feed.name) is not feed:
            return
        del self.feeds[feed.name]
        await self._unsubscribe(frames_channel(feed.name))

    async def _subscribe(self, channel: str) -> None:
        self._subscribed.add(channel)
        self._confirmed.setdefault(channel, asyncio.Event())
        if self._pubsub is not None:
            try:
                await self._pubsub.subscribe(channel)
            except Exception as exc:  # noqa: BLE001 - the listener resubscribes when Redis returns
                self._down(exc)

    def _oneshot(self, coro: Coroutine[Any, Any, None]) -> None:
        task = asyncio.ensure_future(coro)
        self._oneshots.add(task)
        task.add_done_callback(self._oneshots.discard)

    async def _unsubscribe(self, channel: str) -> None:
        self._subscribed.discard(channel)
        self._confirmed.pop(channel, None)
        if self._pubsub is not None:
            try:
                await self._pubsub.unsubscribe(channel)
            except Exception as exc:  # noqa: BLE001 - as above
                self._down(exc)

    async def _listen(self) -> None:
        """One subscription connection for this node: frame channels of its feeds and its control channel."""
        from redis.exceptions import RedisError

        while True:
            try:
                self._pubsub_ready = False
                self._pubsub = pubsub = self._client.pubsub()
                await pubsub.subscribe(control_channel(self.node), *self._subscribed)
                self._pubsub_ready = True
                while True:
                    msg = await pubsub.get_message(timeout=1.0)
                    if msg is None:
                        continue
                    if msg["type"] == "message":
                        self._on_message(msg)
                    elif msg["type"] == "subscribe":  # Redis confirms: messages on it reach us from now on
                        confirmed = self._confirmed.get(_text(msg["channel"]))
                        if confirmed is not None:
                            confirmed.set()
            except asyncio.CancelledError:
                raise
            except (RedisError, OSError) as exc:
                self._down(exc)
                for confirmed in self._confirmed.values():
                    confirmed.clear()
                if self._pubsub is not None:
                    with contextlib.suppress(Exception):  # already broken
                        await self._pubsub.aclose()
                self._pubsub = None
                await asyncio.sleep(0.5)

    def _on_message(self, msg: dict) -> None:
        channel = _text(msg["channel"])
        data = msg["data"]
        if channel == control_channel(self.node):
            if data[:4] in (REPLAY_MARK, REPLAY_DONE):  # an answer to this node's replay request
                join = self._joins.get(data[4 : 4 + REQUEST_ID_BYTES])
                if join is not None and data[:4] == REPLAY_MARK:
                    join.replayed(data[4 + REQUEST_ID_BYTES :])
                elif join is not None:
                    join.answered.set()
                return
            ctl = json.loads(data)
            want = ctl.get("want")
            if want and want[0] in self.local:
                self._want(want[0], int(want[1]), int(want[2]))
            if ctl.get("replay"):
                self._answer_replay(ctl["replay"])
            return
        name = channel[len(f"{PREFIX}:frames:") :]
        feed = self.feeds.get(name)
        if feed is None:
            return
        if data[:4] == END_MARK:
            end = json.loads(data[4:])
            self._feed_ended(feed, int(end["code"]), str(end["reason"]))
            return
        if len(data) < P.HEADER_BYTES:
            return
        kind, enc = data[1], data[2]
        if kind != P.KIND_AUDIO:
            feed.frames += 1
        for join in feed.joining.values():
            join.live(data, kind, enc)
        self._deliver(feed, data, kind, enc)


def _text(channel: bytes | str) -> str:
    """A channel name as redis-py reports it (bytes unless the client decodes responses) -> str."""
    return channel.decode() if isinstance(channel, bytes) else channel
