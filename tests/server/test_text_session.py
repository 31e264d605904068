"""Text sessions: chunking invariance, the media timeline, and a real server over loopback with real
espeak-ng speech (unit corpus: espeak sentences labelled by the articulatory rules, built here)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import time

import numpy as np
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from clients.client import ViewerClient
from realtime_core.synthesis.corpus import MotionCorpus
from realtime_core.synthesis.synthesizer import UnitSynthesizer
from realtime_core.synthesis.text import SentenceChunker, TextError, clean_text
from realtime_core.synthesis.visemes import VISEME_ID, viseme_of
from server.app import FacecastServer
from server.config import ServerConfig
from server.text_session import TextBackend, TextSession
from tests.server.test_cluster import redis_server  # noqa: F401  (the real redis-server fixture)
from wire import protocol as P

pytestmark = pytest.mark.system  # a real server over loopback with espeak-ng

CORPUS_TEXT = [
    "Bin blue at f two now.",
    "Place green by q seven again.",
    "Lay red with z nine please.",
    "Set white in a one soon.",
    "The quick brown fox jumps over the lazy dog.",
    "How are you today, my friend?",
    "Thank you very much for the lovely evening.",
    "She sells sea shells by the sea shore.",
    "Where were you when the lights went out?",
    "Our house is on the other side of the river.",
]


@pytest.fixture(scope="module")
def backend() -> TextBackend:
    from assets.espeak import synthesizer
    from assets.tts import INVENTORY, language_of_voice, speak
    from realtime_core.phones import PhonemeSegment
    from training.articulatory import render_params

    sentences = []
    for i, text in enumerate(CORPUS_TEXT):
        s = speak(text, language="en")
        n = int(np.ceil(s.duration_s * 30))
        p = render_params([PhonemeSegment(*ph) for ph in s.phones], n, inventory="espeak-en")
        phones = [
            (lab, VISEME_ID[viseme_of(lab, "espeak-en", default="AH")], a, min(b, n / 30)) for lab, a, b in s.phones
        ]
        sentences.append((f"c{i}", np.concatenate([p[:, 1:3], p], axis=1), phones))  # 2 "coefficients" + the 4 params
    corpus = MotionCorpus.of_sentences(
        sentences,
        n_coefficients=2,
        dim_names=("c1", "c2", "upper_lip_raise", "lip_stretch", "mouth_open", "lip_corner_depress"),
    )
    return TextBackend(
        speak=lambda text, language, voice: speak(text, language=language, voice=voice),
        synthesizer=UnitSynthesizer(corpus),
        languages=tuple(INVENTORY),
        sample_rate_hz=synthesizer().sample_rate_hz,
        stall_s=0.5,
        lead_s=0.3,
        language_of_voice=language_of_voice,
    )


def test_chunker_gives_the_same_sentences_for_any_chunking():
    text = (
        "Hello there! How are you today? I am fine; thanks. This one has no end and keeps going "
        "on and on without any full stop at all for a very long while so it must be cut somewhere ok"
    )
    whole = SentenceChunker(max_chars=60)
    want = whole.push(text) + whole.flush()
    rng = np.random.default_rng(0)
    for _ in range(20):
        c = SentenceChunker(max_chars=60)
        cuts = np.sort(rng.choice(len(text), size=8, replace=False))
        got = []
        for piece in np.split(np.array(list(text)), cuts):
            got += c.push("".join(piece))
        got += c.flush()
        assert got == want
    assert want[:3] == ["Hello there!", "How are you today?", "I am fine;"]
    assert all(len(s) <= 60 for s in want)


ABBREVIATED = (
    "Meet Dr. Smith at 3 p.m. today, e.g. now. Here is the list:\n1. Eggs\n2. Milk and bread\n"
    "\u201cHi there.\u201d Then we left\u2026 Apples, pears, etc. Then more. Room No. 5 please. No. "
    "J. R. Tolkien wrote it. Llame a la Sra. Garc\u00eda a las 3 p.m. ma\u00f1ana. Stop! "
)


def test_chunker_does_not_cut_at_abbreviations_initials_or_list_numbers():
    """A user test: 'Meet Dr. Smith at 3 p.m. today, e.g. now.' came out as four sentences (each cut ~0.45 s of
    silence), a markdown list's '1.' and '2.' as sentences, and a closing curly quote or an ellipsis was no end."""
    c = SentenceChunker()
    want = [
        "Meet Dr. Smith at 3 p.m. today, e.g. now.",
        "Here is the list:",
        "1. Eggs",
        "2. Milk and bread",
        "\u201cHi there.\u201d",
        "Then we left\u2026",
        "Apples, pears, etc.",  # an abbreviation that ends a sentence: the next word is capitalised
        "Then more.",
        "Room No. 5 please.",
        "No.",
        "J. R. Tolkien wrote it.",
        "Llame a la Sra. Garc\u00eda a las 3 p.m. ma\u00f1ana.",
        "Stop!",
    ]
    assert c.push(ABBREVIATED) + c.flush() == want
    # the same sentences whatever the chunking (an abbreviation's end waits for the next word's first letter)
    rng = np.random.default_rng(1)
    for _ in range(30):
        c, got = SentenceChunker(), []
        for piece in np.split(np.array(list(ABBREVIATED)), np.sort(rng.choice(len(ABBREVIATED), 12, replace=False))):
            got += c.push("".join(piece))
        assert got + c.flush() == want


def test_a_stall_speaks_whole_words_and_a_long_sentence_can_start_at_a_clause():
    c = SentenceChunker()
    assert c.push("Then he went ho") == [] and c.flush_words() == ["Then he went"]
    assert c.pending.strip() == "ho" and c.flush_words() == []  # a lone fragment waits
    assert c.push("me and slept. ") == ["home and slept."]
    c.push("Well, where were you when the lights went out, and the fox")
    assert c.take_clause(8) == ["Well, where were you when the lights went out,"]  # not at "Well," (one word)
    assert c.take_clause(8) == [] and c.flush() == ["and the fox"]


def test_clean_text_keeps_pronounceable_characters_and_rejects_the_rest():
    assert clean_text("Hi\x00 there 😀 — ¿qué tal?") == "Hi there ¿qué tal?"
    for bad in ("", "   ", "😀🙂", "...!?", None):
        with pytest.raises(TextError):
            clean_text(bad)


def test_clean_text_leaves_out_letters_of_scripts_the_voices_do_not_speak():
    # espeak-ng read "你好世界" as "Chinese letter" four times and Arabic as "Arabic meem Arabic ra ...", exit 0.
    for other in ("你好世界", "مرحبا بالعالم", "١٢٣", "Привет"):
        with pytest.raises(TextError, match="Latin-script letters"):
            clean_text(other)
    assert clean_text("Hello 世界, bye") == "Hello , bye"
    # Latin letters with their marks, Greek letters (read by name), micro, ordinals, fractions and superscripts stay.
    kept = "π is 3.14, 5 µm, 1º, ½ cup, x² straße Zoë ñandú"
    assert clean_text(kept) == kept


