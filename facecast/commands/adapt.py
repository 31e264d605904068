"""``facecast adapt MODEL SPEECH... -o MODEL``: adapt a model's audio side to a new voice."""

from __future__ import annotations

import argparse

from facecast.commands.argtypes import within


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "adapt",
        help="adapt a model to a new voice from 30-60 s of untranscribed speech (MAP, audio side only)",
        description=(
            "Speaker adaptation: the speech files (any audio or video with sound; no transcript) go\n"
            "through the model's own front end, then MAP re-estimation (Gauvain & Lee) moves the\n"
            "audio means and mixture weights of the audio-visual HMM towards the new voice. Visual\n"
            "means, covariances and regressions are kept, so each component's mouth stays the same\n"
            "while its audio anchor moves to the new voice. The streaming matrices are recomputed\n"
            "and the adapted model is written atomically. 30-60 s of speech is the intended amount."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument(
        "model", metavar="MODEL", help="model to adapt: a .npz file or a shipped name (default, low-latency)"
    )
    p.add_argument("speech", nargs="+", metavar="SPEECH", help="enrolment recordings of the new voice")
    p.add_argument("-o", "--output", required=True, metavar="MODEL", help="adapted model file to write (.npz)")
    p.add_argument(
        "--relevance",
        type=float,
        default=8.0,
        help="MAP relevance factor tau for the audio means, in frames (higher = closer to MODEL)",
    )
    p.add_argument(
        "--weight-relevance", type=float, default=8.0, help="relevance factor for the mixture weights, in frames"
    )
    p.add_argument("--no-weights", action="store_true", help="adapt the audio means only")
    p.add_argument("--iters", type=within(int, 1, 100), default=5, help="EM iterations")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:

    from assets.audio import is_silent, read_audio
    from assets.errors import SilentAudioError
    from assets.modelfile import ModelFileError, check_model_output, load_model, resolve_model, save_model
    from assets.progress import Progress
    from realtime_core.adaptation import MIN_ENROL_S, adapt_av_model
    from realtime_core.errors import NotSpeechError
    from realtime_core.hmm.adapt import AdaptConfig
    from training.errors import ConfigError

    output = check_model_output(args.output)
    source = resolve_model(args.model)
    if output.exists() and source.exists() and output.samefile(source):
        # Atomic, but the model it adapts was gone: nothing left to compare with, and adaptation can make it worse.
        raise ModelFileError(
            output, "is the model being adapted; write the adapted model beside it (another name) to compare the two"
        )
    model = load_model(args.model)
    before = model.metadata.get("adaptation")
    if before is not None:  # the prior is then the adapted model, not the one trained on many voices
        print(
            f"note: {args.model} is already adapted (to {before.get('seconds', '?')} s of speech); this adapts it "
            "further: adapting the original model to all the recordings at once is the intended use"
        )
    cfg = AdaptConfig(
        relevance=args.relevance, weight_relevance=None if args.no_weights else args.weight_relevance, n_iter=args.iters
    )
    recordings = []
    for path in Progress(args.speech, desc="reading speech", unit="file"):
        samples, _ = read_audio(path, rate_hz=model.sample_rate_hz)
        if is_silent(samples):  # its frames would pull a component to silence
            raise SilentAudioError(path, "silent: no voice to adapt to; nothing written")
        recordings.append(samples)
    seconds = sum(len(x) for x in recordings) / model.sample_rate_hz
    if seconds < MIN_ENROL_S:  # as a session's enrol: a second of speech at least
        raise ConfigError(f"{seconds:.1f} s of speech; at least {MIN_ENROL_S:g} s is needed (30-60 s is intended)")
    from threadpoolctl import threadpool_limits

    # One BLAS thread: the E-step is many small GEMMs, which multi-threaded OpenBLAS made about
    # ten times slower on 2 busy cores (measured 2.9 s vs 0.28 s for 10 s of speech).
    with threadpool_limits(1):
        try:
            adapted, result = adapt_av_model(model, recordings, config=cfg)
        except NotSpeechError as exc:
            names = ", ".join(str(p) for p in args.speech)
            raise NotSpeechError(f"{names}: {exc}; nothing written") from None
    if result.n_frames == 0:
        print("no speech frames: the model is unchanged")
    sound_s = result.n_frames / model.frontend.mfcc.frame_rate_hz  # digital silence is left out (its frames)
    if sound_s < 10:
        print(f"note: only {sound_s:.1f} s of sound; 30-60 s of speech is the intended amount (few components move)")
    out = save_model(args.output, adapted)
    info = adapted.metadata.get("adaptation", {})
    ll0, ll1 = info.get("audio_loglik_per_frame", [float("nan")] * 2)
    print(
        f"adapted on {len(recordings)} file(s), {seconds:.1f} s of audio ({result.n_frames} frames of sound): "
        f"{info.get('components_visited', 0)} of {model.hmm.n_states * model.hmm.n_mix} components visited; "
        f"audio log-likelihood per frame {ll0:.2f} -> {ll1:.2f} ({len(result.history) - 1} EM iterations)"
    )
    print(f"wrote {out}")
    # Nothing here sees the talker's lips, and a higher audio likelihood is not a better mouth: 45-48 s of a new voice
    # lowered r(mouth_open) on held-out speech of that voice with the shipped default model (docs/training.md).
    print(
        "caution: nothing here checks the adapted model against lips, and adaptation can make it worse: with the "
        "shipped default model it lowered r(mouth_open) on held-out speech of each new voice measured, with "
        "low-latency it raised it for one of three (docs/training.md, 'Speaker adaptation'). Compare both on a video "
        f"of the talker first: facecast eval --model {out} --video-dir FOLDER, then --model {args.model}"
    )
    return 0
