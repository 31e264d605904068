"""Live sessions and their viewers: fan-out with per-viewer backpressure (asyncio, no sockets opened here).

A :class:`LiveSession` couples one session handle with any number of :class:`Viewer` objects. The
handle is either a :class:`LocalSession` (the sans-I/O :class:`server.session.Session` run on the
event loop) or a :class:`server.workers.RemoteSession` (the same session in a compute process):
both offer the one async interface :class:`SessionHandle`, so nothing here branches on where a
session runs.

Fan-out: each frame is encoded once per (kind, encoding) that somebody watches, given one header
with the send time, and offered to every viewer of that kind. A viewer that keeps up (nothing
queued, socket buffer under 64 KiB) gets each message written synchronously, as python-websockets'
``broadcast`` does, without a task switch per message. Otherwise the message goes to the viewer's
bounded queue, drained by its own sender task; offering a message never waits. When a queue is full
the oldest message is dropped and counted (the freshest frame matters most for live animation); a
viewer that keeps dropping for ``viewer_max_behind_s`` is closed with 4000.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from websockets.asyncio.server import ServerConnection, broadcast
from websockets.frames import Frame, Opcode
from websockets.protocol import OPEN

from realtime_core.face.keyframes import MorphRig
from server.describe import summary
from server.errors import AudioFormatError, IngestOverrun, ServerSideClose
from server.guard import IngestPacer
from server.session import Frame as VideoFrame
from server.session import Output, Session, morph_delta_payloads
from server.workers import RemoteSession
from wire import protocol as P

if TYPE_CHECKING:
    from server.app import FacecastServer
    from server.cluster import RemoteFeed
    from server.protocol import ViewRequest

log = logging.getLogger("facecast.server")
sessions_log = logging.getLogger("facecast.sessions")
"""One INFO line per session started and ended and per viewer closed for being too slow (a deployer saw them only
as counts in /metrics); apart from ``facecast.server``'s incidents, which are rate-limited."""

FAIR_SLICE_S = 0.1  # audio processed per turn of the loop when a client sends a large block
# A viewer whose socket buffer holds less than this gets messages written synchronously
# (websockets' broadcast); others go through their queue and sender task (backpressure, drops).
FAST_PATH_BUFFER_BYTES = 64 * 1024


class InputFormat(Protocol):
    """What live sessions and descriptions read of a session's input format (a :class:`SessionConfig`,
    or a text session's fixed format)."""

    @property
    def sample_rate_hz(self) -> int: ...
    @property
    def channels(self) -> int: ...


class SessionHandle(Protocol):
    """What a live session needs from its session, wherever it runs (read-only facts: a local
    session's are attributes, a worker's properties)."""

    @property
    def config(self) -> InputFormat: ...
    @property
    def rate_hz(self) -> int: ...
    @property
    def fps(self) -> int: ...
    @property
    def frames_out(self) -> int: ...
    @property
    def samples_out(self) -> int: ...
    @property
    def frame_bytes(self) -> int: ...
    @property
    def algorithmic_delay_s(self) -> float: ...

    async def push_bytes(self, data: bytes) -> Output: ...
    async def push(self, samples: np.ndarray) -> Output: ...
    async def flush(self) -> Output: ...
    async def apply_control(self, msg: dict) -> dict: ...
    async def close(self) -> None: ...
    def control_state(self) -> dict: ...


class LocalSession:
    """A :class:`Session` run on the event loop behind the async :class:`SessionHandle` interface."""

    def __init__(self, core: Session) -> None:
        self.core = core
        self.config = core.config
        self.rate_hz = core.rate_hz
        self.fps = core.fps
        self.frame_bytes = core.frame_bytes
        self.algorithmic_delay_s = core.algorithmic_delay_s

    @property
    def frames_out(self) -> int:
        return self.core.frames_out

    @property
    def samples_out(self) -> int:
        return self.core.samples_out

    async def push_bytes(self, data: bytes) -> Output:
        return self.core.push_bytes(data)

    async def push(self, samples: np.ndarray) -> Output:
        return self.core.push(samples)

    async def flush(self) -> Output:
        return self.core.flush()

    async def apply_control(self, msg: dict) -> dict:
        return self.core.apply_control(msg)

    async def close(self) -> None:
        """Nothing to release: the session lives in this process."""

    def control_state(self) -> dict:
        return self.core.control_state()


