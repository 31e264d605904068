"""A viewer joining a remote text session (server.cluster.ReplayJoin): which messages it keeps, in which
order, and what happens without an answer. The whole path over a real redis-server and two processes is
tests/server/test_cluster.py::test_a_late_text_viewer_on_any_node_gets_the_sentence_so_far."""

from __future__ import annotations

import asyncio

from server.cluster import Cluster, ReplayJoin
from wire import protocol as P


def _msg(kind: int, encoding: int, index: int) -> bytes:
    return P.pack_header(kind, encoding, index, 0, 1.0, index / 30, 0.0)


def _keep(join: ReplayJoin, msg: bytes) -> None:
    join.live(msg, msg[1], msg[2])


def _drain(join: ReplayJoin) -> list[bytes]:
    """What the joining viewer is sent, in order (server.app's loop)."""
    out = []
    while (msg := join.next_message()) is not None:
        out.append(msg)
    return out


def test_live_messages_count_only_after_the_answer_and_only_of_the_viewers_kinds():
    join = ReplayJoin(P.KIND_PARAMS, P.ENC_FLOAT32, audio=True, limit=16)
    _keep(join, _msg(P.KIND_PARAMS, P.ENC_FLOAT32, 5))  # before the answer: in the sentence, or older
    join.replayed(b"s0")
    join.replayed(b"s1")
    join.answered.set()
    join.replayed(b"late")  # nothing of the answer after its done marker
    _keep(join, _msg(P.KIND_AUDIO, P.ENC_INT16, 6))
    _keep(join, _msg(P.KIND_ARKIT52, P.ENC_FLOAT32, 6))  # another viewer's kind
    _keep(join, _msg(P.KIND_PARAMS, P.ENC_FLOAT32, 6))
    assert _drain(join) == [
        b"s0",
        b"s1",
        _msg(P.KIND_AUDIO, P.ENC_INT16, 6),
        _msg(P.KIND_PARAMS, P.ENC_FLOAT32, 6),
    ]


async def _end_feed(feed) -> None:
    """Nothing to close here."""


def test_without_an_answer_the_viewer_joins_with_the_live_stream_only():
    async def main():
        cluster = Cluster(
            "redis://127.0.0.1:1/0",
            node="n",
            advertise="",
            heartbeat_s=1.0,
            deliver=lambda *a: None,
            end_feed=_end_feed,
        )  # never started: answer() uses no connection
        join = ReplayJoin(P.KIND_PARAMS, P.ENC_FLOAT32, audio=False, limit=16)
        join.replayed(b"part of an answer")
        await cluster.answer(join, timeout_s=0.05)
        join.replayed(b"the rest, too late")
        _keep(join, _msg(P.KIND_PARAMS, P.ENC_FLOAT32, 9))
        return join

    join = asyncio.run(main())
    assert join.gave_up and _drain(join) == [_msg(P.KIND_PARAMS, P.ENC_FLOAT32, 9)]


def test_live_messages_held_while_the_sentence_is_sent_are_bounded_dropping_the_oldest():
    # A viewer slow to take a long sentence: the live stream keeps arriving meanwhile. Held like the
    # viewer's own queue (Viewer.offer): the newest `limit` kept, the older ones dropped and counted;
    # the sentence itself is sent whole.
    limit, n_live, n_sentence = 4, 50, 30
    join = ReplayJoin(P.KIND_PARAMS, P.ENC_FLOAT32, audio=False, limit=limit)
    sentence = [b"s%d" % i for i in range(n_sentence)]
    for m in sentence:
        join.replayed(m)
    join.answered.set()
    live = [_msg(P.KIND_PARAMS, P.ENC_FLOAT32, i) for i in range(n_live)]
    for m in live:
        _keep(join, m)
    assert join.dropped == n_live - limit
    assert _drain(join) == sentence + live[-limit:]
    # sent, the join holds nothing: the next live message is held again, nothing more dropped
    _keep(join, live[0])
    assert join.dropped == n_live - limit and _drain(join) == [live[0]]