def test_clean_text_keeps_the_symbols_a_synthesiser_reads_as_words():
    # "$19.99 or 50%" lost its dollar and percent: espeak-ng reads both signs, the cleaning dropped them.
    assert clean_text("Pay $19.99 or 50% (€5, £3) at 3:45 on 12/05 & a+b=c @ 20°") == (
        "Pay $19.99 or 50% (€5, £3) at 3:45 on 12/05 & a+b=c @ 20°"
    )
    # Markdown marks and emoji are not words.
    assert clean_text("## Title **bold** 👍") == "Title bold"
    # "3.14 × 1,000,000" was spoken "three point one four one million": the maths signs are read too
    maths = "3.14 × 1,000,000 ≈ 3 ± 0.2; 6 ÷ 2 − 1 ≤ 2 ≥ 1 ≠ 0"
    assert clean_text(maths) == maths


def test_spoken_symbols_reach_the_synthesiser(espeak):
    from assets.tts import speak

    # More phones with the sign than without: the words "percent" and "dollar" are spoken.
    with_signs, without = speak("$20 or 50%", language="en"), speak("20 or 50", language="en")
    assert len(with_signs.phones) >= len(without.phones) + 8
    times, bare = speak("3 × 4", language="en"), speak("3 4", language="en")  # "times"
    assert len(times.phones) >= len(bare.phones) + 4


def test_sentences_share_one_media_timeline(backend):
    s = TextSession(backend, language="en", voice=None)
    outs1, rep1 = s.speak("Hello world.")
    outs2, rep2 = s.speak("Good morning to you.")
    outs = outs1 + outs2
    per = backend.sample_rate_hz // 30
    for k, o in enumerate(outs):
        (f,) = o.frames
        assert f.index == k and f.media_time == pytest.approx(k / 30)
        assert o.audio.start == k * per and o.audio.media_time == pytest.approx(k / 30) and len(o.audio.samples) == per
    assert rep2["media_time"] == pytest.approx(len(outs1) / 30)
    assert rep1["frames"] + rep2["frames"] == s.frames_out
    # the audio carries the speech (not silence) and the mouth moves while it speaks
    audio = np.concatenate([o.audio.samples for o in outs1])
    assert np.abs(audio).max() > 0.05
    assert np.ptp([o.frames[0].params[2] for o in outs1]) > 0.05
    # each sentence starts and ends at rest (the synthesizer's rest pose: zero parameters here) in
    # a silent pause, so one sentence joins the next without a jump
    for o in (outs1[0], outs1[-1], outs2[0], outs2[-1]):
        np.testing.assert_allclose(o.frames[0].params, 0.0, atol=1e-12)
        assert not np.any(o.audio.samples)
    with pytest.raises(TextError):
        s.speak("😀")
    with pytest.raises(Exception, match="unsupported language"):
        TextSession(backend, language="fr", voice=None)


def test_a_piece_over_the_text_limit_is_rejected_whole(backend):
    """docs/protocol.md section 9: a text piece over 5000 characters is answered with "rejected" (it
    was chunked and spoken: 6000 characters made three minutes of speech from one message)."""
    from realtime_core.synthesis.text import MAX_TEXT_CHARS

    s = TextSession(backend, language="en", voice=None)
    assert s.push_text("Hello there. How") == ["Hello there."]
    with pytest.raises(TextError, match=f"limit is {MAX_TEXT_CHARS}"):
        s.push_text("word " * (MAX_TEXT_CHARS // 5 + 1))
    assert s.chunker.pending == "How"  # nothing of the refused piece was kept
    # Within the limit: accepted, and cut into sentences the chunker's size.
    assert all(0 < len(x) <= s.chunker.max_chars for x in s.push_text("word " * (MAX_TEXT_CHARS // 5 - 1)))


async def open_text(server_url: str, session: str):
    """A text client of the server at ``server_url`` whose English session ``session`` has started (its
    `started` reply read and checked); the caller closes (or drops) it."""
    ws = await connect(server_url.replace("http", "ws") + "/text")
    await ws.send(json.dumps({"type": "start", "session": session, "language": "en"}))
    assert json.loads(await ws.recv())["type"] == "started"
    return ws


@contextlib.asynccontextmanager
async def started_text(server_url: str, session: str):
    """:func:`open_text`, closed on leaving."""
    async with await open_text(server_url, session) as ws:
        yield ws


@contextlib.asynccontextmanager
async def running(model, backend):
    srv = FacecastServer(model, config=ServerConfig(port=0))
    srv.text_backend = backend
    await srv.start()
    try:
        yield srv
    finally:
        await srv.stop()


def test_text_session_over_loopback(model, backend):
    """Chunks in, viewers get audio + frames on one clock; bad text is rejected and the session goes
    on; a stalled sentence is spoken after stall_s; the first frame leaves quickly."""

    async def main():
        async with running(model, backend) as srv:
            url = srv.url.replace("http", "ws")
            replies = []
            async with connect(url + "/text") as ws:
                await ws.send(json.dumps({"type": "start", "session": "bot", "language": "en"}))
                started = json.loads(await ws.recv())
                async with ViewerClient(srv.url, session="bot", kind="params") as viewer:
                    collect = asyncio.ensure_future(viewer.collect())
                    t0 = time.perf_counter()
                    for piece in ("Hello the", "re, how are", " you? "):
                        await ws.send(json.dumps({"type": "text", "text": piece}))
                    replies.append(json.loads(await ws.recv()))  # "Hello there, how are you?" spoken
                    await ws.send(json.dumps({"type": "text", "text": "😀😀. "}))
                    replies.append(json.loads(await ws.recv()))  # rejected, the session goes on
                    await ws.send(json.dumps({"type": "text", "text": "I am fine thank you "}))
                    replies.append(json.loads(await ws.recv()))  # stalled: "I am fine thank you" after stall_s
                    # (whole words: the trailing space; a last word without one would wait, as a fragment)
                    stall_wait = time.perf_counter() - t0
                    await ws.send(json.dumps({"type": "end"}))
                    replies.append(json.loads(await ws.recv()))
                    got = await collect
            return started, replies, got, stall_wait

    started, replies, got, stall_wait = asyncio.run(main())
    assert started["type"] == "started" and started["audio_rate_hz"] == 22050
    spoken1, rejected, spoken2, ended = replies
    assert spoken1["type"] == "spoken" and spoken1["text"] == "Hello there, how are you?"
    assert rejected["type"] == "rejected" and "pronounceable" in rejected["reason"]
    assert spoken2["type"] == "spoken" and spoken2["text"].startswith("I am fine") and stall_wait >= 0.5
    assert spoken2["media_time"] == pytest.approx(spoken1["frames"] / 30)
    assert ended["type"] == "ended" and ended["frames"] == spoken1["frames"] + spoken2["frames"]
    print(f"first frame {ended['first_frame_ms']} ms after the first text piece")
    assert np.isfinite(ended["first_frame_ms"])
    # the viewer got every frame in order at k / 30 and the audio on the same clock
    idx = [m.index for m in got.frames]
    assert idx == list(range(ended["frames"]))
    assert all(m.media_time == pytest.approx(m.index / 30) for m in got.frames)
    assert got.description["audio"]["rate_hz"] == 22050
    # A text session takes expression controls, so its viewers are offered them (the browser viewer's buttons).
    assert got.description["expressions"] == ["neutral", "smile", "sad", "surprise", "anger"]
    audio_t = [m.media_time for m in got.audio]
    assert audio_t == pytest.approx([k / 30 for k in range(len(audio_t))])
    assert len(got.audio) == ended["frames"] and got.close_code == P.CLOSE_NORMAL


LONG = "Where were you when the lights went out, and the quick brown fox jumps over the lazy dog? "


def test_a_viewer_joining_mid_sentence_gets_that_sentence_from_its_first_frame(model, backend):
    """docs/protocol.md section 3: a viewer that joins a text session while a sentence plays is sent that
    sentence from its first frame (frames and audio, in order), then the live stream; one that joins
    after the sentence has played starts with the next frame. (A late `facecast view --record` used to
    miss the first sentence's start: the frames leave at real time, and it got only those after it joined.)"""

    async def join(srv):
        async with ViewerClient(srv.url, session="bot", kind="params") as viewer:
            return await viewer.collect()

    async def main():
        async with running(model, backend) as srv:
            async with started_text(srv.url, "bot") as ws:
                await ws.send(json.dumps({"type": "text", "text": LONG}))
                first = json.loads(await ws.recv())
                t_spoken = time.perf_counter()
                await asyncio.sleep(0.5)  # the sentence (several seconds) is playing, ~0.8 s of it released
                mid = asyncio.ensure_future(join(srv))
                await asyncio.sleep(first["duration_s"] + 0.5 - (time.perf_counter() - t_spoken))  # it has played
                after = asyncio.ensure_future(join(srv))
                await asyncio.sleep(0.5)  # connected before the next sentence starts
                await ws.send(json.dumps({"type": "text", "text": "Bin blue at f two now. "}))
                second = json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "end"}))
                ended = json.loads(await ws.recv())
                return first, second, ended, await asyncio.wait_for(mid, 30), await asyncio.wait_for(after, 30)

    first, second, ended, mid, after = asyncio.run(asyncio.wait_for(main(), 90))
    assert first["duration_s"] > 3 and second["media_time"] == pytest.approx(first["duration_s"])
    n = ended["frames"]
    assert [m.index for m in mid.frames] == list(range(n))  # the whole first sentence, then the rest
    assert [m.media_time for m in mid.audio] == pytest.approx([k / 30 for k in range(n)])
    assert all(m.media_time == pytest.approx(m.index / 30) for m in mid.frames)
    assert [m.index for m in after.frames] == list(range(first["frames"], n))  # the next sentence only
    assert len(after.audio) == second["frames"]
    assert mid.close_code == after.close_code == P.CLOSE_NORMAL


def test_a_viewer_held_for_a_text_session_gets_each_frame_once_from_frame_0(model, backend):
    """A viewer that asks to wait (view query ``wait``) for a text session not yet started is subscribed as the
    session opens, before its first sentence: it gets every frame and audio block from 0, each once (a viewer
    joining while a sentence plays is first sent that sentence, SentenceReplay; a held viewer joins before any
    sentence has begun, so none is sent twice)."""

    async def held(srv):
        async with ViewerClient(srv.url, session="bot", kind="params", wait_s=20) as viewer:
            return await viewer.collect()

    async def main():
        async with running(model, backend) as srv:
            rec = asyncio.ensure_future(held(srv))
            for _ in range(2000):  # at most 10 s
                if srv.holds:
                    break
                await asyncio.sleep(0.005)
            assert len(srv.holds) == 1
            async with started_text(srv.url, "bot") as ws:
                await ws.send(json.dumps({"type": "text", "text": "Bin blue at f two now. Set white in a one soon. "}))
                await ws.send(json.dumps({"type": "end"}))
                replies = [json.loads(await ws.recv()) for _ in range(3)]
            return replies, await asyncio.wait_for(rec, 30)

    replies, rec = asyncio.run(asyncio.wait_for(main(), 90))
    assert [r["type"] for r in replies] == ["spoken", "spoken", "ended"]
    n = replies[-1]["frames"]
    assert n == replies[0]["frames"] + replies[1]["frames"]
    assert [m.index for m in rec.frames] == list(range(n))
    assert [m.index for m in rec.audio] == list(range(n))
    assert rec.close_code == P.CLOSE_NORMAL


def test_a_text_session_that_speaks_nothing_ends_normally(model, backend):
    """Only unspeakable text, then end: `ended` with 0 frames and first_frame_ms null, close 1000 (was a
    NaN first_frame_ms that the JSON encoder refused: close 1011, an internal error)."""

    async def main():
        async with running(model, backend) as srv, started_text(srv.url, "mute") as ws:
            await ws.send(json.dumps({"type": "text", "text": "\u0001\u0002"}))
            rejected = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "end"}))
            ended = json.loads(await ws.recv())
            await ws.wait_closed()
            return rejected, ended, ws.close_code

    rejected, ended, code = asyncio.run(asyncio.wait_for(main(), 60))
    assert rejected["type"] == "rejected" and "pronounceable" in rejected["reason"]
    assert ended == {"type": "ended", "frames": 0, "audio_s": 0.0, "first_frame_ms": None}
    assert code == P.CLOSE_NORMAL


