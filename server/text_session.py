"""Text sessions for chatbots: text in (whole or streamed in pieces), speech + lip motion out to viewers.

Theory of operation
-------------------
A client opens ``/text`` and sends ``{"type": "start", "session": NAME, "language": "en"|"es",
"voice": optional espeak voice}``, then ``{"type": "text", "text": "..."}`` pieces as a language
model writes them, and ``{"type": "end"}`` (docs/protocol.md). :class:`TextSession` (sans-I/O)
collects the pieces into sentences (:class:`realtime_core.synthesis.text.SentenceChunker`); each
complete sentence is spoken by the injected text-to-speech function, its lip motion selected from
recorded units (:class:`realtime_core.synthesis.synthesizer.UnitSynthesizer`, the phone timings of
the synthesiser) and appended to the session's media timeline: sentence audio is padded to a
whole number of frames so frame ``k`` stays at media time ``k / 30`` and the audio block of frame
``k`` starts there too. Viewers subscribe with ``/view`` exactly as for audio sessions (same
messages, same description; the audio rate is the synthesiser's).

The asyncio side (:func:`handle_text`) runs synthesis off the event loop (a thread), releases
frames at the pace of real time plus ``lead_s`` (so viewers' queues never overflow and playback
starts at once), speaks pending text through its last whole word after ``stall_s`` without a new
piece (a stalled stream still gets its words out; a trailing word fragment waits for
``FRAGMENT_STALLS`` more stalls), starts a long sentence at a clause boundary when the viewers
would otherwise wait for it (:data:`CLAUSE_WORDS`, :data:`CLAUSE_AHEAD_S`; without a clause boundary at
its last whole word, :data:`RUN_ON_WORDS`), stops the speech on
``{"type": "cancel"}`` (the mouth eased to rest, the session open for more text), takes expression controls
from its source and its viewers as an audio session does (applied as each frame is released: below), plays out every
sentence accepted when its source drops without ``end`` (nothing accepted is lost), and answers bad
text with ``{"type": "rejected"}`` while the session goes on serving its viewers.

Expressions: frames are synthesised a sentence ahead and released up to ``lead_s`` before their media time, so the
session's expression (:class:`server.controls.ControlState`, an :class:`realtime_core.expressions.ExpressionTrack`
on the media clock) is applied when a frame is released (:meth:`TextSession.release`), not when it is made: a
control takes effect, with its ease, on every frame not yet released, and a control's "now" (its default ``at``,
its lateness check) is the next frame to be released.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn, Protocol

import numpy as np
from websockets.asyncio.server import ServerConnection
from websockets.exceptions import ConnectionClosed

from realtime_core.errors import ConfigError
from realtime_core.mapping.expression import express
from realtime_core.synthesis.rest import RestPauses
from realtime_core.synthesis.search import crossfade
from realtime_core.synthesis.synthesizer import UnitSynthesizer
from realtime_core.synthesis.text import MAX_TEXT_CHARS, SentenceChunker, TextError
from server.controls import CONTROLS, ControlState, apply_controls
from server.errors import (
    AudioFormatError,
    ControlError,
    ProtocolViolation,
    ServerConfigError,
    reason_value,
)
from server.protocol import MAX_START_BYTES, loads_bounded
from server.session import AudioBlock, Frame, Output
from server.timing import StageTimes
from wire import protocol as P

FPS = 30
MAX_VOICE_CHARS = 64
"""A start's ``voice`` is an espeak-ng voice name (``en-gb-x-rp``): longer is refused before it is looked up."""
REJECTED_TEXT_CHARS = 200
"""A ``rejected`` reply quotes the text it refuses up to this many characters (a piece may hold 5000)."""
FRAGMENT_STALLS = 2.0
"""A word fragment left pending after a stall ("Then he went ho": "ho") is spoken after this many more
``stall_s`` without a new piece (3 s more at the default 1.5 s). Why wait longer: a source that paused
mid-word usually resumes (a network hiccup, a tool call), and a fragment spoken early is a wrong word
("ho", then "me") where waiting costs only time; a source that stopped for good without ``end`` still
gets its last word out."""
CLAUSE_WORDS = 8
"""A sentence still being written may be started at a clause boundary (comma, ``;``, ``:``, dash) once
this many words are before it, when the viewers have less than :data:`CLAUSE_AHEAD_S` of speech queued.
Why: a long first sentence was spoken only once it was complete (36 words at ~17 tokens/s: the first
frame 2 s after the first piece); each cut costs the silences a sentence starts and ends with."""
RUN_ON_WORDS = 20
"""A sentence still being written with no clause boundary is started at its last whole word once this many
words are pending, when the viewers have less than :data:`CLAUSE_AHEAD_S` of speech queued. Why: 600
characters without punctuation waited for the 300-character cut, the first frame 5.3 s after the first
piece; 20 words is past most sentences without a comma (a cut costs the silences and the intonation)."""
TEXT_CONTROLS = ("expression", "expression_ease_s")
"""The controls a text session takes. Not gain or smoothing_ms: its mouth comes from recorded lips (unit
selection), not from a model whose output a user tunes."""
CLAUSE_AHEAD_S = 1.0
"""Speech queued ahead of the viewers' clock (s) under which a clause is started (see CLAUSE_WORDS):
with more queued, the rest of the sentence usually arrives before the viewers need it, and no cut."""


