"""``facecast perceptual build|serve|report``: the perceptual test kit (docs/perceptual.md)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "perceptual",
        help="perceptual tests with people: build stimuli, run the browser test, report the results",
        formatter_class=HelpFormatter,
        description=(
            "Intelligibility in noise (seed 000 Sec. 6.2: audio only A, real talker N, facecast head S),\n"
            "emotion perception (seed 002 Sec. VII-C) and opinion scores (seed 001 Sec. 4.2).\n"
            "  facecast perceptual build -o STIM           render every stimulus once (cached, with a manifest)\n"
            "  facecast perceptual serve STIM --db DB      run the test in the browser; answers go to DB\n"
            "  facecast perceptual report DB -o REPORT     scores, C_V (eq. 13), confusions, tests, plots"
        ),
    )
    ps = p.add_subparsers(dest="perceptual_command", required=True, metavar="STEP")

    b = ps.add_parser(
        "build", help="render and cache every stimulus; write the manifest", formatter_class=HelpFormatter
    )
    b.add_argument(
        "-o", "--output", default="perceptual_stimuli", help="stimulus folder (manifest.json, media/, cache/)"
    )
    b.add_argument(
        "--grid", help="GRID s1 folder (video/, align/); default ../shared/data/video/grid_s1 beside the checkout"
    )
    b.add_argument("--snr", type=float, nargs="+", default=[-5.0, -10.0, -15.0], help="SNRs (dB) of the sentence block")
    b.add_argument(
        "--cv-snr",
        type=float,
        nargs="*",
        default=[-5.0, -10.0, -15.0],
        help="SNRs (dB) of the syllable block (none: no syllable block)",
    )
    b.add_argument(
        "--synthetic-audio",
        nargs="+",
        choices=("clean", "noisy"),
        default=["clean"],
        help="speech that drives the head: clean (condition S, as in seed 000) and/or noisy (Sn)",
    )
    b.add_argument(
        "--sentences-per-cell", type=int, default=2, help="GRID test sentences per condition x SNR cell per participant"
    )
    b.add_argument("--no-practice", action="store_true", help="no practice block")
    b.add_argument(
        "--cv-languages",
        nargs="*",
        choices=("en", "es"),
        default=["en", "es"],
        help="espeak-ng languages of the syllables (none: no syllable block)",
    )
    b.add_argument("--cv-syllables", nargs="+", help="a subset of the 27 syllables (e.g. pa ba ma) for a pilot")
    b.add_argument(
        "--cv-design",
        choices=("latin", "factorial"),
        default="latin",
        help="latin: each syllable once per participant; factorial: every syllable in every cell",
    )
    b.add_argument("--emotion-sentences", type=int, default=1, help="sentences shown neutral / smiling / sad")
    b.add_argument("--mos-sentences", type=int, default=2, help="sentences rated real (N) vs synthetic (S)")
    b.add_argument(
        "--mos-clip",
        action="append",
        default=[],
        metavar="SYSTEM=CLIP.mp4",
        help="another clip to rate on the five-point scales (repeatable)",
    )
    b.add_argument("--model", help="speech->parameters model: a .npz file or a shipped name (default, low-latency)")
    b.add_argument("--width", type=int, default=640, help="video width")
    b.add_argument("--height", type=int, default=480, help="video height")
    b.add_argument("--seed", type=int, default=0, help="sentence choice and noise seed")
    b.add_argument("--level", type=float, default=-20.0, help="presentation level: RMS over speech, dBFS")
    b.add_argument(
        "--expression-strength",
        type=float,
        default=1.0,
        help="intensity 0..1 of the smiling and sad faces (as render --expression smile:X)",
    )
    b.set_defaults(run=run_build)

    s = ps.add_parser(
        "serve", help="run the test: participant page, answers to SQLite, results page", formatter_class=HelpFormatter
    )
    s.add_argument("stimuli", nargs="?", default="perceptual_stimuli", help="stimulus folder made by build")
    s.add_argument("--db", default="perceptual.sqlite", help="response database (created if missing)")
    s.add_argument("--host", default="127.0.0.1", help="address to listen on (0.0.0.0 for other machines)")
    s.add_argument("--port", type=int, default=8090, help="port (0: any free port)")
    s.add_argument("--results-key", help="key of the experimenter's results page (default: random, printed)")
    s.set_defaults(run=run_serve)

    r = ps.add_parser(
        "report", help="analyse a response database into a Markdown report with plots", formatter_class=HelpFormatter
    )
    r.add_argument("db", help="response database written by serve")
    r.add_argument("-o", "--output", help="report folder (default: DB name + _report)")
    r.add_argument(
        "--include-incomplete",
        action="store_true",
        help="also analyse participants who did not finish (default: finished ones only)",
    )
    r.set_defaults(run=run_report)


def run_build(args: argparse.Namespace) -> int:
    from pathlib import Path

    from assets.files import check_writable_folder
    from perceptual.design import SYLLABLES
    from perceptual.errors import BuildError
    from perceptual.stimuli import BuildConfig, build

    clips = []
    for spec in args.mos_clip:
        system, sep, path = spec.partition("=")
        if not sep:
            raise BuildError(f"--mos-clip {spec!r}: expected SYSTEM=CLIP.mp4")
        clips.append((system, Path(path)))
    cfg = BuildConfig(
        out_dir=check_writable_folder(args.output),  # before any stimulus is rendered
        grid_root=Path(args.grid) if args.grid else None,
        snrs_db=tuple(args.snr),
        cv_snrs_db=tuple(args.cv_snr),
        synthetic_audio=tuple(args.synthetic_audio),
        sentences_per_cell=args.sentences_per_cell,
        practice=not args.no_practice,
        cv_languages=tuple(args.cv_languages),
        cv_syllables=tuple(args.cv_syllables or SYLLABLES),
        cv_design=args.cv_design,
        emotion_sentences=args.emotion_sentences,
        mos_sentences=args.mos_sentences,
        mos_clips=tuple(clips),
        model=Path(args.model) if args.model else None,
        width=args.width,
        height=args.height,
        seed=args.seed,
        level_dbfs=args.level,
        expression_strength=args.expression_strength,
    )
    m = build(cfg)
    stats = m.data["stats"]
    print(
        f"perceptual build {m.root}: test {m.test_id}, {len(m.stimuli)} stimuli in {len(m.blocks)} blocks "
        f"({', '.join(b.name for b in m.blocks)}); made {stats['made']} files, reused {stats['reused']}"
    )
    print(f"next: facecast perceptual serve {m.root}")
    return 0


def run_serve(args: argparse.Namespace) -> int:
    from pathlib import Path

    from perceptual.server import ServeConfig, serve

    serve(
        ServeConfig(
            stimuli=Path(args.stimuli), db=Path(args.db), host=args.host, port=args.port, results_key=args.results_key
        )
    )
    return 0


def run_report(args: argparse.Namespace) -> int:
    from pathlib import Path

    from perceptual.report import write_report

    db = Path(args.db)
    out = Path(args.output) if args.output else db.with_name(db.stem + "_report")
    md = write_report(db, out, include_incomplete=args.include_incomplete)
    print(f"perceptual report {md}")
    return 0
