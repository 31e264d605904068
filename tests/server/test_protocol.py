"""The sans-I/O service protocol from tables, without sockets (as h11's tests do).

Each row feeds an :class:`IngestProtocol` a sequence of events and checks the actions it answers
with: replies, close codes and reasons, and the work it asks the shell to do.
"""

from __future__ import annotations

import json

import pytest

from server import protocol as SP
from server.errors import ProtocolViolation
from server.protocol import Close, Control, Feed, Finish, Open, Send, State
from wire import protocol as P

START = {"type": "start", "session": "s", "sample_rate": 16000, "format": "pcm_s16le"}


def _start(**kw) -> str:
    msg = dict(START, **kw)
    return json.dumps({k: v for k, v in msg.items() if v is not None})


def _opened(token: str | None = None) -> SP.IngestProtocol:
    proto = SP.IngestProtocol(token=token)
    (action,) = proto.receive(_start(token=token))
    assert isinstance(action, Open)
    assert proto.opened({"session": "s"}) == [Send({"type": "started", "session": "s"})]
    return proto


# (name, first message, server token, close code, words of the reason)
START_REFUSALS = [
    ("binary first", b"\x00\xff", None, P.CLOSE_UNSUPPORTED_DATA, "expected a JSON start"),
    ("not json", "{garbage", None, P.CLOSE_INVALID_PAYLOAD, "not valid JSON"),
    ("json list", "[1, 2]", None, P.CLOSE_INVALID_PAYLOAD, "must be a JSON object"),
    ("deep json", "[" * 30000 + "]" * 30000, None, P.CLOSE_INVALID_PAYLOAD, "nests deeper"),
    (
        "deep in object",
        '{"type": "start", "x": ' + "[" * 50 + "]" * 50 + "}",
        None,
        P.CLOSE_INVALID_PAYLOAD,
        "nests deeper",
    ),
    ("huge text", json.dumps({"type": "start", "pad": "x" * 70000}), None, P.CLOSE_TOO_BIG, "over"),
    ("wrong type", json.dumps({"type": "control"}), None, P.CLOSE_POLICY, "first message must be"),
    ("no rate", _start(sample_rate=None), None, P.CLOSE_BAD_REQUEST, "lacks sample_rate"),
    ("absurd rate", _start(sample_rate=10**9), None, P.CLOSE_BAD_REQUEST, "sample_rate must be"),
    ("bool rate", _start(sample_rate=True), None, P.CLOSE_BAD_REQUEST, "sample_rate must be"),
    ("bad format", _start(format="mp3"), None, P.CLOSE_BAD_REQUEST, "format must be one of"),
    ("bad channels", _start(channels=99), None, P.CLOSE_BAD_REQUEST, "channels must be"),
    ("unknown field", _start(colour="red"), None, P.CLOSE_BAD_REQUEST, "unknown start fields ['colour']"),
    ("unknown input", _start(input="smell"), None, P.CLOSE_BAD_REQUEST, "input must be one of"),
    ("bad name", _start(session="../etc"), None, P.CLOSE_BAD_REQUEST, "session must be 1-64"),
    ("long name", _start(session="x" * 65), None, P.CLOSE_BAD_REQUEST, "session must be 1-64"),
    ("no token", _start(), "sesame", P.CLOSE_UNAUTHORIZED, "token"),
    ("wrong token", _start(token="nope"), "sesame", P.CLOSE_UNAUTHORIZED, "token"),
    ("token not a string", _start(token=["sesame"]), "sesame", P.CLOSE_UNAUTHORIZED, "token"),
]


@pytest.mark.parametrize("name, first, token, code, words", START_REFUSALS, ids=[r[0] for r in START_REFUSALS])
def test_start_refusals(name, first, token, code, words):
    proto = SP.IngestProtocol(token=token)
    actions = proto.receive(first)
    assert len(actions) == 1 and isinstance(actions[0], Close), actions
    assert actions[0].code == code
    assert words in actions[0].reason
    assert len(actions[0].reason.encode()) <= 123  # fits a close frame
    assert proto.state is State.CLOSED


def test_a_good_start_opens_with_the_right_config():
    proto = SP.IngestProtocol(token="sesame", lag=2)
    (action,) = proto.receive(_start(sample_rate=48000, format="f32le", channels=2, token="sesame"))
    assert isinstance(action, Open) and action.name == "s" and action.kind == "audio"
    cfg = action.config
    assert (cfg.sample_rate_hz, cfg.sample_format, cfg.channels, cfg.lag) == (48000, "f32le", 2, 2)
    assert proto.state is State.OPENING
    assert proto.refused(P.CLOSE_CONFLICT, "taken") == [Close(P.CLOSE_CONFLICT, "taken")]
    assert proto.state is State.CLOSED


