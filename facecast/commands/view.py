"""``facecast view [URL]``: watch a live session; ``--record OUT.mp4`` renders it with its audio."""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_URL = "http://127.0.0.1:8765"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "view",
        help="watch a live session; --record renders it to MP4 with the speech",
        formatter_class=HelpFormatter,
        description="Connect to a facecast server as a viewer of one session (vertex deltas and the relayed "
        "audio). --record OUT.mp4 renders every frame offscreen (EGL) and muxes the session's audio in, "
        "frame k at k/30 s of the session, when the session ends (or after --duration). Watching live with "
        "sound is the browser viewer's job: open the server's URL in a browser.",
    )
    p.add_argument("url", nargs="?", default=DEFAULT_URL, help="the server's base URL")
    p.add_argument("--session", default=None, help="session to watch (default %(default)s = the first live one)")
    p.add_argument("--record", type=Path, default=None, metavar="OUT.mp4", help="render the stream into this MP4 (required: there is no live window)")
    p.add_argument("--wait", type=float, default=10.0, help="seconds to wait for the session to start")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default %(default)s = when the session ends)")
    p.add_argument("--token-env", default=None, metavar="VAR", help="environment variable holding the server's token (default %(default)s = no token)")
    p.add_argument("--width", type=int, default=640, help="video width in pixels")
    p.add_argument("--height", type=int, default=480, help="video height in pixels")
    p.set_defaults(run=run)


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

    from clients.errors import ClientError
    from clients.render.renderer import RenderConfig
    from clients.viewer.stream import StreamConfig, fetch_head, pick_session, record_stream
    from clients.viewer.video import render_recording

    if args.record is None:
        raise ClientError(
            f"a live window is not available here (no display support in this build); open {args.url}/ in a "
            "browser to watch and listen, or pass --record OUT.mp4 to render the session to a video")
    token = token_from_env(args.token_env)

    async def main():
        session = await pick_session(args.url, args.session, args.wait)
        mesh = await fetch_head(args.url)
        cfg = StreamConfig(url=args.url, session=session, kind="deltas", encoding="int16", token=token,
                           wait_s=args.wait, max_s=args.duration)
        print(f"facecast view: recording session {session!r} from {args.url}", flush=True)
        return session, mesh, await record_stream(cfg)

    session, mesh, rec = asyncio.run(main())
    out, n = render_recording(rec, mesh, args.record, config=RenderConfig(width=args.width, height=args.height,
                                                                           margin=1.25))
    print(f"facecast view: wrote {out}: {n} frames ({n / rec.fps:.2f} s) of {session!r} with its audio; "
          f"session closed with {rec.close_code} {rec.close_reason}")
    return 0
