"""The service protocol without I/O: ingest and view connections as state machines.

Theory of operation
-------------------
Like h11 or python-websockets' ``protocol.py``, this module reads no socket and no clock. The
asyncio shell (:mod:`server.app`) feeds an :class:`IngestProtocol` the events of one ingest
connection (a text or binary message arrived, the start timer ran out, the peer went away, the
server is stopping, and the outcomes of the work it asked for) and performs the actions it returns,
in order:

=================  =====================================================================
action             what the shell does
=================  =====================================================================
``Send(msg)``      send the JSON text message ``msg`` to the peer
``Close(c, r)``    close the connection with code ``c`` and reason ``r``; nothing follows
``Open(n, cfg)``   open session ``n`` (admission may refuse: :meth:`IngestProtocol.refused`)
``Feed(data)``     push one binary block into the session (:meth:`IngestProtocol.audio_rejected`)
``Control(msg)``   apply a control message (:meth:`control_applied` / :meth:`control_rejected`)
``Finish()``       flush the session's last frames to its viewers, then :meth:`finished`
=================  =====================================================================

The states are ``AWAIT_START -> OPENING -> STREAMING -> FINISHING -> CLOSED``. Every protocol
breach yields a ``Close`` with a code from :mod:`wire.protocol` and a reason naming the problem;
:attr:`IngestProtocol.viewer_close` is what the session's viewers are told when it ends.

Extending: a *session kind* (:data:`SESSION_KINDS`, chosen by the start message's ``input`` field,
default ``"audio"``) names its extra start fields, builds its session configuration and says
whether binary messages are its input; text message types after the start are dispatched through
:data:`MESSAGE_TYPES` (``control``, ``end``). A text-driven session adds a kind and a message type.

:func:`parse_view_query` turns a ``/view`` query string into a :class:`ViewRequest` or raises
:class:`~server.errors.ProtocolViolation` with the close code (:func:`view_wait_s` reads its ``wait``);
:func:`loads_bounded` parses client JSON with size and depth limits (a protocol error, never a RecursionError).
"""

from __future__ import annotations

import enum
import hmac
import json
import math
import urllib.parse
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from server.errors import ProtocolViolation, ServerConfigError, reason_value
from server.session import SessionConfig
from wire import protocol as P

MAX_JSON_DEPTH = 8  # control and start messages nest two levels; anything deeper is hostile
MAX_TEXT_BYTES = 64 * 1024  # a text message is a start/control/end object, never this big
MAX_START_BYTES = 64 << 20
"""A start message may carry an enrolment recording (base64 ``enrol``): it is bounded by the server's
``max_message_bytes`` (the WebSocket limit, 4 MiB by default: 60 s of up to 24 kHz pcm_s16le mono)
rather than by MAX_TEXT_BYTES; its nesting is still bounded."""


# -- actions (what the shell must do) ----------------------------------------------------------------


@dataclass(frozen=True)
class Send:
    message: dict


@dataclass(frozen=True)
class Close:
    code: int
    reason: str


@dataclass(frozen=True)
class Open:
    name: str
    config: SessionConfig
    kind: str
    batch: bool = False


@dataclass(frozen=True)
class Feed:
    data: bytes


@dataclass(frozen=True)
class Control:
    message: dict


@dataclass(frozen=True)
class Finish:
    pass


Action = Send | Close | Open | Feed | Control | Finish


# -- bounded JSON --------------------------------------------------------------------------------------


def json_depth_exceeds(text: str, limit: int) -> bool:
    """True if ``text`` nests arrays/objects deeper than ``limit`` (brackets inside strings ignored).

    O(n) in the worst case, but the common message has few brackets and returns at once."""
    if text.count("[") + text.count("{") <= limit:
        return False
    depth = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > limit:
                return True
        elif ch in "]}":
            depth -= 1
    return False


