"""SIGTERM (`kill PID`) ends a command as Ctrl-C does: a render killed mid-way left its half-written
`.NAME.tmp.mp4` beside the output (Python's default SIGTERM ends the process where it stands)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from assets.audio import write_wav
from tests.speech import speechlike

pytestmark = pytest.mark.system  # a real render with ffmpeg in a subprocess


def test_a_render_ended_by_sigterm_leaves_nothing_behind_and_exits_143(tmp_path):
    wav = write_wav(tmp_path / "long.wav", speechlike(60.0, 16000, seed=2), 16000)
    out = tmp_path / "out"
    small = ["--width", "160", "--height", "120"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "facecast", "render", str(wav), "-o", str(out / "take.mp4"), *small],
        cwd=Path(__file__).resolve().parents[2],  # this checkout's facecast
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env={**os.environ, "FACECAST_CACHE": os.environ.get("FACECAST_CACHE", str(tmp_path / "cache"))},
    )
    deadline = time.monotonic() + 240
    while not (out.is_dir() and any(out.iterdir())):  # ffmpeg has started writing the temporary file
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, "the render never started writing"
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert list(out.iterdir()) == [], list(out.iterdir())  # no partial video, no temporary file
    assert b"Traceback" not in err, err
