#!/usr/bin/env python3
"""Regenerate the README's pictures: docs/img/viewer.png (the browser viewer in headless Chromium,
watching a live session) and docs/img/frame.png (one frame of the offline renderer).

    .venv/bin/python scripts/screenshots.py [--model M.npz] [--out docs/img]

Needs what the browser test needs (chromium, node_modules from `npm ci`). Without --model it uses
the shipped model when there is one, otherwise the tests' small random model mapped into the mouth
parameters' typical ranges (the motion then is not speech-like, but the pictures show the product).
The session's audio is espeak-ng speech when espeak-ng is installed.
"""

from __future__ import annotations

import argparse
import asyncio
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SENTENCE = "Speech goes in, and a face comes out, in real time, on any head you give it."


def _model():
    from assets.modelfile import load_model
    from training.errors import TrainingError

    try:
        return load_model(None), "the shipped model"
    except (TrainingError, OSError) as exc:
        from tests.speech import plausible_model

        return plausible_model(), f"the tests' small random model (no shipped model: {exc})"


def _speech(tmp: Path):
    """(samples (n,) float32 at 16 kHz, what it is): espeak-ng's voice, else speech-like noise."""
    from assets.audio import read_audio
    from realtime_core.features.resample import resample_audio

    if shutil.which("espeak-ng"):
        wav = tmp / "speech.wav"
        subprocess.run(["espeak-ng", "-s", "150", "-w", str(wav), SENTENCE], check=True, capture_output=True)
        x, rate = read_audio(wav)
        return resample_audio(x, rate, 16000).astype("float32"), "espeak-ng speech"
    from tests.speech import speechlike

    return speechlike(6.0, 16000), "speech-like noise (espeak-ng is not installed)"


async def _stream_forever(url: str, name: str, samples, stop: asyncio.Event) -> None:
    from clients.client import IngestClient, stream_samples

    async with IngestClient(url, session=name, sample_rate_hz=16000) as ing:
        while not stop.is_set():
            await stream_samples(ing, samples, realtime=True)
        await ing.end()


def render_frame(out: Path) -> None:
    """One frame of the built-in head mid-vowel, three-quarter view, through the offline renderer."""
    import numpy as np
    from PIL import Image

    from assets.heads.rigfile import builtin_rig
    from clients.render.renderer import RenderConfig, renderer_for_rig

    rig, mesh = builtin_rig()
    with renderer_for_rig(rig, mesh, RenderConfig(width=640, height=480, view="three_quarter")) as r:
        img = r.render(rig.deformed(np.array([0.02, 0.03, 0.2, 0.0])))
    Image.fromarray(img).save(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "img", help="folder for the PNGs (default docs/img)")
    ap.add_argument("--model", type=Path, default=None, help="model file (default: shipped, else a small test model)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    from assets.heads.rigfile import builtin_rig
    from server.app import Head
    from tests.live_server import LiveServer

    if args.model is not None:
        from assets.modelfile import load_model

        model, what = load_model(args.model), str(args.model)
    else:
        model, what = _model()
    print(f"screenshots: model: {what}")
    render_frame(args.out / "frame.png")
    print(f"screenshots: wrote {args.out / 'frame.png'}")
    rig, mesh = builtin_rig()
    srv = LiveServer(model, Head(rig, mesh))
    with tempfile.TemporaryDirectory() as tmp:
        samples, said = _speech(Path(tmp))
        print(f"screenshots: session 'demo' streams {said} in a loop")
        stop = asyncio.Event()
        fut = srv.submit(_stream_forever(srv.url, "demo", samples, stop))
        try:
            subprocess.run(
                ["node", str(REPO / "scripts" / "screenshots.mjs"), srv.url, "demo", str(args.out / "viewer.png")],
                cwd=REPO,
                check=True,
                timeout=180,
            )
        finally:
            srv.loop.call_soon_threadsafe(stop.set)
            fut.result(60)
            srv.stop()
    print(f"screenshots: wrote {args.out / 'viewer.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