def loads_bounded(text: str, what: str, *, max_bytes: int = MAX_TEXT_BYTES, max_depth: int = MAX_JSON_DEPTH) -> dict:
    """Client JSON text -> dict, or ProtocolViolation (1009 too big, 1007 malformed / too deep / not an object)."""
    if len(text) > max_bytes:
        raise ProtocolViolation(P.CLOSE_TOO_BIG, f"{what} is over {max_bytes} bytes")
    if json_depth_exceeds(text, max_depth):
        raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, f"{what} nests deeper than {max_depth} levels")
    try:
        obj = json.loads(text)
    except (ValueError, RecursionError):
        raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, f"{what} is not valid JSON") from None
    if not isinstance(obj, dict):
        raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, f"{what} must be a JSON object")
    return obj


def token_ok(given: object, want: str | None) -> bool:
    """Constant-time token check; True when the server has no token."""
    if want is None:
        return True
    return isinstance(given, str) and hmac.compare_digest(given.encode(), want.encode())


# -- session kinds -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SessionKind:
    """How a start message of this kind becomes a session configuration.

    fields: start-message fields this kind accepts besides type/session/token/input;
    build: (start message, server lag) -> session configuration (ServerConfigError if invalid);
    binary_input: True if binary messages after the start are the session's input."""

    fields: frozenset[str]
    build: Callable[[dict, int], SessionConfig]
    binary_input: bool = True


def _audio_config(start: dict, lag: int) -> SessionConfig:
    if "sample_rate" not in start:
        raise ServerConfigError("start message lacks sample_rate")
    return SessionConfig(
        sample_rate_hz=start["sample_rate"],
        channels=start.get("channels", 1),
        sample_format=start.get("format", "pcm_s16le"),
        lag=lag,
        enrol=start.get("enrol"),
        auto_gain=start.get("auto_gain"),
    )


SESSION_KINDS: dict[str, SessionKind] = {
    "audio": SessionKind(
        fields=frozenset({"sample_rate", "format", "channels", "enrol", "auto_gain"}), build=_audio_config
    ),
}
"""Start-message ``input`` value -> session kind (``"audio"`` when absent)."""

COMMON_START_FIELDS = frozenset({"type", "session", "token", "input", "batch"})


# -- ingest ----------------------------------------------------------------------------------------------


class State(enum.Enum):
    AWAIT_START = "await_start"
    OPENING = "opening"
    STREAMING = "streaming"
    FINISHING = "finishing"
    CLOSED = "closed"


MessageHandler = Callable[["IngestProtocol", dict], list[Action]]

MESSAGE_TYPES: dict[str, MessageHandler] = {}
"""Text message ``type`` after the start -> handler (``control``, ``end``; extensible)."""


def message_type(name: str) -> Callable[[MessageHandler], MessageHandler]:
    def register(handler: MessageHandler) -> MessageHandler:
        MESSAGE_TYPES[name] = handler
        return handler

    return register