def test_text_session_refuses_bad_starts(model, backend):
    async def attempt(start):
        async with running(model, backend) as srv, connect(srv.url.replace("http", "ws") + "/text") as ws:
            await ws.send(json.dumps(start))
            with contextlib.suppress(Exception):
                await ws.recv()
            await ws.wait_closed()
            return ws.close_code, ws.close_reason

    code, reason = asyncio.run(attempt({"type": "start", "session": "x", "language": "fr"}))
    assert code == P.CLOSE_BAD_REQUEST and "unsupported language" in reason
    code, reason = asyncio.run(attempt({"type": "start", "session": "x", "voice": "xx-nope"}))
    assert code == P.CLOSE_BAD_REQUEST and "voice" in reason


def test_an_overlong_voice_is_refused_quoted_short(model, backend):
    """A start whose voice held 100,000 characters was answered with all of them quoted in the reason (the close
    frame then cut it to its first 123 bytes: the voice's own characters, not what was wrong)."""

    async def attempt():
        async with running(model, backend) as srv, connect(srv.url.replace("http", "ws") + "/text") as ws:
            await ws.send(json.dumps({"type": "start", "session": "x", "voice": "x" * 100_000}))
            with contextlib.suppress(ConnectionClosed):
                await ws.recv()
            return ws.close_code, ws.close_reason

    code, reason = asyncio.run(attempt())
    assert code == P.CLOSE_BAD_REQUEST and reason.startswith("voice must be a name of at most 64 characters, got 'x"), (
        reason
    )
    assert reason.endswith("...") and len(reason) < 123, reason  # the repr cut to 40 characters


def test_a_voice_without_a_language_speaks_the_voices_language(model, backend):
    """`{"voice": "es"}` and no language was refused (4400: "es" is not an English voice) while `facecast say
    --voice es` speaks Spanish: the language is inferred from the voice the same way (assets.tts.language_of_voice)."""

    async def main():
        async with running(model, backend) as srv, connect(srv.url.replace("http", "ws") + "/text") as ws:
            await ws.send(json.dumps({"type": "start", "session": "es", "voice": "es"}))
            started = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "text", "text": "Hola, ¿qué tal? "}))
            spoken = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "end"}))
            return started, spoken

    started, spoken = asyncio.run(asyncio.wait_for(main(), 60))
    assert started["type"] == "started" and started["language"] == "es"
    assert spoken["type"] == "spoken" and spoken["frames"] > 0


