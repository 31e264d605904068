"""``facecast record [URL] -o OUT``: save a live session as .glb, .csv, .json or .tsv."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter
    from facecast.commands.headopts import add_head_options
    from facecast.commands.outputs import add_output_option
    from facecast.commands.view import DEFAULT_URL, add_session_options

    p = sub.add_parser(
        "record",
        help="save a live session's animation (glTF, CSV, JSON or Rhubarb TSV)",
        formatter_class=HelpFormatter,
        description="Watch one session's mouth parameters (for a .glb without --head: the weights of the served "
        "head's own targets) and audio until it ends (or --duration), then write them in the format of the output's "
        "suffix: .glb (the server's head animated as its viewers saw it, the audio as a .wav beside it), .csv "
        "(curves with a time column t, s of the session), .json (the same curves, the audio as a .wav beside "
        "it), .tsv (Rhubarb-style mouth-shape cues), .wav (the session's audio alone). The same writers as "
        "`facecast animate -o`. Without --head the .glb is the head the server serves, fetched from it, with the "
        "weights of its own morph targets it sent per frame; a retargeted head needs --head with its file. A "
        "video of the session: `facecast view URL --record take.mp4`. Exit status: 0 a whole take (or "
        "--duration's), 3 a partial take (the server closed the session before its end, e.g. 1001 shutting "
        "down: what arrived is written), 2 an error.",
    )
    p.add_argument(
        "url", nargs="?", default=DEFAULT_URL, help="the server's base URL (http:// or ws://; its /view URL too)"
    )
    p.add_argument("--session", default=None, help="session to record (default %(default)s = the first live one)")
    add_output_option(
        p, formats=".glb/.csv/.json/.tsv/.wav (a .glb or .json with a .wav beside it)", repeatable=False, required=True
    )
    add_head_options(
        p,
        help_head="head of the .glb (default: the server's own, fetched from it; a head driven by its own targets): "
        "'builtin', a rig file (.npz) or a mesh, which must be the server's head",
    )
    p.set_defaults(head=None)  # None: the served head (add_head_options' default is the built-in head)
    p.add_argument(
        "--glb-morphs",
        choices=("units", "arkit52"),
        default="units",
        help=".glb morph targets: the head's own (its own targets, or a retargeted rig's 4 mouth units) "
        "or ARKit's 52 blendshapes (built-in head)",
    )
    add_session_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import asyncio
    import contextlib
    import threading

    from assets.audio import write_wav
    from assets.files import check_writable
    from clients.client import server_url
    from clients.errors import ClientError
    from clients.export.files import FORMATS, check_outputs, export_track
    from clients.viewer.stream import ViewerStreamConfig, fetch_head, pick_session, record_stream
    from facecast.commands.outputs import check_output_formats
    from facecast.commands.view import token_from_env
    from realtime_core import VISUAL_PARAMS
    from realtime_core.track import Track

    check_output_formats([args.output], (*FORMATS, ".wav"), hints=RECORD_HINTS)
    glb = args.output.suffix.lower() == ".glb"
    audio_only = args.output.suffix.lower() == ".wav"
    if glb and args.glb_morphs == "arkit52":
        if args.head not in (None, "builtin"):
            # refused before the session is watched: export_track would refuse it only after the whole take
            raise ClientError(
                f"{args.output}: --glb-morphs arkit52 needs the built-in head (ARKit targets), not {args.head}"
            )
        args.head = "builtin"  # the ARKit targets are the built-in head's, resolved here as before
    served = glb and args.head is None  # the .glb is the head the server serves, with the weights it sends
    if served:
        given = [opt for opt, dest, unset in _RESOLVING if getattr(args, dest) != unset]
        if given:  # they shape a head resolved here: without --head nothing is, and they would do nothing
            raise ClientError(f"{' and '.join(given)} need --head (without it the .glb is the server's head as served)")
    # a folder that cannot be made fails now, not after the whole take
    checked = frozenset() if audio_only else check_outputs([args.output])
    if audio_only:
        check_writable(args.output)
    args.url = server_url(args.url, "/view")  # the base URL also when given as the viewers' ws://HOST:PORT/view
    token = token_from_env(args.token_env)

    def resolve():  # (head, ARKit targets or None), in a thread: rigging a new mesh takes seconds
        from facecast.commands.headopts import resolve_from_args

        head = resolve_from_args(args)
        if args.glb_morphs == "arkit52" and args.head == "builtin":
            from clients.export.gltf import builtin_arkit_targets

            return head, builtin_arkit_targets()
        return head, None

    def in_daemon_thread(fn, *, name: str) -> asyncio.Future:
        # Not asyncio.to_thread: asyncio.run joins its executor's threads before it returns (and the
        # interpreter joins them before it exits), so an error while watching was printed only once the
        # rig had finished (9.5 s for a new mesh instead of 0.6 s). A daemon thread is abandoned instead;
        # what it writes to the rig cache is written atomically (assets/files.py), so it leaves no half.
        loop = asyncio.get_running_loop()
        future: asyncio.Future = loop.create_future()

        def settle(result, error: BaseException | None) -> None:
            if future.done():  # cancelled: the watch failed first
                return
            if error is not None:
                future.set_exception(error)
            else:
                future.set_result(result)

        def run() -> None:
            result, error = None, None
            try:
                result = fn()
            except Exception as exc:  # noqa: BLE001 - handed to the awaiting task, which raises it
                error = exc
            with contextlib.suppress(RuntimeError):  # the loop has closed: nobody waits for the head
                loop.call_soon_threadsafe(settle, result, error)

        threading.Thread(target=run, name=name, daemon=True).start()
        return future

    def same_head(head, description: dict) -> None:
        # checked on connecting (or when the head is ready): after the take, a wrong --head threw the
        # whole recording away
        theirs = description.get("head")
        if theirs is not None and theirs["vertex_count"] != len(head.mesh.vertices):
            raise ClientError(
                f"--head {args.head} has {len(head.mesh.vertices)} vertices but the server's head has "
                f"{theirs['vertex_count']}: pass the server's head"
            )

    async def both(watching: asyncio.Future, checking: asyncio.Future, *, explain=None):
        # (the watch's result, the head check's) once both are done. The first failure (the head's first: a head
        # that cannot be had is why the watch failed too) cancels the other and is raised, the viewer closed first;
        # explain() may raise a clearer error for a failed watch.
        await asyncio.wait((watching, checking), return_when=asyncio.FIRST_EXCEPTION)
        for task, other in ((checking, watching), (watching, checking)):
            failure = task.exception() if task.done() else None
            if failure is not None:
                other.cancel()
                await asyncio.gather(other, return_exceptions=True)  # the viewer is closed before raising
                if task is watching and explain is not None:
                    await explain()
                raise failure
        return watching.result(), checking.result()

    async def watch(kind: str, described: asyncio.Future[dict]):
        session = await pick_session(args.url, args.session, args.wait, token)
        cfg = ViewerStreamConfig(
            url=args.url, session=session, kind=kind, token=token, wait_s=args.wait, max_s=args.duration
        )
        print(f"facecast record: recording session {session!r} from {args.url}", flush=True)
        return session, await record_stream(cfg, check_description=described.set_result)

    async def served_head():
        # The head the viewers were sent and the weights of its own targets they were sent (the "morph" kind:
        # what the browser viewer shows), fetched while the session is watched: nothing of the start is missed.
        described: asyncio.Future[dict] = asyncio.get_running_loop().create_future()
        fetching = asyncio.ensure_future(fetch_head(args.url, token, targets=True))
        watching = asyncio.ensure_future(watch("morph", described))

        async def checked_head():
            mesh = await asyncio.shield(fetching)
            served_matches(mesh, await described)
            return mesh

        async def why_no_morph_frames() -> None:
            mesh = await fetching  # a head that cannot be fetched is named first: why there are no morph frames
            if not mesh.targets:  # the server refused the morph kind (4400): its head drives no targets of its own
                raise ClientError(
                    f"{args.url}: the server's head is retargeted (it drives no morph targets of its own), so its "
                    "motion cannot be rebuilt from what it sends: pass --head with the head the server was started with"
                )

        watched, mesh = await both(watching, asyncio.ensure_future(checked_head()), explain=why_no_morph_frames)
        return *watched, (mesh, None)

    def served_matches(mesh, description: dict) -> None:
        # The weights name the targets of the head they were sent for: a server whose /head/mesh.json is another
        # head's (a cluster's node with another --head) is refused on connecting, not by a glb that moves wrongly.
        head = description.get("head") or {}
        if head.get("vertex_count") != len(mesh.vertices) or list(description.get("names", ())) != list(mesh.targets):
            raise ClientError(
                f"{args.url}: the head at /head/mesh.json ({len(mesh.vertices)} vertices, targets "
                f"{list(mesh.targets or ())[:3]}...) is not the one the session's morph weights drive"
            )

    async def main():
        if served:
            return await served_head()
        described: asyncio.Future[dict] = asyncio.get_running_loop().create_future()
        if not glb:
            return *(await watch("params", described)), (None, None)

        async def head_checked():
            resolved = await in_daemon_thread(resolve, name="facecast-record-head")
            same_head(resolved[0], await described)
            return resolved

        # The head resolves while the session is watched and its frames are kept: resolving first (0.8 s
        # with the rig cached, ~13 s for a new mesh) missed the start of a session started just after the
        # recorder. A head that fails, or is not the server's, ends the watch as soon as it is known.
        watched, resolved = await both(
            asyncio.ensure_future(watch("params", described)), asyncio.ensure_future(head_checked())
        )
        return *watched, resolved

    session, rec, (head, arkit) = asyncio.run(main())
    values, first = rec.timeline()
    names = tuple(rec.description["names"]) if served else VISUAL_PARAMS  # the morph kind's: the targets' weights
    track = Track(values=values, fps=rec.fps, start_s=first / rec.fps, names=names)
    audio = (rec.audio_track(track.start_s, track.n_frames), rec.audio_rate_hz)
    if audio_only:  # the audio the frames were timed to, from the first frame on
        files = [write_wav(args.output, *audio)]
    else:
        files = export_track(
            args.output, track, head=head, audio=audio, morphs=args.glb_morphs, arkit_targets=arkit, checked=checked
        )
    late = f", joined at {track.start_s:.2f} s (earlier frames were not seen)" if first > 0 else ""
    # A session closed other than by its end (1001 server shutting down, 4000 too slow, ...) is a partial take:
    # what arrived is written all the same, but the exit status says the take is not whole.
    partial = rec.partial
    print(
        f"facecast record: wrote {', '.join(map(str, files))}: {track.n_frames} frames "
        f"({track.duration_s:.2f} s) of {session!r}{late}; {rec.ending}"
        + ("; a partial take: the session did not end normally" if partial else "")
    )
    return PARTIAL_EXIT if partial else 0


PARTIAL_EXIT = 3
"""Exit status of a take cut short by the server (its frames written): 0 is a whole take (or --duration's),
2 an error before anything was written."""


RECORD_HINTS = {
    ".mp4": "record writes the animation, not a video: `facecast view URL --session S --record take.mp4` renders one",
}
"""What to use instead of an output ``record`` does not write."""

_RESOLVING: tuple[tuple[str, str, object], ...] = (
    ("--head-part", "head_part", []),
    ("--landmarks", "landmarks", None),
    ("--head-mode", "head_mode", "auto"),
    ("--target-map", "target_map", None),
)
"""The head options that only shape a head resolved here (``--head``): (option, dest, unset value)."""
