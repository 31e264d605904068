"""``facecast demo``: speech -> live session -> viewers, on built-in defaults; writes an MP4."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "demo",
        help="run the whole product on built-in defaults (espeak-ng speech, live server, MP4)",
        formatter_class=HelpFormatter,
        description="Synthesise a few sentences with espeak-ng (or listen to the microphone with --mic), start the "
        "server, stream the speech through a live session in real time and print the URLs to watch it, then "
        "render what a viewer received to an MP4 (built-in head, offline renderer).",
    )
    p.add_argument("--mic", action="store_true", help="use the default microphone instead of synthesised speech")
    p.add_argument("--seconds", type=float, default=None, help="with --mic: stop after this long (default: Ctrl-C)")
    p.add_argument("--host", default="127.0.0.1", help="interface to bind")
    p.add_argument("--port", type=int, default=8765, help="TCP port (0 = any free port)")
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        help="model file (.npz) or a shipped name: default, low-latency (docs/default_model.md)",
    )
    p.add_argument("--rig", type=Path, default=None, help="rig file (.npz); default: the built-in head")
    p.add_argument("--voice", default="en-us", help="espeak-ng voice")
    p.add_argument(
        "--text", action="append", default=None, help="a sentence to say instead of the built-in ones (repeatable)"
    )
    p.add_argument("--out", type=Path, default=Path("facecast_demo.mp4"), help="MP4 to write")
    p.add_argument("--no-video", action="store_true", help="do not render the MP4")
    p.add_argument(
        "--once",
        action="store_true",
        help="exit after the MP4 instead of serving and replaying the speech until Ctrl-C",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio

    from threadpoolctl import threadpool_limits

    from assets.files import check_writable
    from assets.heads.head import resolve_head
    from assets.modelfile import load_model
    from clients.render.video import check_video_path
    from facecast.demo import SENTENCES, DemoConfig, run_demo, serve_replay, write_mp4

    web = Path(__file__).resolve().parents[2] / "clients" / "web"
    npm = Path(__file__).resolve().parents[2] / "node_modules"  # three.js for the browser viewer (npm ci)
    cfg = DemoConfig(
        host=args.host,
        port=args.port,
        mic=args.mic,
        mic_seconds=args.seconds,
        sentences=tuple(args.text) if args.text else SENTENCES,
        voice=args.voice,
        video=None if args.no_video else args.out,
        web_root=web if web.is_dir() else None,
        node_modules=npm if npm.is_dir() else None,
    )
    if cfg.video is not None:  # refused now, not after the session has been streamed in real time
        check_writable(check_video_path(cfg.video))
    model = load_model(args.model)
    head = resolve_head(args.rig or "builtin")
    with threadpool_limits(1):
        result = asyncio.run(run_demo(cfg, model, head))
    print(
        f"facecast demo: the viewer received {len(result.params)} frames "
        f"({len(result.params) / 30:.1f} s) and {len(result.audio) / result.audio_rate_hz:.1f} s of audio"
    )
    if cfg.video is not None and len(result.params):
        print(f"facecast demo: rendering {cfg.video} ...", flush=True)
        path = write_mp4(cfg.video, head, result.params, result.audio, result.audio_rate_hz)
        print(f"facecast demo: wrote {path.resolve()}")
    if not args.once and result.speech is not None:
        with threadpool_limits(1):
            asyncio.run(serve_replay(cfg, model, head, result.speech, result.speech_rate_hz))
    return 0