class IngestProtocol:
    """One ingest connection's state machine. token: the server's shared secret (None = open);
    lag: the server's extra smoothing frames for every session."""

    def __init__(self, *, token: str | None = None, lag: int = 0) -> None:
        self.token = token
        self.lag = lag
        self.state = State.AWAIT_START
        self.name: str | None = None
        self.kind: SessionKind | None = None
        self.viewer_close = (P.CLOSE_NORMAL, "session ended")
        self._ending_reply = True  # "ended" is sent for an end message, not for a shutdown

    # events from the peer

    def receive(self, message: str | bytes) -> list[Action]:
        """A message arrived from the peer."""
        try:
            if self.state is State.AWAIT_START:
                return self._start(message)
            if self.state is not State.STREAMING:
                return []  # after Finish/Close the shell stops reading; late messages are moot
            if isinstance(message, (bytes, bytearray, memoryview)):
                if self.kind is None or not self.kind.binary_input:
                    raise ProtocolViolation(P.CLOSE_UNSUPPORTED_DATA, "this session takes no binary messages")
                return [Feed(bytes(message))]
            if len(message) > MAX_TEXT_BYTES:
                raise ProtocolViolation(P.CLOSE_TOO_BIG, f"text message is over {MAX_TEXT_BYTES} bytes")
            if json_depth_exceeds(message, MAX_JSON_DEPTH):
                raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, f"message nests deeper than {MAX_JSON_DEPTH} levels")
            try:
                msg = json.loads(message)
            except (ValueError, RecursionError):
                raise ProtocolViolation(
                    P.CLOSE_UNSUPPORTED_DATA, "text message is not JSON: audio must be sent as binary messages"
                ) from None
            if not isinstance(msg, dict):
                raise ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, "a control message must be a JSON object")
            kind = msg.get("type")
            if kind == "start":
                raise ProtocolViolation(P.CLOSE_POLICY, "second start message: the session has started")
            handler = MESSAGE_TYPES.get(kind) if isinstance(kind, str) else None
            if handler is None:
                raise ProtocolViolation(
                    P.CLOSE_POLICY, f"unknown message type {reason_value(kind)} (expected {' or '.join(MESSAGE_TYPES)})"
                )
            return handler(self, msg)
        except ProtocolViolation as exc:
            return self._violation(exc)

    def start_timed_out(self, timeout_s: float) -> list[Action]:
        """No start message within the start timeout."""
        if self.state is not State.AWAIT_START:
            return []
        return self._violation(ProtocolViolation(P.CLOSE_POLICY, f"no start message within {timeout_s:g} s"))

    def feeds_binary(self) -> bool:
        """Whether a binary message now would be answered by exactly ``[Feed(message)]`` (the shell
        may then feed it without calling :meth:`receive`)."""
        return self.state is State.STREAMING and self.kind is not None and self.kind.binary_input

    def idle_timed_out(self, timeout_s: float) -> list[Action]:
        """A started ingest sent nothing for ``timeout_s``."""
        if self.state is not State.STREAMING:
            return []
        return self._violation(ProtocolViolation(P.CLOSE_POLICY, f"idle: no message for {timeout_s:g} s"))

    def too_fast(self, reason: str) -> list[Action]:
        """The ingest ran ahead of real time beyond its burst and the server closes rather than paces."""
        return self._violation(ProtocolViolation(P.CLOSE_TOO_FAST, reason))

    def connection_lost(self) -> list[Action]:
        """The peer hung up (without an end message): finish what it sent."""
        if self.state is State.STREAMING:
            self.state = State.FINISHING
            self._ending_reply = False
            return [Finish()]
        self.state = State.CLOSED
        return []

    def shutdown(self) -> list[Action]:
        """The server is stopping: flush the session, then close with 1001."""
        if self.state is State.STREAMING:
            self.state = State.FINISHING
            self._ending_reply = False
            self.viewer_close = (P.CLOSE_GOING_AWAY, "server shutting down")
            return [Finish()]
        if self.state is State.CLOSED:
            return []
        self.state = State.CLOSED
        return [Close(P.CLOSE_GOING_AWAY, "server shutting down")]

    # outcomes of the shell's work

    def opened(self, started: dict) -> list[Action]:
        """The session is open: ``started`` is its description for the peer."""
        self.state = State.STREAMING
        return [Send({"type": "started", **started})]

    def refused(self, code: int, reason: str) -> list[Action]:
        """Admission refused the session (full, name taken)."""
        self.state = State.CLOSED
        return [Close(code, reason)]

    def audio_rejected(self, reason: str) -> list[Action]:
        """A fed block was not usable audio: the source broke the protocol."""
        return self._violation(ProtocolViolation(P.CLOSE_INVALID_PAYLOAD, reason))

    def control_applied(self, state: dict) -> list[Action]:
        return [Send({"type": "ack", "controls": state})]

    def control_rejected(self, reason: str) -> list[Action]:
        return [Send({"type": "rejected", "reason": reason})]

    def finished(self, frames: int, audio_s: float) -> list[Action]:
        """The session's last frames went out to its viewers."""
        if self.state is State.CLOSED:
            return []
        self.state = State.CLOSED
        if self._ending_reply:
            return [Send({"type": "ended", "frames": frames, "audio_s": audio_s}), Close(*self.viewer_close)]
        return [Close(*self.viewer_close)]

    # internals

    def _start(self, message: str | bytes) -> list[Action]:
        if not isinstance(message, str):
            raise ProtocolViolation(P.CLOSE_UNSUPPORTED_DATA, "expected a JSON start message (text) first, got binary")
        # Only a start message carrying an enrolment recording may exceed MAX_TEXT_BYTES.
        limit = MAX_START_BYTES if len(message) > MAX_TEXT_BYTES and '"enrol"' in message else MAX_TEXT_BYTES
        start = loads_bounded(message, "start message", max_bytes=limit)
        if start.get("type") != "start":
            raise ProtocolViolation(
                P.CLOSE_POLICY, f'first message must be {{"type": "start"}}, got type {reason_value(start.get("type"))}'
            )
        if not token_ok(start.get("token"), self.token):
            raise ProtocolViolation(P.CLOSE_UNAUTHORIZED, "missing or wrong token")
        input_kind = start.get("input", "audio")
        kind = SESSION_KINDS.get(input_kind) if isinstance(input_kind, str) else None
        if kind is None:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"input must be one of {sorted(SESSION_KINDS)}")
        unknown = sorted(set(start) - COMMON_START_FIELDS - kind.fields)
        if unknown:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"unknown start fields {reason_value(unknown[:5])}")
        name = start.get("session")
        if not isinstance(name, str) or not P.SESSION_NAME.match(name):
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, P.SESSION_NAME_RULE)
        batch = start.get("batch", False)
        if not isinstance(batch, bool):
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, "batch must be true or false")
        try:
            config = kind.build(start, self.lag)
        except ServerConfigError as exc:
            raise ProtocolViolation(P.CLOSE_BAD_REQUEST, str(exc)) from None
        self.state = State.OPENING
        self.name, self.kind = name, kind
        return [Open(name, config, str(input_kind), batch)]

    def _violation(self, exc: ProtocolViolation) -> list[Action]:
        if self.state in (State.STREAMING, State.FINISHING):
            # The session ends where it is (no flush); its viewers are told why in one line.
            self.viewer_close = (P.CLOSE_NORMAL, "session ended: its source broke the protocol")
        self.state = State.CLOSED
        return [Close(exc.code, exc.reason)]