def test_a_source_that_drops_without_end_has_its_accepted_speech_played_out(model, backend):
    """A user test: a source got `spoken` for a 79-frame sentence and dropped its connection; a viewer got 16
    frames, then "1000 session ended". Nothing accepted is lost: every sentence spoken (and the pending text,
    as `end` would) reaches the viewers whole, then the session ends."""

    async def main():
        async with running(model, backend) as srv:
            ws = await open_text(srv.url, "drop")
            async with ViewerClient(srv.url, session="drop", kind="params") as viewer:
                collect = asyncio.ensure_future(viewer.collect())
                await ws.send(json.dumps({"type": "text", "text": LONG + "And then the"}))
                spoken = json.loads(await ws.recv())
                ws.transport.abort()  # dropped: no `end`, no close handshake
                got = await asyncio.wait_for(collect, 60)
            return spoken, got

    spoken, got = asyncio.run(asyncio.wait_for(main(), 90))
    idx = [m.index for m in got.frames]
    assert spoken["frames"] > 60 and idx == list(range(len(idx)))
    assert len(idx) > spoken["frames"] + 15  # the sentence whole, then "And then the" (spoken as `end` would)
    assert [m.media_time for m in got.audio] == pytest.approx([k / 30 for k in range(len(idx))])
    assert got.close_code == P.CLOSE_NORMAL


@pytest.mark.parametrize("after_end", [False, True])
def test_a_server_stopping_ends_a_text_session_at_once_with_1001(model, backend, after_end):
    """SIGTERM with a chatbot mid-answer: the text handler never looked at the shutdown, so the server closed
    its socket after close_timeout_s (1001 with no reason, to the source and the viewers), and the dropped source
    then had every accepted sentence played out in real time before the process could exit (18.6 s after SIGTERM
    with 22 s of speech queued). Now the source and viewers get 1001 "server shutting down" and the rest of the
    speech is dropped, as for an audio session; also while `end` plays the answer out."""

    async def main():
        srv = FacecastServer(model, config=ServerConfig(port=0))
        srv.text_backend = backend
        await srv.start()
        stopped = None
        try:
            ws = await open_text(srv.url, "stop")
            async with ViewerClient(srv.url, session="stop", kind="params") as viewer:
                collect = asyncio.ensure_future(viewer.collect())
                await ws.send(json.dumps({"type": "text", "text": LONG * 8}))  # ~30 s of speech
                spoken = json.loads(await ws.recv())
                assert spoken["type"] == "spoken"
                if after_end:
                    await ws.send(json.dumps({"type": "end"}))
                    await asyncio.sleep(0.5)
                stopped = asyncio.ensure_future(srv.stop())
                await asyncio.wait_for(asyncio.shield(stopped), 10)  # it waited for the speech to play out
                got = await asyncio.wait_for(collect, 10)
            with contextlib.suppress(ConnectionClosed):
                while True:  # the other sentences' replies, then the close
                    await ws.recv()
            return spoken, got, ws.close_code, ws.close_reason
        finally:
            await (stopped if stopped is not None else srv.stop())

    spoken, got, code, reason = asyncio.run(asyncio.wait_for(main(), 60))
    assert (code, reason) == (P.CLOSE_GOING_AWAY, "server shutting down")
    assert (got.close_code, got.close_reason) == (P.CLOSE_GOING_AWAY, "server shutting down")
    idx = [m.index for m in got.frames]
    assert idx == list(range(len(idx))) and len(idx) < 8 * spoken["frames"]  # not played out


def test_a_server_stopping_while_a_dropped_source_plays_out_ends_it_at_once(model, backend):
    """A source that drops without `end` has its accepted speech played out in real time; a server stopping
    meanwhile waited for all of it (the play-out did not look at the shutdown): stop() with ~30 s queued took
    until the speech had played. Now the viewers get 1001 "server shutting down" and the rest is dropped."""

    async def main():
        srv = FacecastServer(model, config=ServerConfig(port=0))
        srv.text_backend = backend
        await srv.start()
        stopped = None
        try:
            ws = await open_text(srv.url, "gone")
            async with ViewerClient(srv.url, session="gone", kind="params") as viewer:
                collect = asyncio.ensure_future(viewer.collect())
                await ws.send(json.dumps({"type": "text", "text": LONG * 8}))  # ~30 s of speech
                spoken = json.loads(await ws.recv())
                assert spoken["type"] == "spoken"
                ws.transport.abort()  # dropped: its speech plays out to the viewer (nothing accepted is lost)...
                await asyncio.sleep(0.5)
                stopped = asyncio.ensure_future(srv.stop())  # ...unless the server stops
                await asyncio.wait_for(asyncio.shield(stopped), 10)  # it waited for the speech to play out
                got = await asyncio.wait_for(collect, 10)
            return spoken, got
        finally:
            await (stopped if stopped is not None else srv.stop())

    spoken, got = asyncio.run(asyncio.wait_for(main(), 60))
    assert (got.close_code, got.close_reason) == (P.CLOSE_GOING_AWAY, "server shutting down")
    idx = [m.index for m in got.frames]
    assert idx == list(range(len(idx))) and 0 < len(idx) < 8 * spoken["frames"]  # not played out


def test_cancel_stops_the_speech_eases_the_mouth_to_rest_and_the_session_goes_on(model, backend):
    """Barge-in: `{"type": "cancel"}` drops every frame not yet released (the sentence playing and those queued,
    counted in the reply), eases the mouth from the last frame released to rest over RestPauses.ramp_s with
    silent audio, and the session takes more text on the same timeline."""

    async def main():
        async with running(model, backend) as srv, started_text(srv.url, "cut") as ws:
            async with ViewerClient(srv.url, session="cut", kind="params") as viewer:
                collect = asyncio.ensure_future(viewer.collect())
                await ws.send(json.dumps({"type": "text", "text": LONG + "Bin blue at f two now. "}))
                first, second = json.loads(await ws.recv()), json.loads(await ws.recv())
                await asyncio.sleep(1.0)  # mid-way through the first sentence (several seconds)
                await ws.send(json.dumps({"type": "text", "text": "and this pending text is dropped too"}))
                await ws.send(json.dumps({"type": "cancel"}))
                cancelled = json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "text", "text": "Thank you very much. "}))
                third = json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "end"}))
                ended = json.loads(await ws.recv())
                got = await asyncio.wait_for(collect, 60)
            return first, second, cancelled, third, ended, got

    first, second, cancelled, third, ended, got = asyncio.run(asyncio.wait_for(main(), 90))
    assert second["text"] == "Bin blue at f two now." and cancelled["type"] == "cancelled"
    assert cancelled["dropped"] == 2  # the sentence playing and the one queued
    cut = round(cancelled["media_time"] * 30)
    assert 0 < cut < first["frames"]  # the first sentence was cut mid-way: the rest of it never left
    n_ease = 6  # RestPauses().ramp_s * 30
    assert third["text"] == "Thank you very much." and third["media_time"] == pytest.approx((cut + n_ease) / 30)
    assert ended["frames"] == cut + n_ease + third["frames"]
    idx = [m.index for m in got.frames]
    assert idx == list(range(ended["frames"]))  # one timeline, nothing dropped reached the viewer
    values = np.array([m.values for m in got.frames])
    ease = values[cut - 1 : cut + n_ease]  # the last frame released, then the ease
    dist = np.abs(ease).max(axis=1)  # the rest pose is zero parameters here
    assert dist[0] > 0.01 and np.all(np.diff(dist) <= 1e-6) and dist[-1] < 1e-6  # moving, eased, at rest
    assert np.abs(np.diff(ease, axis=0)).max() <= 0.35 * dist[0] + 1e-6  # no jump: the smoothstep's steps
    audio = np.concatenate([m.values for m in got.audio[cut : cut + n_ease]])
    assert not np.any(audio)
    assert len(got.audio) == ended["frames"] and got.close_code == P.CLOSE_NORMAL