class SpeechLike(Protocol):
    """What the text-to-speech function returns (e.g. :class:`assets.tts.Speech`)."""

    @property
    def samples(self) -> np.ndarray: ...  # (n,) float32 in [-1, 1]
    @property
    def sample_rate_hz(self) -> int: ...
    @property
    def phones(self) -> tuple: ...  # ((label, start_s, end_s), ...)
    @property
    def inventory(self) -> str: ...
    @property
    def text(self) -> str: ...
    def padded(self) -> SpeechLike: ...  # with the silences the face rests in before and after it


@dataclass(frozen=True, kw_only=True)
class TextBackend:
    """Everything a text session needs, injected by the command line (the server does not import
    training code). speak(text, language, voice) -> SpeechLike, raising a ConfigError subclass for
    text it cannot speak or a bad language/voice; synthesizer: unit selection over the corpus;
    languages: the supported language codes; sample_rate_hz: the rate ``speak`` produces (must be a
    multiple of 30 Hz, e.g. espeak-ng's 22050 Hz); lead_s: how far frames run ahead of real time;
    stall_s: pending text is spoken after this long without a new piece; n_best: unit sequences
    averaged (see UnitSynthesizer.synthesize); language_of_voice(voice, default="en") -> the language a
    start (or a text message) with a voice and no language speaks, ``default`` for a bare variant
    (:func:`assets.tts.language_of_voice`, as ``facecast say``; None: "en", or the session's language)."""

    speak: Callable[[str, str, str | None], SpeechLike]
    synthesizer: UnitSynthesizer
    languages: tuple[str, ...]
    sample_rate_hz: int
    lead_s: float = 0.5
    stall_s: float = 1.5
    n_best: int = 1
    language_of_voice: Callable[..., str] | None = None

    def __post_init__(self) -> None:
        if self.sample_rate_hz % FPS:
            raise ServerConfigError(f"speech rate {self.sample_rate_hz} Hz is not a multiple of {FPS} Hz")
        if not 0 <= self.lead_s <= 10 or not 0.1 <= self.stall_s <= 60:
            raise ServerConfigError("lead_s must be in 0..10 s and stall_s in 0.1..60 s")


@dataclass(frozen=True)
class _TextConfig:
    sample_rate_hz: int
    channels: int = 1


