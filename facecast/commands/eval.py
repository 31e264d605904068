"""``facecast eval``: accuracy of a model beside the loudness baseline, written to docs/accuracy.md."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from assets.shared import shared_data_root
from facecast.commands.argtypes import floats, ints

SHARED = shared_data_root()
OTHER_TALKERS = SHARED / "video" / "grid"
"""The default --video-dir: four GRID clips, three of them by talkers other than s1 (the data README)."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "eval",
        help="accuracy on real lips (GRID), held-out synthetic voices and real aligned speech",
        formatter_class=HelpFormatter,
        description="Score a model with the live streaming path, beside a loudness baseline (the frame's RMS "
        "level in dB as a mouth-opening predictor). Real lips, truth measured by `facecast extract` (needs the "
        "video extra): (1) held-out GRID s1 sentences (the test split of assets.grid, never tuned on; --grid-split "
        "val for choices); (2) the clips in --video-dir (default: other GRID talkers; s1's clip there is left "
        "out; given, only those clips are scored, unless --grid-s1, --speech-dir or --synthetic ask for more). Per "
        "parameter: r at lag 0, the best lag and its r, nu = std(est)/std(true), the share of bilabial closures "
        "the estimate reaches (mouth_open <= 0.01 IOD). Then (3) real speech with phone alignments (--speech-dir; "
        "truth = the articulatory rules on the real phone timings), (4) held-out synthetic voices (espeak "
        "variants f5, m7; truth = the rules) and (5) the real speech of (3) per clip.",
    )
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        help="model file (.npz) or a shipped name: default, low-latency (docs/default_model.md)",
    )
    p.add_argument(
        "--synthetic",
        type=Path,
        default=None,
        help="held-out synthetic corpus folder "
        "(default: build 40 utterances per language with voice variants f5,m7, seed 1234)",
    )
    p.add_argument(
        "--speech-dir",
        type=Path,
        default=None,
        help="real speech with phone alignments (default: shared data speech/, skipped when missing)",
    )
    p.add_argument(
        "--video-dir",
        type=Path,
        default=None,
        help="a folder of talking-face clips to score (default: the GRID clips of talkers other than s1, "
        "shared data video/grid); given, only these clips are scored (their face tracks measured once and cached, "
        "with progress) and the other sections only when named: --grid-s1, --speech-dir, --synthetic",
    )
    p.add_argument(
        "--grid-s1",
        type=Path,
        default=None,
        help="the GRID s1 corpus (default: shared data video/grid_s1, skipped when missing)",
    )
    p.add_argument("--grid-split", choices=("test", "val"), default="test", help="GRID s1 split to score")
    p.add_argument("--cache-dir", default=None, help="face-track cache (default $FACECAST_CACHE or ~/.cache/facecast)")
    p.add_argument(
        "--output",
        type=Path,
        default=None,
        help="write the markdown here (e.g. docs/accuracy.md), plots beside it; an existing latency-dial section "
        "of that file is kept",
    )
    p.add_argument(
        "--dial",
        nargs="+",
        default=None,
        metavar="MODEL",
        help="latency dial instead: score these models (files or shipped names) at every --lags on the GRID s1 "
        "--grid-split (use val: choices are made on it) against their algorithmic delay; with --output, replace "
        "only the dial section of that file and plot beside it",
    )
    p.add_argument(
        "--lags",
        type=lambda t: tuple(ints(t)),
        default=(0,),
        help="fixed-lag smoothing frames for --dial, e.g. 0,1",
    )
    p.add_argument(
        "--kappas",
        type=lambda t: tuple(floats(t)),
        default=None,
        help="with --dial: choose each model's audio-likelihood exponent per lag among these on the scored split "
        "(highest r(mouth_open) keeping >= 90%% of closures); shipped models (default, low-latency) always run "
        "as they ship; default: the models' own",
    )
    from facecast.commands.speech_options import add_mapper_options

    add_mapper_options(p)
    p.add_argument(
        "--mu",
        type=Path,
        default=None,
        metavar="DIR",
        help="instead: paper 002's numbers for the models `facecast mu -o DIR` wrote (HMM and MLP re-scored "
        "on the GRID s1 train and test sentences; expressions and keyframes from DIR/report.json)",
    )
    p.set_defaults(run=run)