def test_after_end_a_cancel_cuts_the_play_out_and_text_is_rejected(model, backend):
    """A chatbot sends `end` after its answer's last piece, then its user talks over the answer: the cancel was not
    read until the last frame had played (the answer was spoken to its end), and text sent after `end` got no reply.
    Now the cancel cuts the play-out as before `end` (the ease, then `ended`) and the text is rejected."""

    async def main():
        async with running(model, backend) as srv, started_text(srv.url, "late") as ws:
            async with ViewerClient(srv.url, session="late", kind="params") as viewer:
                collect = asyncio.ensure_future(viewer.collect())
                await ws.send(json.dumps({"type": "text", "text": LONG}))
                spoken = json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "end"}))
                await asyncio.sleep(1.0)  # mid-way through the sentence (several seconds)
                await ws.send(json.dumps({"type": "text", "text": "Too late. "}))
                rejected = json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "cancel"}))
                cancelled, ended = json.loads(await ws.recv()), json.loads(await ws.recv())
                got = await asyncio.wait_for(collect, 60)
            return spoken, rejected, cancelled, ended, got

    spoken, rejected, cancelled, ended, got = asyncio.run(asyncio.wait_for(main(), 90))
    assert rejected == {"type": "rejected", "text": "Too late. ", "reason": "after end: the session is ending"}
    assert cancelled["type"] == "cancelled" and cancelled["dropped"] == 1
    cut = round(cancelled["media_time"] * 30)
    assert 0 < cut < spoken["frames"]  # cut mid-way: the rest of the sentence never left
    assert ended["type"] == "ended" and ended["frames"] == cut + 6  # then the 0.2 s ease to rest
    assert [m.index for m in got.frames] == list(range(ended["frames"])) and got.close_code == P.CLOSE_NORMAL


def test_a_second_cancel_during_the_ease_eases_again_from_where_the_mouth_is(model, backend):
    """A second `cancel` 50 ms after the first dropped the ease's frames not yet released and eased nothing (its
    sentence spans were gone), so the session ended with the mouth open (mouth_open 0.096 in a user's take)."""

    async def main():
        async with running(model, backend) as srv, started_text(srv.url, "twice") as ws:
            async with ViewerClient(srv.url, session="twice", kind="params") as viewer:
                collect = asyncio.ensure_future(viewer.collect())
                await ws.send(json.dumps({"type": "text", "text": LONG}))
                assert json.loads(await ws.recv())["type"] == "spoken"
                await ws.send(json.dumps({"type": "end"}))
                await asyncio.sleep(1.0)
                await ws.send(json.dumps({"type": "cancel"}))
                first = json.loads(await ws.recv())
                await asyncio.sleep(0.05)
                await ws.send(json.dumps({"type": "cancel"}))
                second, ended = json.loads(await ws.recv()), json.loads(await ws.recv())
                got = await asyncio.wait_for(collect, 60)
            return first, second, ended, got

    first, second, ended, got = asyncio.run(asyncio.wait_for(main(), 90))
    assert first["type"] == second["type"] == "cancelled" and ended["type"] == "ended"
    cut2 = round(second["media_time"] * 30)
    assert ended["frames"] == cut2 + 6  # eased again from the last frame released
    values = np.array([m.values for m in got.frames])
    assert len(values) == ended["frames"] and np.abs(values[-1]).max() < 1e-6  # at rest at the end


def test_a_stall_mid_word_speaks_the_whole_words_and_the_fragment_waits(model, backend):
    """A user test: after "Then he went ho" and a stall the server spoke "Then he went ho", then "me and slept".
    A stall speaks through the last word boundary; the fragment waits for more text (or a longer stall)."""

    async def main():
        async with running(model, backend) as srv, started_text(srv.url, "stall") as ws:
            await ws.send(json.dumps({"type": "text", "text": "Then he went ho"}))
            a = json.loads(await ws.recv())  # after stall_s
            await asyncio.sleep(0.2)
            await ws.send(json.dumps({"type": "text", "text": "me and slept. Good ni"}))
            b = json.loads(await ws.recv())
            c = json.loads(await ws.recv())  # "Good" after a stall, then "ni" after FRAGMENT_STALLS more
            d = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "end"}))
            return [m["text"] for m in (a, b, c, d)]

    assert asyncio.run(asyncio.wait_for(main(), 60)) == ["Then he went", "home and slept.", "Good", "ni"]


def _streamed_word_by_word(model, backend, session: str, text: str) -> list[dict]:
    """``text`` sent to a new text session a word a piece (as a language model streams it), then `end`: the
    replies before `ended`."""

    async def main():
        async with running(model, backend) as srv, started_text(srv.url, session) as ws:
            for word in text.split(" "):
                await ws.send(json.dumps({"type": "text", "text": word + " "}))
            await ws.send(json.dumps({"type": "end"}))
            replies = []
            while (m := json.loads(await ws.recv()))["type"] != "ended":
                replies.append(m)
            return replies

    return asyncio.run(asyncio.wait_for(main(), 60))


def test_a_long_first_sentence_starts_at_a_clause_boundary(model, backend):
    """A 36-word first sentence streamed at ~17 tokens/s was spoken only once complete (first frame 2 s after the
    first piece): with nothing queued for the viewers, it is started at a clause boundary after >= 8 words."""
    text = (
        "Well, when you get to the old bridge by the river, turn left and keep walking past the bakery, "
        "the school and the park until you see a small blue house with a red door on your right. "
    )

    texts = [m["text"] for m in _streamed_word_by_word(model, backend, "clause", text)]
    assert texts[0] == "Well, when you get to the old bridge by the river,"  # not at "Well," (one word)
    assert " ".join(texts) == " ".join(text.split())  # all of it, in order


def test_a_run_on_first_sentence_starts_at_a_word_boundary(model, backend):
    """600 characters without punctuation waited for the 300-character cut (first frame 5.3 s after the first
    piece at LLM pace): with nothing queued and no clause boundary, the text is started at its last whole word
    once 20 words are pending; the rest follows, nothing lost or doubled."""
    from server.text_session import RUN_ON_WORDS

    text = " ".join(f"word{i} and more" for i in range(8))  # 24 words, no punctuation

    texts = [m["text"] for m in _streamed_word_by_word(model, backend, "runon", text)]
    assert texts[0] == " ".join(text.split()[:RUN_ON_WORDS])  # started as soon as 20 whole words were there
    assert " ".join(texts) == text


