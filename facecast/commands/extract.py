"""``facecast extract VIDEO|FOLDER...``: pose-free face landmarks and mouth parameters of talking-face video."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "extract",
        help="measure face landmarks and the four mouth parameters on talking-face video (MediaPipe)",
        description=(
            "Extract the audio with ffmpeg, track 3D face landmarks per frame with MediaPipe's face mesh,\n"
            "remove head pose, resample to exactly 30 fps and measure the four mouth parameters (IOD units,\n"
            "relative to the clip's rest pose: the silences of its word alignment when there is one).\n"
            "Folders are searched recursively. Work runs in parallel processes and is cached by file\n"
            "content in $FACECAST_CACHE (default ~/.cache/facecast): a second run only reads the cache.\n"
            "Bad clips are skipped with one line each and counted in the report (JSON). With -o, the\n"
            "tracks are also written as a corpus folder for `facecast train`.\n"
            "Needs the optional extra: pip install 'facecast[video]'."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("videos", nargs="+", metavar="VIDEO", help="talking-face videos or folders of them")
    p.add_argument("-o", "--out", default=None, metavar="OUT_DIR", help="also write a corpus folder here")
    p.add_argument("--cache-dir", default=None, help="cache folder (default $FACECAST_CACHE or ~/.cache/facecast)")
    p.add_argument("--workers", type=int, default=2, help="parallel processes (one MediaPipe graph each)")
    p.add_argument(
        "--report",
        default=None,
        metavar="JSON",
        help="quality report (default OUT_DIR/extract_report.json with -o, else none)",
    )
    p.add_argument(
        "--plots",
        type=int,
        default=0,
        metavar="N",
        help="plot N clips (a seeded sample): parameters, audio level, words, neutral face",
    )
    p.add_argument("--plot-dir", default=None, help="where the plots go (default OUT_DIR/plots or the report's folder)")
    p.add_argument(
        "--require-alignment",
        action="store_true",
        help="skip clips without a word alignment (default: find rest from the audio level instead)",
    )
    p.add_argument(
        "--split",
        choices=("train", "val", "test"),
        default=None,
        help="with -o: only GRID sentences of this split (assets.grid.split_of)",
    )
    p.add_argument("--audio-rate", type=int, default=16000, help="sample rate of the extracted audio, Hz")
    p.add_argument("--language", default="en", help="language code written to the manifest")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import random
    import sys
    from pathlib import Path

    from assets.progress import Progress
    from training.video import (
        ExtractConfig,
        extract_corpus,
        find_videos,
        grid_split_of,
        load_face_track,
        passed_over,
        save_plot,
        write_report,
        write_track_corpus,
    )

    if args.out:
        from assets.files import check_writable_folder

        check_writable_folder(args.out)  # before the clips are measured
    cfg = ExtractConfig(audio_rate_hz=args.audio_rate, language=args.language)
    videos = find_videos(args.videos)
    others = passed_over(args.videos)
    if others:
        kinds = sorted({p.suffix.lower() or "(no suffix)" for p in others})
        print(
            f"passed over {len(others)} file(s) not named as video ({', '.join(kinds)}), e.g. {others[0]}",
            file=sys.stderr,
        )
    report = extract_corpus(
        videos,
        cache_dir=args.cache_dir,
        workers=args.workers,
        config=cfg,
        require_alignment=args.require_alignment,
        progress=Progress,
        log=lambda line: Progress.write(line, file=sys.stderr),
    )
    doc = report.as_json()
    if not report.clips:
        from training.errors import TrainingError

        first = report.skipped[0] if report.skipped else {"file": " ".join(args.videos), "reason": "no video found"}
        more = f" (and {len(report.skipped) - 1} more skipped)" if len(report.skipped) > 1 else ""
        raise TrainingError(f"{first['file']}: {first['reason']}{more}")
    ok = [Path(c["file"]) for c in report.clips]
    rate = len(ok) / report.seconds if report.seconds > 0 else float("nan")
    print(
        f"{doc['n_ok']} of {doc['n_videos']} clips ok ({doc['n_extracted']} measured, {doc['n_cached']} from the "
        f"cache), {doc['n_skipped']} skipped, in {report.seconds:.1f} s ({rate:.2f} clips/s, {report.workers} workers)"
    )
    if doc["summary"]:
        print("summary:", doc["summary"])
    out = Path(args.out) if args.out else None
    report_path = Path(args.report) if args.report else (out / "extract_report.json" if out else None)
    if report_path is not None:
        write_report(report, report_path)
        print(f"wrote {report_path}")

    def load(v: Path):
        return load_face_track(v, cache_dir=args.cache_dir, config=cfg)

    if out is not None:
        keep = [v for v in ok if args.split is None or grid_split_of(v) == args.split]
        tracks = (load(v) for v in Progress(keep, desc="corpus", unit="clip"))
        manifest = write_track_corpus(list(tracks), out, language=args.language)
        print(f"wrote {len(keep)} utterances -> {manifest}")
    if args.plots > 0 and ok:
        plot_dir = (
            Path(args.plot_dir)
            if args.plot_dir
            else (out / "plots" if out else report_path.parent / "plots" if report_path else Path("extract_plots"))
        )
        from assets.grid import align_for_video, read_words

        for v in random.Random(0).sample(ok, min(args.plots, len(ok))):
            track = load(v)
            align = align_for_video(v)
            png = save_plot(track, plot_dir / f"{v.stem}.png", read_words(align) if align else None)
            print(f"plot {png}")
    return 0