def _default_folders(args: argparse.Namespace) -> None:
    """--grid-s1 / --speech-dir: a folder given by name must exist (a typo used to skip its section and exit 0);
    unset, the shared data's, whose sections are skipped with a line when it is missing."""
    from training.errors import ConfigError

    for option, attr, default in (
        ("--grid-s1", "grid_s1", SHARED / "video" / "grid_s1"),
        ("--speech-dir", "speech_dir", SHARED / "speech"),
    ):
        given = getattr(args, attr)
        if given is not None and not given.is_dir():
            raise ConfigError(f"{option} {given}: folder not found")
        setattr(args, attr, default if given is None else given)


def _reproduce(args: argparse.Namespace) -> str:
    """The command the report's "Produced by" line names: every option that changes what it scores (it named
    --model and --grid-split only, so a report on `--video-dir myheldout` read as one on the other GRID talkers).
    After :func:`_default_folders`: a folder equal to its default is left out."""
    from shlex import quote

    given = [
        ("--model", args.model),
        ("--mapper", None if args.mapper == "hmm" else args.mapper),
        ("--grid-split", None if args.grid_split == "test" else args.grid_split),
        ("--grid-s1", None if args.grid_s1 == SHARED / "video" / "grid_s1" else args.grid_s1),
        ("--video-dir", args.video_dir),
        ("--speech-dir", None if args.speech_dir == SHARED / "speech" else args.speech_dir),
        ("--synthetic", args.synthetic),
    ]
    return "facecast eval" + "".join(f" {o} {quote(str(v))}" for o, v in given if v is not None)


def run(args: argparse.Namespace) -> int:
    import tempfile

    from assets.files import atomic_write_bytes
    from assets.modelfile import load_speech_model
    from assets.progress import Progress
    from training.corpus import load_corpus
    from training.evaluation import format_markdown, real_speech_items, score_set
    from training.reallips import evaluate_lips, lips_markdown, plot_lips, s1_clips

    # --video-dir: a user comparing a model on their own clips. The other sections only when named: it scored GRID
    # s1's test split, the shared speech and a synthetic corpus besides (3 GRID clips: 90 s on a first run, measuring
    # s1's 90 test sentences; 7.9 s with them cached; the clips alone 2.9 s, 5.7 s measuring them too).
    named = {"grid_s1": args.grid_s1, "speech_dir": args.speech_dir, "synthetic": args.synthetic}
    wanted = {k: args.video_dir is None or v is not None for k, v in named.items()}
    _default_folders(args)
    if args.mu is not None:
        return _run_mu(args)
    if args.dial:
        return _run_dial(args)
    model = load_speech_model(args.mapper, args.model)
    plot_dir = args.output.parent if args.output is not None else None
    stem = args.output.stem if args.output is not None else "accuracy"
    lips_md, summary = [], {}
    if wanted["grid_s1"] and args.grid_s1.is_dir():
        clips = s1_clips(args.grid_split, root=args.grid_s1, cache_dir=args.cache_dir, progress=Progress)
        s, items = evaluate_lips(model, clips)
        summary["s1"] = s
        goals = {
            "r(mouth_open) >= 0.92": s.r["mouth_open"] >= 0.92,
            "r(lip_stretch) >= 0.80": s.r["lip_stretch"] >= 0.80,
            "r(upper_lip_raise) >= 0.75": s.r["upper_lip_raise"] >= 0.75,
            "closure >= 90%": s.closure_rate >= 0.9,
            "nu(mouth_open) in 0.8..1.2": 0.8 <= s.nu["mouth_open"] <= 1.2,
        }
        lips_md.append(
            lips_markdown(
                f"1. Real lips: GRID s1 held-out sentences ({args.grid_split} split)",
                s,
                note=f"{len(clips)} sentences the model never trained on; truth = the lips "
                "measured by `facecast extract`.",
                goals=goals,
            )
        )
        if plot_dir is not None:
            png = plot_lips(items, s, plot_dir / f"{stem}_s1_{args.grid_split}.png", title=f"GRID s1 {args.grid_split}")
            lips_md.append(f"![s1 {args.grid_split}]({png.name})\n\n")
    elif wanted["grid_s1"]:
        print(f"skipping GRID s1: {args.grid_s1} not found", file=sys.stderr)
    video_dir = args.video_dir if args.video_dir is not None else OTHER_TALKERS
    if video_dir.is_dir():
        section, summary["other"] = clips_section(
            model, video_dir, cache_dir=args.cache_dir, plot_dir=plot_dir, stem=stem, progress=Progress
        )
        lips_md.append(section)
    elif args.video_dir is not None:  # asked for by name: not found is the user's mistake, not a section to skip
        from training.errors import ConfigError

        raise ConfigError(f"--video-dir {args.video_dir}: folder not found")
    else:
        print(f"skipping other talkers: {video_dir} not found", file=sys.stderr)
    if wanted["speech_dir"] and args.speech_dir.is_dir():
        from training.reallips import real_speech_clips, score_real_speech

        s = score_real_speech(model, real_speech_clips(args.speech_dir))
        summary["speech"] = s
        lips_md.append(
            lips_markdown(
                "3. Other voices without video: real speech with phone alignments",
                s,
                note="ARCTIC, LibriVox and praatio recordings; truth = the articulatory rules on the real phone "
                "timings (their own r against real lips is about 0.5-0.6, so r here is bounded well below 1); the "
                "closures are the aligned /p b m/ phones.",
                goals={"closure >= 90%": s.closure_rate >= 0.9},
            )
        )
    results = []
    if wanted["synthetic"]:
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
            results.append(
                (
                    "4. Held-out synthetic voices (espeak variants never used in training; truth = the rules)",
                    score_set(model, "synthetic", items),
                )
            )
    if wanted["speech_dir"] and args.speech_dir.is_dir():
        results.append(
            (
                "5. Real speech, truth from the articulatory rules on real phone timings (per clip)",
                score_set(model, "real", real_speech_items(args.speech_dir)),
            )
        )
    elif wanted["speech_dir"]:
        print(f"skipping real speech: {args.speech_dir} not found", file=sys.stderr)
    rest = format_markdown(results, _reproduce(args))
    head, _, body = rest.partition("\n## ")
    text = head + "".join(lips_md) + ("## " + body if body else "")
    print(text)
    if args.output is not None:
        from training.latency import existing_dial_section, splice_dial_section
        from training.report import carry_over_sections

        # The latency dial (`facecast eval --dial`) and the sections other commands write (`--mu`,
        # `facecast units eval`) are measured separately; keep them.
        old = args.output.read_text(encoding="utf-8") if args.output.is_file() else ""
        dial = existing_dial_section(old)
        text = splice_dial_section(carry_over_sections(text, old, skip=dial), dial)
        atomic_write_bytes(args.output, text.encode())
        print(f"wrote {args.output}")
    return 0


