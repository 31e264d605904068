"""``facecast extract VIDEO... -o OUT_DIR``: mouth parameters measured on talking-face video."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "extract",
        help="measure the four mouth parameters on talking-face video (MediaPipe face mesh)",
        description=(
            "Extract the audio with ffmpeg, track 3D face landmarks per frame with MediaPipe's face\n"
            "mesh, remove head pose, measure the four mouth parameters (IOD units, relative to the\n"
            "clip's neutral pose), resample to exactly 30 fps and write the corpus layout\n"
            "(source 'video'). Needs the optional extra: pip install 'facecast[video]'."
        ),
        formatter_class=HelpFormatter,
    )
    p.add_argument("videos", nargs="+", metavar="VIDEO", help="talking-face videos (mp4, mpg, webm, ...)")
    p.add_argument("-o", "--out", required=True, metavar="OUT_DIR", help="corpus folder to write")
    p.add_argument("--plot", action="store_true",
                   help="save <utterance>/mouth_open.png per clip (with the GRID word alignment when found)")
    p.add_argument("--audio-rate", type=int, default=16000, help="sample rate of the extracted audio, Hz")
    p.add_argument("--language", default="en", help="language code written to the manifest")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np
    from tqdm import tqdm

    from realtime_core.features import loudness_db
    from training.video import ExtractConfig, extract_videos

    cfg = ExtractConfig(audio_rate_hz=args.audio_rate, language=args.language)
    manifest, tracks = extract_videos(
        [Path(v) for v in args.videos], Path(args.out), cfg, plot=args.plot, progress=tqdm
    )
    for tr in tracks:
        mo = tr.params[:, 2]
        energy = loudness_db(tr.samples, tr.sample_rate_hz, len(mo))
        r = float(np.corrcoef(mo, energy)[0, 1]) if mo.std() > 0 else float("nan")
        print(f"{tr.path.name}: {len(tr.video_times_s)} frames at {tr.video_fps:g} fps -> {len(mo)} at 30 fps, "
              f"face in {tr.face_fraction:.0%}, mouth_open {mo.min():.3f}..{mo.max():.3f} IOD, "
              f"r(mouth_open, audio dB) = {r:.2f}")
    print(f"wrote {len(tracks)} utterances -> {manifest}")
    return 0
