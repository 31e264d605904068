"""Time to the first frame of a text session for a chatbot-like stream, and what each cut of a sentence costs.

    python -m facecast serve --text --no-head --port 8947 &
    python scripts/text_first_frame.py http://127.0.0.1:8947 [--rate 17] [--runs 3]

Streams two texts to ``/text`` as a language model does (~1.3 pieces a word, ``--rate`` pieces a second; a viewer
attached first): a 47-word first sentence, and a short "Sure!" before a 14-word one. Prints the server's
``first_frame_ms`` (first piece -> frame 0 released, docs/protocol.md section 9), the sentences spoken (where on
the session's clock, how long) and the silent gaps inside the speech the viewer got (>= 0.15 s below 1e-3): a cut
at a comma shows as a longer gap than the comma's own pause.
"""

from __future__ import annotations

import argparse
import asyncio
import json

import numpy as np
from websockets.asyncio.client import connect

from clients.client import ViewerClient

LONG = (
    "When you get to the old stone bridge at the end of the village, turn left and keep walking "
    "along the river past the bakery, the school and the little park until you see a small blue house "
    "with a red door on your right. Knock twice. "
)
SHORT = "Sure! When you get to the old stone bridge at the end of the village, turn left. "


def pieces(text: str) -> list[str]:
    """Words longer than 5 letters in two pieces, as a language model's tokens split them."""
    out = []
    for w in text.split(" "):
        out += [w[: len(w) // 2], w[len(w) // 2 :] + " "] if len(w) > 5 else [w + " "]
    return out


def gaps_s(audio: np.ndarray, rate_hz: int, *, level: float = 1e-3, min_s: float = 0.15) -> list[float]:
    """Runs of |audio| < level at least min_s long between the first and the last sound (s)."""
    loud = np.flatnonzero(np.abs(audio) > level)
    if len(loud) < 2:
        return []
    gaps = np.diff(loud) / rate_hz
    return [round(float(g), 3) for g in gaps if g >= min_s]


async def stream(url: str, name: str, text: str, rate: float) -> tuple[dict, list[dict], np.ndarray, int]:
    async with connect(url.replace("http", "ws", 1) + "/text") as ws:
        await ws.send(json.dumps({"type": "start", "session": name, "language": "en"}))
        json.loads(await ws.recv())
        async with ViewerClient(url, session=name, kind="params") as viewer:
            collect = asyncio.ensure_future(viewer.collect())
            replies: list[dict] = []

            async def read() -> None:
                async for m in ws:
                    replies.append(json.loads(m))

            reader = asyncio.ensure_future(read())
            for piece in pieces(text):
                await ws.send(json.dumps({"type": "text", "text": piece}))
                await asyncio.sleep(1 / rate)
            await ws.send(json.dumps({"type": "end"}))
            await reader
            got = await collect
    audio = np.concatenate([m.values for m in got.audio])
    return replies[-1], [r for r in replies if r["type"] == "spoken"], audio, got.description["audio"]["rate_hz"]


async def main(url: str, rate: float, runs: int) -> None:
    for run in range(runs):
        for label, text in (("long", LONG), ("short", SHORT)):
            ended, spoken, audio, rate_hz = await stream(url, f"ttff-{label}-{run}", text, rate)
            print(
                f"{label}: {len(text.split())} words, {len(pieces(text))} pieces at {rate:g}/s; "
                f"first_frame_ms {ended['first_frame_ms']}; audio {ended['audio_s']:.2f} s"
            )
            for s in spoken:
                print(f"   {s['media_time']:6.2f} s {s['duration_s']:5.2f} s  {s['text']!r}")
            print(f"   silent gaps inside the speech (s): {gaps_s(audio, rate_hz)}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("url", help="the server, e.g. http://127.0.0.1:8947")
    ap.add_argument("--rate", type=float, default=17.0, help="pieces a second (default 17)")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    asyncio.run(main(args.url, args.rate, args.runs))
