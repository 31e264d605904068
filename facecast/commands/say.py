"""``facecast say "TEXT" -o OUT.mp4|.glb|.csv|.json|.tsv``: text -> speech + recorded lip motion (unit selection)."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from facecast.commands.argtypes import add_background_option


class _ListVoices(argparse.Action):
    """``--list-voices``: print the voices and exit before TEXT and -o are asked for (as ``--version`` does); the
    list was only in the error for an unknown voice."""

    def __init__(self, option_strings: list[str], dest: str, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        from assets.espeak import LANGUAGES, VARIANTS

        for lang, voices in LANGUAGES.items():
            print(f"{lang}: {' '.join(voices)}")
        print(f"variants (VOICE+VARIANT, or a variant alone): {' '.join(VARIANTS)}")
        parser.exit()


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter
    from facecast.commands.outputs import add_output_option

    p = sub.add_parser(
        "say",
        help="text -> synthetic speech and a talking head by unit selection over real recorded lips",
        formatter_class=HelpFormatter,
        description="Speak TEXT with espeak-ng and animate the head with recorded lip motion (seed 001, Ma et al. "
        "2006): the phones and their timings from the synthesiser select the longest matching stretches of a real "
        "talker's recorded motion (GRID s1), warped onto the phone durations and joined smoothly. With --audio, "
        "the user's own recording of TEXT is force-aligned instead (pocketsphinx, English) and the audio-driven "
        "model's motion on it is mixed in, most before speech where the in-breath is heard but not written. "
        "The output format follows the suffix: .mp4 (rendered, speech muxed in), .glb (morph-target animation + "
        ".wav beside it), "
        ".csv / .json (curves), .tsv (mouth cues), .wav (the speech alone, e.g. beside a .csv or .tsv), "
        ".npz (the full motion: landmark PCA coefficients, the four "
        "parameters and the Motion Unit parameters of paper 002).",
    )
    p.add_argument("text", help="what to say (for --audio: the transcript of the recording)")
    add_output_option(p, formats=".mp4/.glb/.csv/.json/.tsv/.wav/.npz", repeatable=True, required=True)
    p.add_argument(
        "--lang", choices=("en", "es"), default=None, help="language of TEXT (default: the --voice's, else en)"
    )
    p.add_argument(
        "--voice",
        default=None,
        help="espeak-ng voice, e.g. en-us, en-gb-x-rp+f3, es (Spanish without --lang), or a variant f3",
    )
    p.add_argument(
        "--list-voices",
        action=_ListVoices,
        help="print the espeak-ng voices and variants --voice takes, by language, and exit",
    )
    p.add_argument("--rate", type=int, default=175, help="speaking rate, words per minute")
    p.add_argument(
        "--audio",
        type=Path,
        default=None,
        help="a recording of TEXT to animate instead of synthesised speech (forced alignment; English)",
    )
    p.add_argument(
        "--audio-blend",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="with --audio: mix the audio-driven model's motion on the recording into the unit-selection motion, "
        "most in the pause before speech, where the in-breath is heard but not written (text + recording; "
        "--no-audio-blend: the recording gives only the phone timings; docs/unit_selection.md)",
    )
    p.add_argument(
        "--corpus",
        type=Path,
        default=None,
        help="unit corpus (.npz); default: the shipped one or the newest built by `facecast units build`",
    )
    p.add_argument(
        "--n-best",
        type=int,
        default=1,
        help="average the motion of this many unit sequences from "
        "different recordings, their range restored (1 = the paper's single sequence; 10 follows held-out "
        "lips best: r 0.908 against 0.846, at about 15-45 ms of synthesis per sequence; docs/unit_selection.md)",
    )
    from facecast.commands.headopts import add_head_options
    from facecast.commands.speech_options import add_expression_options

    add_expression_options(p)
    add_head_options(
        p, help_head="head for .mp4/.glb: 'builtin', a rig file (.npz) or a head mesh (glb/gltf/vrm/obj/ply)"
    )
    p.add_argument("--width", type=int, default=640, help="video width (pixels)")
    p.add_argument("--height", type=int, default=480, help="video height (pixels)")
    add_background_option(p)
    p.add_argument(
        "--samples",
        type=int,
        default=0,
        help="MSAA samples (0 = none, the default: with the software renderer 4 samples cost about 3x the CPU time "
        "per frame for a barely visible smoothing of the silhouette)",
    )
    p.add_argument(
        "--preset",
        default="veryfast",
        help="x264 speed preset (veryfast: about 3x faster than ffmpeg's medium at the same quality, crf 20)",
    )
    p.add_argument("--verbose", action="store_true", help="print the selected units and stage timings")
    p.set_defaults(run=run)


def write_motion(path: Path, frames, stored) -> Path:
    """The whole synthesised motion as ``.npz`` (no pickle): ``frames`` (n, K + 4) float32 at 30 fps
    (K landmark PCA coefficients, then the four mouth parameters), ``dim_names``, and what turns the
    coefficients into lower-face landmark displacements from the neutral face (IOD units):
    ``pca_mean`` (3P,), ``pca_components`` (K, 3P), ``landmark_indices`` (P,) MediaPipe numbering,
    ``neutral`` (P, 3) the corpus's mean neutral face; displacements = frames[:, :K] @ pca_components
    + pca_mean, reshaped (n, P, 3). When the corpus carries Motion Units (paper 002), also ``mups``
    (n, A) float32 the Utterance MU parameters of the same frames and the basis that rebuilds the
    displacements from them: ``mu_mean`` (3P,), ``mu_units`` (A, 3P); displacements = mups @ mu_units
    + mu_mean (to the MUs' 97 % of the variance)."""
    import io

    import numpy as np

    from assets.files import atomic_write_bytes

    k = stored.corpus.n_coefficients
    mu = stored.motion_units
    extra = (
        {}
        if mu is None
        else {
            "mups": stored.mups(np.asarray(frames)[:, :k]).astype(np.float32),
            "mu_mean": mu.mean,
            "mu_units": mu.units,
        }
    )
    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        **extra,
        frames=np.asarray(frames, dtype=np.float32),
        fps=np.array(30.0),
        dim_names=np.array(stored.corpus.dim_names),
        pca_mean=stored.pca_mean,
        pca_components=stored.pca_components,
        landmark_indices=stored.landmark_indices,
        neutral=stored.neutral,
    )
    return atomic_write_bytes(path, buf.getvalue())


