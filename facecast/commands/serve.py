"""``facecast serve``: the real-time streaming server (WebSocket ingest and viewers, HTTP health)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import asyncio
    from collections.abc import Coroutine


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter
    from facecast.commands.headopts import add_head_options

    p = sub.add_parser(
        "serve",
        help="run the streaming server (audio in, animation frames out over WebSocket)",
        formatter_class=HelpFormatter,
        description="Serve live sessions: audio arrives over WebSocket (/ingest), from the microphone (--mic) or "
        "from files (--file); viewers subscribe to a session (/view) and receive mouth parameters, vertex deltas "
        "or blendshape weights, one binary message per 33 ms frame, plus the session's audio. Plain HTTP on the "
        "same port: /health, /metrics, /head/mesh (glTF), /head/texture. Protocol: docs/protocol.md. "
        "Command-line values override the [server] table of --config.",
    )
    # SUPPRESS: unset options fall back to --config, then to ServerConfig's defaults.
    p.add_argument(
        "--host",
        default=argparse.SUPPRESS,
        help="interface to bind (default: the config's, else 127.0.0.1 = this machine only)",
    )
    p.add_argument(
        "--port",
        type=int,
        default=argparse.SUPPRESS,
        help="TCP port (default: the config's, else 8765; 0 = any free port)",
    )
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        help="model file (.npz) or a shipped name: default, low-latency (docs/default_model.md); "
        "with --mapper mlp: a mapper file (default: the shipped one)",
    )
    from facecast.commands.speech_options import add_mapper_options

    add_mapper_options(p)
    head = p.add_mutually_exclusive_group()
    head.add_argument(
        "--head",
        type=Path,
        default=None,
        help="head mesh (glb/gltf/vrm/obj/ply): its own morph targets, or rigged at start-up",
    )
    head.add_argument("--rig", type=Path, default=None, help="rig file (.npz from facecast's rigging)")
    head.add_argument("--no-head", action="store_true", help="serve parameters and blendshapes only (no vertex deltas)")
    add_head_options(p, head=False)
    p.add_argument("--config", type=Path, default=None, help="TOML file with a [server] table (ServerConfig fields)")
    p.add_argument(
        "--redis",
        default=argparse.SUPPRESS,
        metavar="URL",
        help="join the cluster sharing this Redis (redis://HOST:PORT/DB; default: the config's redis_url, else "
        "none: one process; docs/deploy.md)",
    )
    p.add_argument(
        "--token-env",
        default=None,
        metavar="VAR",
        help="require the shared token held in this environment variable (kept off the command line)",
    )
    p.add_argument("--mic", action="store_true", help="also run a session named 'mic' from the default microphone")
    p.add_argument(
        "--auto-gain",
        action="store_true",
        default=None,
        help="bring every audio session's input to the model's training speech level first (a quiet microphone "
        "moves the mouth as a loud one); a start message's auto_gain still decides for its session",
    )
    p.add_argument(
        "--file",
        type=Path,
        action="append",
        default=[],
        help="also stream this audio file as a session named after it (repeatable)",
    )
    p.add_argument("--fast", action="store_true", help="stream --file as fast as possible instead of in real time")
    p.add_argument(
        "--workers",
        type=int,
        default=argparse.SUPPRESS,
        help="worker processes (default: the config's, else 0 = everything on one event loop)",
    )
    p.add_argument(
        "--worker-mode",
        choices=("compute", "connections"),
        default=argparse.SUPPRESS,
        help="compute: workers run the sessions' per-frame work, sockets stay here (use up to cores - 1); "
        "connections: workers run whole sessions with their ingest and viewer sockets (use one per core)",
    )
    p.add_argument(
        "--text",
        action="store_true",
        help="enable text sessions (/text): chatbot text -> espeak-ng speech + recorded lip units",
    )
    p.add_argument("--corpus", type=Path, default=None, help="unit corpus for --text (default: shipped or built)")
    p.add_argument("--text-n-best", type=int, default=1, help="unit sequences averaged per sentence for --text")
    p.add_argument(
        "--web-root", type=Path, default=None, help="directory served at / (default: clients/web if present)"
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio
    import logging
    import os
    import time
    from pathlib import Path

    from assets.heads.mesh import MESH_SUFFIXES
    from assets.modelfile import load_speech_model
    from facecast.commands.headopts import resolve_from_args
    from server.app import FacecastServer, run_server
    from server.cluster import shown_url
    from server.config import ServerConfig
    from server.errors import ServerConfigError
    from server.eventloop import process_loop
    from server.eventloop import run as run_on_loop
    from server.guard import WILDCARD_HOSTS, client_url, http_url
    from server.session import SessionConfig
    from server.sources import FileConfig, FileSource, MicConfig, MicSource, file_session_names

    token = None
    if args.token_env:
        token = os.environ.get(args.token_env)
        if not token:
            raise ServerConfigError(f"--token-env {args.token_env}: the environment variable is empty or unset")
    web_root = args.web_root
    if web_root is None:
        default_web = Path(__file__).resolve().parents[2] / "clients" / "web"
        web_root = default_web if default_web.is_dir() else None
    node_modules = Path(__file__).resolve().parents[2] / "node_modules"  # `npm ci` at the repo root (three.js)
    overrides = {
        "host": getattr(args, "host", None),
        "port": getattr(args, "port", None),
        "token": token,
        "web_root": web_root,
        "node_modules": node_modules if node_modules.is_dir() else None,
        "workers": getattr(args, "workers", None),
        "worker_mode": getattr(args, "worker_mode", None),
        "auto_gain": getattr(args, "auto_gain", None),  # None when not given: a config file's value stands
        "redis_url": getattr(args, "redis", None),
    }
    config = (
        ServerConfig.from_toml(args.config, **overrides)
        if args.config
        else ServerConfig(**{k: v for k, v in overrides.items() if v is not None})
    )
    if config.redis_url is not None:
        from server.cluster import check_reachable

        check_reachable(config.redis_url)  # before the model and head load (seconds): a wrong address at once
    model = load_speech_model(args.mapper, args.model)
    kind = "MLP mapper" if args.mapper == "mlp" else "model"
    print(
        f"facecast serve: {kind} {args.model or 'default'}, algorithmic delay "
        f"{model.frontend.algorithmic_delay_ms():.1f} ms (lag 0; docs/architecture.md, Delay)"
        + ("; auto gain: every audio session's input brought to the model's speech level" if config.auto_gain else ""),
        flush=True,
    )
    spec = args.rig or args.head or "builtin"
    mesh = not args.no_head and args.rig is None and Path(spec).suffix.lower() in MESH_SUFFIXES
    if mesh:
        # Rigging a new scan takes minutes; the server said nothing between its model line and "listening". Which
        # way the head goes is known once it is read: a head with its own mouth targets is not rigged (issue 12).
        print(
            f"facecast serve: head {spec}: loading; a mesh with enough mouth targets is driven by them (prepared "
            "once, seconds), any other is rigged on its first use (minutes for a scan); both are read from the "
            "cache after; --rig RIG.npz (facecast rig) starts from a rig file",
            flush=True,
        )
    started = time.perf_counter()
    head = None if args.no_head else resolve_from_args(args, spec)
    if mesh and head is not None:
        how = "driven by its own morph targets" if head.kind == "morph" else "retargeted (a rig)"
        print(f"facecast serve: head ready in {time.perf_counter() - started:.1f} s, {how}", flush=True)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    logging.getLogger("websockets").setLevel(logging.WARNING)  # one line per HTTP request is noise
    server = FacecastServer(model, head=head, config=config)
    if args.text:
        from server.text_session import espeak_backend

        server.text_backend = espeak_backend(args.corpus, n_best=args.text_n_best)

    async def main() -> None:
        mic = MicSource(MicConfig()).open() if args.mic else None  # fail before listening
        files = [FileSource(FileConfig(path=path, realtime=not args.fast)) for path in args.file]  # too
        names = file_session_names(args.file, taken=["mic"] if mic is not None else [])
        for path, src in zip(args.file, files):
            try:  # a rate no session takes fails here too, not once the server is listening
                SessionConfig(sample_rate_hz=src.sample_rate_hz, channels=src.channels)
            except ServerConfigError as exc:
                raise ServerConfigError(f"--file {path}: {exc}") from None
        ready: asyncio.Future = asyncio.get_running_loop().create_future()
        run = asyncio.ensure_future(run_server(server, ready=ready))
        await asyncio.wait({ready, run}, return_when=asyncio.FIRST_COMPLETED)
        if not ready.done():  # start-up failed (port taken, Redis unreachable): its one-line error
            run.result()
        endpoints = "/ingest, /view" + (", /text" if args.text else "")
        # A URL whose Host the server accepts (allowed_hosts): the bound address was printed whatever it said
        url = client_url(config.host, server.port, config.allowed_hosts)
        if url is not None:
            everywhere = f", bound to {config.host or '*'}: every interface" if config.host in WILDCARD_HOSTS else ""
            print(
                f"facecast serve: listening on {url} (ws {url.replace('http', 'ws')}{endpoints}{everywhere}); "
                "Ctrl-C stops",
                flush=True,
            )
        else:
            hosts = ", ".join(config.allowed_hosts or ())
            print(
                f"facecast serve: listening on {config.host} port {server.port} ({endpoints}); Ctrl-C stops. "
                f"allowed_hosts admits only {hosts}: clients must come by one of those names (a proxy, DNS); "
                f"{http_url(config.host, server.port)} itself is refused (403 Host not allowed)",
                flush=True,
            )
        listening = time.perf_counter()
        # What a client needs and what the server joined, said at start (a user found them only in the config file)
        if config.token is not None:
            print("facecast serve: a token is required (clients give it as ?token=T or in their start message)")
        if server.cluster is not None:
            redis = shown_url(server.cluster.url)
            role = {
                "both": "computes sessions and serves viewers",
                "compute": "computes sessions",
                "edge": "serves viewers and relays ingests to a computing node",
            }[config.role]
            print(f"facecast serve: cluster node {server.cluster.node!r} on {redis} ({role})", flush=True)
        tasks = []
        for path, src, name in zip(args.file, files, names):
            print(f"facecast serve: file {path} ({src.duration_s:.1f} s) as session {name!r}", flush=True)
            run_file = server.run_source(name, aiter(src), sample_rate_hz=src.sample_rate_hz, label=f"file {path}")
            tasks.append(_reported(run_file, f"file {path}: session {name!r}"))
        if mic is not None:
            print(f"facecast serve: microphone at {mic.sample_rate_hz} Hz as session 'mic'", flush=True)
            run_mic = server.run_source(
                "mic", mic, sample_rate_hz=mic.sample_rate_hz, channels=mic.channels, label="microphone"
            )
            tasks.append(_reported(run_mic, "microphone: session 'mic'"))
        try:
            await run
        finally:
            for t in tasks:
                t.cancel()
        # Ctrl-C printed nothing: say the server has stopped (its sessions ended, their viewers told 1001)
        print(f"facecast serve: stopped after {time.perf_counter() - listening:.0f} s of serving", flush=True)

    front = config.workers > 0 and config.worker_mode == "connections"
    run_on_loop(main(), process_loop(config.event_loop, connection_front=front))
    return 0


def _reported(session: Coroutine[Any, Any, object], what: str) -> asyncio.Task:
    """Run a local source's session as a task whose failure is logged in one line naming ``what`` (a file
    and its session): nothing awaits these tasks while the server runs, and a refused or broken session
    (its name taken, the server full, audio the model rejects) vanished without a word. The server goes on."""
    import asyncio
    import logging

    from realtime_core.errors import FacecastError

    def report(task: asyncio.Task) -> None:
        if task.cancelled():
            return
        exc = task.exception()
        if isinstance(exc, FacecastError):  # a user-facing error: its message says it all
            logging.getLogger("facecast.serve").error("%s failed: %s", what, exc)
        elif exc is not None:  # a bug: its traceback
            logging.getLogger("facecast.serve").error("%s failed", what, exc_info=exc)

    task = asyncio.ensure_future(session)
    task.add_done_callback(report)
    return task