@message_type("control")
def _on_control(proto: IngestProtocol, msg: dict) -> list[Action]:
    return [Control(msg)]


@message_type("end")
def _on_end(proto: IngestProtocol, msg: dict) -> list[Action]:
    proto.state = State.FINISHING
    return [Finish()]


CLOSE_REASON_BYTES = 123
"""A close frame's payload is at most 125 bytes (RFC 6455 5.5): the 2-byte code, then the reason."""


def fit_close_reason(reason: str) -> str:
    """``reason`` cut to at most :data:`CLOSE_REASON_BYTES` of UTF-8, at a character boundary.

    Counted in bytes, not characters: a reason quoting a client's non-ASCII value (up to 4 bytes a
    character) would otherwise make the close frame too long, and websockets would raise instead of
    closing (an internal error for what is a protocol error). A lone surrogate (JSON allows
    ``"\\ud800"``) cannot be encoded at all: it becomes "?"."""
    data = reason.encode("utf-8", "replace")[:CLOSE_REASON_BYTES]
    return data.decode("utf-8", "ignore")  # "ignore" drops a character the cut split


# -- view ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ViewRequest:
    """A parsed ``/view`` query: session name, subscription kind and encoding names, their header
    kind/encoding numbers, and whether the session's audio is relayed too."""

    session: str
    kind: str
    encoding: str
    header_kind: int
    header_encoding: int
    audio: bool