class TextSession:
    """One text stream -> speech and frames on one media timeline. Duck-types the parts of
    :class:`server.session.Session` that live sessions and viewers use (rates, counters, flush,
    controls). Not thread-safe: the owner serialises calls."""

    def __init__(
        self, backend: TextBackend, *, language: str, voice: str | None, rig=None, times: StageTimes | None = None
    ) -> None:
        if language not in backend.languages:
            raise ServerConfigError(
                f"unsupported language {reason_value(language)}; supported: {list(backend.languages)}"
            )
        self.backend = backend
        self.language = language
        self.voice = voice
        self.rig = rig
        self.times = times if times is not None else StageTimes()
        self.rate_hz = backend.sample_rate_hz
        self.fps = FPS
        self.config = _TextConfig(backend.sample_rate_hz)
        self.algorithmic_delay_s = 0.0
        self.chunker = SentenceChunker()
        self.frames_out = 0
        self.samples_out = 0
        self._audio_index = 0
        self.sentences = 0
        self.finished = False
        self._k = backend.synthesizer.corpus.n_coefficients
        self.controls = ControlState()
        self.released = 0  # the next frame to be released (release): a control's media time "now" is released / FPS

    # -- the parts of a session handle (server.live.SessionHandle) that live sessions use --------
    frame_bytes = 2  # nominal: text sessions take no audio

    def control_state(self) -> dict:
        state = self.controls.describe()
        return {k: state[k] for k in TEXT_CONTROLS}

    async def apply_control(self, msg: dict) -> dict:
        """A control message ``{"type": "control", "expression": {...}, "expression_ease_s": s}`` -> the control
        state, as :meth:`server.session.Session.apply_control` (same validation and reasons); ``at`` is media time,
        checked against (and by default) the next frame to be released. ControlError (nothing applied) otherwise."""
        for key in msg:
            if key != "type" and key in CONTROLS and key not in TEXT_CONTROLS:
                raise ControlError(
                    f"a text session takes only the controls {', '.join(TEXT_CONTROLS)}, not {reason_value(key)}"
                )
        self.controls = apply_controls(self.controls, msg, now_s=self.released / FPS)
        return self.control_state()

    def release(self, out: Output) -> Output:
        """Frames leaving for the viewers now -> the same frames under the session's expression at their media time
        (``params`` expressed, ``expression`` and ``speech_params`` set as :class:`server.session.Session` does, so
        ARKit-52 weights carry the recipes and a head driven by its own targets its face shapes); untouched (the
        same bytes) while no expression was ever set. In place: no payload of a frame is made before its release."""
        frames = out.frames
        alpha = self.controls.expression_at(np.array([f.media_time for f in frames]))
        if alpha is not None:
            speech = np.array([f.raw_params for f in frames])
            for f, p, a, s in zip(frames, express(speech, alpha), alpha, speech):
                f.params, f.expression, f.speech_params = p, a, s
        self.released = frames[-1].index + 1
        return out

    async def push_bytes(self, data: bytes) -> Output:
        raise AudioFormatError("a text session takes text messages, not audio")

    async def push(self, samples: np.ndarray) -> Output:
        raise AudioFormatError("a text session takes text messages, not audio")

    async def flush(self) -> Output:
        """End of the text: nothing left to emit here (pending text is spoken by :meth:`finish_text`)."""
        self.finished = True
        return Output([], None)

    async def close(self) -> None:
        """Nothing to release."""

    # -- text ---------------------------------------------------------------------------------
    def push_text(self, text: str, expression: object = None) -> list[str]:
        """A piece of text -> the sentences it completed (speak each with :meth:`speak`). Raises
        TextError for a piece over MAX_TEXT_CHARS (nothing of it is kept): the limit holds per
        message, not only per sentence, or one message could queue minutes of speech.

        expression: a text message's ``expression`` (a control's value, ``{"name", "intensity", "at"}``), ``at``
        by default where the next sentence spoken starts (the one holding the piece's first words): a language model
        that tags each sentence's emotion. ControlError for a bad one (nothing of the piece is kept then either)."""
        if len(text) > MAX_TEXT_CHARS:
            raise TextError(f"text piece is {len(text)} characters long; the limit is {MAX_TEXT_CHARS}")
        controls = self.controls
        if expression is not None:
            if isinstance(expression, dict):
                expression = {"at": self.frames_out / FPS, **expression}
            controls = apply_controls(self.controls, {"expression": expression}, now_s=self.released / FPS)
        done = self.chunker.push(text)
        self.controls = controls
        return done

    def finish_text(self) -> list[str]:
        """The pending text as a sentence (stall or end of the stream)."""
        return self.chunker.flush()

    def speak(self, sentence: str) -> tuple[list[Output], dict]:
        """Synthesise one sentence -> per-frame Outputs (frame + its audio block) appended to the
        timeline, and a report. Raises ConfigError (TextError) for text that cannot be spoken."""
        t0 = time.perf_counter()
        # silence before and after each sentence, the face at rest there: a sentence starts and
        # ends with the lips together, so sentences join without a jump (synthesised speech has no in-breath)
        speech = self.backend.speak(sentence, self.language, self.voice).padded()
        t1 = time.perf_counter()
        n = int(np.ceil(len(speech.samples) * FPS / speech.sample_rate_hz - 1e-9))
        if speech.sample_rate_hz != self.rate_hz:
            raise ServerConfigError(f"speech came at {speech.sample_rate_hz} Hz, the session runs at {self.rate_hz} Hz")
        # On one BLAS thread, as `facecast say`: the server holds BLAS so while it serves (FacecastServer.start).
        res = self.backend.synthesizer.synthesize(
            list(speech.phones), speech.inventory, n_frames=n, n_best=self.backend.n_best, rest_pauses=RestPauses()
        )
        t2 = time.perf_counter()
        self.times.add("text_speech", t1 - t0)
        self.times.add("text_units", t2 - t1)
        per = self.rate_hz // FPS
        audio = np.zeros(n * per)
        audio[: len(speech.samples)] = speech.samples[: n * per]
        params = res.frames[:, self._k :]
        outs = []
        now = time.perf_counter()
        for j in range(n):
            k = self.frames_out
            frame = Frame(
                k,
                k / FPS,
                params[j].astype(np.float64),
                params[j].astype(np.float64),
                (t2 - t0) / n,
                now,
                self.rig,
                self.times,
            )
            block = AudioBlock(
                self._audio_index, self.samples_out, self.samples_out / self.rate_hz, audio[j * per : (j + 1) * per]
            )
            self._audio_index += 1
            self.samples_out += per
            self.frames_out += 1
            outs.append(Output([frame], block))
        self.sentences += 1
        sel, tgt = res.selection, res.target
        report = {
            "type": "spoken",
            "text": speech.text,
            "frames": n,
            "media_time": outs[0].frames[0].media_time,
            "duration_s": n / FPS,
            "units": sel.n_units,
            "junctions_outside_corpus": sel.n_mismatched,
            "unknown_phones": sorted(set(tgt.unknown)),
            "synthesis_ms": round(1000 * (t2 - t0), 1),
            "language": self.language,
        }
        return outs, report

    def cancel(self, next_index: int, last_params: np.ndarray | None) -> list[Output]:
        """Interrupt the speech: the timeline rewound to ``next_index`` (the frames from there on were
        not released and are dropped) and, when ``last_params`` ((4,) the last released frame's mouth
        parameters) is given, frames easing from it to the rest pose over ``RestPauses.ramp_s`` (the
        smoothstep a sentence's end eases with), with silent audio; the last frame is at rest."""
        per = self.rate_hz // FPS
        self.frames_out = self._audio_index = next_index
        self.samples_out = next_index * per
        if last_params is None:
            return []
        rest = self.backend.synthesizer.rest[self._k :]
        n = max(1, round(RestPauses().ramp_s * FPS))
        w = crossfade(np.arange(1, n + 1) / n)
        now = time.perf_counter()
        outs = []
        for j in range(n):
            k = self.frames_out
            params = last_params + w[j] * (rest - last_params)
            frame = Frame(k, k / FPS, params, params.copy(), 0.0, now, self.rig, self.times)
            block = AudioBlock(self._audio_index, self.samples_out, self.samples_out / self.rate_hz, np.zeros(per))
            self._audio_index += 1
            self.samples_out += per
            self.frames_out += 1
            outs.append(Output([frame], block))
        return outs


