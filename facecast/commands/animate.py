"""``facecast animate``: speech file -> mouth parameters at 30 fps (CSV), by the live path."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "animate",
        help="speech file -> mouth parameters at 30 fps",
        formatter_class=HelpFormatter,
        description="Estimate the four mouth parameters from a speech file. The default --mode stream runs "
        "exactly the live server's streaming path, so the result equals what a live session produces frame for "
        "frame; --mode batch runs batch HMM inversion (eq. 7 EM) over the whole file.",
    )
    p.add_argument("speech", type=Path, help="speech audio (WAV; other formats through ffmpeg)")
    p.add_argument("--csv", type=Path, required=True, help="output CSV: t (s, frame k at k/30) and the 4 parameters")
    p.add_argument("--model", type=Path, default=None, help="model file (.npz); default: the shipped model")
    p.add_argument("--mode", choices=("stream", "batch"), default="stream", help="streaming (live) or batch HMMI")
    p.add_argument("--lag", type=int, default=0, help="extra frames of fixed-lag smoothing (stream mode)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from realtime_core.inversion import StreamConfig
    from realtime_core.pipeline import speech_to_params
    from training.audio_io import read_audio
    from training.corpus import _atomic_write_bytes, format_params_csv
    from training.modelfile import load_model
    from training.trainer import resample

    model = load_model(args.model)
    samples, rate = read_audio(args.speech)
    x = resample(samples, rate, model.sample_rate_hz)
    params = speech_to_params(model, x, mode=args.mode, stream=StreamConfig(lag=args.lag))
    _atomic_write_bytes(args.csv, format_params_csv(params).encode())
    print(f"wrote {args.csv}: {len(params)} frames ({len(params) / 30:.2f} s) from {args.speech}")
    return 0
