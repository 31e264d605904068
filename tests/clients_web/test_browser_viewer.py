"""The browser viewer for real: Debian's Chromium (headless, SwiftShader WebGL) driven by Playwright.

A real server on loopback streams a session in real time; ``viewer_check.mjs`` loads the page, which
must find the session, download the head, show frames and play the audio; the mouth region must
differ between a closed and an open frame; after the session ends and starts again the page must
reconnect by itself; no console error may occur. Screenshots go to ``artifacts/clients_web/``.
"""

from __future__ import annotations

import asyncio
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.clients_web.conftest import REPO, stream_session

CHROMIUM = Path("/usr/bin/chromium")
SCRIPT = Path(__file__).with_name("viewer_check.mjs")
ARTIFACTS = REPO / "artifacts" / "clients_web"


def _require_browser() -> None:
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium is not installed (scripts/setup.sh installs it: apt-get install chromium)")
    if shutil.which("node") is None:
        pytest.skip("node is not installed")
    for pkg in ("playwright-core", "three"):
        if not (REPO / "node_modules" / pkg / "package.json").is_file():
            pytest.skip(f"node_modules/{pkg} is missing (scripts/setup.sh runs `npm ci` at the repository root)")


def _read_step(proc: subprocess.Popen, want: str) -> dict:
    """Next JSON line of the script; fails the test with the script's report on an error step."""
    for line in proc.stdout:
        msg = json.loads(line)
        if msg["step"] == "error":
            pytest.fail(f"viewer_check.mjs: {msg['error']}\nconsole errors: {msg['console_errors']}")
        if msg["step"] == want:
            return msg
    pytest.fail(f"viewer_check.mjs ended before step {want!r}: {proc.stderr.read()}")


def _png(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)


def test_browser_viewer_shows_the_session_in_sync_and_reconnects(live):
    _require_browser()
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    name = "webcheck"
    stops = [asyncio.Event(), asyncio.Event()]  # used only on the server's loop (set through it)
    first = live.submit(stream_session(live.url, name, 40.0, stop=stops[0]))
    proc = subprocess.Popen(["node", str(SCRIPT), live.url, name, str(ARTIFACTS)], cwd=REPO, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    second = None
    try:
        frames = _read_step(proc, "frames")
        mouth = _read_step(proc, "mouth")
        _read_step(proc, "waiting")
        # End the session and start it again under the same name: the page must follow alone.
        live.loop.call_soon_threadsafe(stops[0].set)
        first.result(30)
        second = live.submit(stream_session(live.url, name, 40.0, seed=1, stop=stops[1]))
        proc.stdin.write("go\n")
        proc.stdin.flush()
        again = _read_step(proc, "reconnected")
        done = _read_step(proc, "done")
    finally:
        live.loop.call_soon_threadsafe(stops[1].set)
        live.loop.call_soon_threadsafe(stops[0].set)
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)
        if second is not None:
            second.result(30)

    st = frames["state"]
    assert name in frames["listed"]  # the page lists the live session
    assert st["kind"] == "deltas" and st["frames"] >= 30 and st["connections"] == 1
    assert st["audio"]["running"] and st["audio"]["played"] > 0  # the relayed speech was scheduled
    assert st["deliveryMs"] is not None and st["behindAudioMs"] is not None  # delays are measured and shown

    # The canvas shows a head, not an empty or one-colour picture.
    page = _png(ARTIFACTS / "viewer.png")
    canvas = page[:, : int(page.shape[1] * 0.6)]
    background = np.median(canvas.reshape(-1, 3), axis=0)
    covered = np.mean(np.abs(canvas - background).sum(axis=2) > 30)
    assert 0.1 < covered < 0.9, f"{covered:.0%} of the canvas differs from the background"
    assert canvas.std() > 20

    # The mouth region differs between a closed and an open frame.
    assert mouth["peaks"]["open"] > mouth["peaks"]["closed"]
    closed, opened = _png(ARTIFACTS / "closed.png"), _png(ARTIFACTS / "open.png")
    assert closed.shape == opened.shape
    changed = np.mean(np.abs(opened - closed).sum(axis=2) > 60)
    assert changed > 0.02, f"only {changed:.1%} of the mouth region changed between closed and open"

    assert again["state"]["connections"] >= 2 and again["state"]["received"] >= 15
    assert done["console_errors"] == []