def espeak_backend(corpus: str | Path | None = None, *, n_best: int = 1) -> TextBackend:
    """The standard backend: espeak-ng speech (:mod:`assets.tts`) and unit selection over a unit corpus
    (``corpus`` None = the shipped or newest built one, :func:`assets.unitcorpus.find_unit_corpus`)."""
    from assets.espeak import synthesizer
    from assets.tts import INVENTORY, language_of_voice, speak
    from assets.unitcorpus import find_unit_corpus, load_unit_corpus

    stored = load_unit_corpus(find_unit_corpus(corpus))
    return TextBackend(
        speak=lambda text, language, voice: speak(text, language=language, voice=voice),
        synthesizer=UnitSynthesizer(stored.corpus, rest=stored.rest_frame()),
        languages=tuple(INVENTORY),
        sample_rate_hz=synthesizer().sample_rate_hz,
        n_best=n_best,
        language_of_voice=language_of_voice,
    )


async def _speech_choice(
    msg: dict, backend: TextBackend, *, language: str, voice: str | None, current: tuple[str, str | None] | None = None
) -> tuple[str, str | None]:
    """A start's or a text message's ``language`` / ``voice`` -> ``(language, voice)`` to speak with; ``language`` and
    ``voice`` are what holds without them (a voice given alone names its language; a bare variant such as "f3" keeps
    ``language``: a Spanish session asking for a female voice stays Spanish; a language given alone takes its default
    voice). Raises ConfigError (a TextError) naming a bad language or voice. A voice other than ``current`` is tried
    (off the event loop), so a bad one fails here, not mid-sentence."""
    voice = msg.get("voice", voice if "language" not in msg else None)
    if voice is not None and (not isinstance(voice, str) or len(voice) > MAX_VOICE_CHARS):
        # quoted short: a 100,000-character voice was quoted whole, and the close frame's limit cut off the voices
        raise TextError(f"voice must be a name of at most {MAX_VOICE_CHARS} characters, got {reason_value(voice)}")
    infer = backend.language_of_voice
    language = msg["language"] if "language" in msg else infer(voice, language) if infer else language
    if not isinstance(language, str) or language not in backend.languages:
        raise TextError(f"unsupported language {reason_value(language)}; supported: {list(backend.languages)}")
    if voice is not None and (language, voice) != current:
        await asyncio.to_thread(backend.speak, "a", language, voice)
    return language, voice


