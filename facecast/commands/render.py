"""``facecast render SPEECH.wav -o OUT.mp4``: animate a head offline and write a video with the speech."""

from __future__ import annotations

import argparse
from dataclasses import replace

from facecast.commands.argtypes import add_background_option, within


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter
    from facecast.commands.headopts import add_head_options
    from facecast.commands.speech_options import add_auto_gain_option, add_expression_options, add_mapper_options

    p = sub.add_parser(
        "render",
        help="render an animated head to MP4 (with the speech muxed in) and optionally PNG frames",
        formatter_class=HelpFormatter,
        description=(
            "Mouth parameters come from the speech by the live streaming path (--model, --mapper), as\n"
            "`facecast animate` does, or from --params (CSV: t, upper_lip_raise, lip_stretch, mouth_open,\n"
            "lip_corner_depress; e.g. an edited `facecast animate --csv`)."
        ),
    )
    p.add_argument("speech", help="speech audio (WAV; other formats through ffmpeg), muxed into the video")
    add_head_options(p)
    p.add_argument(
        "--model",
        help="speech->parameters model (used when --params is not given): a .npz file or a shipped name: "
        "default, low-latency",
    )
    add_mapper_options(p)
    add_auto_gain_option(p)
    add_expression_options(p)
    p.add_argument("--params", help="mouth parameters CSV (or facecast's JSON curves) instead of the speech model")
    p.add_argument("-o", "--output", required=True, help="video file to write (.mp4; also .mov, .m4v, .mkv)")
    p.add_argument("--png-dir", help="also write every frame as PNG into this folder")
    p.add_argument("--view", choices=("front", "three_quarter"), default="front", help="camera view")
    p.add_argument("--width", type=int, default=640, help="image width in pixels")
    p.add_argument("--height", type=int, default=480, help="image height in pixels")
    p.add_argument("--fps", type=within(float, 1, 240, "fps"), default=30.0, help="video frame rate")
    p.add_argument("--samples", type=int, default=4, help="MSAA samples (0 disables anti-aliasing)")
    add_background_option(p)
    p.add_argument("--credit", help="attribution text drawn on every frame (default: known heads' licence credit)")
    p.add_argument(
        "--beside",
        metavar="VIDEO",
        help="a recording of the same speech (usually SPEECH itself, e.g. the talker's clip) drawn left of the "
        "head at every frame's media time, scaled to --height: judge the lip-sync by eye",
    )
    p.set_defaults(run=run)


def _params_for_speech(frames, args: argparse.Namespace):
    """``--params`` frames (F, 4) at ``args.fps`` cut to the speech they are muxed with, with one warning line when
    the two differ by more than a frame. A file longer than the speech failed after the whole render with "ffmpeg
    failed (-1)" (ffmpeg ends the video with its sound and stopped reading the frames), and one shorter ended the
    video, and its sound, where the file ends without a word (3 s of parameters for 164 s of speech: a 3 s video)."""
    import math
    import sys

    from assets.audio import read_audio

    samples, rate = read_audio(args.speech)
    speech_s = len(samples) / rate
    n_speech = math.ceil(speech_s * args.fps - 1e-9)  # the speech path's count: the last frame starts in the sound
    if abs(len(frames) - n_speech) > 1:
        shorter = "the speech" if n_speech < len(frames) else "the parameters"
        print(
            f"facecast render: warning: {args.params}: {len(frames) / args.fps:.2f} s of mouth parameters for "
            f"{speech_s:.2f} s of speech in {args.speech}: the video ends with {shorter}, at "
            f"{min(n_speech, len(frames)) / args.fps:.2f} s",
            file=sys.stderr,
        )
    return frames[:n_speech]


BESIDE_SLACK_S = 0.2
"""s: a --beside recording whose picture ends further than this from the speech is said to (a clip's audio and
picture are taken as one recording within the same 0.2 s by `facecast extract`)."""


