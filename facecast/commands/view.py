"""``facecast view [URL]``: watch a live session; ``--record OUT.mp4`` renders it with its audio."""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_URL = "http://127.0.0.1:8765"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "view",
        help="watch a live session in a window with sound; --record renders it to MP4",
        formatter_class=HelpFormatter,
        description="Connect to a facecast server as a viewer of one session (vertex deltas and the relayed "
        "audio). Where a display exists a window shows the head live and the default sound device plays the "
        "speech in sync (frames and sound share one timeline, delayed by --buffer-ms); when the session ends "
        "or the server restarts the window waits for it to come back. --record OUT.mp4 instead renders every "
        "frame offscreen (EGL, no display needed) and muxes the session's audio in, frame k at k/30 s of the "
        "session, when the session ends (or after --duration); it exits 3 when the server closed the session "
        "before its end (a partial take, written), as `facecast record` does. The browser viewer at the server's "
        "URL does the same in any browser.",
    )
    p.add_argument(
        "url", nargs="?", default=DEFAULT_URL, help="the server's base URL (http:// or ws://; its /view URL too)"
    )
    p.add_argument("--session", default=None, help="session to watch (default %(default)s = the first live one)")
    p.add_argument(
        "--record",
        type=Path,
        default=None,
        metavar="OUT.mp4",
        help="render the stream into this MP4 instead of showing a window (default %(default)s = window)",
    )
    p.add_argument(
        "--screenshot",
        type=Path,
        default=None,
        metavar="PNG",
        help="window mode: save the last image shown as PNG on exit, Ctrl-C included (default %(default)s = none)",
    )
    p.add_argument(
        "--save-sound",
        type=Path,
        default=None,
        metavar="WAV",
        help="window mode: on exit, write the sound as handed to the sound device (its silences and "
        "timeline moves included) to this WAV, to check what was played (default %(default)s = none)",
    )
    p.add_argument("--buffer-ms", type=float, default=80.0, help="window mode: jitter buffer before a frame is shown")
    add_session_options(p)
    p.add_argument("--width", type=int, default=640, help="window or video width in pixels")
    p.add_argument("--height", type=int, default=480, help="window or video height in pixels")
    p.set_defaults(run=run)


def add_session_options(p: argparse.ArgumentParser) -> None:
    """--wait, --duration and --token-env: how view and record attach to a live session."""
    p.add_argument(
        "--wait",
        type=float,
        default=10.0,
        help="seconds to wait for the session to start (the server holds the viewer meanwhile: it gets the "
        "session from its first audio block)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        help="stop after this many seconds (default %(default)s = when the session ends)",
    )
    add_token_option(p)


def add_token_option(p: argparse.ArgumentParser) -> None:
    """--token-env: the environment variable holding the server's token (read by :func:`token_from_env`)."""
    p.add_argument(
        "--token-env",
        default=None,
        metavar="VAR",
        help="environment variable holding the server's token (default %(default)s = no token)",
    )


def token_from_env(var: str | None) -> str | None:
    """The token held in environment variable ``var`` (kept off the command line), or None."""
    import os

    from clients.errors import ClientError

    if var is None:
        return None
    token = os.environ.get(var)
    if not token:
        raise ClientError(f"--token-env {var}: the environment variable is empty or unset")
    return token


def run(args: argparse.Namespace) -> int:
    import asyncio

    from clients.client import server_url
    from clients.render.renderer import RenderConfig
    from clients.viewer.stream import ViewerStreamConfig, fetch_head, pick_session, record_stream
    from clients.viewer.video import render_recording

    args.url = server_url(args.url, "/view")  # the base URL also when given as the viewers' ws://HOST:PORT/view
    token = token_from_env(args.token_env)
    if args.record is None:
        return _window(args, token)
    from assets.files import check_writable
    from clients.render.video import check_video_path, check_video_size

    check_writable(check_video_path(args.record))  # before the session is watched, not after it ended
    check_video_size(args.width, args.height)

    async def main():
        session = await pick_session(args.url, args.session, args.wait, token)
        mesh = await fetch_head(args.url, token)
        cfg = ViewerStreamConfig(
            url=args.url,
            session=session,
            kind="deltas",
            encoding="int16",
            token=token,
            wait_s=args.wait,
            max_s=args.duration,
        )
        print(f"facecast view: recording session {session!r} from {args.url}", flush=True)
        return session, mesh, await record_stream(cfg)

    session, mesh, rec = asyncio.run(main())
    out, n = render_recording(
        rec, mesh, args.record, config=RenderConfig(width=args.width, height=args.height, margin=1.25)
    )
    print(
        f"facecast view: wrote {out}: {n} frames ({n / rec.fps:.2f} s) of {session!r} with its audio; {rec.ending}"
        + ("; a partial take: the session did not end normally" if rec.partial else "")
    )
    # As `facecast record`'s: a script told a take cut short (1001, a server killed) from a whole one only there.
    from facecast.commands.record import PARTIAL_EXIT

    return PARTIAL_EXIT if rec.partial else 0


def _window(args: argparse.Namespace, token: str | None) -> int:
    import asyncio
    import os
    import statistics

    from clients.errors import ClientError
    from clients.render.renderer import RenderConfig
    from clients.viewer.live import run_window
    from clients.viewer.stream import ViewerStreamConfig, fetch_head, pick_session

    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ClientError(
            f"no display here: pass --record OUT.mp4 to render the session to a video, or open "
            f"{args.url}/ in a browser to watch and listen"
        )

    async def setup():
        return await pick_session(args.url, args.session, args.wait, token), await fetch_head(args.url, token)

    session, mesh = asyncio.run(setup())
    cfg = ViewerStreamConfig(
        url=args.url, session=session, kind="deltas", encoding="int16", token=token, wait_s=args.wait
    )
    import signal

    # Ctrl-C (SIGINT) stops the window, as it stops `facecast serve`, also when the window was started from a job
    # that ignores SIGINT (a shell's background `&` does, and Python then keeps ignoring it): the window kept
    # running, and its --screenshot was never written.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    st = run_window(
        cfg,
        mesh,
        config=RenderConfig(width=args.width, height=args.height, margin=1.25),
        buffer_s=args.buffer_ms / 1000,
        duration_s=args.duration,
        screenshot=args.screenshot,
        save_sound=args.save_sound,
    )
    delivery = f"{statistics.median(st.delivery_ms):.1f} ms" if st.delivery_ms else "-"
    print(
        f"facecast view: showed {st.shown} of {st.received} frames"
        + ("" if st.first_index is None else f" received from frame {st.first_index}")
        + f" ({st.lost} lost, {st.skipped} skipped, "
        f"{st.resyncs} resyncs), {st.connections} connection(s), delivery median {delivery}, "
        f"sound {'on ' + st.audio_device if st.audio_device else 'off'}"
        + (
            f" ({st.audio_underruns} device underrun(s): each about 2 s of silence through PulseAudio)"
            if st.audio_underruns
            else ""
        )
        + (f"; wrote {args.screenshot}" if args.screenshot else "")
        + (f"; wrote {st.saved_sound}" if st.saved_sound else "")
        + ("; stopped with Ctrl-C" if st.interrupted else "")
    )
    return 0  # Ctrl-C included: it is how a window is stopped, not a failure
