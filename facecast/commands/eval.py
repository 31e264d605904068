"""``facecast eval``: accuracy of a model beside the loudness baseline, written to docs/accuracy.md."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "eval",
        help="accuracy on held-out synthetic voices, real aligned speech and real faces",
        formatter_class=HelpFormatter,
        description="Score a model with the live streaming path, beside a loudness baseline (the frame's RMS "
        "level in dB as a mouth-opening predictor): (1) held-out synthetic utterances from espeak voices never "
        "used in training (variants f5 and m7; built on the fly unless --synthetic is given); (2) real speech "
        "with phone alignments, truth from the articulatory rules on the real phone timings; (3) real faces: "
        "GRID clips, truth measured by `facecast extract` (needs the video extra), with the best lag.",
    )
    p.add_argument("--model", type=Path, default=None, help="model file (.npz); default: the shipped model")
    p.add_argument("--synthetic", type=Path, default=None, help="held-out synthetic corpus folder "
                   "(default: build 40 utterances per language with voice variants f5,m7, seed 1234)")
    p.add_argument("--speech-dir", type=Path, default=SHARED / "speech", help="real speech with phone alignments")
    p.add_argument("--video-dir", type=Path, default=SHARED / "video" / "grid", help="talking-face clips (GRID)")
    p.add_argument("--output", type=Path, default=None, help="write the markdown table here (e.g. docs/accuracy.md)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import tempfile

    from assets.files import atomic_write_bytes
    from assets.modelfile import load_model
    from training.corpus import load_corpus
    from training.evaluation import format_markdown, real_speech_items, score_set, video_items

    model = load_model(args.model)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        syn = args.synthetic
        if syn is None:
            from training.build_corpus import BuildConfig, VoiceSampling, build_corpus
            from training.evaluation import EVAL_VARIANTS

            syn = Path(tmp) / "heldout"
            build_corpus(
                BuildConfig(out_dir=syn, sentences=40, seed=1234, voices=VoiceSampling(variants=EVAL_VARIANTS))
            )
        items = [(u.id, u.samples, u.sample_rate_hz, u.params) for u in load_corpus(syn)]
        results.append(("1. Held-out synthetic voices (espeak variants never used in training)",
                        score_set(model, "synthetic", items)))
    if args.speech_dir.is_dir():
        results.append(("2. Real speech, truth from the articulatory rules on real phone timings",
                        score_set(model, "real", real_speech_items(args.speech_dir))))
    else:
        print(f"skipping real speech: {args.speech_dir} not found", file=sys.stderr)
    if args.video_dir.is_dir():
        results.append(("3. Real faces (GRID), truth from `facecast extract`",
                        score_set(model, "video", video_items(args.video_dir))))
    else:
        print(f"skipping real faces: {args.video_dir} not found", file=sys.stderr)
    command = "facecast eval" + (f" --model {args.model}" if args.model else "")
    text = format_markdown(results, command)
    print(text)
    if args.output is not None:
        atomic_write_bytes(args.output, text.encode())
        print(f"wrote {args.output}")
    return 0
