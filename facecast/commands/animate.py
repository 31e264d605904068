"""``facecast animate SPEECH -o OUT``: speech file -> mouth parameters at 30 fps (CSV, glTF, JSON, TSV), by the live
path; ``--curves arkit52|ovr15``: the CSV / JSON as blendshape weights."""

from __future__ import annotations

import argparse
from pathlib import Path

from facecast.commands.argtypes import within


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter
    from facecast.commands.headopts import add_head_options
    from facecast.commands.outputs import add_output_option
    from facecast.commands.speech_options import add_auto_gain_option, add_expression_options, add_mapper_options

    p = sub.add_parser(
        "animate",
        help="speech file -> mouth parameters at 30 fps",
        formatter_class=HelpFormatter,
        description="Estimate the four mouth parameters from a speech file. The default --mode stream runs "
        "exactly the live server's streaming path, so the result equals what a live session produces frame for "
        "frame; --mode batch runs batch HMM inversion (eq. 7 EM) over the whole file.",
    )
    p.add_argument("speech", type=Path, help="speech audio (WAV; other formats through ffmpeg)")
    # Exports (clients/export); at least one -o or --csv/--glb/--json/--tsv is required. -o as `say` and `record`
    # take it; the flags name the format themselves (the older spelling, kept).
    add_output_option(p, formats=".csv/.glb/.json/.tsv", repeatable=True, required=False)
    p.add_argument("--csv", type=Path, default=None, help="output CSV: t (s, frame k at k/30) and the 4 parameters")
    p.add_argument(
        "--glb",
        type=Path,
        default=None,
        help="output glTF binary: the head animated by morph-target weights (a head's own targets, e.g. the built-in "
        "head's ARKit mouth targets; a retargeted rig's 4 parameters; --glb-morphs), speech as .wav beside it",
    )
    p.add_argument("--json", type=Path, default=None, help="output JSON curves with a time column t (s)")
    p.add_argument("--tsv", type=Path, default=None, help="output Rhubarb-style mouth-shape cues (A-H, X) for 2D tools")
    add_head_options(p, help_head="head for --glb: 'builtin', a rig file (.npz) or a mesh (glb/gltf/vrm/obj/ply)")
    p.add_argument(
        "--glb-morphs",
        choices=("units", "arkit52"),
        default="units",
        help="--glb morph targets: the head's own (its own targets, or a retargeted rig's 4 mouth units) "
        "or ARKit's 52 blendshapes (built-in head)",
    )
    p.add_argument(
        "--curves",
        choices=("params", "arkit52", "ovr15"),
        default="params",
        help=".csv/.json curves: the 4 mouth parameters (IOD), or blendshape weights in [0, 1] for an engine's own "
        "face: arkit52 = ARKit's 52 (Apple's names and order; speech plus --expression's shapes: what --glb-morphs "
        "arkit52 animates and a live viewer of kind blendshapes receives), ovr15 = the 15 Oculus visemes (its ovr15 "
        "encoding)",
    )
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        help="model file (.npz) or a shipped name: default, low-latency (docs/default_model.md); "
        "--mapper mlp: default the shipped MLP mapper",
    )
    add_mapper_options(p)
    add_auto_gain_option(p)
    add_expression_options(p)
    p.add_argument("--mode", choices=("stream", "batch"), default="stream", help="streaming (live) or batch HMMI")
    p.add_argument(
        "--lag", type=within(int, 0, 30, "frames"), default=0, help="extra frames of fixed-lag smoothing (stream mode)"
    )
    p.add_argument(
        "--fps",
        type=within(float, 1, 240, "fps"),
        default=30.0,
        help="frame rate of the written curves, cues and glb keys (the model runs at 30 fps; other rates are "
        "linearly interpolated from it, e.g. 24 for film, 60 for a game)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from assets.audio import read_audio
    from assets.errors import FileProblem
    from assets.modelfile import load_speech_model
    from assets.tracks import write_csv
    from clients.export.errors import ExportError
    from clients.export.files import FORMATS, check_outputs, export_track
    from facecast.commands.outputs import check_distinct_outputs, check_output_formats
    from facecast.commands.speech_options import (
        apply_expressions,
        expression_intensities,
        quiet_speech_db,
        shipped_model,
        warn_if_clipped,
        warn_if_quiet,
    )
    from realtime_core import VISUAL_PARAMS
    from realtime_core.errors import InvalidAudioError
    from realtime_core.inversion import StreamConfig
    from realtime_core.pipeline import speech_to_params, speech_to_params_and_mups, with_auto_gain
    from realtime_core.track import DEFAULT_FPS, Track

    exports = {"glb": args.glb, "json": args.json, "tsv": args.tsv}  # the format named by the flag
    # -o's format follows the suffix; --csv writes CSV whatever the name (as it always has).
    written = [*(args.output or ()), *(o for o in exports.values() if o is not None)]
    if not written and args.csv is None:
        from training.errors import ConfigError

        raise ConfigError("give at least one output: -o OUT (.csv/.glb/.json/.tsv), --csv, --glb, --json or --tsv")
    check_distinct_outputs([*([args.csv] if args.csv is not None else []), *written])
    # Every refusal comes before the first output is written (no partial set of files) and before the
    # model runs: the export formats, the .wav beside a .glb/.json (never the input speech), the head.
    for fmt, out in exports.items():
        if out is not None and out.suffix.lower() != f".{fmt}":
            raise ExportError(f"{out}: --{fmt} writes a .{fmt} file; give a name ending in .{fmt}")
    check_output_formats(args.output or (), FORMATS)
    checked = check_outputs(written, source=args.speech)
    glbs = [o for o in written if o.suffix.lower() == ".glb"]
    if (
        args.curves != "params"
        and args.csv is None
        and not [o for o in written if o.suffix.lower() in (".csv", ".json")]
    ):
        raise ExportError(f"--curves {args.curves} is what a .csv or .json output holds: give one (-o OUT.csv)")
    if glbs and args.glb_morphs == "arkit52" and args.head != "builtin":
        raise ExportError(f"{glbs[0]}: --glb-morphs arkit52 needs the built-in head (ARKit targets), not {args.head}")
    head = None
    if glbs:
        from facecast.commands.headopts import resolve_from_args

        head = resolve_from_args(args)
    model = load_speech_model(args.mapper, args.model)
    if args.auto_gain:
        model = with_auto_gain(model)
    samples, rate = read_audio(args.speech)
    # the shipped models' training level (a user's own may differ); said after the animation, with the noise gate's say
    quiet = quiet_speech_db(samples, rate) if shipped_model(args) and not args.auto_gain else None
    warn_if_clipped("animate", args.speech, samples)
    mups = None
    try:
        if args.expression and args.mode == "stream" and getattr(model, "expressions", None) is not None:
            params, mups = speech_to_params_and_mups(model, samples, rate)  # the live path, keeping the MUPs
        else:
            params = speech_to_params(model, samples, rate, mode=args.mode, stream=StreamConfig(lag=args.lag))
    except InvalidAudioError as exc:  # e.g. shorter than one analysis window: name the file
        raise FileProblem(args.speech, str(exc)) from None
    speech = params
    warn_if_quiet("animate", args.speech, quiet, speech)
    params = apply_expressions(params, args, mups=mups, model=model, command="animate")
    # The cues of the model's own frames, placed on the asked rate's frames (a one-frame closure between two of them
    # vanished from the interpolated curves: clients.export.rhubarb.cues).
    model_track = Track(values=params)
    fps = float(args.fps)
    if fps != DEFAULT_FPS:  # the model's frames, interpolated onto the asked rate (as `render --fps`)
        # One interpolation of both tracks' channels side by side (the same frame times; without an expression the
        # speech's parameters are the parameters, interpolated once).
        both = params if speech is params else np.hstack([params, speech])
        names = tuple(f"{n}{i}" for i in range(both.shape[1] // len(VISUAL_PARAMS)) for n in VISUAL_PARAMS)
        # As long as the 30 fps frames at any rate (each frame starting before their end; render --fps alike).
        both = Track(values=both, names=names).at_fps(fps).values
        params, speech = both[:, : len(VISUAL_PARAMS)], both[:, -len(VISUAL_PARAMS) :]
    # Every output goes through the one track codec (assets.tracks) or the exporters built on it.
    track = Track(values=params, fps=fps)
    intensities = expression_intensities(args, len(params), fps)
    curves, units = track, "IOD"  # what a .csv / .json holds
    if args.curves != "params":
        from realtime_core.blendshapes import blendshape_names, blendshape_weights

        # As a live session's blendshape kinds: ARKit has the expressions' own shapes (the speech's weights plus
        # their recipes), the visemes have none (the parameters with the expression applied).
        if args.curves == "arkit52" and intensities is not None:
            weights = blendshape_weights(speech, "arkit52", expression=intensities)
        else:
            weights = blendshape_weights(params, args.curves)
        curves = Track(values=weights, names=blendshape_names(args.curves), fps=fps)
        units = f"{args.curves} blendshape weight [0, 1]"
    if args.csv is not None:
        write_csv(args.csv, curves)
    arkit = None
    if glbs and args.glb_morphs == "arkit52" and args.head == "builtin":
        from clients.export.gltf import builtin_arkit_targets

        arkit = builtin_arkit_targets()
    for out in written:
        suffix = out.suffix.lower()
        export_track(
            out,
            curves if suffix in (".csv", ".json") else model_track if suffix == ".tsv" else track,
            cue_fps=fps,
            units=units,
            head=head,
            audio=(samples, rate),
            morphs=args.glb_morphs,
            arkit_targets=arkit,
            checked=checked,  # probed above: not again per file
            # ARKit: the speech's weights plus the expressions' own shapes (mouthSmile, brows ...)
            arkit_track=Track(values=speech, fps=fps),
            expression=intensities,
        )
    delay = (
        f"algorithmic delay {model.frontend.algorithmic_delay_ms(args.lag):.1f} ms"
        if args.mode == "stream"
        else "batch"
    )
    for out in [*([args.csv] if args.csv is not None else []), *written]:
        print(
            f"wrote {out}: {len(params)} frames ({len(params) / fps:.2f} s at {fps:g} fps) from {args.speech} ({delay})"
        )
    return 0