def clips_section(
    model, folder: Path, *, cache_dir=None, plot_dir: Path | None = None, stem: str = "accuracy", progress=None
):
    """The real-lips section of the talking-face clips in ``folder`` (their face tracks measured, or read from
    the cache, with ``progress(iterable, desc=, unit=)`` around them, e.g. assets.progress.Progress):
    ``(markdown, LipScores)``.
    Titled "other talkers" for the default folder (:data:`OTHER_TALKERS`), else after the folder: a user's
    folder may hold anyone, s1 included. ConfigError when it holds no clip."""
    from training.errors import ConfigError
    from training.reallips import evaluate_lips, lips_markdown, other_talker_clips, plot_lips

    default = folder.resolve() == OTHER_TALKERS.resolve()
    what = "other talkers" if default else f"clips in {folder}"
    clips = other_talker_clips(folder, cache_dir=cache_dir, progress=progress, desc=what)
    if not clips:
        raise ConfigError(f"--video-dir {folder}: no talking-face clips there (video files, e.g. .mp4 .mpg)")
    s, items = evaluate_lips(model, clips, progress=progress)
    goals = {
        "r(mouth_open) >= 0.70": s.r["mouth_open"] >= 0.70,
        "r(mouth_open) >= loudness + 0.20": s.r["mouth_open"] >= s.r_loudness + 0.20,
    }
    if default:
        title = "2. Real lips: other talkers (never used for any choice)"
        note = f"{len(clips)} clips of talkers other than s1 from {folder.name}/ (s1's bbaf2n left out)"
    else:
        title = f"2. Real lips: {what}"
        note = f"{len(clips)} clips from {folder}/ (any named like s1's GRID clip bbaf2n left out)"
    md = lips_markdown(title, s, note=note + "; closures only where a word alignment exists.", goals=goals)
    if plot_dir is not None:
        import re

        name = (
            "other_talkers" if default else "clips_" + (re.sub(r"[^A-Za-z0-9]+", "_", folder.name).strip("_") or "dir")
        )
        png = plot_lips(items, s, plot_dir / f"{stem}_{name}.png", title=what)
        md += f"![{what}]({png.name})\n\n"
    return md, s