def audio_message(out: Output, now: float) -> bytes:
    """The wire message of an output's audio block (``out.audio`` set), sent at ``now`` (epoch s)."""
    a = out.audio
    assert a is not None
    return P.pack_header(P.KIND_AUDIO, P.ENC_INT16, a.index, a.samples.size, 1 / 32768, a.media_time, now) + a.payload()


def frame_messages(out: Output, kind: int, encoding: int, now: float) -> list[bytes]:
    """The wire messages of an output's frames in one (kind, encoding), sent at ``now`` (epoch s)."""
    msgs = []
    for frame in out.frames:
        payload, count, scale = frame.payload(kind, encoding)
        msgs.append(P.pack_header(kind, encoding, frame.index, count, scale, frame.media_time, now) + payload)
    return msgs


class SentenceReplay:
    """A text session's sentence now playing, as fanned out so far (docs/protocol.md section 3).

    Why: a text session's frames leave at real time (plus a short lead), so a viewer that joined
    after a sentence began, e.g. ``facecast view --record`` started beside the chatbot, got only the
    sentence's tail; now it is first sent the sentence from its first frame, then the live stream.
    The text pacer marks where each sentence starts and until when it plays on the wall clock
    (:meth:`begin`); the fan-out adds each output when it is delivered (:meth:`add`), so an output
    still waiting for its turn's vertex deltas is not here yet and reaches a joining viewer once."""

    def __init__(self) -> None:
        self.outputs: list[Output] = []  # the sentence's outputs delivered so far, in order
        self.first_index = -1  # the frame index the next sentence to be delivered starts with
        self.playing_until = float("-inf")  # time.perf_counter() when the sentence's last frame has played

    def begin(self, first_index: int, playing_until: float) -> None:
        self.first_index, self.playing_until = first_index, playing_until

    def add(self, out: Output) -> None:
        if out.frames and out.frames[0].index == self.first_index:
            self.outputs = []
        self.outputs.append(out)

    def playing(self, now: float) -> bool:
        """Whether a sentence is still playing at ``now`` (time.perf_counter()): worth replaying."""
        return bool(self.outputs) and now < self.playing_until

    def since(self, index: int) -> list[Output]:
        """The kept outputs whose frames start at ``index`` or later."""
        return [o for o in self.outputs if o.frames and o.frames[0].index >= index]


def _replay_messages(outs: list[Output], kind: int, encoding: int, audio: bool) -> Iterator[bytes]:
    """Replayed outputs' messages in the fan-out's order (each audio block before its frame), stamped
    as they are made."""
    for out in outs:
        now = time.time()
        if audio and out.audio is not None:
            yield audio_message(out, now)
        yield from frame_messages(out, kind, encoding, now)


def deliver(viewers: list[Viewer], msg: bytes, now: float) -> None:
    """Hand one message to viewers: a synchronous write for those keeping up (no task switch per
    message), the bounded queue for the others.

    The synchronous write frames the message once (websockets' own ``Frame.serialize``; a server's
    frames are unmasked and compression is off, so the bytes are the same for every viewer) and
    writes those bytes to each viewer's transport: websockets' ``broadcast`` would build, serialise
    and copy the frame once per viewer, the largest per-viewer cost of fan-out after the send call
    itself. A connection not plainly open (closing, a fragmented message in progress, an
    extension negotiated) goes through ``broadcast``, which handles those cases."""
    fast: list[Viewer] = []
    for v in viewers:
        if v.writable_now():
            fast.append(v)
        else:
            v.offer(msg, now)
    if not fast:
        return
    wire: bytes | None = None
    other = []
    for v in fast:
        ws = v.ws
        proto = ws.protocol
        if (
            proto.state is OPEN
            and not proto.extensions
            and not proto.expect_continuation_frame
            and ws.send_in_progress is None
        ):
            if wire is None:
                wire = Frame(Opcode.BINARY, msg).serialize(mask=False)
            ws.transport.write(wire)
        else:
            other.append(ws)
        v.sent += 1
    if other:
        broadcast(other, msg)