def test_fenced_code_is_not_spoken_and_a_link_is_spoken_as_its_text():
    """A chatbot's markdown answer read its code block aloud ("python", "print hello", "x equals one, two, three"),
    answered `rejected` for the closing fence and read a link's URL letter by letter ("h t t p s colon slash...")."""
    answer = (
        '# Getting started\n\nHere is **how**:\n\n```python\nprint("hello. world")\nx = [1, 2, 3]\n```\n'
        "That's it! See [the docs](https://example.com/docs?x=1) now.\n  ~~~\nmore code; here\n  ~~~\nDone. "
        "Inline ```x``` stays.\n```\nunclosed code at the end"
    )
    want = ["# Getting started", "Here is **how**:", "That's it!", "See [the docs](https://example.com/docs?x=1) now."]
    want += ["Done.", "Inline ```x``` stays."]
    rng = np.random.default_rng(2)
    for n_cuts in (0, 5, 40):  # the same sentences whatever the chunking: a fence line is judged whole
        c, got = SentenceChunker(), []
        for piece in np.split(np.array(list(answer)), np.sort(rng.choice(len(answer), n_cuts, replace=False))):
            got += c.push("".join(piece))
        assert got + c.flush() == want
    assert [clean_text(s) for s in want[2:4]] == ["That's it!", "See the docs now."]
    # `facecast say` cleans a whole answer at once: the same words
    assert clean_text(answer) == "Getting started Here is how : That's it! See the docs now. Done. Inline x stays."
    with pytest.raises(TextError, match="a fenced code block is not spoken"):
        clean_text("```\nls -la\n```")
    # a new answer after a cancel does not start inside the cut answer's code block
    c = SentenceChunker()
    assert c.push("Look:\n```\ncode\n") == ["Look:"]
    c.reset()
    assert c.push("Hello there. ") == ["Hello there."]


def test_markdown_rules_and_table_delimiters_are_skipped_not_rejected():
    """A chatbot's table delimiter row (`|---|---|`) and thematic break (`---`) each came back `rejected` ("no
    pronounceable characters"), a refusal its client had to tell from a real one: they are layout, skipped as a
    fence is, whatever the chunking; a line that starts with dashes and has words is still spoken."""
    answer = "Results:\n\n| name | score |\n|:---|---:|\n| Ann | 3 |\n\n---\n* * *\n-- and that is all. "
    want = ["Results:", "| name | score |", "| Ann | 3 |", "-- and that is all."]
    rng = np.random.default_rng(5)
    for n_cuts in (0, 7, 30):
        c, got = SentenceChunker(), []
        for piece in np.split(np.array(list(answer)), np.sort(rng.choice(len(answer), n_cuts, replace=False))):
            got += c.push("".join(piece))
        assert got + c.flush() == want
    assert clean_text(want[1]) == "name score"


def _contains(seq: list[str], part: list[str]) -> bool:
    """Whether ``part`` occurs in ``seq`` as a contiguous run."""
    return any(seq[i : i + len(part)] == part for i in range(len(seq) - len(part) + 1))


def test_a_url_is_spoken_as_its_host_through_facecast_serve_text(model_path, espeak):
    """A chatbot's bare URL was read letter by letter ("h t t p s colon slash slash docs dot python dot org slash
    three slash library ..."). Through a real `facecast serve --text` over loopback: the sentence is spoken with
    the URL as its host; the viewer's audio is espeak-ng's reading of the text written out by hand (so its phone
    events are the server's), in which no letter of "https" and no "colon" or "slash" is spelled; every phone is
    one the unit selection knows, and the mouth moves through the whole sentence."""
    from assets.espeak import Voice
    from assets.tts import speak
    from benchmarks.server_harness import ServerProcess

    sentence = "See https://docs.python.org/3/library/re.html?highlight=sub#re.sub for the details."
    by_hand = "See docs.python.org for the details."
    srv = ServerProcess(model_path, head=False, args=("--text",))

    async def main():
        async with started_text(srv.url, "bot") as ws, ViewerClient(srv.url, session="bot") as viewer:
            collect = asyncio.ensure_future(viewer.collect())
            await ws.send(json.dumps({"type": "text", "text": sentence + " "}))
            spoken = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "end"}))
            ended = json.loads(await ws.recv())
            return spoken, ended, await collect

    try:
        spoken, ended, got = asyncio.run(asyncio.wait_for(main(), 60))
    finally:
        srv.stop()
    assert spoken["type"] == "spoken" and spoken["text"] == by_hand and spoken["unknown_phones"] == []
    assert ended["type"] == "ended" and ended["frames"] == spoken["frames"]
    # the viewer heard exactly espeak-ng reading the text written by hand (int16 on the wire)
    speech = speak(by_hand, language="en")
    want = speech.padded()
    audio = np.concatenate([m.values for m in got.audio])
    assert len(audio) == spoken["frames"] * 22050 // 30 >= len(want.samples)
    np.testing.assert_allclose(audio[: len(want.samples)], want.samples, atol=1.5 / 32768)
    assert not np.any(audio[len(want.samples) :])

    def phones(text: str) -> list[str]:  # espeak-ng's phone events for text as given (no normalisation), no pauses
        syn = espeak.synthesize(text, Voice(language="en", base="en-us"), noise_seed=0)
        return [p.phoneme for p in syn.phonemes if p.phoneme not in ("_", "_:", "_!", "_^_", ";")]

    said, before = phones(by_hand), phones(clean_text(sentence))  # before: the URL as the cleaning left it
    assert said == [p for p, _, _ in speech.phones if p not in ("_", "_:", "_!", "_^_", ";")]
    for spelled in ("h t t p s", "colon", "slash", "library"):  # what the URL was read as
        assert _contains(before, phones(spelled)) and not _contains(said, phones(spelled)), spelled
    # the mouth moves in every quarter of the speech (unit selection got phones for every word)
    speech = [(a, b) for p, a, b in want.phones if not p.startswith("_")]
    t0, t1 = speech[0][0], speech[-1][1]
    mouth = np.array([m.values[2] for m in got.frames])
    for q in range(4):
        k0, k1 = int(30 * (t0 + q * (t1 - t0) / 4)), int(30 * (t0 + (q + 1) * (t1 - t0) / 4))
        assert np.ptp(mouth[k0 : k1 + 1]) > 0.03, (q, mouth[k0 : k1 + 1])


@pytest.mark.slow
def test_text_session_is_registered_cluster_wide(model, backend, redis_server):  # noqa: F811 (fixture)
    """Two nodes share a real redis-server: a text session on node A is listed by /sessions on node B,
    a viewer on B receives every frame and audio block of it on the same clock, and the name is
    taken cluster-wide (a second text session of that name on B is refused naming node A)."""
    from clients.client import http_get

    def config(node: str) -> ServerConfig:
        return ServerConfig(port=0, redis_url=redis_server.url, node_id=node, heartbeat_s=0.2, close_timeout_s=1.0)

    async def main():
        a = FacecastServer(model, config=config("na"))
        b = FacecastServer(model, config=config("nb"))
        a.text_backend = b.text_backend = backend
        await a.start()
        await b.start()
        try:
            async with started_text(a.url, "bot") as ws:
                status, body = await http_get(b.url, "/sessions")
                listed = json.loads(body)
                async with connect(b.url.replace("http", "ws") + "/text") as ws2:
                    await ws2.send(json.dumps({"type": "start", "session": "bot", "language": "en"}))
                    with contextlib.suppress(Exception):
                        await asyncio.wait_for(ws2.recv(), 5)
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(ws2.wait_closed(), 5)  # not refused: stays open, checked below
                    taken = (ws2.close_code, ws2.close_reason)
                async with ViewerClient(b.url, session="bot", kind="params") as viewer:
                    collect = asyncio.ensure_future(viewer.collect())
                    await asyncio.sleep(0.5)  # the owner learns of B's wants within a heartbeat
                    await ws.send(json.dumps({"type": "text", "text": "Bin blue at f two now. "}))
                    spoken = json.loads(await ws.recv())
                    await ws.send(json.dumps({"type": "end"}))
                    ended = json.loads(await ws.recv())
                    got = await asyncio.wait_for(collect, 20)
            return status, listed, taken, spoken, ended, got
        finally:
            await b.stop()
            await a.stop()

    status, listed, taken, spoken, ended, got = asyncio.run(asyncio.wait_for(main(), 90))
    assert status == 200 and listed["scope"] == "cluster"
    rows = {r["name"]: r for r in listed["sessions"]}
    assert rows["bot"]["node"] == "na" and rows["bot"]["source"] == "text"
    # A viewer on another node sends nothing (its node takes no viewer messages): it is offered no expressions.
    assert got.description["expressions"] == []
    assert taken[0] == P.CLOSE_CONFLICT and "na" in taken[1]
    assert spoken["type"] == "spoken" and ended["frames"] == spoken["frames"]
    idx = [m.index for m in got.frames]
    assert idx == list(range(ended["frames"]))
    assert all(m.media_time == pytest.approx(m.index / 30) for m in got.frames)
    assert len(got.audio) == ended["frames"]
    assert got.close_code == P.CLOSE_NORMAL