# (name, message after the start, expected actions; None = a Close whose code and words are given)
STREAMING = [
    ("audio", b"\x00\x01", [Feed(b"\x00\x01")], None, None),
    (
        "control",
        json.dumps({"type": "control", "gain": {"mouth_open": 2}}),
        [Control({"type": "control", "gain": {"mouth_open": 2}})],
        None,
        None,
    ),
    ("end", json.dumps({"type": "end"}), [Finish()], None, None),
    ("text audio", "hello", None, P.CLOSE_UNSUPPORTED_DATA, "audio must be sent as binary"),
    ("array", "[1]", None, P.CLOSE_INVALID_PAYLOAD, "must be a JSON object"),
    ("second start", _start(), None, P.CLOSE_POLICY, "second start"),
    ("unknown type", json.dumps({"type": "dance"}), None, P.CLOSE_POLICY, "unknown message type 'dance'"),
    ("type not a string", json.dumps({"type": {"a": 1}}), None, P.CLOSE_POLICY, "unknown message type"),
    (
        "deep control",
        '{"type": "control", "gain": ' + "[" * 5000 + "]" * 5000 + "}",
        None,
        P.CLOSE_INVALID_PAYLOAD,
        "nests deeper",
    ),
    ("huge control", json.dumps({"type": "control", "x": "y" * 70000}), None, P.CLOSE_TOO_BIG, "over"),
]


@pytest.mark.parametrize("name, message, want, code, words", STREAMING, ids=[r[0] for r in STREAMING])
def test_streaming_messages(name, message, want, code, words):
    proto = _opened()
    actions = proto.receive(message)
    if want is not None:
        assert actions == want
        return
    assert len(actions) == 1 and isinstance(actions[0], Close)
    assert (actions[0].code, words in actions[0].reason) == (code, True), actions
    assert proto.state is State.CLOSED
    # The session's viewers are told the source broke the protocol, with a normal close.
    assert proto.viewer_close == (P.CLOSE_NORMAL, "session ended: its source broke the protocol")


def test_end_then_finished_replies_ended_and_closes_normally():
    proto = _opened()
    assert proto.receive(json.dumps({"type": "end"})) == [Finish()]
    assert proto.state is State.FINISHING
    assert proto.receive(b"late audio") == []  # after the end nothing more is read
    assert proto.finished(30, 1.0) == [
        Send({"type": "ended", "frames": 30, "audio_s": 1.0}),
        Close(P.CLOSE_NORMAL, "session ended"),
    ]
    assert proto.finished(30, 1.0) == []


def test_controls_are_acked_or_rejected_and_the_session_goes_on():
    proto = _opened()
    assert proto.control_applied({"smoothing_ms": 1.0}) == [Send({"type": "ack", "controls": {"smoothing_ms": 1.0}})]
    assert proto.control_rejected("no") == [Send({"type": "rejected", "reason": "no"})]
    assert proto.state is State.STREAMING


def test_bad_audio_closes_1007():
    proto = _opened()
    assert proto.audio_rejected("not a whole number") == [Close(P.CLOSE_INVALID_PAYLOAD, "not a whole number")]
    assert proto.state is State.CLOSED


def test_shutdown_and_hangup():
    proto = _opened()
    assert proto.shutdown() == [Finish()]
    assert proto.finished(3, 0.1) == [Close(P.CLOSE_GOING_AWAY, "server shutting down")]  # no "ended" reply
    waiting = SP.IngestProtocol()
    assert waiting.shutdown() == [Close(P.CLOSE_GOING_AWAY, "server shutting down")]
    hung = _opened()
    assert hung.connection_lost() == [Finish()]
    assert hung.finished(3, 0.1) == [Close(P.CLOSE_NORMAL, "session ended")]


def test_start_timeout():
    proto = SP.IngestProtocol()
    assert proto.start_timed_out(0.5) == [Close(P.CLOSE_POLICY, "no start message within 0.5 s")]
    assert _opened().start_timed_out(0.5) == []


