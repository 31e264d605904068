"""Progress bars: tqdm's bar on a terminal, whole lines in a log (stderr a file or a pipe)."""

from __future__ import annotations

import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from assets.audio import write_wav
from tests.speech import speechlike

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def adapt_argv(tmp_path) -> list[str]:
    """`facecast adapt` on five short recordings: a real command with a bar over its files."""
    speech = []
    for i in range(5):
        write_wav(tmp_path / f"s{i}.wav", speechlike(1.0, 16000, seed=i), 16000)
        speech.append(str(tmp_path / f"s{i}.wav"))
    model = tmp_path / "adapted.npz"
    return [sys.executable, "-m", "facecast", "adapt", "default", *speech, "-o", str(model), "--iters", "1"]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO)}


def test_a_command_writes_whole_progress_lines_into_a_log(adapt_argv, tmp_path):
    """`facecast adapt ... 2> log`: every redraw of the bar landed in the file, joined by carriage returns. Now
    the log gets whole lines: the bar as it starts and its final count (a run this short writes no other)."""
    log = tmp_path / "log"
    with log.open("wb") as err:
        subprocess.run(adapt_argv, stderr=err, stdout=subprocess.DEVNULL, env=_env(), check=True, timeout=300)
    text = log.read_bytes().decode()
    assert "\r" not in text, repr(text)
    bars = [line for line in text.splitlines() if line.startswith("reading speech:")]
    assert len(bars) == 2, text
    assert "0/5" in bars[0] and "100%" in bars[1] and "5/5" in bars[1], bars
    assert all(line.isascii() for line in bars)


def test_on_a_terminal_the_bar_is_drawn_in_place(adapt_argv):
    """The same command with stderr on a terminal (a pseudo-terminal 100 columns wide): tqdm's bar, redrawn
    in place with carriage returns, as before."""
    main, tty = pty.openpty()
    fcntl.ioctl(tty, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    proc = subprocess.Popen(adapt_argv, stderr=tty, stdout=subprocess.DEVNULL, env=_env())
    os.close(tty)
    got = b""
    while True:
        try:
            chunk = os.read(main, 65536)
        except OSError:  # EIO: the command ended and closed the terminal
            break
        if not chunk:
            break
        got += chunk
    os.close(main)
    assert proc.wait(timeout=300) == 0
    text = got.decode()
    assert text.count("\rreading speech:") >= 2 and "5/5" in text, repr(text)
