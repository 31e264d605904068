"""``facecast phones``: ARPAbet phone labels for the GRID s1 corpus, inside its word spans."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "phones",
        help="label the GRID s1 corpus with phones (pocketsphinx, placed inside the GRID word spans)",
        description=(
            "For every GRID sentence (video/<id>.mp4 + align/<id>.align) force-align the fixed\n"
            "pronunciations with pocketsphinx (10 ms frames) and place each word's phones inside its\n"
            "GRID word span; a word the aligner puts > 0.1 s away from GRID's span is spread over\n"
            "the span instead. Writes one JSON file\n"
            "(ARPAbet + SIL; the method of each sentence; GRID CC BY 4.0 credit), checks that the\n"
            "phones tile every word span and prints duration statistics. Needs ffmpeg and the\n"
            "optional extra 'align' (pocketsphinx)."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument(
        "--root",
        default=None,
        metavar="DIR",
        help="GRID s1 folder with video/ and align/ (default: ../shared/data/video/grid_s1)",
    )
    p.add_argument(
        "-o",
        "--out",
        default=None,
        metavar="JSON",
        help="file to write (default: in the repository, assets/data/grid_s1_phones.json; with --method hmm, "
        "assets/data/grid_s1_phones_hmm.json)",
    )
    p.add_argument("--workers", type=int, default=2, help="parallel processes")
    p.add_argument(
        "--method",
        choices=("pocketsphinx", "hmm"),
        default="pocketsphinx",
        help="pocketsphinx (US-English model, placed in GRID's word spans) or hmm (this talker's own "
        "monophone HMMs by embedded re-estimation, training/phone_hmm.py; word edges free within 0.1 s)",
    )
    p.add_argument("--no-align", action="store_true", help="spread every word's phones (no pocketsphinx, no audio)")
    p.add_argument("--plot", default=None, metavar="PNG", help="also plot waveform, words and phones of --plot-id")
    p.add_argument("--plot-id", default="bbaf2n", help="sentence to plot")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from collections import Counter, defaultdict
    from pathlib import Path

    import numpy as np

    from assets import grid
    from assets.files import check_writable
    from assets.progress import Progress
    from training.errors import ConfigError
    from training.grid_phones import (
        ALIGN_RATE_HZ,
        BILABIALS,
        VOWELS,
        check_free_sentence,
        check_sentence,
        default_path,
        label_corpus,
        save_phone_plot,
        write_grid_phones,
    )

    out = check_writable(Path(args.out) if args.out else default_path(args.method))  # not after minutes of labelling
    root = Path(args.root) if args.root else grid.default_root()
    sents = grid.sentences(root)
    if not sents:
        raise ConfigError(f"no GRID sentences (video/*.mp4 with align/*.align) under {root}")
    labelled, skipped = label_corpus(
        sents, workers=args.workers, align=not args.no_align, progress=Progress, method=args.method, say=print
    )
    out = write_grid_phones(out, labelled)

    by_id = {s.sentence_id: s for s in sents}
    methods = Counter(s.method for s in labelled)
    spread = Counter(w for s in labelled for w in s.spread_words)
    n_words = 0
    problems: list[str] = []
    durations: dict[str, list[float]] = defaultdict(list)
    for s in labelled:
        words = grid.read_words(by_id[s.sentence_id].align)
        n_words += sum(w not in grid.SILENCE_WORDS for _, _, w in words)
        chk = check_free_sentence(s.phones, words) if s.method == "hmm" else check_sentence(s.phones, words)
        problems += [f"{s.sentence_id}: {p}" for p in chk.problems]
        for ph, d in chk.durations:
            durations[ph].append(d)
    print(f"wrote {len(labelled)} sentences -> {out}")
    print("methods: " + ", ".join(f"{m} {n}" for m, n in methods.most_common()))
    print(
        f"words spread instead of aligned: {sum(spread.values())} of {n_words} "
        f"({', '.join(f'{w} {n}' for w, n in spread.most_common(8))})"
    )
    for group, members in (
        ("vowels", VOWELS),
        ("bilabials P B M", BILABIALS),
        ("other consonants", set(durations) - VOWELS - BILABIALS),
    ):
        ms = np.array([x for ph in members for x in durations.get(ph, [])]) * 1000
        if len(ms):
            print(
                f"{group}: {len(ms)} phones, duration ms min {ms.min():.0f} / p5 {np.percentile(ms, 5):.0f} / "
                f"median {np.median(ms):.0f} / p95 {np.percentile(ms, 95):.0f} / max {ms.max():.0f}"
            )
    offs = np.array([s.max_word_offset_s for s in labelled if s.max_word_offset_s is not None]) * 1000
    if len(offs):
        print(
            f"largest word-edge difference aligner vs GRID per sentence, ms: median {np.median(offs):.0f}, "
            f"p95 {np.percentile(offs, 95):.0f}, max {offs.max():.0f}"
        )
    print(
        f"SIL found at word edges inside GRID word spans: {sum(s.edge_silences for s in labelled)} "
        f"in {sum(s.edge_silences > 0 for s in labelled)} sentences"
    )
    print(f"tiling/pronunciation problems: {len(problems)}")
    for p in problems[:20]:
        print(f"  {p}")
    for path, why in skipped:
        print(f"skipped {path}: {why}")
    if args.plot:
        from training.grid_phones import read_grid_phones_file
        from training.video import decode_audio

        sid = args.plot_id
        if sid not in by_id:
            raise ConfigError(f"--plot-id {sid!r} is not a sentence under {root}")
        phones = read_grid_phones_file(out)[sid]
        png = save_phone_plot(
            decode_audio(by_id[sid].video, ALIGN_RATE_HZ),
            ALIGN_RATE_HZ,
            grid.read_words(by_id[sid].align),
            phones.phones,
            args.plot,
            title=f"GRID s1 {sid}: '{grid.sentence_text(sid)}' ({phones.method})",
        )
        print(f"plot -> {png}")
    return 0 if not problems else 1