class Viewer:
    """One subscriber: a bounded queue of ready messages drained by its own sender task."""

    def __init__(
        self,
        ws: ServerConnection,
        live: LiveSession | RemoteFeed,
        *,
        kind: int,
        encoding: int,
        audio: bool,
        server: FacecastServer,
    ) -> None:
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
                sessions_log.info(
                    "a viewer of session %r closed (4000): behind for over %g s, %d messages dropped",
                    self.live.name,
                    self.server.config.viewer_max_behind_s,
                    self.dropped,
                )
                self.server.spawn(
                    self.server.close_ws(
                        self.ws,
                        P.CLOSE_TOO_SLOW,
                        f"viewer too slow: behind for over "
                        f"{self.server.config.viewer_max_behind_s:g} s, {self.dropped} messages dropped",
                    )
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


class Hold:
    """One viewer held for a session that has not opened yet: ``opened`` is set with the session when it opens
    (or with the ProtocolViolation the viewer is closed with instead), ``joined`` by the viewer once it is
    subscribed (or gone), which the opening waits for."""

    def __init__(self, name: str) -> None:
        loop = asyncio.get_running_loop()
        self.name = name
        self.opened: asyncio.Future[LiveSession] = loop.create_future()
        self.joined: asyncio.Future[None] = loop.create_future()

    def done_joining(self) -> None:
        if not self.joined.done():
            self.joined.set_result(None)


class HeldViewers:
    """Viewers held until their session opens (a view query's ``wait``), by session name.

    Why: a viewer that connected just before its session started was refused (4004) and retried every 50 ms
    (clients/viewer/stream.py RETRY_S); it joined after the session's first push, so it had the frames from frame
    0 (they lag the audio by the model's context) but not the first audio block(s) (up to 630 samples at 16 kHz).
    A held viewer is woken by the session's opening (:meth:`open`, from ``FacecastServer.release_held``), which
    waits until it has subscribed before the session is fed anything: it gets every audio block and frame."""

    def __init__(self) -> None:
        self._held: dict[str, list[Hold]] = {}

    def __len__(self) -> int:
        return sum(len(h) for h in self._held.values())

    def add(self, name: str) -> Hold:
        hold = Hold(name)
        self._held.setdefault(name, []).append(hold)
        return hold

    def drop(self, hold: Hold) -> None:
        """Forget a hold whose viewer is done waiting (woken, out of time or gone)."""
        held = self._held.get(hold.name, [])
        if hold in held:
            held.remove(hold)
            if not held:
                del self._held[hold.name]
        hold.done_joining()

    def open(self, live: LiveSession) -> list[asyncio.Future[None]]:
        """Wake the viewers held for ``live``; returns what to await for them to have subscribed."""
        holds = self._held.pop(live.name, [])
        for hold in holds:
            if not hold.opened.done():
                hold.opened.set_result(live)
        return [h.joined for h in holds]

    def refuse(self, name: str | None, code: int, reason: str) -> int:
        """Close the viewers held for session ``name`` (None: every one) with ``code`` and ``reason`` (the server's
        own: the hand-off to a connection worker, a shutdown); returns how many were held."""
        names = list(self._held) if name is None else [name]
        n_held = 0
        for n in names:
            for hold in self._held.pop(n, []):
                if not hold.opened.done():
                    hold.opened.set_exception(ServerSideClose(code, reason))
                    n_held += 1
        return n_held


class EndWake:
    """Cuts a session handler's waits short when its session is ended from outside (the server stopping sets
    :attr:`LiveSession.ended`): each wait runs under an ``asyncio.Timeout`` (a deadline, or None) that the end
    moves to now, so the awaited call raises TimeoutError and the handler looks at ``ended``. One await per wait,
    not a task raced against the end: an ingest's block then reaches its session one loop turn after it arrives
    instead of three. The ingest (its idle limit) and the text session (its stall timer, the play-out after
    `end` or after its source dropped) wait this one way."""

    def __init__(self, ended: asyncio.Event) -> None:
        self.ended = ended
        self._loop = asyncio.get_running_loop()
        self._waits: list[asyncio.Timeout] = []
        self._watch = asyncio.ensure_future(ended.wait())
        self._watch.add_done_callback(self._wake)

    def _wake(self, watch: asyncio.Future) -> None:
        if not watch.cancelled():  # cancelled: closed, the handler ended first
            for t in self._waits:
                if not t.expired():  # one that has just run out raises its TimeoutError already
                    t.reschedule(self._loop.time())

    def until(self, when: float | None) -> _EndOrDeadline:
        """``async with wake.until(loop_time or None):`` a wait that raises TimeoutError at ``when`` or at the
        session's end, whichever is first (at once when it has ended already)."""
        return _EndOrDeadline(self, self._loop.time() if self.ended.is_set() else when)

    def close(self) -> None:
        self._watch.cancel()


class _EndOrDeadline:
    """One wait of :class:`EndWake` (a plain class: the ingest enters one per block)."""

    __slots__ = ("timeout", "wake")

    def __init__(self, wake: EndWake, when: float | None) -> None:
        self.wake = wake
        self.timeout = asyncio.timeout_at(when)

    async def __aenter__(self) -> asyncio.Timeout:
        await self.timeout.__aenter__()
        self.wake._waits.append(self.timeout)
        return self.timeout

    async def __aexit__(self, *exc: Any) -> None:
        self.wake._waits.remove(self.timeout)
        await self.timeout.__aexit__(*exc)  # raises TimeoutError for a wait it cut short; never suppresses


class LiveSession:
    """A session with its viewers: feed it audio, it fans frames out."""

    def __init__(self, name: str, session: SessionHandle, server: FacecastServer, *, source: str) -> None:
        self.name = name
        self.session = session
        self.server = server
        self.source = source
        self.takes_viewer_controls = True  # its viewers' expression controls reach it (server.app._watch)
        self.viewers: set[Viewer] = set()
        self.dropped = 0
        self.started = time.time()
        self.ended = asyncio.Event()
        self.descriptions: dict[ViewRequest, str] = {}  # server.describe.view_description_text's cache
        self.pacer: IngestPacer | None = None  # set for real-time ingests (not batch, not local sources)
        self.overrun = "pace"
        self.paced_s = 0.0
        self.batch = False
        self.replay: SentenceReplay | None = None  # text sessions: the sentence a joining viewer gets first

    async def feed_bytes(self, data: bytes) -> int:
        """One binary block of the session's format -> frames produced (AudioFormatError if bad)."""
        self._set_precompute()
        return self._fanout(await self.session.push_bytes(data))

    def _set_precompute(self) -> None:
        """Tell a session in a compute worker which vertex-delta payloads its viewers (here and on other
        nodes) watch, so the worker encodes them off the loop (a local session encodes on the loop)."""
        if not isinstance(self.session, RemoteSession):
            return
        kinds = {(v.kind, v.encoding) for v in self.viewers if v.kind == P.KIND_DELTAS}
        cluster = self.server.cluster
        if cluster is not None:
            kinds.update(k for k in cluster.wants(self.name) if k[0] == P.KIND_DELTAS)
        self.session.precompute = tuple(sorted(kinds))

    def feed_now(self, data: bytes) -> bool:
        """Feed one binary block synchronously (from the connection's data callback) when that needs no
        waiting: a session on this loop, a whole number of samples within one fair slice, the pacer
        has no delay. False, having done nothing, otherwise (and when the block is malformed: the
        caller then takes :meth:`feed_bytes_fairly`, which raises the error naming it)."""
        s = self.session
        if not isinstance(s, LocalSession) or self.ended.is_set():
            return False
        frame, rate = s.frame_bytes, s.config.sample_rate_hz
        n = len(data) // frame
        if len(data) % frame or n > max(1, int(FAIR_SLICE_S * rate)):
            return False
        now = asyncio.get_running_loop().time() if self.pacer is not None else 0.0
        if self.pacer is not None and self.pacer.would_wait(n / rate, now) > 0:
            return False
        try:
            out = s.core.push_bytes(data)
        except AudioFormatError:
            return False
        if self.pacer is not None:
            self.pacer.delay(n / rate, now)  # counted as the awaited path would have (0: no wait)
        self._fanout(out)
        return True

    async def feed_bytes_fairly(self, data: bytes) -> int:
        """Like :meth:`feed_bytes`, but a large block (a client sending faster than real time) is
        processed in slices of at most ``FAIR_SLICE_S`` of audio with a yield to the loop between
        them, so one session's burst never holds up the other sessions for more than a few frames."""
        s = self.session
        frame = s.frame_bytes
        step = max(1, int(FAIR_SLICE_S * s.config.sample_rate_hz)) * frame
        if len(data) % frame:
            return await self.feed_bytes(data)  # a partial sample raises the AudioFormatError naming it
        if len(data) <= step:
            await self._pace(len(data) // frame)
            return await self.feed_bytes(data)
        n = 0
        for i in range(0, len(data), step):
            if self.ended.is_set():  # shutting down: what was processed is flushed, the rest dropped
                break
            piece = data[i : i + step]
            await self._pace(len(piece) // frame)
            n += await self.feed_bytes(piece)
            await asyncio.sleep(0)
        return n

    async def _pace(self, samples: int) -> None:
        """Hold an ingest to real time plus its burst (:class:`server.guard.IngestPacer`): wait, or
        raise IngestOverrun when the server is set to close overrunning ingests."""
        if self.pacer is None:
            return
        loop = asyncio.get_running_loop()
        wait = self.pacer.delay(samples / self.session.config.sample_rate_hz, loop.time())
        if wait <= 0:
            return
        if self.overrun == "close":
            raise IngestOverrun(
                f"ingest ran over {self.pacer.burst_s:g} s ahead of real time "
                '(send in real time, or start with "batch": true)'
            )
        self.paced_s += wait
        with contextlib.suppress(TimeoutError):  # a shutdown (ended) cuts the wait short
            await asyncio.wait_for(self.ended.wait(), wait)

    async def feed(self, samples: np.ndarray) -> int:
        """(n,) or (n, channels) float samples -> frames produced."""
        self._set_precompute()
        return self._fanout(await self.session.push(samples))

    async def finish(self) -> int:
        """End of the audio: flush the remaining frames to the viewers."""
        out = await self.session.flush()
        self.server.turn_deltas.flush()  # what waits for the turn's end goes first, then the last frames
        return self._fanout_now(out)

    async def control(self, msg: dict) -> dict:
        """Apply a control message (ControlError if rejected); returns the control state."""
        return await self.session.apply_control(msg)

    async def send_sentence(self, ws: ServerConnection, kind: int, encoding: int, audio: bool) -> None:
        """Send a joining viewer the sentence now playing (text sessions: :class:`SentenceReplay`) from
        its first frame until caught up with the fan-out, each audio block before its frame as the
        fan-out sends them. The caller registers the viewer right after, with no await in between,
        so the viewer then gets every later output once. Straight to the socket, not through the
        viewer's bounded queue: a sentence is more messages than the queue holds."""
        replay = self.replay
        if replay is None or not replay.playing(time.perf_counter()):
            return
        nxt = -1
        while outs := replay.since(nxt):
            for msg in _replay_messages(outs, kind, encoding, audio):
                await ws.send(msg)
            nxt = outs[-1].frames[-1].index + 1

    def sentence_messages(self, kind: int, encoding: int, audio: bool) -> list[bytes]:
        """The sentence now playing as :meth:`send_sentence` would send it now, all at once ([] when none
        is playing): a viewer joining on another node is sent these (server.cluster.Cluster.replay)."""
        replay = self.replay
        if replay is None or not replay.playing(time.perf_counter()):
            return []
        return list(_replay_messages(replay.since(-1), kind, encoding, audio))

    def _fanout(self, out: Output) -> int:
        """Hand one push's frames and audio to the viewers (here and, with a cluster, on other nodes).

        When the frames need vertex deltas computed on this loop, the whole output waits for the end
        of the loop turn (:class:`TurnDeltas`), so the deltas of every session served in the turn are
        computed back to back; a session with output waiting queues behind it (its order is kept)."""
        turn = self.server.turn_deltas
        if turn.holds(self) or (out.frames and self._deltas_here()):
            turn.add(self, out)
            return len(out.frames)
        return self._fanout_now(out)

    def _deltas_here(self) -> bool:
        """Whether this session's frames get vertex deltas computed on this loop (a local session with
        a delta viewer; a compute worker's session brings them ready)."""
        return isinstance(self.session, LocalSession) and any(v.kind == P.KIND_DELTAS for v in self.viewers)

    def _fanout_now(self, out: Output) -> int:
        if self.replay is not None:
            self.replay.add(out)
        cluster = self.server.cluster
        remote = cluster.wants(self.name) if cluster is not None else ()
        if not self.viewers and not remote:
            return len(out.frames)
        t0 = time.perf_counter()
        now = time.time()
        if out.audio is not None:
            listeners = [v for v in self.viewers if v.audio]
            if listeners or (P.KIND_AUDIO, P.ENC_INT16) in remote:
                msg = audio_message(out, now)
                deliver(listeners, msg, now)
                if remote and cluster is not None:  # remote is empty without a cluster
                    cluster.publish(self.name, msg)
        if out.frames:
            groups: dict[tuple[int, int], list[Viewer]] = {k: [] for k in remote if k[0] != P.KIND_AUDIO}
            for v in self.viewers:
                groups.setdefault((v.kind, v.encoding), []).append(v)
            for frame in out.frames:
                for (kind, enc), members in groups.items():
                    payload, count, scale = frame.payload(kind, enc)
                    msg = P.pack_header(kind, enc, frame.index, count, scale, frame.media_time, now) + payload
                    deliver(members, msg, now)
                    if cluster is not None and (kind, enc) in remote:
                        cluster.publish(self.name, msg)
        self.server.times.add("fanout", time.perf_counter() - t0)
        return len(out.frames)

    def describe(self) -> dict:
        return summary(self)


class TurnDeltas:
    """Outputs whose vertex deltas are computed at the end of the event loop's turn, together.

    Why: a vertex viewer's frame costs the morph head's keyframe solve, a (19, 8319) product over
    632 KB of float32 targets and the int16 encoding; on a busy loop each of those starts cold (the
    other sessions' work has evicted the targets and the code's data), ~170 us a frame, while the
    same work for several frames back to back costs ~70-100 us each (docs/service.md, "Vertex deltas
    by loop turn"). So instead of encoding deltas in each connection's callback, a session with a
    delta viewer queues its output here; one callback per turn (scheduled with ``call_soon``, so it
    runs before the next turn's I/O callbacks) computes every queued frame's deltas, then fans the
    outputs out in the order they came. Each frame is computed by the same call as before
    (:meth:`server.session.Frame.payload`), so the bytes are the same; what changes is when: at the
    end of the turn instead of in the middle, at most one turn's work later. ``flush`` is also called
    directly where the order with a later message matters (a session's last frames, its end)."""

    def __init__(self) -> None:
        self.pending: list[tuple[LiveSession, Output]] = []
        self._holding: set[LiveSession] = set()
        self.batches = 0  # flushes that computed deltas, and the frames they held (metrics, tests)
        self.frames = 0

    def holds(self, live: LiveSession) -> bool:
        return live in self._holding

    def add(self, live: LiveSession, out: Output) -> None:
        if not self.pending:
            asyncio.get_running_loop().call_soon(self.flush)
        self.pending.append((live, out))
        self._holding.add(live)

    def flush(self) -> None:
        """Compute the queued frames' deltas, then fan every queued output out, in order."""
        pending, self.pending = self.pending, []
        self._holding.clear()
        if not pending:
            return
        n = 0
        # Morph-target heads' frames, by (rig, encoding): each group in one compiled pass over the
        # targets (server.session.morph_delta_payloads: the same bytes as frame by frame).
        morph: dict[tuple[int, int], list[VideoFrame]] = {}
        for live, out in pending:
            kinds = {(v.kind, v.encoding) for v in live.viewers if v.kind == P.KIND_DELTAS}
            for frame in out.frames:
                for kind, enc in kinds:
                    if isinstance(frame.rig, MorphRig):
                        morph.setdefault((id(frame.rig), enc), []).append(frame)
                    else:
                        with contextlib.suppress(Exception):  # a failing payload raises again in the fan-out, logged
                            frame.payload(kind, enc)
                n += 1 if kinds else 0
        for (_, enc), frames in morph.items():
            with contextlib.suppress(Exception):  # as above: the fan-out's own call raises it again, logged
                morph_delta_payloads(frames, enc)
        if n:
            self.batches += 1
            self.frames += n
        for live, out in pending:
            try:
                live._fanout_now(out)
            except Exception:  # a bug: logged, and the other sessions' frames still go out
                log.exception("fan-out of session %r failed", live.name)
