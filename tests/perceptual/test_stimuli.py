"""The built stimulus set: sizes, one noisy signal per cell, audio/video alignment, the cache, and the
manifest's refusals (tampered file, edited manifest, stale kit version, changed source)."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from scipy.signal import correlate

from perceptual.errors import ManifestError
from perceptual.stimuli import build, load_manifest
from tests.perceptual.harness import ARTIFACTS, grid_root, tiny_config

# Renders and muxes a real stimulus set (ffmpeg, OpenGL).
pytestmark = [pytest.mark.system, pytest.mark.slow]


def _probe(path) -> dict:
    out = subprocess.run(
        [
            "ffprobe",
            "-v",
            "error",
            "-show_entries",
            "stream=codec_type,width,height,start_time,duration",
            "-of",
            "json",
            str(path),
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return {s["codec_type"]: s for s in json.loads(out)["streams"]}


def _decoded(path, rate: int) -> np.ndarray:
    from assets.audio import read_audio

    return read_audio(path, rate_hz=rate)[0].astype(np.float64)


def test_every_stimulus_has_the_frame_size_and_streams_of_its_condition(stimuli):
    for st in stimuli.stimuli.values():
        s = _probe(stimuli.root / st["file"])
        assert "audio" in s
        if st["condition"] == "A":
            assert "video" not in s
        else:
            assert (s["video"]["width"], s["video"]["height"]) == (640, 480)
            # Both streams start together and last about as long (within one video frame).
            assert float(s["video"]["start_time"]) == float(s["audio"]["start_time"]) == 0.0
            assert abs(float(s["video"]["duration"]) - float(s["audio"]["duration"])) < 0.045


def test_a_n_and_s_of_one_cell_carry_the_same_noisy_speech_in_time(stimuli):
    cells = {}
    for st in stimuli.stimuli.values():
        if st["block"] == "grid":
            cells.setdefault((st["item"], st["snr_db"]), {})[st["condition"]] = stimuli.root / st["file"]
    (_item, _snr), files = next(iter(sorted(cells.items())))
    rate = 44100
    ref = _decoded(files["A"], rate)
    for cond in ("N", "S"):
        x = _decoded(files[cond], rate)
        n = min(len(ref), len(x))
        # Cross-correlation lag of the decoded audio against the audio-only stimulus: no shift.
        c = correlate(x[:n], ref[:n], mode="full", method="fft")[n - 1 - 441 : n + 441]
        lag = int(np.argmax(c)) - 441
        assert abs(lag) <= 1, f"{cond} audio is shifted by {lag} samples"
        assert np.corrcoef(x[:n], ref[:n])[0, 1] > 0.95  # the same noise sample, AAC-coded twice


def test_rebuilding_reuses_every_cached_file(stimuli):
    again = build(tiny_config(ARTIFACTS / "stimuli", grid_root()))
    assert again.data["stats"]["made"] == 0
    assert again.test_id == stimuli.test_id


@pytest.fixture()
def copy(stimuli, tmp_path):
    dst = tmp_path / "stim"
    shutil.copytree(stimuli.root, dst, ignore=shutil.ignore_patterns("cache"))
    return dst


def test_a_tampered_stimulus_file_is_refused_by_name(copy):
    man = json.loads((copy / "manifest.json").read_text())
    f = copy / next(iter(man["stimuli"].values()))["file"]
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0xFF
    f.write_bytes(bytes(data))
    with pytest.raises(ManifestError, match=f"tampered.*{f.name}"):
        load_manifest(copy)


def test_a_missing_stimulus_file_is_refused(copy):
    man = json.loads((copy / "manifest.json").read_text())
    (copy / next(iter(man["stimuli"].values()))["file"]).unlink()
    with pytest.raises(ManifestError, match="missing"):
        load_manifest(copy)


def test_an_edited_manifest_is_refused(copy):
    man = json.loads((copy / "manifest.json").read_text())
    st = next(iter(man["stimuli"].values()))
    st["truth"] = {"letter": "a", "digit": "0"}
    st["sha256"] = "0" * 64
    (copy / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(ManifestError, match="edited"):
        load_manifest(copy)


def test_a_manifest_of_another_kit_version_is_stale(copy):
    man = json.loads((copy / "manifest.json").read_text())
    man["kit_version"] = 0
    (copy / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(ManifestError, match="stale manifest"):
        load_manifest(copy)


def test_a_changed_source_makes_the_stimuli_stale(copy, tmp_path):
    man = json.loads((copy / "manifest.json").read_text())
    src = tmp_path / "source.mp4"
    src.write_bytes(b"changed since the build")
    man["sources"] = {str(src): "0" * 64}
    (copy / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(ManifestError, match=r"source .* changed"):
        load_manifest(copy)