def _dial_made_by(args: argparse.Namespace) -> str:
    """The dial section's "made by": the command as run, reading back as the same run (models as given, not by
    their stems; the GRID s1 folder when not the default), and `scripts/latency_dial.sh` only when it scored that
    script's tcT_whW models: `eval --dial default low-latency` (scripts/train_low_latency_model.sh) was reported
    as made by the dial script, and `tc3_wh2` named a file that is not there."""
    import re
    from shlex import quote

    from assets.modelfile import SHIPPED_MODELS

    command = (
        f"facecast eval --dial {' '.join(quote(str(m)) for m in args.dial)}"
        + ("" if args.grid_s1 == SHARED / "video" / "grid_s1" else f" --grid-s1 {quote(str(args.grid_s1))}")
        + f" --grid-split {args.grid_split}"
        + (f" --lags {','.join(map(str, args.lags))}" if tuple(args.lags) != (0,) else "")
        + (f" --kappas {','.join(f'{k:g}' for k in args.kappas)}" if args.kappas else "")
    )
    swept = any(
        m not in SHIPPED_MODELS and re.fullmatch(r"tc\d+_wh[\d.]+", Path(m).stem) is not None for m in args.dial
    )
    if not swept:
        return f"made by `{command}`"
    return (
        f"made by `bash scripts/latency_dial.sh` (it trains the tcT_whW models with one s1-only recipe, only t_c "
        f"and the window changed) running `{command}`"
    )


def _run_mu(args: argparse.Namespace) -> int:
    from assets.files import atomic_write_bytes
    from training.mu_report import mu_markdown
    from training.mu_train import score_saved

    text = mu_markdown(score_saved(args.mu, args.grid_s1, cache_dir=args.cache_dir), f"facecast eval --mu {args.mu}")
    print(text)
    if args.output is not None:
        atomic_write_bytes(args.output, text.encode())
        print(f"wrote {args.output}")
    return 0


def _run_dial(args: argparse.Namespace) -> int:
    """``--dial``: every model at every lag on the s1 split -> table (and plot, file section with --output)."""
    import json

    from assets.files import atomic_write_bytes
    from assets.modelfile import SHIPPED_MODELS, load_model
    from assets.progress import Progress
    from training.errors import ConfigError
    from training.latency import (
        dial_markdown,
        plot_dial,
        score_dial,
        splice_dial_section,
    )
    from training.reallips import s1_clips

    if not args.grid_s1.is_dir():
        raise ConfigError(f"--dial needs the GRID s1 corpus: {args.grid_s1} not found")
    # Shipped names as they are, files by their stem (the table's first column).
    models = [(name if name in SHIPPED_MODELS else Path(name).stem, load_model(name)) for name in args.dial]
    clips = s1_clips(args.grid_split, root=args.grid_s1, cache_dir=args.cache_dir, progress=Progress)
    points = score_dial(
        models, clips, lags=args.lags, likelihood_scales=args.kappas, keep_own=SHIPPED_MODELS.keys(), progress=Progress
    )
    png_name = None
    if args.output is not None:
        png = plot_dial(
            points,
            args.output.parent / f"{args.output.stem}_latency_dial.png",
            title=f"GRID s1 {args.grid_split} split, {len(clips)} sentences",
        )
        png_name = png.name
    section = dial_markdown(
        points,
        split=args.grid_split,
        png_name=png_name,
        note=f"{len(clips)} sentences; {_dial_made_by(args)}. The shipped pair and the choice between them: "
        "docs/default_model.md.",
    )
    print(section)
    print(
        json.dumps(
            [
                {**p.as_json(), "scores": {k: v for k, v in p.as_json()["scores"].items() if k != "per_clip"}}
                for p in points
            ]
        )
    )
    if args.output is not None:
        old = args.output.read_text(encoding="utf-8") if args.output.is_file() else ""
        atomic_write_bytes(args.output, splice_dial_section(old, section).encode())
        print(f"wrote the latency-dial section of {args.output} and {png_name}")
    return 0