def run(args: argparse.Namespace) -> int:
    import tempfile
    import time

    import numpy as np
    from threadpoolctl import threadpool_limits

    from assets.audio import read_audio, write_wav
    from assets.files import check_writable
    from assets.unitcorpus import find_unit_corpus, load_unit_corpus
    from clients.export.files import FORMATS, check_outputs, export_track
    from facecast.commands.headopts import resolve_from_args
    from facecast.commands.outputs import check_distinct_outputs, check_output_formats
    from facecast.commands.speech_options import apply_expressions
    from realtime_core.synthesis.rest import RestPauses
    from realtime_core.synthesis.synthesizer import UnitSynthesizer
    from realtime_core.track import Track
    from training.errors import ConfigError

    t_start = time.perf_counter()
    outs = [Path(o) for o in args.output]
    check_output_formats(outs, (".mp4", ".npz", ".wav", *FORMATS))
    check_distinct_outputs(outs)
    checked = check_outputs([o for o in outs if o.suffix.lower() in FORMATS], source=args.audio)  # never over --audio
    apply_expressions(np.zeros((1, 4)), args)  # a misspelt --expression fails before any synthesis
    if args.audio is not None and any(o.resolve() == args.audio.resolve() for o in outs):
        raise ConfigError(f"{args.audio}: an output would overwrite the --audio recording; give it another name")
    for o in outs:  # before any work; an .mp4's temporary folder is made beside it, so its folder must exist
        if o.resolve() not in checked:  # the exports were probed by check_outputs
            check_writable(o)
    if any(o.suffix.lower() == ".mp4" for o in outs):
        from clients.render.video import check_video_size

        check_video_size(args.width, args.height)
    timings: dict[str, float] = {}

    def lap(name: str, t0: float) -> float:
        now = time.perf_counter()
        timings[name] = now - t0
        return now

    from assets.tts import language_of_voice

    # `--voice es` alone was refused as "not one of en-us, en, ... for 'en'": the voice names its language
    lang = args.lang or language_of_voice(args.voice)
    t = time.perf_counter()
    if args.audio is not None:
        from assets.tts import day_first, parse_voice
        from training.force_align import force_align, speech_in_pauses_s

        if lang != "en":
            raise ConfigError("--audio needs English (the forced aligner's model is US English)")
        samples, rate = read_audio(args.audio)
        # "07/12/2026" in the transcript is 7 December to a British --voice, as `say` without --audio reads it
        # (it was July 12 whatever the voice: the recording said one date, the alignment expected another)
        first = day_first(parse_voice(lang, args.voice, rate_wpm=args.rate))
        alignment = force_align(samples, rate, args.text, source=args.audio, day_first=first)
        speech_s, unaligned_s = speech_in_pauses_s(samples, rate, alignment)
        if unaligned_s > 1.0 and unaligned_s > 0.3 * speech_s:
            # pocketsphinx aligns any transcript: one that does not match the recording used to pass silently
            print(
                f"facecast say: warning: {unaligned_s:.1f} of the {speech_s:.1f} s of speech in {args.audio} fall "
                "outside the transcript's words: does the text match the recording?",
                file=sys.stderr,
            )
        phones = [(p.phoneme, p.start_s, p.end_s) for p in alignment.phones]
        inventory = "arpabet"
        duration_s = len(samples) / rate
        t = lap("forced alignment", t)
    else:
        from assets.tts import speak

        # silence before and after, the face at rest there (a user's --audio keeps its own ends)
        speech = speak(args.text, language=lang, voice=args.voice, rate_wpm=args.rate).padded()
        samples, rate, phones, inventory, duration_s = (
            speech.samples,
            speech.sample_rate_hz,
            list(speech.phones),
            speech.inventory,
            speech.duration_s,
        )
        t = lap("speech synthesis", t)
    stored = load_unit_corpus(find_unit_corpus(args.corpus))
    with threadpool_limits(1):  # small matrices: one BLAS thread is fastest on a loaded machine
        synth = UnitSynthesizer(stored.corpus, rest=stored.rest_frame())
        t = lap("corpus + graph", t)
        n_frames = int(np.ceil(duration_s * 30 - 1e-9))
        # synthesised speech has no in-breath: its pauses at rest; a recording's breath is real
        rest = RestPauses() if args.audio is None else None
        res = synth.synthesize(phones, inventory, n_frames=n_frames, n_best=args.n_best, rest_pauses=rest)
        t = lap("unit selection", t)
        motion = res.frames
        mixed = args.audio is not None and args.audio_blend
        if mixed:
            from assets.modelfile import load_model
            from realtime_core.pipeline import speech_to_params

            motion = synth.with_recording(res, speech_to_params(load_model(None), samples, rate))
            t = lap("audio-driven blend", t)
    k = stored.corpus.n_coefficients
    # Expressions layer on the four parameters as on an audio-driven file (animate, render): every output
    # carries them, the .npz's parameter columns too (its landmark coefficients stay the recorded lips').
    params = apply_expressions(motion[:, k:], args, command="say")
    if args.expression:
        motion = np.concatenate([motion[:, :k], params], axis=1)
    track = Track(values=params)
    head = None
    if any(o.suffix.lower() in (".mp4", ".glb") for o in outs):
        head = resolve_from_args(args)
        t = lap("head", t)  # its own lap: it was counted in the first output's time (e.g. "write .csv 3852 ms")
    for out in outs:
        if out.suffix.lower() == ".mp4":
            from assets.heads.landmarks import credit_for
            from clients.render.renderer import RenderConfig, renderer_for_rig
            from clients.render.video import VideoConfig, with_caption, write_video

            assert head is not None  # resolved above whenever an .mp4 is among the outputs
            rig, mesh = head
            credit = credit_for(mesh.name)
            cfg = RenderConfig(width=args.width, height=args.height, samples=args.samples)
            if args.background is not None:
                cfg = replace(cfg, background=args.background)
            with tempfile.TemporaryDirectory(prefix=".facecast-say-", dir=out.resolve().parent) as tmp:
                wav = write_wav(Path(tmp) / "speech.wav", samples, rate)
                with renderer_for_rig(rig, mesh, cfg) as r:

                    def frame(p, r=r, rig=rig, credit=credit):  # one frame (h, w, 3) uint8 with the credit
                        return with_caption(r.render(rig.deformed(p)), credit)

                    write_video(
                        params,
                        frame,
                        out,
                        size=(cfg.width, cfg.height),
                        audio=wav,
                        config=VideoConfig(fps=30.0, preset=args.preset),
                    )
        elif out.suffix.lower() == ".npz":
            write_motion(out, motion, stored)
        elif out.suffix.lower() == ".wav":  # the speech the motion is timed to (16-bit mono, its own rate)
            write_wav(out, samples, rate)
        else:
            export_track(out, track, head=head, audio=(samples, rate), checked=checked)
        t = lap(f"write {out.suffix}", t)
    sel = res.selection
    tgt = res.target
    print(
        f"say: {len(tgt.labels)} phones ({inventory}), {duration_s:.2f} s of speech, {sel.n_units} recorded units"
        + (f", {sel.n_mismatched} junctions outside the corpus's visemes" if sel.n_mismatched else "")
        + (f", {tgt.substituted} phones shown by a look-alike viseme" if tgt.substituted else "")
        + (f", unknown phones {sorted(set(tgt.unknown))}" if tgt.unknown else "")
        + (", the recording's audio-driven motion mixed in" if mixed else "")
    )
    if args.verbose:
        sent = stored.corpus.phone_sentence()[sel.states]
        print("units:", " ".join(f"{tgt.labels[m]}<{stored.corpus.sentence_ids[s]}>" for m, s in enumerate(sent)))
        print(
            "timings:",
            ", ".join(f"{k} {1000 * v:.0f} ms" for k, v in timings.items()),
            f"| total {1000 * (time.perf_counter() - t_start):.0f} ms",
        )
    for out in outs:
        if out.suffix.lower() == ".wav":
            print(f"wrote {out}: {len(samples) / rate:.2f} s of speech at {rate} Hz")
        else:
            print(f"wrote {out}: {len(params)} frames ({len(params) / 30:.2f} s)")
    return 0