def _warn_if_beside_differs(video, speech_s: float, path) -> None:
    """One warning line when the --beside picture (``video``: assets.video.VideoFrames) ends more than
    :data:`BESIDE_SLACK_S` from the speech's ``speech_s`` seconds: a 1 s clip beside 3 s of speech froze on its last
    picture for 2 s without a word."""
    import sys

    import numpy as np

    times = video.times_s
    picture_s = float(times[-1] + (np.median(np.diff(times)) if len(times) > 1 else 0.0))
    if abs(picture_s - speech_s) > BESIDE_SLACK_S:
        then = "its last picture is held to the end" if picture_s < speech_s else "the video ends with the speech"
        print(
            f"facecast render: warning: {path}: {picture_s:.2f} s of picture beside {speech_s:.2f} s of speech: "
            f"{then} (--beside takes a recording of the same speech)",
            file=sys.stderr,
        )


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from assets.audio import check_audio_path
    from assets.files import check_writable
    from assets.tracks import read_params_resampled
    from clients.render.renderer import RenderConfig, renderer_for_rig
    from clients.render.video import (
        VideoConfig,
        check_video_path,
        check_video_size,
        params_for_audio,
        write_video,
    )
    from training.errors import ConfigError

    out = Path(args.output).resolve()
    inputs = (("speech", args.speech), ("--beside video", args.beside), ("--params file", args.params))
    for what, given in inputs:
        # as `say --audio`: a talking-face clip given as the speech (or --beside) was replaced by the render
        if given is not None and Path(given).resolve() == out:
            raise ConfigError(f"{args.output}: the video would overwrite the {what} it is made from; give another name")
    check_writable(check_video_path(args.output))  # before any work: a folder that cannot be made fails now
    check_video_size(args.width, args.height)  # --beside adds an even width (assets.video.read_video_frames)
    if args.png_dir:
        check_writable(Path(args.png_dir) / "frame_00000.png")
    check_audio_path(args.speech)
    video = None
    if args.beside:
        from assets.video import read_video_frames

        video = read_video_frames(args.beside, height=args.height)  # before the rig: a bad file fails now
    if args.params:
        frames = _params_for_speech(read_params_resampled(args.params, args.fps).values, args)
    else:
        from facecast.commands.speech_options import quiet_speech_db, shipped_model, warn_if_clipped, warn_if_quiet

        level: list[float | None] = [None]  # the quiet speech's level, said with the noise gate's rows after the model

        def check(samples: np.ndarray, rate: int) -> None:
            if shipped_model(args) and not args.auto_gain:
                level[0] = quiet_speech_db(samples, rate)
            warn_if_clipped("render", args.speech, samples)

        track = params_for_audio(args.speech, args.model, mapper=args.mapper, check=check, auto_gain=args.auto_gain)
        warn_if_quiet("render", args.speech, level[0], track.values)
        frames = track.at_fps(args.fps).values  # as long as the speech at any rate (the video is not cut short)
    from facecast.commands.speech_options import apply_expressions, expression_intensities

    frames = apply_expressions(frames, args, fps=args.fps, command="render")
    alpha = expression_intensities(args, len(frames), args.fps)  # a head's own face shapes (brows, eyes, cheeks)
    from facecast.commands.headopts import resolve_from_args

    rig, mesh = resolve_from_args(args)
    from assets.heads.landmarks import credit_for
    from clients.render.video import with_caption

    credit = args.credit if args.credit is not None else credit_for(mesh.name)
    cfg = RenderConfig(width=args.width, height=args.height, view=args.view, samples=args.samples)
    if args.background is not None:
        cfg = replace(cfg, background=args.background)
    width = cfg.width
    if video is not None:
        from clients.render.video import beside

        shown = video.shown_at(np.arange(len(frames)) / args.fps)  # the recorded picture of each frame's instant
        _warn_if_beside_differs(video, len(frames) / args.fps, args.beside)
        width += video.frames.shape[2]
    with renderer_for_rig(rig, mesh, cfg) as r:

        def draw(k: int) -> np.ndarray:
            image = with_caption(r.render(rig.deformed(frames[k], None if alpha is None else alpha[k])), credit)
            return image if video is None else beside(video.frames[shown[k]], image)

        from assets.progress import Progress

        out = write_video(
            # a 10-minute file renders for about as long: a bar on a terminal, a line every 30 s in a log
            Progress(np.arange(len(frames)), desc="render", unit="frame"),
            draw,
            args.output,
            size=(width, cfg.height),
            audio=args.speech,
            png_dir=args.png_dir,
            config=VideoConfig(fps=args.fps),
        )
    print(
        f"render {out}: {len(frames)} frames at {args.fps:g} fps, {width}x{cfg.height}, view {cfg.view}"
        + (f", {args.beside} at the left" if video is not None else "")
    )
    return 0