def query_args(path: str) -> dict[str, str]:
    """The query of a request path as {name: last value} (bounded: at most 32 fields)."""
    query = urllib.parse.urlsplit(path).query
    try:
        pairs = urllib.parse.parse_qsl(query, max_num_fields=32)
    except ValueError:
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, "too many query fields") from None
    return dict(pairs)


VIEWER_CONTROLS = frozenset({"type", "expression", "expression_ease_s"})
"""The only message a viewer may send: an expression control (the browser viewer's picker)."""


def parse_viewer_message(message: object) -> dict:
    """A viewer's message -> the control to apply; ProtocolViolation (1008) for anything but an
    expression control (size and nesting bounded like every client text)."""
    if not isinstance(message, str):
        raise ProtocolViolation(P.CLOSE_POLICY, "viewers send only expression controls (got a binary message)")
    try:
        msg = loads_bounded(message, "viewer message")
    except ProtocolViolation as exc:  # not a (bounded) JSON object: a viewer talking out of turn
        raise ProtocolViolation(P.CLOSE_POLICY, f"viewers send only expression controls ({exc.reason})") from None
    if msg.get("type") != "control" or not set(msg) <= VIEWER_CONTROLS or len(msg) < 2:
        raise ProtocolViolation(
            P.CLOSE_POLICY, 'viewers send only expression controls ({"type": "control", "expression": {...}})'
        )
    return msg


def parse_view_query(
    args: Mapping[str, str], *, token: str | None, has_head: bool, morph_head: bool = False
) -> ViewRequest:
    """A viewer's query -> ViewRequest, or ProtocolViolation with the close code and reason.
    has_head: the server has a head (vertex deltas); morph_head: it is driven by its own morph targets."""
    if not token_ok(args.get("token"), token):
        raise ProtocolViolation(P.CLOSE_UNAUTHORIZED, "missing or wrong token")
    name = args.get("session")
    # 4400, not 4004: a client retries 4004 (the session may start), never a query that cannot name a session
    if name is None:
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, "the view query needs session=NAME")
    if not P.SESSION_NAME.match(name):
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"{P.SESSION_NAME_RULE}, got {reason_value(name)}")
    kind = args.get("kind", "params")
    encodings = P.VIEW_KINDS.get(kind)
    if encodings is None:
        raise ProtocolViolation(
            P.CLOSE_BAD_REQUEST, f"kind must be one of {sorted(P.VIEW_KINDS)}, got {reason_value(kind)}"
        )
    enc_name = args.get("encoding", next(iter(encodings)))
    if enc_name not in encodings:
        raise ProtocolViolation(
            P.CLOSE_BAD_REQUEST, f"encoding for {kind} must be one of {sorted(encodings)}, got {reason_value(enc_name)}"
        )
    if kind in ("deltas", "morph") and not has_head:
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"this server has no head rig: {kind} are unavailable")
    if kind == "morph" and not morph_head:
        raise ProtocolViolation(
            P.CLOSE_BAD_REQUEST, "this server's head has no morph targets it drives: ask for deltas (or params)"
        )
    audio = args.get("audio", "1")
    if audio not in ("0", "1"):
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, "audio must be 0 or 1")
    hk, he = encodings[enc_name]
    return ViewRequest(name, kind, enc_name, hk, he, audio == "1")


def view_wait_s(args: Mapping[str, str], *, longest_s: float) -> float:
    """A viewer query's ``wait``: seconds to hold the viewer for a session that has not started (0: answer 4004
    at once, as without it), cut to the server's ``longest_s``; ProtocolViolation (4400) unless a number >= 0.
    Kept out of :class:`ViewRequest`: that is the key of a session's cached descriptions, which a wait does not
    change."""
    raw = args.get("wait")
    if raw is None:
        return 0.0
    try:
        wait = float(raw)
    except ValueError:
        wait = math.nan
    if not wait >= 0 or math.isinf(wait):  # NaN fails the comparison
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"wait must be a number of seconds >= 0, got {reason_value(raw)}")
    return min(wait, longest_s)
