"""``facecast send SPEECH [URL]``: stream a speech file into a running server as one live session."""

from __future__ import annotations

import argparse
from pathlib import Path

FAST_AHEAD_S = 1.5
"""s: how far ahead of real time ``send --fast`` sends. A server holds an ingest to real time plus its
``ingest_burst_s`` (2 s by default; docs/protocol.md section 7), so audio sent further ahead only queued in the
sockets (~95 s of 22.05 kHz s16 on loopback) with the keepalive pings and pongs behind it: `send --fast` of 164 s
ended after 40 s with "1011 keepalive ping timeout" (a server with ``ingest_overrun`` "close" closed it with 4029 at
2 s). A file this long or shorter goes at once."""

FAST_HOLD_S = 0.25
"""s: how long ``send --fast`` waits after its session has started before sending audio. The server replays
nothing, and a fast session's frames all leave within a few hundredths of a second of its start (57 frames of
1.9 s in 0.04 s on loopback), so a `view` / `record` started first, retrying every 50 ms (RETRY_S), found it over
(exit 2, "4004 no session" once --wait ran out) or joined it at 1.0-1.3 s. In real time the first frame leaves
about 0.2 s after the start, which those retries catch; this is five of them."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter
    from facecast.commands.view import DEFAULT_URL, add_token_option

    p = sub.add_parser(
        "send",
        help="stream a speech file into a running server as a live session (the ingest client)",
        formatter_class=HelpFormatter,
        description="Connect to a `facecast serve` server's /ingest and stream SPEECH (WAV; other formats "
        "through ffmpeg) as one session, in real time unless --fast, then end the session and print the "
        "server's reply (frames made, seconds of audio). Viewers watch it meanwhile: the browser viewer "
        "at the server's URL, `facecast view` or `facecast record`. A file on the server's own machine can "
        "also be streamed by `facecast serve --file`.",
    )
    p.add_argument("speech", type=Path, help="speech audio file")
    p.add_argument(
        "url", nargs="?", default=DEFAULT_URL, help="the server's base URL (http:// or ws://; its /ingest URL too)"
    )
    p.add_argument("--session", default=None, help="session name (default %(default)s = the file's name)")
    p.add_argument(
        "--fast",
        action="store_true",
        help=f"send as fast as the server takes it instead of in real time, after {FAST_HOLD_S:g} s in which "
        "the viewers waiting for the session (view, record) connect, so they get it from its first frame: the "
        f"first {FAST_AHEAD_S:g} s of audio at once, the rest in real time (a server holds an ingest to real time "
        "plus 2 s)",
    )
    p.add_argument(
        "--enrol",
        type=Path,
        default=None,
        metavar="VOICE",
        help="speaker enrolment: a recording of the talker (30-60 s intended, 1-120 s accepted; any audio file) "
        "sent with the session's start, converted to the session's rate, mono, 16-bit; the server animates this "
        "session with its model adapted to the voice (docs/protocol.md, `enrol`)",
    )
    p.add_argument(
        "--auto-gain",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="ask the server to bring the speech to the model's training level first (a quiet take moves the mouth "
        "as a loud one), or not (--no-auto-gain); default: the server's setting",
    )
    add_token_option(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from assets.audio import check_audio_path
    from clients.client import ingest_file, server_url
    from facecast.commands.view import token_from_env

    check_audio_path(args.speech)
    if args.enrol is not None:
        check_audio_path(args.enrol)
    url = server_url(args.url, "/ingest")  # the base URL also when given as the endpoint, ws://HOST:PORT/ingest
    token = token_from_env(args.token_env)
    session = args.session if args.session is not None else args.speech.stem
    pace = "as fast as the server takes it" if args.fast else "in real time"
    print(f"facecast send: streaming {args.speech} as session {session!r} to {url} {pace}", flush=True)
    hold = FAST_HOLD_S if args.fast else 0.0
    started, ended = asyncio.run(
        ingest_file(
            url,
            args.speech,
            session=session,
            ahead_s=FAST_AHEAD_S if args.fast else 0.0,
            token=token,
            hold_s=hold,
            enrol=args.enrol,
            auto_gain=args.auto_gain,
        )
    )
    if started.get("auto_gain"):
        print("facecast send: the server brings the speech to the model's level (auto gain)")
    if "enrolled_s" in started:
        print(f"facecast send: the server adapted the session to {started['enrolled_s']:.2f} s of {args.enrol}")
    print(
        f"facecast send: session {session!r} ended: {ended.get('frames')} frames, "
        f"{float(ended.get('audio_s', 0.0)):.2f} s of audio"
    )
    return 0
