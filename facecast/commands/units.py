"""``facecast units build|eval``: the unit-selection corpus of GRID s1 and its objective evaluation."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "units",
        help="build the unit-selection motion corpus (GRID s1) or evaluate it on real lips",
        formatter_class=HelpFormatter,
    )
    which = p.add_subparsers(dest="units", required=True, metavar="ACTION")
    actions = (
        ("build", "build (or find in the cache) the corpus of the GRID s1 train + val sentences"),
        (
            "eval",
            (
                "held-out test sentences from text with real timings vs the real lips, beside the "
                "audio-driven HMM and the articulatory rules (seed 001 Sec. 4.1)"
            ),
        ),
    )
    for name, text in actions:
        q = which.add_parser(name, help=text, formatter_class=HelpFormatter, description=text)
        q.add_argument(
            "--grid",
            type=Path,
            default=None,
            help="GRID s1 folder (video/, align/); default: ../shared/data/video/grid_s1 beside the checkout",
        )
        q.add_argument(
            "--phones",
            type=Path,
            default=None,
            help="GRID phone boundaries (default: the shipped talker-specific HMM labels, "
            "assets/data/grid_s1_phones_hmm.json; the pocketsphinx ones: assets/data/grid_s1_phones.json)",
        )
        q.add_argument(
            "--cache-dir",
            type=Path,
            default=None,
            help="extraction/corpus cache (default $FACECAST_CACHE or ~/.cache/facecast)",
        )
        q.add_argument(
            "--only-extracted",
            action="store_true",
            help="use only sentences the shared extraction has cached (never run MediaPipe)",
        )
        q.set_defaults(run=_run_build if name == "build" else _run_eval)
        if name == "build":
            q.add_argument(
                "--ship",
                action="store_true",
                help="also write the corpus to assets/data/ (the one `facecast say` uses by default)",
            )
        else:
            q.add_argument("--model", type=Path, default=None, help="HMM baseline model (default: the shipped one)")
            q.add_argument("--n-best", default="1,10", help="unit sequences averaged, one row per value")
            q.add_argument(
                "--split",
                choices=("test", "val"),
                default="test",
                help="test: the held-out sentences; val: the corpus's val sentences, each with its own "
                "recording excluded (leave-one-out; where settings are chosen)",
            )
            q.add_argument(
                "--recording",
                default="default",
                metavar="LEAD,SPEECH,TRAIL|default|none",
                help="also score text + recording: the audio-driven model's output on the real audio mixed "
                "into the unit selection output with these weights in the leading pause, speech and the "
                "trailing pause (default: realtime_core.synthesis.recording.RecordingBlend's; none: pure "
                "text rows only)",
            )
            q.add_argument("--output", type=Path, default=None, help="write the markdown section here")
            q.add_argument(
                "--figure",
                type=Path,
                default=None,
                help="Fig. 8 PNG (default: img/unitsel_fig8.png beside --output, _val before .png for --split val; "
                "without --output, in the current folder)",
            )


def figure_path(figure: Path | None, output: Path | None, split: str) -> tuple[Path, str]:
    """(where ``units eval`` writes its Fig. 8 PNG, the link to it from the ``output`` markdown). The default was
    the relative ``docs/img/unitsel_fig8.png`` whatever ``--output`` said: a run from the checkout replaced the
    committed test figure (with the val one for ``--split val``), a run elsewhere made a ``docs/img`` there."""
    import os

    if figure is None:
        name = "unitsel_fig8.png" if split == "test" else f"unitsel_fig8_{split}.png"
        figure = output.parent / "img" / name if output is not None else Path(name)
    link = Path(os.path.relpath(figure, output.parent)).as_posix() if output is not None else figure.name
    return figure, link


def _corpus(args: argparse.Namespace):
    from assets import grid
    from assets.progress import Progress
    from training.grid_phones import HMM_PATH, read_grid_phones
    from training.unit_corpus import build_grid_corpus

    root = args.grid or grid.default_root()
    phones = read_grid_phones(args.phones or HMM_PATH)
    sents = [s for s in grid.sentences(root) if s.split != "test"]
    return (
        build_grid_corpus(
            sents, phones, cache_dir=args.cache_dir, only_extracted=args.only_extracted, progress=Progress, say=print
        ),
        root,
        phones,
    )


def _run_build(args: argparse.Namespace) -> int:
    stored, path = _corpus(args)[0]
    print(
        f"unit corpus {path}: {stored.corpus.n_sentences} sentences, {stored.corpus.n_phones} phones, "
        f"{stored.corpus.n_coefficients} EM-PCA components ({100 * stored.meta['explained']:.1f} % of the variance)"
    )
    if args.ship:
        from assets.unitcorpus import SHIPPED, save_unit_corpus

        save_unit_corpus(SHIPPED, stored)
        print(f"wrote {SHIPPED}")
    return 0


def _run_eval(args: argparse.Namespace) -> int:
    import json

    from threadpoolctl import threadpool_limits

    from assets import grid
    from assets.files import atomic_write_bytes, check_writable
    from assets.modelfile import load_model
    from assets.progress import Progress
    from realtime_core.synthesis.recording import RecordingBlend
    from training.errors import ConfigError, FileProblem
    from training.unit_corpus import is_extracted, phone_rows
    from training.unitsel_eval import evaluate, fig8, markdown
    from training.video import load_face_track

    if args.recording == "none":
        recording = None
    elif args.recording == "default":
        recording = RecordingBlend()
    else:
        try:
            lead, speech, trail = (float(x) for x in args.recording.split(","))
        except ValueError:
            raise ConfigError(
                f"--recording: expected LEAD,SPEECH,TRAIL weights, default or none, got {args.recording!r}"
            ) from None
        recording = RecordingBlend(lead=lead, speech=speech, trail=trail)
    fig, link = figure_path(args.figure, args.output, args.split)
    for out in (args.output, fig):  # before the corpus is built and searched (minutes), not after
        if out is not None:
            check_writable(out)
    (stored, _), root, phones = _corpus(args)
    tests = []
    for s in grid.sentences(root, split=args.split):
        if s.sentence_id not in phones or (args.only_extracted and not is_extracted(s.video, args.cache_dir)):
            continue
        try:
            tests.append(
                (s.sentence_id, load_face_track(s.video, cache_dir=args.cache_dir), phone_rows(phones[s.sentence_id]))
            )
        except FileProblem as exc:
            print(f"skipping {s.sentence_id}: {exc.problem}")
    n_best = tuple(int(x) for x in args.n_best.split(","))
    with threadpool_limits(1):
        rows, curves = evaluate(
            stored,
            tests,
            model=load_model(args.model),
            n_best=n_best,
            progress=Progress,
            leave_one_out=args.split == "val",
            model_label=str(args.model) if args.model else "shipped default model",
            recording=recording,
        )
    print(json.dumps(rows, indent=1))
    fig = fig8(curves, fig)
    cmd = "facecast units eval" + (" --only-extracted" if args.only_extracted else "")
    cmd += " --split val" if args.split == "val" else ""
    text = markdown(rows, n_sentences=len(tests), corpus_meta=stored.meta, command=cmd, figure=link, split=args.split)
    print(text)
    if args.output is not None:
        atomic_write_bytes(args.output, text.encode())
        print(f"wrote {args.output}")
    return 0