def test_text_session_rejections_quote_the_text_and_hostile_json_is_refused(model, backend):
    """docs/protocol.md section 9.6: every "rejected" reply carries `text` (what was refused, its first 200
    characters; null when the message's `text` was not a string: that reply lacked the field, as did the
    one for a piece over 5000 characters), and the session goes on; JSON nested 30000 deep closes with
    1007 (json.loads raised RecursionError: an internal error, 1011)."""
    from realtime_core.synthesis.text import MAX_TEXT_CHARS

    long_piece = "word " * (MAX_TEXT_CHARS // 5 + 1)

    async def main():
        async with running(model, backend) as srv:
            url = srv.url.replace("http", "ws") + "/text"
            async with connect(url) as ws:
                await ws.send(json.dumps({"type": "start", "session": "r", "language": "en"}))
                assert json.loads(await ws.recv())["type"] == "started"
                replies = []
                for msg in ({"type": "text", "text": 42}, {"type": "text"}, {"type": "text", "text": long_piece}):
                    await ws.send(json.dumps(msg))
                    replies.append(json.loads(await ws.recv()))
                await asyncio.sleep(1.5)  # the rejected pieces start no clock (first_frame_ms below)
                await ws.send(json.dumps({"type": "text", "text": "Bin blue at f two now.", "flush": True}))
                replies.append(json.loads(await ws.recv()))
                await ws.send(json.dumps({"type": "end"}))
                replies.append(json.loads(await ws.recv()))
                await ws.wait_closed()
                closed = ws.close_code, ws.close_reason  # the session's, not a rejection's reason
            async with connect(url, max_size=None) as ws:
                await ws.send(json.dumps({"type": "start", "session": "deep", "language": "en"}))
                assert json.loads(await ws.recv())["type"] == "started"
                await ws.send("[" * 30000 + "]" * 30000)
                with contextlib.suppress(Exception):
                    await ws.recv()
                await ws.wait_closed()
                deep = ws.close_code, ws.close_reason
            return replies, closed, deep, srv.metrics()

    replies, closed, deep, metrics = asyncio.run(asyncio.wait_for(main(), 60))
    not_str, missing, too_long, spoken, ended = replies
    assert closed == (P.CLOSE_NORMAL, "session ended")
    # first_frame_ms runs from the first piece accepted, not from the rejected ones 1.5 s before it
    assert ended["first_frame_ms"] < 1500
    assert not_str == {"type": "rejected", "text": None, "reason": "text must be a string, got 42"}
    assert missing == {"type": "rejected", "text": None, "reason": "text must be a string, got None"}
    assert set(too_long) == {"type", "text", "reason"} and too_long["text"] == long_piece[:200]
    assert f"limit is {MAX_TEXT_CHARS}" in too_long["reason"]
    assert spoken["type"] == "spoken" and ended["type"] == "ended" and ended["frames"] == spoken["frames"]
    assert deep[0] == P.CLOSE_INVALID_PAYLOAD and "nests deeper" in deep[1]
    assert "1011" not in metrics["closes"]


def test_a_server_selects_units_on_one_blas_thread_while_it_serves(model, backend):
    """Unit selection runs on one BLAS thread, as `facecast say` does (the thread count changes the selection's sums
    in their last digits; on a 2-core machine more threads contend): any FacecastServer holds BLAS at one thread from
    start to stop (it was pinned per sentence, and `facecast serve`'s whole process once more), and gives the process
    its own count back when it stops."""
    import dataclasses

    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads() -> set[int]:
        return {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}

    class Recording(UnitSynthesizer):
        def synthesize(self, *args, **kwargs):
            self.blas_threads = blas_threads()
            return super().synthesize(*args, **kwargs)

    synth = Recording(backend.synthesizer.corpus)

    async def main():
        async with running(model, dataclasses.replace(backend, synthesizer=synth)) as srv:
            serving = blas_threads()
            async with started_text(srv.url, "blas") as ws:
                await ws.send(json.dumps({"type": "text", "text": "Bin blue at f two now. "}))
                spoken = json.loads(await ws.recv())
        return serving, spoken

    with threadpool_limits(2):  # the embedding process's own count, whatever the machine's default
        serving, spoken = asyncio.run(asyncio.wait_for(main(), 60))
        after = blas_threads()
    assert spoken["type"] == "spoken" and spoken["frames"] > 0
    assert serving == synth.blas_threads == {1}
    assert after == {2}


def test_a_text_message_can_change_the_language_and_keeps_the_session(model, backend):
    """A conversation that turns to Spanish had to end its session (its viewers closed) and start another: a text
    message's `language` / `voice` now switch the session from that piece on. The pending English words are spoken
    first, in English; the Spanish piece in Spanish (its frame count is what Spanish espeak-ng makes of it, not
    English); an unsupported language is rejected with the piece and the session goes on in its language."""
    from assets.tts import speak

    def frames(text: str, language: str) -> int:
        s = speak(text, language=language).padded()
        return int(np.ceil(len(s.samples) * 30 / s.sample_rate_hz - 1e-9))

    async def main():
        async with running(model, backend) as srv:
            async with started_text(srv.url, "bot") as ws, ViewerClient(srv.url, session="bot", kind="params") as v:
                collect = asyncio.ensure_future(v.collect())
                await ws.send(json.dumps({"type": "text", "text": "Thank you very"}))
                await ws.send(json.dumps({"type": "text", "text": "Mañana", "language": "fr"}))
                rejected = json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "text", "text": "Hasta mañana, amigo. ", "language": "es"}))
                english, spanish = json.loads(await ws.recv()), json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "text", "text": "Gracias. ", "voice": "f3"}))  # a variant: still es
                variant = json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "end"}))
                ended = json.loads(await ws.recv())
                got = await asyncio.wait_for(collect, 60)
            return rejected, english, spanish, variant, ended, got

    rejected, english, spanish, variant, ended, got = asyncio.run(asyncio.wait_for(main(), 90))
    assert rejected["type"] == "rejected" and "unsupported language 'fr'" in rejected["reason"]
    assert rejected["text"] == "Mañana"  # refused with its piece: not spoken in the old language either
    assert english == {**english, "type": "spoken", "text": "Thank you very", "language": "en"}
    assert english["frames"] == frames("Thank you very", "en")
    assert spanish == {**spanish, "type": "spoken", "text": "Hasta mañana, amigo.", "language": "es"}
    es, en = frames("Hasta mañana, amigo.", "es"), frames("Hasta mañana, amigo.", "en")
    assert es != en and spanish["frames"] == es
    assert variant["language"] == "es" and spanish["media_time"] == pytest.approx(english["frames"] / 30)
    # one session, one viewer stream through the change: every frame in order
    assert [m.index for m in got.frames] == list(range(ended["frames"])) and got.close_code == P.CLOSE_NORMAL


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3 - 2 * u)


