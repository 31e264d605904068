"""``facecast corpus OUT_DIR``: build a synthetic (plus real) audio-visual training corpus."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "corpus",
        help="build a training corpus: espeak-ng speech labelled by articulatory rules",
        description=(
            "Synthesise sentences with espeak-ng (English and Spanish voices, variants, rates and\n"
            "pitches), turn their phoneme timings into the four mouth parameters at 30 fps,\n"
            "optionally degrade the audio like a real microphone, and write the corpus layout\n"
            "(manifest.json; per utterance audio.wav, params.csv, phonemes.json).\n"
            "The same seed writes identical files."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("out_dir", metavar="OUT_DIR", help="corpus folder to write")
    p.add_argument("--sentences", type=int, default=300, help="synthetic utterances per language")
    p.add_argument("--languages", default="en,es", help="comma-separated language codes (en, es)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random draw")
    p.add_argument("--augment", action="store_true", help="add reverberation, noise, level changes, resampling")
    p.add_argument(
        "--real",
        action="append",
        default=[],
        metavar="DIR",
        help="also add real speech with phone alignments found under DIR (source 'real'; repeatable), "
        "e.g. ../shared/data/speech",
    )
    p.add_argument(
        "--align",
        action="store_true",
        help="with --real: also force-align transcribed WAVs (<stem>.txt or metadata.csv) that have no phone "
        "alignment, with pocketsphinx (pip install 'facecast[align]')",
    )
    p.add_argument(
        "--variants",
        default=None,
        help="comma-separated espeak voice variants to draw from ('base' = no variant), e.g. to keep the "
        "evaluation voices f5,m7 out of training; default: all of base,m1..m7,f1..f5",
    )
    p.add_argument("--lead-ms", type=float, default=33.0, help="move rule labels this much earlier (lips lead sound)")
    p.add_argument(
        "--engine",
        choices=("espeak", "festival"),
        default="espeak",
        help="speech engine: espeak-ng (English and Spanish voices) or Festival (English diphone and HTS "
        "voices, closer to human speech; --sentences counts its utterances, --languages and --variants "
        "do not apply)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import time
    from pathlib import Path

    from assets.files import check_writable_folder
    from assets.progress import Progress
    from training.articulatory import ArticulatoryConfig
    from training.build_corpus import BuildConfig, VoiceSampling, build_corpus

    check_writable_folder(args.out_dir)  # before any speech is synthesised (a traceback after, otherwise)
    if args.engine == "festival":
        return _festival(args)
    langs = tuple(s.strip() for s in args.languages.split(",") if s.strip())
    voices = VoiceSampling()
    if args.variants is not None:
        voices = VoiceSampling(
            variants=tuple(None if v.strip() == "base" else v.strip() for v in args.variants.split(",") if v.strip())
        )
    cfg = BuildConfig(
        out_dir=Path(args.out_dir),
        sentences=args.sentences,
        languages=langs,
        seed=args.seed,
        augment=args.augment,
        real_dirs=tuple(Path(d) for d in args.real),
        force_align=args.align,
        articulatory=ArticulatoryConfig(lead_s=args.lead_ms / 1000.0),
        voices=voices,
    )
    t0 = time.perf_counter()
    rep = build_corpus(cfg, progress=Progress)
    wall = time.perf_counter() - t0
    src = ", ".join(f"{k}: {v}" for k, v in sorted(rep.by_source.items()))
    print(
        f"wrote {rep.n_utterances} utterances ({src}), {rep.audio_s / 60:.1f} min of audio, "
        f"in {wall:.1f} s -> {rep.manifest}"
    )
    for path, why in rep.skipped:
        print(f"skipped {path}: {why}")
    return 0


def _festival(args: argparse.Namespace) -> int:
    from pathlib import Path

    from assets.progress import Progress
    from training.articulatory import ArticulatoryConfig
    from training.build_corpus import load_sentences
    from training.festival import VOICES, FestivalVoice, build_festival_corpus

    base = load_sentences("en")
    sentences = [base[i % len(base)] for i in range(args.sentences)]
    voices = [FestivalVoice(name=v, stretch=x) for v in VOICES for x in (0.85, 1.0, 1.15)]
    manifest = build_festival_corpus(
        Path(args.out_dir),
        sentences,
        seed=args.seed,
        voices=voices,
        augment_audio=args.augment,
        articulatory=ArticulatoryConfig(lead_s=args.lead_ms / 1000.0),
        progress=Progress,
    )
    print(f"wrote {len(sentences)} Festival utterances -> {manifest}")
    return 0