# (query, token, has_head ("morph": a head driven by its own targets), close code or None, words of the
# reason / expected (kind, encoding, audio))
VIEW_QUERIES = [
    ("session=a", None, False, None, ("params", "float32", True)),
    ("session=a&kind=deltas", None, True, None, ("deltas", "int16", True)),
    ("session=a&kind=deltas&encoding=float16&audio=0", None, True, None, ("deltas", "float16", False)),
    ("session=a&kind=blendshapes&encoding=ovr15", None, False, None, ("blendshapes", "ovr15", True)),
    ("session=a&kind=deltas", None, False, P.CLOSE_BAD_REQUEST, "no head rig"),
    ("session=a&kind=morph", None, "morph", None, ("morph", "float32", True)),
    ("session=a&kind=morph&encoding=float16", None, "morph", None, ("morph", "float16", True)),
    ("session=a&kind=morph", None, True, P.CLOSE_BAD_REQUEST, "no morph targets"),
    ("session=a&kind=morph", None, False, P.CLOSE_BAD_REQUEST, "no head rig"),
    ("session=a&kind=smell", None, False, P.CLOSE_BAD_REQUEST, "kind must be"),
    ("session=a&kind=params&encoding=int8", None, False, P.CLOSE_BAD_REQUEST, "encoding for params"),
    ("session=a&audio=yes", None, False, P.CLOSE_BAD_REQUEST, "audio must be 0 or 1"),
    ("session=a", "sesame", False, P.CLOSE_UNAUTHORIZED, "token"),
    ("session=a&token=nope", "sesame", False, P.CLOSE_UNAUTHORIZED, "token"),
    ("session=a&token=sesame", "sesame", False, None, ("params", "float32", True)),
    ("", None, False, P.CLOSE_BAD_REQUEST, "needs session=NAME"),
    ("kind=params", None, False, P.CLOSE_BAD_REQUEST, "needs session=NAME"),
    ("session=", None, False, P.CLOSE_BAD_REQUEST, "needs session=NAME"),
    ("session=" + "x" * 500, None, False, P.CLOSE_BAD_REQUEST, "session must be 1-64 characters"),
    ("session=a%20b", None, False, P.CLOSE_BAD_REQUEST, "got 'a b'"),
    ("&".join(f"f{i}=1" for i in range(100)), None, False, P.CLOSE_BAD_REQUEST, "too many query fields"),
]


@pytest.mark.parametrize("query, token, has_head, code, want", VIEW_QUERIES)
def test_view_queries(query, token, has_head, code, want):
    try:
        req = SP.parse_view_query(
            SP.query_args("/view?" + query), token=token, has_head=bool(has_head), morph_head=has_head == "morph"
        )
    except ProtocolViolation as exc:
        assert code is not None, f"refused: {exc}"
        assert exc.code == code and want in exc.reason
        assert len(exc.reason.encode()) <= 123
        return
    assert code is None, f"accepted {req}"
    assert (req.kind, req.encoding, req.audio) == want
    assert (req.header_kind, req.header_encoding) == P.VIEW_KINDS[req.kind][req.encoding]


def test_json_depth_scan_ignores_brackets_in_strings():
    assert not SP.json_depth_exceeds(json.dumps({"a": "[[[[[[[[[[[[[[[[[[[["}), 3)
    assert not SP.json_depth_exceeds(json.dumps({"a": '\\"[[[[[[[[[[[[[[[[[[[['}), 3)
    assert SP.json_depth_exceeds(json.dumps({"a": [[[[1]]]]}), 3)
    assert not SP.json_depth_exceeds(json.dumps({"a": [[[1]]]}), 4)


@pytest.mark.parametrize(
    "reason",
    [
        "ordinary reason",
        "x" * 200,
        "sample_rate must be an integer, got " + "\U000f44d1" * 40,  # 4-byte characters
        "é" * 70 + "x",  # a cut through a 2-byte character
        "lone surrogate \udb91 in a client's value",
    ],
)
def test_close_reasons_fit_a_close_frame(reason):
    """RFC 6455: a close frame carries at most 125 bytes, 2 of them the code; websockets raises on
    more (it did for a reason quoting a non-ASCII value: an internal error instead of a refusal)."""
    fitted = SP.fit_close_reason(reason)
    data = fitted.encode("utf-8")  # strict: what websockets does
    assert len(data) <= 123
    kept = reason.encode("utf-8", "replace")
    assert kept.startswith(data) and len(data) >= min(len(kept), 123) - 3  # a prefix, cut at most one character