def test_a_text_session_takes_expression_controls_on_the_frames_not_yet_released(model, backend):
    """A chatbot's avatar smiling while it speaks: a viewer's expression control (the browser's button) reaches a text
    session, whose frames were made a sentence ahead; the frames from the control's media time on carry it (eased),
    the frames released before are the speech alone, bit for bit; a bad control from the text source gets the reply an
    audio session gives and the session streams on (it answered every control 'text sessions have no controls')."""
    from realtime_core.blendshapes import blendshape_weights
    from realtime_core.expressions import EXPRESSIONS
    from realtime_core.mapping.expression import express

    text = LONG + "Bin blue at f two now. "
    bad = {"type": "control", "expression": {"name": "grin"}}

    async def speak(srv, name, smile: bool):
        url = srv.url.replace("http", "ws")
        async with (
            started_text(srv.url, name) as ws,
            ViewerClient(srv.url, session=name, kind="params", audio=False) as params,
            ViewerClient(srv.url, session=name, kind="blendshapes", encoding="arkit52", audio=False) as arkit,
        ):
            collect = asyncio.gather(params.collect(), arkit.collect())
            await ws.send(json.dumps({"type": "text", "text": text}))
            spoken = [json.loads(await ws.recv()), json.loads(await ws.recv())]  # both sentences made
            ack = rejected = None
            if smile:
                await asyncio.sleep(1.0)  # mid-way through the first sentence (several seconds)
                async with connect(f"{url}/view?session={name}&kind=params&audio=0") as button:
                    await button.recv()  # the description
                    ctl = {"name": "smile", "intensity": 0.6}
                    await button.send(json.dumps({"type": "control", "expression": ctl, "expression_ease_s": 0.2}))
                    while isinstance(ack := await button.recv(), bytes):  # the ack comes between the frames
                        pass
                await ws.send(json.dumps(bad))
                rejected = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "end"}))
            ended = json.loads(await ws.recv())
            got_params, got_arkit = await asyncio.wait_for(collect, 60)
        return spoken, ack, rejected, ended, got_params, got_arkit

    async def main():
        async with running(model, backend) as srv:
            plain = await speak(srv, "plain", smile=False)
            smiling = await speak(srv, "smiling", smile=True)
            async with connect(srv.url.replace("http", "ws") + "/ingest") as audio:  # an audio session's reply
                await audio.send(json.dumps({"type": "start", "session": "audio", "sample_rate": 16000}))
                assert json.loads(await audio.recv())["type"] == "started"
                await audio.send(json.dumps(bad))
                audio_rejected = json.loads(await audio.recv())
        return plain, smiling, audio_rejected

    plain, smiling, audio_rejected = asyncio.run(asyncio.wait_for(main(), 120))
    *_, p_ended, p_params, p_arkit = plain
    spoken, ack, rejected, ended, s_params, s_arkit = smiling
    assert p_params.description["expressions"] == s_params.description["expressions"] == ["neutral", *EXPRESSIONS]
    assert rejected == audio_rejected and rejected["type"] == "rejected" and "grin" in rejected["reason"]
    ack = json.loads(ack)
    assert ack["type"] == "ack" and ack["controls"]["expression_ease_s"] == 0.2
    (event,) = ack["controls"]["expression"]
    at = event["at"]  # the next frame to be released when the button was pressed
    n = ended["frames"]
    assert n == p_ended["frames"] == spoken[0]["frames"] + spoken[1]["frames"]
    assert [m.index for m in s_params.frames] == list(range(n)) and s_params.close_code == P.CLOSE_NORMAL
    t = np.arange(n) / 30
    before = t < at - 1e-9
    k = int(before.sum())
    assert 0 < k < spoken[0]["frames"]  # pressed mid-way through the first sentence, made before the press
    speech = np.array([m.values for m in p_params.frames], dtype=np.float64)
    got = np.array([m.values for m in s_params.frames], dtype=np.float64)
    np.testing.assert_array_equal(got[before], speech[before])  # released before the press: speech alone
    # From the press on: eased to 0.6 of a smile over 0.2 s from `at` (smoothstep), the speech under it.
    alpha = np.zeros((n, len(EXPRESSIONS)))
    alpha[:, EXPRESSIONS.index("smile")] = 0.6 * _smoothstep((t - at) / 0.2)
    want = express(speech, alpha)
    np.testing.assert_allclose(got[~before], want[~before], atol=1e-6)
    assert np.abs(got[k + 6 :] - speech[k + 6 :]).max() > 0.01  # the smile moves the mouth
    # ARKit-52: the speech's weights plus the recipe (cheeks, eyes: shapes speech does not drive), as computed here.
    arkit = np.array([m.values for m in s_arkit.frames])
    plain_arkit = np.array([m.values for m in p_arkit.frames])
    np.testing.assert_array_equal(arkit[before], plain_arkit[before])
    np.testing.assert_allclose(arkit, blendshape_weights(speech, "arkit52", expression=alpha), atol=2e-6)
    cheek = s_arkit.description["names"].index("cheekSquintLeft")
    assert arkit[k + 6 :, cheek] == pytest.approx(0.6 * 0.5) and not np.any(plain_arkit[:, cheek])


def test_a_text_message_expression_starts_with_its_sentence(backend):
    """A language model tagging each sentence's emotion: `{"type": "text", "text": ..., "expression": {...}}` sets the
    expression from where the piece's sentence starts on the media clock, eased; frames released before any
    expression are the speech alone (no expression set), and a bad expression refuses the piece whole."""
    from realtime_core.expressions import EXPRESSIONS
    from server.errors import ControlError

    s = TextSession(backend, language="en", voice=None)
    outs1, _ = s.speak(*s.push_text("Hello world. "))
    first = [s.release(o).frames[0] for o in outs1]
    assert all(f.expression is None and f.speech_params is None for f in first)
    assert all(np.array_equal(f.params, f.raw_params) for f in first)
    with pytest.raises(ControlError, match="grin"):
        s.push_text("Good morning to you. ", {"name": "grin"})
    assert s.chunker.pending == ""  # nothing of the refused piece was kept
    outs2, report = s.speak(*s.push_text("Good morning to you. ", {"name": "sad", "intensity": 0.5}))
    assert report["media_time"] == pytest.approx(len(outs1) / 30)
    frames = [s.release(o).frames[0] for o in outs2]
    sad = np.array([f.expression[EXPRESSIONS.index("sad")] for f in frames])
    u = np.clip(np.arange(len(frames)) / 30 / 0.3, 0, 1)  # eased over the default 0.3 s from the sentence's start
    np.testing.assert_allclose(sad, 0.5 * u * u * (3 - 2 * u), atol=1e-12)
    assert all(np.array_equal(f.speech_params, f.raw_params) for f in frames)
    assert s.control_state()["expression"] == [
        {"at": pytest.approx(len(outs1) / 30), "intensity": pytest.approx({e: 0.5 * (e == "sad") for e in EXPRESSIONS})}
    ]
