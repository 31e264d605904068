"""`facecast demo`'s pieces for real: espeak-ng speech through a live session watched over loopback,
then rendered to an MP4 by the offline renderer."""

from __future__ import annotations

import asyncio
import json
import subprocess

import numpy as np
import pytest

from facecast.demo import DemoConfig, run_demo, synthesise, write_mp4
from realtime_core.features.resample import resample_audio
from realtime_core.pipeline import speech_to_params
from tests.prerequisites import missing

# espeak-ng, a live server and ffmpeg.
pytestmark = pytest.mark.system


def test_demo_streams_speech_and_writes_an_mp4(model, head, ffmpeg, tmp_path):
    from server.errors import AudioSourceError

    sentences = ("Hello there.",)
    try:
        synthesise(sentences, "en-us")
    except AudioSourceError as exc:
        missing(f"espeak-ng unavailable: {exc}")
    cfg = DemoConfig(port=0, sentences=sentences, video=None)
    lines: list[str] = []
    result = asyncio.run(run_demo(cfg, model, head, announce=lines.append))
    # The viewer saw the whole live session: exactly what `facecast animate` gives for the speech.
    # (resampled in float64 like the server; `animate` resamples float32 WAV samples in float32.)
    speech, rate = result.speech, result.speech_rate_hz
    ref = speech_to_params(model, resample_audio(speech.astype(np.float64), rate, model.sample_rate_hz))
    assert result.params.shape == ref.shape
    np.testing.assert_allclose(result.params, ref, rtol=1e-4, atol=1e-4)
    assert any("/view?session=demo" in line for line in lines)
    out = write_mp4(
        tmp_path / "demo.mp4", head, result.params, result.audio, result.audio_rate_hz, width=160, height=120
    )
    probe = json.loads(
        subprocess.run(
            ["ffprobe", "-v", "error", "-count_frames", "-show_streams", "-of", "json", str(out)],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    )
    kinds = {s["codec_type"]: s for s in probe["streams"]}
    assert set(kinds) == {"video", "audio"}
    assert abs(int(kinds["video"]["nb_read_frames"]) - len(ref)) <= 1
    assert [p.name for p in tmp_path.iterdir()] == ["demo.mp4"]  # no temporary files left behind


def test_demo_prints_its_urls_while_the_session_runs_when_piped(tmp_path):
    """`facecast demo` piped (`| tee log`, nohup, CI) printed the viewer URL and "speak now" into a
    block buffer: they appeared after the session had ended and the server was gone. The URL read
    from the pipe must answer while the demo still streams."""
    import os
    import sys
    import urllib.request
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(repo)}
    env.pop("PYTHONUNBUFFERED", None)
    sentence = "Please bring me my umbrella before the big storm arrives tonight, and also my coat."
    cmd = [sys.executable, "-m", "facecast", "demo", "--port", "0", "--once", "--no-video", "--text", sentence]
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        while line and "  open http://" not in line:
            line = proc.stdout.readline()
        assert line, f"no URL printed: {proc.stderr.read() if proc.stderr else ''}"[-500:]
        url = line.split()[1]
        with urllib.request.urlopen(url + "health", timeout=5) as r:  # the server is still up
            assert json.loads(r.read())["sessions"] == 1
    finally:
        proc.kill()
        proc.wait(30)