def _text_message(raw: Any) -> dict:
    if not isinstance(raw, str):
        raise ProtocolViolation(P.CLOSE_UNSUPPORTED_DATA, "a text session takes JSON text messages, not binary")
    # Nesting bounded like every client text (json.loads of "[[[..." raised RecursionError: an internal
    # error, 1011). The size bound is the WebSocket's max_message_bytes, not /ingest's 64 KiB for control
    # messages: a piece over 5000 characters is answered "rejected" and the session goes on, not closed.
    return loads_bounded(raw, "message", max_bytes=MAX_START_BYTES)


def _violation(kind: Any) -> NoReturn:
    """A message a started text session does not take: a second start, or an unknown type."""
    if kind == "start":
        raise ProtocolViolation(P.CLOSE_POLICY, "second start message: the session has started")
    raise ProtocolViolation(
        P.CLOSE_POLICY, f"unknown message type {reason_value(kind)} (expected text, flush, cancel, control or end)"
    )


async def handle_text(server, ws: ServerConnection) -> None:
    """The ``/text`` endpoint (protocol in docs/protocol.md)."""
    from server.live import EndWake, LiveSession, SentenceReplay, sessions_log
    from server.protocol import token_ok

    backend: TextBackend | None = getattr(server, "text_backend", None)
    if backend is None:
        raise ProtocolViolation(
            P.CLOSE_NOT_FOUND, "text sessions are not enabled on this server (facecast serve --text)"
        )
    try:
        first = await asyncio.wait_for(ws.recv(), server.config.start_timeout_s)
    except TimeoutError:
        raise ProtocolViolation(
            P.CLOSE_POLICY, f"no start message within {server.config.start_timeout_s:g} s"
        ) from None
    start = _text_message(first)
    if start.get("type") != "start":
        got = reason_value(start.get("type"))
        raise ProtocolViolation(P.CLOSE_POLICY, f'first message must be {{"type": "start"}}, got {got}')
    if not token_ok(start.get("token"), server.config.token):
        raise ProtocolViolation(P.CLOSE_UNAUTHORIZED, "missing or wrong token")
    unknown = sorted(set(start) - {"type", "session", "language", "voice", "token"})
    if unknown:
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, f"unknown start fields {unknown}")
    name = start.get("session")
    if not isinstance(name, str) or not P.SESSION_NAME.match(name):
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, P.SESSION_NAME_RULE)
    try:
        # `{"voice": "es"}` alone was refused (Spanish voice, English by default): the voice names its language
        language, voice = await _speech_choice(start, backend, language="en", voice=None)
        session = TextSession(
            backend, language=language, voice=voice, rig=server.head.rig if server.head else None, times=server.times
        )
    except ConfigError as exc:
        raise ProtocolViolation(P.CLOSE_BAD_REQUEST, str(exc)) from None
    try:
        server._admission(name)  # the server's one admission check (name, capacity, shutdown)
    except ServerConfigError as exc:
        raise ProtocolViolation(getattr(exc, "code", P.CLOSE_BAD_REQUEST), str(exc)) from None
    live = LiveSession(name, session, server, source="text")
    live.replay = SentenceReplay()
    server.sessions[name] = live
    if server.cluster is not None:
        # registered cluster-wide like an audio session: /sessions on every node lists it, and viewers
        # on other nodes receive its frames and audio through the cluster's channels (live._fanout)
        owner = await server.cluster.claim(live)
        if owner is not None:
            del server.sessions[name]
            raise ProtocolViolation(P.CLOSE_CONFLICT, f"session {name!r} already exists (on node {owner})")
    await server.release_held(live)  # viewers held for it (view query wait) subscribe before its first sentence
    sessions_log.info("session %r started: text, %s%s", name, language, f", voice {voice}" if voice else "")
    queue: asyncio.Queue = asyncio.Queue()
    clock: dict[str, float] = {}
    first_piece: list[float] = []
    sentence_ends: dict[int, float] = {}  # a sentence's first frame index -> its end, media time (s)
    spans: list[tuple[int, int]] = []  # accepted sentences' frame ranges [first, end) not yet fully released
    released: dict[str, Any] = {"next": 0, "params": None}  # the next frame to release, the last one's params
    easing = [0, 0]  # the frames [first, end) of the last cancel's ease to rest

    async def pacer() -> None:
        """Release frames no earlier than ``lead_s`` before their media time on the wall clock."""
        while True:
            out = await queue.get()
            if out is None:
                return
            mt = out.frames[0].media_time
            if "t0" not in clock:
                clock["t0"] = time.perf_counter() - mt
                if first_piece:
                    clock["first_frame_s"] = time.perf_counter() - first_piece[0]
            wait = clock["t0"] + mt - backend.lead_s - time.perf_counter()
            if wait > 0:
                await asyncio.sleep(wait)
            elif clock["t0"] + mt < time.perf_counter() - 1.0:  # fell behind (a long pause in the text): re-anchor
                clock["t0"] = time.perf_counter() - mt
            end = sentence_ends.pop(out.frames[0].index, None)
            if end is not None and live.replay is not None:  # a sentence starts: what a joining viewer gets
                live.replay.begin(out.frames[0].index, clock["t0"] + end)
            live._fanout(session.release(out))
            # the speech params (before the expression): a cancel's ease starts there and is expressed as it leaves
            released["next"], released["params"] = out.frames[-1].index + 1, out.frames[-1].raw_params

    async def reply(msg: dict) -> None:
        # a source that dropped still has its accepted speech played out (below): its replies go nowhere
        with contextlib.suppress(ConnectionClosed):
            await ws.send(P.dumps(msg))

    def enqueue(outs: list[Output]) -> None:
        spans[:] = [span for span in spans if span[1] > released["next"]]  # those played are no longer needed
        first = outs[0].frames[0].index
        sentence_ends[first] = outs[-1].frames[-1].media_time + 1 / FPS
        spans.append((first, outs[-1].frames[-1].index + 1))
        for o in outs:
            queue.put_nowait(o)

    async def say(sentences: list[str]) -> None:
        for sentence in sentences:
            if live.ended.is_set():  # the server is stopping: its loop below ends the session at once
                return
            try:
                outs, report = await asyncio.to_thread(session.speak, sentence)
            except ConfigError as exc:  # TextError: nothing pronounceable; the session goes on
                await reply({"type": "rejected", "text": sentence[:REJECTED_TEXT_CHARS], "reason": str(exc)})
                continue
            enqueue(outs)
            await reply(report)

    def ahead_s() -> float:
        """Speech queued ahead of the viewers' clock (s): all of it before the first frame leaves."""
        return session.frames_out / FPS - (time.perf_counter() - clock["t0"] if "t0" in clock else 0.0)

    async def finish() -> None:
        """Speak what is pending and wait until the last frame has been released."""
        await say(session.finish_text())
        queue.put_nowait(None)
        await pace

    pace: asyncio.Future[None]  # the pacer task; a cancel replaces it

    async def cancel() -> dict:
        """Barge-in: what is not yet released is dropped (frames already sent, up to lead_s, still play), the pending
        text too, and the mouth eases to rest; -> the `cancelled` reply."""
        nonlocal pace
        pace.cancel()
        await asyncio.gather(pace, return_exceptions=True)
        while not queue.empty():
            queue.get_nowait()
        session.chunker.reset()  # a new answer follows: not inside the cut one's code block
        nxt = released["next"]
        cut = [span for span in spans if span[1] > nxt]
        # Moving: a sentence cut mid-way, or an earlier cancel's ease not yet all released (a second cancel during
        # it dropped the rest of the ease and left the mouth open where it was).
        moving = any(first < nxt for first, _ in cut) or easing[1] > nxt
        spans.clear()
        for k in [k for k in sentence_ends if k >= nxt]:
            del sentence_ends[k]
        ease = session.cancel(nxt, released["params"] if moving else None)
        easing[:] = [nxt, nxt + len(ease)]
        if ease:
            sentence_ends[nxt] = ease[-1].frames[-1].media_time + 1 / FPS
            for o in ease:
                queue.put_nowait(o)
        pace = asyncio.ensure_future(pacer())
        return {"type": "cancelled", "dropped": len(cut), "media_time": nxt / FPS}

    async def control(msg: dict) -> dict:
        """A control message from the source -> its reply, as an ingest's (``ack`` or ``rejected`` with the reason)."""
        try:
            return {"type": "ack", "controls": await live.control(msg)}
        except ControlError as exc:
            return {"type": "rejected", "reason": str(exc)}

    async def play_out() -> bool:
        """After `end`: wait until the last frame has been released (the pacer met its end mark), still reading the
        source: a `cancel` cuts the play-out (a chatbot's user talks over the answer's last sentences, which were
        spoken to the end before), text is rejected (the session is ending), `flush` and `end` change nothing.
        False when the server started stopping first (nothing waits for the rest of the speech then)."""
        reading: asyncio.Future | None = None
        try:
            async with wake.until(None):
                while not pace.done():
                    if reading is None:
                        reading = asyncio.ensure_future(ws.recv())
                    await asyncio.wait({pace, reading}, return_when=asyncio.FIRST_COMPLETED)
                    if not reading.done():
                        continue
                    try:
                        raw = reading.result()
                    except ConnectionClosed:  # the source left after `end`: its speech plays out all the same
                        await asyncio.wait({pace})
                        return True
                    reading = None
                    msg = _text_message(raw)
                    kind = msg.get("type")
                    if kind == "cancel":
                        await reply(await cancel())
                        queue.put_nowait(None)  # the session still ends, after the ease
                    elif kind == "text":
                        text = msg.get("text")
                        shown = text[:REJECTED_TEXT_CHARS] if isinstance(text, str) else None
                        await reply({"type": "rejected", "text": shown, "reason": "after end: the session is ending"})
                    elif kind == "control":  # the frames still to be released take it
                        await reply(await control(msg))
                    elif kind not in ("flush", "end"):
                        _violation(kind)
        except TimeoutError:  # only the server stopping ends this wait
            return False
        finally:
            if reading is not None:
                reading.cancel()
        return True

    pace = asyncio.ensure_future(pacer())
    code, reason = P.CLOSE_NORMAL, "session ended"
    stalled = False  # a stall spoke the pending words and left a word fragment waiting
    # A server stopping sets live.ended: every wait of this handler (the source's next message, the play-out after
    # `end` or after the source dropped) is cut short there, as an ingest's is (EndWake). The text handler never
    # looked: the server closed its socket after close_timeout_s (1001 with no reason), and the source's drop then
    # played every accepted sentence out in real time before the process could exit (18.6 s after SIGTERM with
    # 22 s of speech queued).
    loop = asyncio.get_running_loop()
    wake = EndWake(live.ended)
    try:
        await ws.send(
            P.dumps(
                {
                    "type": "started",
                    "session": name,
                    "fps": FPS,
                    "audio_rate_hz": session.rate_hz,
                    "language": language,
                    "view_path": f"/view?session={name}",
                }
            )
        )
        while True:
            wait_s = (FRAGMENT_STALLS if stalled else 1.0) * backend.stall_s
            try:
                if live.ended.is_set():
                    raise TimeoutError
                async with wake.until(loop.time() + wait_s if session.chunker.pending.strip() else None):
                    raw = await ws.recv()
            except TimeoutError:  # the stream stalled mid-sentence: speak its whole words (later the fragment)
                if live.ended.is_set():  # the server is stopping: what is not yet released is dropped
                    code, reason = P.CLOSE_GOING_AWAY, "server shutting down"
                    break
                done = session.finish_text() if stalled else session.chunker.flush_words()
                stalled = bool(session.chunker.pending.strip())
                await say(done)
                continue
            msg = _text_message(raw)
            kind = msg.get("type")
            if kind == "text":
                stalled = False
                text = msg.get("text")
                if not isinstance(text, str):  # no text to quote: null (docs/protocol.md section 9.6)
                    # its own name: `reason` is the session's close reason (it closed with this one at its end)
                    why = f"text must be a string, got {reason_value(text)}"
                    await reply({"type": "rejected", "text": None, "reason": why})
                    continue
                if "language" in msg or "voice" in msg:
                    # A conversation that changes language keeps its session (and its viewers): the text pending
                    # in the old language is spoken first, in it; this piece and what follows in the new one.
                    now = (session.language, session.voice)
                    try:
                        switch = await _speech_choice(msg, backend, language=now[0], voice=now[1], current=now)
                    except ConfigError as exc:
                        await reply({"type": "rejected", "text": text[:REJECTED_TEXT_CHARS], "reason": str(exc)})
                        continue
                    if switch != now:
                        await say(session.finish_text())
                        session.language, session.voice = switch
                        sessions_log.info(
                            "session %r now speaks %s%s", name, switch[0], f", voice {switch[1]}" * bool(switch[1])
                        )
                received = time.perf_counter()
                try:
                    done = session.push_text(text, msg.get("expression"))
                except (TextError, ControlError) as exc:
                    await reply({"type": "rejected", "text": text[:REJECTED_TEXT_CHARS], "reason": str(exc)})
                    continue
                if not first_piece:  # the first piece accepted: a rejected one starts no speech (it counted 2.6 s)
                    first_piece.append(received)
                if msg.get("flush"):
                    done += session.finish_text()
                elif not done and ahead_s() < CLAUSE_AHEAD_S:  # the viewers would wait for the whole sentence
                    done = session.chunker.take_clause(CLAUSE_WORDS) or session.chunker.take_words(RUN_ON_WORDS)
                await say(done)
            elif kind == "flush":
                stalled = False
                await say(session.finish_text())
            elif kind == "cancel":
                stalled = False
                await reply(await cancel())
            elif kind == "control":
                await reply(await control(msg))
            elif kind == "end":
                await say(session.finish_text())
                queue.put_nowait(None)
                if not await play_out():  # the server is stopping: what is not yet released is dropped
                    code, reason = P.CLOSE_GOING_AWAY, "server shutting down"
                    break
                await ws.send(
                    P.dumps(
                        {
                            "type": "ended",
                            "frames": session.frames_out,
                            "audio_s": session.samples_out / session.rate_hz,
                            # null when nothing was spoken (JSON has no NaN)
                            "first_frame_ms": (
                                round(1000 * clock["first_frame_s"], 1) if "first_frame_s" in clock else None
                            ),
                        }
                    )
                )
                break
            else:
                _violation(kind)
    except ProtocolViolation:
        code, reason = P.CLOSE_NORMAL, "session ended: its source broke the protocol"
        raise
    except ConnectionClosed:
        # The source dropped without `end`: what it was told was spoken plays out to the viewers, and its
        # pending text is spoken as `end` would (nothing accepted is lost); then the session ends. Not when the
        # server is stopping (its socket closed by the shutdown): nothing would wait for the speech.
        try:
            if server.stopping:
                raise TimeoutError
            async with wake.until(None):
                await finish()
        except TimeoutError:  # the server is stopping: what is not yet released is dropped
            code, reason = P.CLOSE_GOING_AWAY, "server shutting down"
    finally:
        pace.cancel()
        wake.close()
        if code == P.CLOSE_GOING_AWAY:
            # The source first: the session's end lets the server's stop go on to close every socket left with
            # 1001 and no reason, which the source's close (after the viewers') raced and sometimes lost.
            await server.close_ws(ws, code, reason)
        await server._end_session(live, code, reason)
    if code != P.CLOSE_GOING_AWAY:
        await server.close_ws(ws, code, reason)
